//! A `database.url` that lists several PostgreSQL hosts, the way libpq takes it
//! (`postgres://rackd@db1:5432,db2:5432/rackd?target_session_attrs=read-write`), and the
//! finder that keeps rackd's pool on the host that takes writes through a failover.
//!
//! Why rackd does this itself: sqlx's `PgConnectOptions` reads one host from a URL and no
//! `target_session_attrs` (sqlx-postgres 0.9, `options/parse.rs`), and its pool connects to
//! the one host it was given. A site whose PostgreSQL fails over to a promoted replica
//! would otherwise need a proxy or a DNS name moved by its failover tool; both remain fine
//! (one host in the URL), this is the alternative with nothing in between.
//!
//! Decisions:
//! - **The form.** Hosts in the URL's authority, separated by commas, each with its own
//!   port or none (`h1,h2:5433,[::1]:5434`); everything else (user, password, database,
//!   `sslmode` and the rest of the query) is the same for every host. libpq's other form,
//!   `?host=h1,h2&port=...`, is refused with a message naming this one.
//! - **`target_session_attrs`**: `any`, `read-write` or `primary`, as libpq means them
//!   (`read-write`: `transaction_read_only` is off; `primary`: not in recovery). Without
//!   it, `read-write` when the URL lists several hosts (the only reason to list them is to
//!   find the one that takes writes; libpq's `any` would settle on a replica), `any` with
//!   one (as before: no extra query per connection). `read-only`, `standby` and
//!   `prefer-standby` are refused: every rackd node writes.
//! - **Every new connection is checked** (`after_connect`) unless the attribute is `any`:
//!   a session on a read-only server is closed before anyone uses it, and the pool tries
//!   again with its backoff. So nothing rackd reads comes from a replica: not a job, and
//!   not the cluster's lease, whose row on a replica may be behind the primary's.
//! - **The finder** (several hosts): a task that keeps a connection of its own to the
//!   current host and asks it the check every [`CHECK_EVERY`]. When that fails (the host is
//!   gone, or takes no writes now) it tries the hosts in the order listed, each within
//!   [`CONNECT_TIMEOUT`], backing off from 50 ms to [`MAX_BACKOFF`] between rounds, until
//!   one passes; then points the pool at it (`Pool::set_connect_options`: the pool's next
//!   connection goes there) and logs the switch. It stays on a host while it passes, and
//!   does not go back to the first listed when that one returns, which after a failover
//!   is as a replica anyway.
//! - **Old connections are not handed out again**: once the current host failed its
//!   check, a connection the pool made before is closed when next asked for
//!   (`before_acquire`, by its age), instead of being tried on a dead or read-only server.
//!   Connections taken out of the pool (the job writer's, a `LISTEN`) end with their
//!   server, or fail on their first write to a read-only one, and are replaced from the
//!   pool.
//! - **What it cannot fence**: a primary that comes back *as a primary* after its replica
//!   was promoted. Two servers then take writes, and rackd nodes that chose differently
//!   (one switched, one restarted and took the first listed) would hold two leases in two
//!   databases. Rebuild the old primary as a replica (`pg_rewind` or a new base backup)
//!   before it serves again, as every failover tool does (docs/operations/standby.md).

use std::str::FromStr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use sqlx::postgres::{PgConnectOptions, PgConnection, PgPool};
use sqlx::{ConnectOptions, Connection};

/// How often the finder asks the current host.
pub const CHECK_EVERY: Duration = Duration::from_millis(250);
/// How long a host has to connect and answer the check.
pub const CONNECT_TIMEOUT: Duration = Duration::from_secs(2);
/// The longest wait between two rounds of the hosts.
pub const MAX_BACKOFF: Duration = Duration::from_secs(1);

/// What a server must be for rackd to use it (libpq's `target_session_attrs`, the values a
/// node that writes can take).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SessionAttrs {
    /// Any server that answers.
    Any,
    /// One whose sessions take writes (`transaction_read_only` off).
    ReadWrite,
    /// One not in recovery (`pg_is_in_recovery()` false).
    Primary,
}

impl SessionAttrs {
    /// As written in a URL.
    pub fn as_str(self) -> &'static str {
        match self {
            SessionAttrs::Any => "any",
            SessionAttrs::ReadWrite => "read-write",
            SessionAttrs::Primary => "primary",
        }
    }

    /// Whether the server of `conn` is one to use.
    pub async fn check(self, conn: &mut PgConnection) -> Result<bool, sqlx::Error> {
        match self {
            SessionAttrs::Any => conn.ping().await.map(|_| true),
            SessionAttrs::ReadWrite => {
                let read_only: String =
                    sqlx::query_scalar("SHOW transaction_read_only").fetch_one(conn).await?;
                Ok(read_only == "off")
            }
            SessionAttrs::Primary => {
                let recovering: bool =
                    sqlx::query_scalar("SELECT pg_is_in_recovery()").fetch_one(conn).await?;
                Ok(!recovering)
            }
        }
    }
}

/// Why a `postgres://` URL's hosts cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum HostsError {
    /// A `target_session_attrs` rackd does not take.
    #[error(
        "target_session_attrs={0} is not supported: rackd writes, so it takes any, read-write or primary \
         (read-write is the default with several hosts)"
    )]
    Attrs(String),
    /// Hosts listed in `?host=`.
    #[error(
        "list several hosts in the URL itself (postgres://USER@HOST1:PORT1,HOST2:PORT2/DB), not in ?host= or ?port="
    )]
    HostParameter,
    /// An empty host in the list (`h1,,h2`).
    #[error("an empty host in the URL's list of hosts")]
    EmptyHost,
    /// What the driver says of one host's URL.
    #[error("not a PostgreSQL URL: {0}")]
    Driver(String),
}

/// The hosts of a `postgres://` URL, each as a URL of its own.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Hosts {
    /// One URL per host, in the order listed, without `target_session_attrs` (which sqlx
    /// does not read): what the driver and `PgTls::of` are given.
    pub urls: Vec<String>,
    /// Each host as `HOST:PORT` (or as written), for logs.
    pub labels: Vec<String>,
    /// What a server must be.
    pub attrs: SessionAttrs,
}

impl Hosts {
    /// Reads the hosts of `url` (`postgres://` or `postgresql://`), each checked by the
    /// driver.
    pub fn parse(url: &str) -> Result<Hosts, HostsError> {
        let (scheme, rest) = url.split_once("://").unwrap_or(("postgres", url));
        let end = rest.find(['/', '?']).unwrap_or(rest.len());
        let (authority, tail) = rest.split_at(end);
        let (user, list) = match authority.rsplit_once('@') {
            Some((user, list)) => (format!("{user}@"), list),
            None => (String::new(), authority),
        };
        let (path, query) = tail.split_once('?').unwrap_or((tail, ""));
        // The query as written, less `target_session_attrs`.
        let mut attrs = None;
        let mut kept = Vec::new();
        for pair in query.split('&').filter(|p| !p.is_empty()) {
            let Some((key, value)) = form_urlencoded::parse(pair.as_bytes()).next() else { continue };
            match &*key {
                "target_session_attrs" => attrs = Some(value.into_owned()),
                "host" | "hostaddr" | "port" if value.contains(',') => return Err(HostsError::HostParameter),
                _ => kept.push(pair),
            }
        }
        let query = if kept.is_empty() { String::new() } else { format!("?{}", kept.join("&")) };
        let hosts: Vec<&str> = list.split(',').collect();
        if hosts.len() > 1 && hosts.iter().any(|h| h.is_empty()) {
            return Err(HostsError::EmptyHost);
        }
        let attrs = match attrs.as_deref().map(str::to_ascii_lowercase).as_deref() {
            None if hosts.len() > 1 => SessionAttrs::ReadWrite,
            None | Some("any") => SessionAttrs::Any,
            Some("read-write") => SessionAttrs::ReadWrite,
            Some("primary") => SessionAttrs::Primary,
            Some(other) => return Err(HostsError::Attrs(other.to_owned())),
        };
        let urls: Vec<String> =
            hosts.iter().map(|host| format!("{scheme}://{user}{host}{path}{query}")).collect();
        for url in &urls {
            PgConnectOptions::from_str(url).map_err(|e| HostsError::Driver(e.to_string()))?;
        }
        let labels = hosts.iter().map(|h| (*h).to_owned()).collect();
        Ok(Hosts { urls, labels, attrs })
    }
}

/// Since when connections the pool made before are not handed out again: the last time
/// the current host failed its check.
#[derive(Clone, Debug)]
pub struct Fresh(Arc<Mutex<Instant>>);

impl Fresh {
    /// Nothing old yet.
    pub fn new() -> Fresh {
        Fresh(Arc::new(Mutex::new(Instant::now())))
    }

    /// Connections made before now are old.
    fn mark(&self) {
        *self.0.lock().unwrap_or_else(|p| p.into_inner()) = Instant::now();
    }

    /// Whether a connection opened `age` ago was made after the last mark.
    pub fn keeps(&self, age: Duration) -> bool {
        age < self.0.lock().unwrap_or_else(|p| p.into_inner()).elapsed()
    }
}

impl Default for Fresh {
    fn default() -> Self {
        Fresh::new()
    }
}

/// A connection to `options` that passes `attrs`, within [`CONNECT_TIMEOUT`]; or why not,
/// in words for the log.
pub async fn connect_checked(
    options: &PgConnectOptions,
    attrs: SessionAttrs,
) -> Result<PgConnection, String> {
    let attempt = async {
        let mut conn = options.connect().await.map_err(|e| e.to_string())?;
        match attrs.check(&mut conn).await {
            Ok(true) => Ok(conn),
            Ok(false) => {
                let _ = conn.close().await;
                Err(format!("not {} (target_session_attrs)", attrs.as_str()))
            }
            Err(e) => Err(e.to_string()),
        }
    };
    tokio::time::timeout(CONNECT_TIMEOUT, attempt)
        .await
        .unwrap_or_else(|_| Err("no answer within 2 s".into()))
}

/// The first host (in the order listed) that passes `attrs`, with its connection; or what
/// each one said.
pub async fn first_passing(
    hosts: &[PgConnectOptions],
    labels: &[String],
    attrs: SessionAttrs,
) -> Result<(usize, PgConnection), Vec<String>> {
    let mut said = Vec::with_capacity(hosts.len());
    for (i, options) in hosts.iter().enumerate() {
        match connect_checked(options, attrs).await {
            Ok(conn) => return Ok((i, conn)),
            Err(why) => said.push(format!("{}: {why}", labels[i])),
        }
    }
    Err(said)
}

/// The finder (see the module doc): keeps `pool` on a host of `hosts` that passes
/// `attrs`, starting on `current` (whose connection `watch` is), until the pool closes.
pub async fn find(
    pool: PgPool,
    hosts: Vec<PgConnectOptions>,
    labels: Vec<String>,
    attrs: SessionAttrs,
    mut current: usize,
    mut watch: Option<PgConnection>,
    fresh: Fresh,
) {
    loop {
        if pool.is_closed() {
            return;
        }
        let passes = match watch.as_mut() {
            Some(conn) => tokio::time::timeout(CONNECT_TIMEOUT, attrs.check(conn))
                .await
                .is_ok_and(|r| r.is_ok_and(|ok| ok)),
            None => false,
        };
        if passes {
            tokio::time::sleep(CHECK_EVERY).await;
            continue;
        }
        drop(watch.take());
        fresh.mark();
        tracing::warn!(
            host = %labels[current],
            target_session_attrs = attrs.as_str(),
            "the database host is gone or no longer fits; trying the hosts of database.url in order"
        );
        let lost = Instant::now();
        let mut backoff = Duration::from_millis(50);
        let (found, conn) = loop {
            if pool.is_closed() {
                return;
            }
            match first_passing(&hosts, &labels, attrs).await {
                Ok(found) => break found,
                Err(said) => tracing::debug!(hosts = ?said, "no database host fits yet"),
            }
            tokio::time::sleep(backoff).await;
            backoff = (backoff * 2).min(MAX_BACKOFF);
        };
        if found != current {
            pool.set_connect_options(hosts[found].clone());
            fresh.mark();
            tracing::warn!(
                from = %labels[current],
                to = %labels[found],
                after_ms = lost.elapsed().as_millis() as u64,
                "database host switched: the pool connects to the new one from now on"
            );
            current = found;
        } else {
            tracing::info!(
                host = %labels[current],
                after_ms = lost.elapsed().as_millis() as u64,
                "the database host answers again"
            );
        }
        watch = Some(conn);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn several_hosts_are_one_url_each_and_read_write_by_default() {
        let hosts = Hosts::parse("postgres://rackd:pw@db1:5432,db2:5433/rackd?sslmode=require").unwrap();
        assert_eq!(
            hosts.urls,
            [
                "postgres://rackd:pw@db1:5432/rackd?sslmode=require",
                "postgres://rackd:pw@db2:5433/rackd?sslmode=require"
            ]
        );
        assert_eq!(hosts.labels, ["db1:5432", "db2:5433"]);
        assert_eq!(hosts.attrs, SessionAttrs::ReadWrite);
        let hosts = Hosts::parse("postgresql://u@[::1]:5432,h2/db?target_session_attrs=any").unwrap();
        assert_eq!(hosts.urls, ["postgresql://u@[::1]:5432/db", "postgresql://u@h2/db"]);
        assert_eq!(hosts.attrs, SessionAttrs::Any);
        let hosts =
            Hosts::parse("postgres://u@h1,h2/db?target_session_attrs=primary&sslmode=disable").unwrap();
        assert_eq!(hosts.attrs, SessionAttrs::Primary);
        assert_eq!(hosts.urls[1], "postgres://u@h2/db?sslmode=disable");
    }

    #[test]
    fn one_host_is_as_before() {
        let url = "postgres://u:p@db.plant:5432/rackd?sslmode=verify-full&sslrootcert=%2Fetc%2Fca.pem";
        let hosts = Hosts::parse(url).unwrap();
        assert_eq!(hosts.urls, [url]);
        assert_eq!(hosts.attrs, SessionAttrs::Any, "libpq's default with one host");
        let hosts = Hosts::parse("postgres:///rackd?host=/run/postgresql").unwrap();
        assert_eq!(hosts.urls, ["postgres:///rackd?host=/run/postgresql"]);
        let hosts = Hosts::parse("postgres://u@h/db?target_session_attrs=read-write").unwrap();
        assert_eq!((hosts.urls[0].as_str(), hosts.attrs), ("postgres://u@h/db", SessionAttrs::ReadWrite));
    }

    #[test]
    fn what_rackd_cannot_use_is_refused_in_words() {
        for attrs in ["standby", "read-only", "prefer-standby", "x"] {
            let e = Hosts::parse(&format!("postgres://u@h1,h2/db?target_session_attrs={attrs}")).unwrap_err();
            assert!(matches!(e, HostsError::Attrs(_)), "{attrs}: {e}");
        }
        let e = Hosts::parse("postgres://u@/db?host=h1,h2&port=1,2").unwrap_err();
        assert!(matches!(e, HostsError::HostParameter), "{e}");
        assert!(matches!(Hosts::parse("postgres://u@h1,,h2/db"), Err(HostsError::EmptyHost)));
        assert!(matches!(Hosts::parse("postgres://u@h1:x,h2/db"), Err(HostsError::Driver(_))));
    }

    #[test]
    fn a_mark_makes_older_connections_old() {
        let fresh = Fresh::new();
        std::thread::sleep(Duration::from_millis(5));
        assert!(fresh.keeps(Duration::ZERO), "made after the mark");
        fresh.mark();
        assert!(!fresh.keeps(Duration::from_millis(5)), "made before the mark");
    }
}
