//! When the store cannot commit: why (a full disk, a read-only store, an I/O error, a
//! database that does not answer), since when, and who is told.
//!
//! The job writer tells [`StoreFault`] how each group went ([`StoreFault::observe`]): a
//! group that failed for one of these [`Cause`]s (as a whole, or any of its requests) sets
//! the fault, the first group that commits something again clears it. Everyone reads it
//! from there: `/readyz` and `GET /api/v1/health` (not ready, `store` names the cause), the
//! API's 503s (`store_full` or `store_unavailable`, with `Retry-After`), `/metrics` (failed
//! commits by cause), and the `store` alarm, which `service::store_alarm` records on device
//! `store`.
//!
//! Decisions:
//! - **What counts.** Only what the database says about itself: SQLite's `SQLITE_FULL`,
//!   `SQLITE_READONLY`, `SQLITE_IOERR` (and `SQLITE_CANTOPEN`, a file gone), PostgreSQL's
//!   classes 53 (insufficient resources: `disk_full`), 58 (system errors: `io_error`), 25006
//!   (a read-only transaction: a standby promoted the other way), 57P0x (shut down,
//!   restarting) and 08 (connection), and a connection that is lost or not to be had. A
//!   request the database refuses for what it asks (a constraint, a state it is not in)
//!   is the request's failure, not the store's.
//! - **Never an answer that looks like success.** A group that failed answered every
//!   request in it with an error; nothing of it is acted on (see
//!   [`super::writer`]'s `durable` module: a failed sync stops the writer, as a failed
//!   fsync stops PostgreSQL, since the kernel may have dropped what it could not write).
//! - **Cleared by a commit, not by time.** A disk that has room again says nothing until
//!   the next commit; the writer commits the moment anything is sent to it, and the alarm's
//!   own record is one such commit. Only a commit that wrote something counts: a group whose
//!   requests were all refused for their own reasons (a 404, a 409) commits nothing, and
//!   SQLite's `COMMIT` of nothing never touches the disk, so it says nothing of it
//!   (`writer`'s `durable::outcome`).

use std::sync::Arc;

use tokio::sync::watch;

use crate::domain::time::now_ms;

/// Why the store cannot commit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Cause {
    /// The disk (or the database's quota) is full.
    Full,
    /// The store takes no writes: a read-only file or filesystem, a PostgreSQL standby.
    ReadOnly,
    /// The disk failed to read or write.
    Io,
    /// The database does not answer (PostgreSQL restarting or unreachable, a connection
    /// cut).
    Unreachable,
}

impl Cause {
    /// Every cause, in the order of their alarm codes.
    pub const ALL: [Cause; 4] = [Cause::Full, Cause::ReadOnly, Cause::Io, Cause::Unreachable];

    /// Its name in metrics, health and logs.
    pub fn as_str(self) -> &'static str {
        match self {
            Cause::Full => "full",
            Cause::ReadOnly => "read_only",
            Cause::Io => "io_error",
            Cause::Unreachable => "unreachable",
        }
    }

    /// The code of its `store` alarm.
    pub fn code(self) -> u16 {
        match self {
            Cause::Full => 0,
            Cause::ReadOnly => 1,
            Cause::Io => 2,
            Cause::Unreachable => 3,
        }
    }

    /// In words, for people (no driver text).
    pub fn words(self) -> &'static str {
        match self {
            Cause::Full => "the disk that holds the database is full",
            Cause::ReadOnly => "the database takes no writes (read-only)",
            Cause::Io => "the disk that holds the database fails to read or write",
            Cause::Unreachable => "the database does not answer",
        }
    }

    /// The code of the API's 503 while the store cannot commit for this cause.
    pub fn api_code(self) -> &'static str {
        match self {
            Cause::Full => "store_full",
            _ => "store_unavailable",
        }
    }

    /// The cause of `e`, if it is the store's own failure (see the module doc).
    pub fn of(e: &sqlx::Error) -> Option<Cause> {
        match e {
            sqlx::Error::Io(io) => Some(Cause::of_io(io)),
            sqlx::Error::PoolTimedOut | sqlx::Error::PoolClosed | sqlx::Error::WorkerCrashed => {
                Some(Cause::Unreachable)
            }
            sqlx::Error::Tls(_) | sqlx::Error::Protocol(_) => Some(Cause::Unreachable),
            sqlx::Error::Database(db) => Cause::of_code(db.code().as_deref()?),
            _ => None,
        }
    }

    /// An operating system's error: a full disk, a read-only filesystem, a connection, or
    /// else the disk's.
    fn of_io(e: &std::io::Error) -> Cause {
        use std::io::ErrorKind as K;
        match e.kind() {
            K::StorageFull | K::QuotaExceeded => Cause::Full,
            K::ReadOnlyFilesystem | K::PermissionDenied => Cause::ReadOnly,
            K::ConnectionRefused
            | K::ConnectionReset
            | K::ConnectionAborted
            | K::NotConnected
            | K::BrokenPipe
            | K::TimedOut
            | K::UnexpectedEof
            | K::HostUnreachable
            | K::NetworkUnreachable
            | K::NetworkDown => Cause::Unreachable,
            _ => Cause::Io,
        }
    }

    /// A database's error code: PostgreSQL's SQLSTATE (always five characters, digits
    /// alone in many) or SQLite's (a number of at most four digits, the primary code in the
    /// low byte of an extended one).
    fn of_code(code: &str) -> Option<Cause> {
        if let Some(n) = code.parse::<u32>().ok().filter(|_| code.len() < 5) {
            return match n & 0xff {
                13 => Some(Cause::Full),
                8 => Some(Cause::ReadOnly),
                10 | 11 | 14 | 26 => Some(Cause::Io),
                _ => None,
            };
        }
        match code {
            "53100" => Some(Cause::Full),
            "25006" => Some(Cause::ReadOnly),
            c if c.starts_with("53") || c.starts_with("58") => Some(Cause::Io),
            c if c.starts_with("57P") || c.starts_with("08") => Some(Cause::Unreachable),
            _ => None,
        }
    }
}

/// The store cannot commit: why, and since when (Unix ms).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fault {
    /// Why (the latest failure's cause).
    pub cause: Cause,
    /// Since the first failure of this spell.
    pub since_ms: i64,
}

/// Whether the store commits, shared by the writer (which tells) and everyone who reads it.
#[derive(Clone)]
pub struct StoreFault {
    state: Arc<watch::Sender<Option<Fault>>>,
}

impl Default for StoreFault {
    fn default() -> Self {
        StoreFault { state: Arc::new(watch::Sender::new(None)) }
    }
}

impl StoreFault {
    /// How a group went: `Ok` once something committed, `Err` with the cause of a failure.
    pub fn observe(&self, outcome: Result<(), Cause>) {
        self.state.send_if_modified(|state| match (outcome, *state) {
            (Ok(()), None) => false,
            (Ok(()), Some(_)) => {
                *state = None;
                true
            }
            (Err(cause), Some(f)) if f.cause == cause => false,
            (Err(cause), Some(f)) => {
                *state = Some(Fault { cause, since_ms: f.since_ms });
                true
            }
            (Err(cause), None) => {
                *state = Some(Fault { cause, since_ms: now_ms() });
                true
            }
        });
    }

    /// The fault now, if the store cannot commit.
    pub fn current(&self) -> Option<Fault> {
        *self.state.borrow()
    }

    /// Follows the fault as it changes.
    pub fn subscribe(&self) -> watch::Receiver<Option<Fault>> {
        self.state.subscribe()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_databases_own_codes_are_told_from_a_requests() {
        assert_eq!(Cause::of_code("13"), Some(Cause::Full), "SQLITE_FULL");
        assert_eq!(Cause::of_code("778"), Some(Cause::Io), "SQLITE_IOERR_WRITE");
        assert_eq!(Cause::of_code("1032"), Some(Cause::ReadOnly), "SQLITE_READONLY_DBMOVED");
        assert_eq!(Cause::of_code("2067"), None, "SQLITE_CONSTRAINT_UNIQUE: the request's");
        assert_eq!(Cause::of_code("53100"), Some(Cause::Full), "disk_full");
        assert_eq!(Cause::of_code("57P01"), Some(Cause::Unreachable), "admin_shutdown");
        assert_eq!(Cause::of_code("08006"), Some(Cause::Unreachable), "connection_failure");
        assert_eq!(Cause::of_code("25006"), Some(Cause::ReadOnly));
        assert_eq!(Cause::of_code("23505"), None, "unique_violation: the request's");
        let full = std::io::Error::from(std::io::ErrorKind::StorageFull);
        assert_eq!(Cause::of(&sqlx::Error::Io(full)), Some(Cause::Full));
        assert_eq!(Cause::of(&sqlx::Error::PoolTimedOut), Some(Cause::Unreachable));
        assert_eq!(Cause::of(&sqlx::Error::RowNotFound), None);
    }

    #[test]
    fn a_spell_keeps_its_start_and_a_commit_ends_it() {
        let fault = StoreFault::default();
        let mut seen = fault.subscribe();
        fault.observe(Ok(()));
        assert!(!seen.has_changed().unwrap() && fault.current().is_none());
        fault.observe(Err(Cause::Full));
        let first = fault.current().unwrap();
        assert!(seen.has_changed().unwrap());
        seen.mark_unchanged();
        fault.observe(Err(Cause::Full));
        assert!(!seen.has_changed().unwrap(), "the same cause again changes nothing");
        fault.observe(Err(Cause::Io));
        assert_eq!(fault.current(), Some(Fault { cause: Cause::Io, since_ms: first.since_ms }));
        fault.observe(Ok(()));
        assert_eq!(fault.current(), None);
    }
}
