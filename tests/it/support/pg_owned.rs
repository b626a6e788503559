//! PostgreSQL servers a test owns, to crash, restart and fail over (issue 53). The shared
//! cluster of [`super::postgres`] serves hundreds of tests at once and is never stopped;
//! these are the test's alone.
//!
//! - [`Owned::primary`] makes a cluster (initdb) and starts it on a port of its own, picked
//!   as the shared cluster's is (below the ephemeral range, [`super::postgres`]).
//! - [`Owned::crash`] stops a server as `pg_ctl stop -m immediate` does: SIGQUIT to the
//!   postmaster, which kills its backends at once, without a checkpoint, so the next start
//!   runs crash recovery. [`Owned::start`] starts it again on the same port, and says when
//!   it answered (`pg_isready`, asked every 20 ms), which the tests time recovery from.
//! - [`Owned::replica_of`] makes a streaming replica of a primary (`pg_basebackup -R`, a
//!   fast checkpoint) and waits until it streams; [`Owned::synchronous`] makes a primary
//!   wait for a replica before it acknowledges a commit (`synchronous_standby_names =
//!   '*'`, `synchronous_commit=on`), so what a client was told is committed is on the
//!   replica; [`Owned::promote`] promotes a replica (`pg_promote()`, waiting until it
//!   takes writes); [`Owned::rebuild_from`] makes a crashed primary the new primary's
//!   replica (a fresh base backup into its folder, on its old port).
//!
//! `synchronous_standby_names` is set with `ALTER SYSTEM`, not on the command line (which
//! a reload cannot change), and a base backup copies `postgresql.auto.conf`: the copy's
//! setting is removed, so a promoted replica does not wait for a replica it does not have
//! yet.
//!
//! The servers run with the shared cluster's settings for speed (`fsync=off`: the tests
//! kill processes, not the machine), but `synchronous_commit=on`, which synchronous
//! replication needs. Their folders are under the temp folder's `rackd-pgown-PID`, removed
//! by the next run (as the shared cluster's); a server is stopped when dropped.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use sqlx::Connection;

use super::postgres::{self, Running, Served};

/// Each server's settings, after the tests' own.
const SETTINGS: &[&str] = &["synchronous_commit=on", "max_connections=100", "wal_level=replica"];

static NEXT: AtomicU32 = AtomicU32::new(1);

/// A PostgreSQL server of the test's own.
pub struct Owned {
    /// Its port on 127.0.0.1, the same across restarts.
    pub port: u16,
    bin: PathBuf,
    as_root: bool,
    /// Its folder: the Unix socket, the log, `data`.
    dir: PathBuf,
    running: Option<Running>,
}

impl Owned {
    /// A new cluster, started, with an empty database `name`.
    pub async fn primary(name: &str) -> Owned {
        let server = tokio::task::block_in_place(|| {
            let mut server = Owned::folder().unwrap_or_else(|e| panic!("a PostgreSQL server: {e}"));
            postgres::initdb(&server.bin, server.as_root, &server.data()).unwrap_or_else(|e| panic!("{e}"));
            server.first_start().unwrap_or_else(|e| panic!("starting PostgreSQL: {e}"));
            server
        });
        server.admin(&format!("CREATE DATABASE {name}")).await;
        server
    }

    /// A streaming replica of `primary`, started and streaming.
    pub async fn replica_of(primary: &Owned) -> Owned {
        let server = tokio::task::block_in_place(|| {
            let mut server = Owned::folder().unwrap_or_else(|e| panic!("a PostgreSQL server: {e}"));
            server.base_backup(primary.port).unwrap_or_else(|e| panic!("{e}"));
            server.first_start().unwrap_or_else(|e| panic!("starting the replica: {e}"));
            server
        });
        primary.streaming_to(&server).await;
        server
    }

    /// The URL of database `name` on this server alone.
    pub fn url(&self, name: &str) -> String {
        format!("postgres://postgres@127.0.0.1:{}/{name}", self.port)
    }

    /// Stops the server at once (`-m immediate`), and waits until it has exited.
    pub async fn crash(&mut self) {
        let Some(running) = self.running.take() else { panic!("the server on {} is not running", self.port) };
        quit(running.pid);
        tokio::task::block_in_place(|| {
            running.exited.recv_timeout(Duration::from_secs(30)).expect("the server exits after SIGQUIT")
        })
        .unwrap_or_else(|e| panic!("waiting for the server: {e}"));
    }

    /// Starts the server again on its port; answers when it first answered.
    pub async fn start(&mut self) -> Instant {
        assert!(self.running.is_none(), "the server on {} runs already", self.port);
        tokio::task::block_in_place(|| {
            match postgres::serve(&self.bin, self.as_root, &self.dir, &self.data(), None, self.port, SETTINGS)
            {
                Ok(Served::Ready(running)) => {
                    self.running = Some(running);
                    Instant::now()
                }
                Ok(Served::PortTaken) => panic!("port {} was taken while the server was down", self.port),
                Err(e) => panic!("restarting PostgreSQL on {}: {e}", self.port),
            }
        })
    }

    /// Promotes this replica, and waits until it takes writes.
    pub async fn promote(&self) {
        let mut admin = self.connect().await;
        let done: bool =
            sqlx::query_scalar("SELECT pg_promote(true, 60)").fetch_one(&mut admin).await.unwrap();
        assert!(done, "the replica on {} did not promote within 60 s", self.port);
        // The setting a replica was copied with is removed; one of a server promoted before
        // (this one was the primary once) goes with a reset.
        self.admin("ALTER SYSTEM RESET synchronous_standby_names").await;
        self.admin("SELECT pg_reload_conf()").await;
    }

    /// Makes this crashed server a streaming replica of `primary` (a base backup into its
    /// folder), on its old port.
    pub async fn rebuild_from(&mut self, primary: &Owned) {
        assert!(self.running.is_none(), "rebuild a stopped server");
        tokio::task::block_in_place(|| {
            std::fs::remove_dir_all(self.data()).expect("removing the old data folder");
            self.base_backup(primary.port).unwrap_or_else(|e| panic!("{e}"));
        });
        self.start().await;
        primary.streaming_to(self).await;
    }

    /// From now on a commit on this primary is acknowledged once a replica has it.
    pub async fn synchronous(&self) {
        self.admin("ALTER SYSTEM SET synchronous_standby_names = '*'").await;
        self.admin("SELECT pg_reload_conf()").await;
        let sql = "SELECT COUNT(*) FROM pg_stat_replication WHERE sync_state = 'sync'";
        let mut admin = self.connect().await;
        super::eventually("a synchronous replica", Duration::from_secs(20), async || {
            let n: i64 = sqlx::query_scalar(sql).fetch_one(&mut admin).await.unwrap();
            if n > 0 { Ok(()) } else { Err(n) }
        })
        .await;
    }

    /// Whether the server is in recovery (a replica).
    pub async fn in_recovery(&self) -> bool {
        let mut admin = self.connect().await;
        sqlx::query_scalar("SELECT pg_is_in_recovery()").fetch_one(&mut admin).await.unwrap()
    }

    /// Waits until `replica` streams from this server.
    async fn streaming_to(&self, replica: &Owned) {
        let mut admin = self.connect().await;
        let sql = "SELECT COUNT(*) FROM pg_stat_replication WHERE state = 'streaming'";
        let what = format!("the replica on {} to stream from {}", replica.port, self.port);
        super::eventually(what, Duration::from_secs(20), async || {
            let n: i64 = sqlx::query_scalar(sql).fetch_one(&mut admin).await.unwrap();
            if n > 0 { Ok(()) } else { Err(n) }
        })
        .await;
    }

    /// Runs `sql` on the maintenance database.
    async fn admin(&self, sql: &str) {
        let mut admin = self.connect().await;
        sqlx::raw_sql(sqlx::AssertSqlSafe(sql.to_owned()))
            .execute(&mut admin)
            .await
            .unwrap_or_else(|e| panic!("{sql} on {}: {e}", self.port));
    }

    async fn connect(&self) -> sqlx::PgConnection {
        sqlx::PgConnection::connect(&self.url("postgres")).await.expect("an admin connection")
    }

    /// A new folder under `rackd-pgown-PID` (earlier runs' removed), no server yet.
    fn folder() -> Result<Owned, String> {
        let (bin, as_root) = (postgres::binaries()?, postgres::as_root()?);
        let parent = std::env::temp_dir().join(format!("rackd-pgown-{}", std::process::id()));
        if NEXT.load(Ordering::Relaxed) == 1 {
            postgres::remove_stale("rackd-pgown");
        }
        if !parent.exists() {
            postgres::folder(&parent, as_root)?;
        }
        let dir = postgres::folder(&parent.join(NEXT.fetch_add(1, Ordering::Relaxed).to_string()), as_root)?;
        Ok(Owned { port: 0, bin, as_root, dir, running: None })
    }

    fn data(&self) -> PathBuf {
        self.dir.join("data")
    }

    /// The first start, on a free port (another if something took it first).
    fn first_start(&mut self) -> Result<(), String> {
        for _ in 0..5 {
            let port = postgres::outside_ephemeral_range()?;
            match postgres::serve(&self.bin, self.as_root, &self.dir, &self.data(), None, port, SETTINGS)? {
                Served::Ready(running) => {
                    (self.port, self.running) = (port, Some(running));
                    return Ok(());
                }
                Served::PortTaken => continue,
            }
        }
        Err("every port tried was taken".into())
    }

    /// `pg_basebackup -R` of the server on `port` into this folder's `data`, without the
    /// primary's `synchronous_standby_names` (see the module doc).
    fn base_backup(&self, port: u16) -> Result<(), String> {
        let out = postgres::command(&self.bin.join("pg_basebackup"), self.as_root)
            .args(["-h", "127.0.0.1", "-p", &port.to_string(), "-U", "postgres", "-R", "-X", "stream"])
            .args(["-c", "fast", "-D"])
            .arg(self.data())
            .output()
            .map_err(|e| format!("pg_basebackup: {e}"))?;
        if !out.status.success() {
            return Err(format!("pg_basebackup failed: {}", String::from_utf8_lossy(&out.stderr)));
        }
        let auto = self.data().join("postgresql.auto.conf");
        let text = std::fs::read_to_string(&auto).map_err(|e| e.to_string())?;
        let kept: String = text
            .lines()
            .filter(|l| !l.contains("synchronous_standby_names"))
            .map(|l| format!("{l}\n"))
            .collect();
        std::fs::write(&auto, kept).map_err(|e| e.to_string())
    }
}

/// SIGQUIT to a postmaster: PostgreSQL's immediate shutdown.
fn quit(pid: u32) {
    let pid = rustix::process::Pid::from_raw(pid as i32).expect("a pid");
    rustix::process::kill_process(pid, rustix::process::Signal::QUIT).expect("signalling the postmaster");
}

impl Drop for Owned {
    fn drop(&mut self) {
        if let Some(running) = self.running.take() {
            quit(running.pid);
            let _ = running.exited.recv_timeout(Duration::from_secs(10));
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}
