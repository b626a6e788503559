//! A commit whose answer was lost, on PostgreSQL: resolved by reading what landed.
//!
//! A `COMMIT` sent over a connection that breaks before its answer comes back (a restarted
//! or failed-over server, a cut link, a terminated session) may have committed or not. The
//! writer cannot answer such a group either way by guessing: failing a group that landed
//! would have a WMS post its jobs again (twice) and leave the machines' reports committed
//! but never acted on; answering one that did not land would lose them.
//!
//! Decisions:
//! - **Every group leaves a mark.** On PostgreSQL each group's transaction ends with an
//!   upsert of the writer's row in `rackd_commits`: the writer's id (drawn at random when
//!   it starts) and a count of its commits, sent in the same message as the `COMMIT`, so it
//!   costs no round trip. The row says which of the writer's groups committed last.
//! - **Any failure of the `COMMIT` itself is unsure**, whatever the error says: a broken
//!   connection, a restarted server, a `FATAL` from a terminated session, as well as a
//!   constraint checked at commit (for which the answer is then "not landed"). A failure
//!   before the `COMMIT` was sent is not: nothing of the group can have committed.
//! - **Settled before anything else is written.** The writer connects afresh (through the
//!   pool, so to whichever server is the primary now), makes sure the old session is gone
//!   (it may still be reading a `COMMIT` the broken link delivered: it is terminated,
//!   which a role may do to its own sessions, and waited for), then reads its row. Until
//!   then it commits nothing else, since the next group's ids and event numbers depend on
//!   it; new requests wait in its queue (or are refused as overloaded when it is full).
//! - **The old session is named by its process id and its start time**, read when the
//!   connection was taken: after a failover another server may run a session with the same
//!   process id, which must not be taken for it.
//! - **Landed: the group is answered as committed** (its events published, its jobs
//!   handed to the dispatcher, its callers told), as if the answer had come. Not landed:
//!   it fails as any failed group does, and nothing of it was written.
//! - **While the database is down the writer keeps trying** (every 50 ms, doubling to
//!   1 s), for as long as anyone can still send it work; it gives up only when every
//!   handle is gone (rackd stops), failing the group as unknown.
//! - **After a failover the new primary holds the truth.** With synchronous replication
//!   (`synchronous_commit = on` and the replica in `synchronous_standby_names`) a `COMMIT`
//!   that returned is on the replica, and an unsure one is there or not as its row says.
//!   With asynchronous replication a group that committed on the old primary may be
//!   missing on the new one; its row then says "not landed" too, and the group is failed:
//!   consistent with what the database now holds (see `docs/operations/standby.md`).
//!
//! SQLite has no such case: its `COMMIT` is the library's own answer in this process.

use std::time::Duration;

use sqlx::PgConnection;

use super::apply::{Answer, Next, Out};
use crate::store::Pool;

/// The mark a writer leaves in each group it commits (see the module doc).
#[derive(Clone, Copy, Debug)]
pub(super) struct Token {
    writer: i64,
    count: i64,
}

impl Default for Token {
    fn default() -> Token {
        // Positive, so a writer's id reads plainly in the table.
        Token { writer: rand::random::<i64>() & i64::MAX, count: 0 }
    }
}

impl Token {
    /// The next group's count, and the statement that records it (run in the group's
    /// transaction, before its `COMMIT`).
    pub(super) fn next(&mut self) -> (i64, String) {
        self.count += 1;
        let sql = format!(
            "INSERT INTO rackd_commits (writer, token, at) VALUES ({}, {}, now()) \
             ON CONFLICT (writer) DO UPDATE SET token = EXCLUDED.token, at = EXCLUDED.at",
            self.writer, self.count
        );
        (self.count, sql)
    }
}

/// Removes the rows of writers that committed nothing for a week (gone, or idle: an idle
/// writer's next group writes its row again).
pub(super) async fn prune(conn: &mut PgConnection) -> Result<(), sqlx::Error> {
    let sql = "DELETE FROM rackd_commits WHERE at < now() - interval '7 days'";
    sqlx::query(sql).execute(conn).await.map(drop)
}

/// A database session, as the server names it.
#[derive(Clone, Debug)]
pub(super) struct Session {
    pid: i32,
    started: String,
}

/// The session of `conn`.
pub(super) async fn session(conn: &mut PgConnection) -> Result<Session, sqlx::Error> {
    let sql = "SELECT pid, backend_start::text FROM pg_stat_activity WHERE pid = pg_backend_pid()";
    let (pid, started): (i32, String) = sqlx::query_as(sql).fetch_one(conn).await?;
    Ok(Session { pid, started })
}

/// A group whose `COMMIT` failed: what it would answer had it landed.
pub(super) struct Unsure {
    /// Its answers, as if it committed.
    pub(super) answers: Vec<Answer>,
    /// What it did.
    pub(super) out: Out,
    /// The writer's numbering after it.
    pub(super) next: Next,
    /// Whether it read a reference stored already (`None`: applied request by request).
    pub(super) stored: Option<bool>,
    /// Its mark.
    pub(super) token: Token,
    /// The session that sent its `COMMIT`.
    pub(super) session: Option<Session>,
    /// How the `COMMIT` failed.
    pub(super) error: sqlx::Error,
}

/// Whether `unsure` landed, read from the database (see the module doc); `None` when every
/// handle of the writer is gone (`closed`) before it could be told. `unreachable` is called
/// once if a try cannot reach the database: the store is down, and everyone is to know it
/// now rather than when it is settled.
pub(super) async fn landed(
    pool: &Pool,
    unsure: &Unsure,
    closed: impl Fn() -> bool,
    unreachable: impl Fn(),
) -> Option<bool> {
    let Pool::Postgres(pool) = pool else { return Some(false) };
    let mut wait = Duration::from_millis(50);
    let mut told = false;
    loop {
        match look(pool, unsure).await {
            Ok(landed) => {
                tracing::warn!(
                    error = %unsure.error,
                    landed,
                    "a commit's answer was lost; read from the database whether it landed"
                );
                return Some(landed);
            }
            Err(e) => {
                tracing::warn!(error = %e, "cannot yet read whether a commit whose answer was lost landed");
                if !std::mem::replace(&mut told, true) {
                    unreachable();
                }
            }
        }
        if closed() {
            return None;
        }
        tokio::time::sleep(wait).await;
        wait = (wait * 2).min(Duration::from_secs(1));
    }
}

/// One try: the old session gone, then the writer's row.
async fn look(pool: &sqlx::PgPool, unsure: &Unsure) -> Result<bool, sqlx::Error> {
    let mut conn = pool.acquire().await?;
    if let Some(session) = &unsure.session {
        gone(&mut conn, session).await?;
    }
    let sql = "SELECT token FROM rackd_commits WHERE writer = $1";
    let token: Option<i64> =
        sqlx::query_scalar(sql).bind(unsure.token.writer).fetch_optional(&mut *conn).await?;
    Ok(token == Some(unsure.token.count))
}

/// Terminates `session` if it still runs, and waits until it has ended (at most 5 s, then
/// an error: the caller tries again).
async fn gone(conn: &mut PgConnection, session: &Session) -> Result<(), sqlx::Error> {
    let sql =
        "SELECT pg_terminate_backend(pid) FROM pg_stat_activity WHERE pid = $1 AND backend_start::text = $2";
    let until = tokio::time::Instant::now() + Duration::from_secs(5);
    loop {
        let alive: Option<bool> = sqlx::query_scalar(sql)
            .bind(session.pid)
            .bind(&session.started)
            .fetch_optional(&mut *conn)
            .await?;
        if alive.is_none() {
            return Ok(());
        }
        if tokio::time::Instant::now() >= until {
            return Err(sqlx::Error::Protocol("the session of a lost commit did not end".into()));
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}
