//! SQLite storage through sqlx: jobs, job history, locations and the event log.
//!
//! The database runs in WAL mode with `synchronous=FULL`, so a commit is on disk when it
//! returns: a 201 means the job survives a power cut. Every change to jobs goes through one
//! writer task ([`writer::Writer`]) that commits many requests per transaction.

pub mod alarms;
pub mod controls;
pub mod events;
pub mod jobs;
pub mod locations;
pub mod stats;
pub mod writer;

use std::path::Path;
use std::str::FromStr;
use std::time::Duration;

use sqlx::SqlitePool;
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions, SqliteSynchronous};

pub use jobs::{Job, JobEvent, JobFilter};

/// The migrations in `migrations/`, embedded in the binary.
pub static MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("./migrations");

/// Opens (creating if needed) the database at `path` and applies pending migrations.
pub async fn open(path: &Path, busy_timeout: Duration) -> Result<SqlitePool, sqlx::Error> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        if let Err(e) = std::fs::create_dir_all(dir) {
            // A folder to create inside one rackd cannot write (a root-owned volume with
            // the database in a subfolder): name that folder, not just "permission denied".
            if let Some(existing) = dir.ancestors().find(|a| a.is_dir()) {
                writable(existing)?;
            }
            return Err(e.into());
        }
        writable(dir)?;
    }
    let options = SqliteConnectOptions::from_str("sqlite:")?
        .filename(path)
        .create_if_missing(true)
        .journal_mode(SqliteJournalMode::Wal)
        .synchronous(SqliteSynchronous::Full)
        .busy_timeout(busy_timeout)
        .foreign_keys(true);
    let pool = SqlitePoolOptions::new().max_connections(8).connect_with(options).await?;
    MIGRATOR.run(&pool).await?;
    Ok(pool)
}

/// Checks that rackd may create files in `dir` (SQLite needs the database's directory for
/// its journal), so that a volume owned by another user is named with the fix instead of
/// SQLite's "unable to open database file". The message names the directory, its owner and
/// rackd's own uid, and the fixes a container user has: give the directory to rackd's uid,
/// mount a named volume (which the image prepares for uid 10001), or run as the owner.
fn writable(dir: &Path) -> std::io::Result<()> {
    use std::os::unix::fs::MetadataExt;
    let probe = dir.join(format!(".rackd-write-test-{}", std::process::id()));
    match std::fs::OpenOptions::new().write(true).create_new(true).open(&probe) {
        Ok(_) => std::fs::remove_file(&probe),
        Err(e) if e.kind() == std::io::ErrorKind::PermissionDenied => {
            let meta = std::fs::metadata(dir)?;
            // /proc/self belongs to the process's effective user.
            let me =
                std::fs::metadata("/proc/self").map(|m| m.uid().to_string()).unwrap_or_else(|_| "?".into());
            let (dir, owner) = (dir.display(), meta.uid());
            // Running as root to write a root-owned folder is not a fix worth offering.
            let as_owner = if owner == 0 {
                String::new()
            } else {
                format!(", or run rackd as uid {owner} (--user {owner})")
            };
            Err(std::io::Error::new(
                e.kind(),
                format!(
                    "cannot write in {dir}: it belongs to uid {owner} (mode {:o}) and rackd runs as uid {me}; \
                     give it to uid {me} (chown {me} {dir}, on the host folder of a bind mount), or mount a \
                     named volume there (-v rackd-data:{dir}; the image runs as uid 10001){as_owner}",
                    meta.mode() & 0o7777,
                ),
            ))
        }
        Err(e) => Err(e),
    }
}

/// Why the store is not ready.
#[derive(Debug, thiserror::Error)]
pub enum NotReady {
    /// The database does not answer.
    #[error("the database does not answer: {0}")]
    Unreachable(#[from] sqlx::Error),
    /// A migration this version needs is not applied.
    #[error("migration {version} ({description}) is not applied")]
    Migration {
        /// The migration's version.
        version: i64,
        /// What it does.
        description: String,
    },
}

/// Whether the database answers and every embedded migration is applied.
pub async fn ready(pool: &SqlitePool) -> Result<(), NotReady> {
    let applied: Vec<i64> =
        sqlx::query_scalar("SELECT version FROM _sqlx_migrations WHERE success = 1").fetch_all(pool).await?;
    match MIGRATOR.iter().find(|m| !applied.contains(&m.version)) {
        Some(m) => Err(NotReady::Migration { version: m.version, description: m.description.to_string() }),
        None => Ok(()),
    }
}
