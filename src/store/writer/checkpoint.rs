//! SQLite's checkpoints after a large group, run beside the writer instead of inside its
//! `COMMIT`.
//!
//! In WAL mode a commit appends the pages it changed to the `-wal` file; a checkpoint
//! copies them back into the database file, and once everything is copied the next write
//! transaction starts the WAL over from its beginning. By default the connection that
//! commits runs the checkpoint itself, inside its `COMMIT`, once the WAL holds 1000 pages.
//! After a group of 51,000 jobs (batch intake) that copy took 60 of the group's 530 ms, and
//! the writer could not start the next group meanwhile.
//!
//! After a large group ([`LARGE_GROUP`] jobs or more) a connection of its own copies the
//! pages instead (`PRAGMA wal_checkpoint(PASSIVE)`, which waits for no one) while the writer
//! goes on with the next group. Measured with `bench intake` (four ABBA blocks): batches
//! +11%, single POSTs unchanged.
//!
//! Decisions:
//! - **Small groups keep SQLite's own checkpoint.** Measured: with every group's checkpoint
//!   on the checkpointer, batches gained 6% and single POSTs lost 4% (four ABBA blocks, each
//!   the same way). Single POSTs are bound by CPU, so the same copying on another thread
//!   gains them nothing, and the restarts made their writer wait. So the writer hands
//!   its checkpoints over only for a large group, and takes them back for a small one; each
//!   switch costs one statement (`PRAGMA wal_autocheckpoint`), steady traffic none.
//! - **At most one checkpoint per [`PAUSE`].** Each checkpoint syncs the WAL and the
//!   database file.
//! - **Passive only on the checkpointer: it never waits, and nobody waits for it.** It
//!   copies what no reader still needs and leaves the rest for its next turn.
//! - **The writer starts the WAL over past [`RESTART_BYTES`] (128 MiB).** SQLite starts the
//!   WAL over only when a write transaction begins with every page copied back, which a
//!   writer that is never idle does not do while someone else checkpoints: with nothing
//!   more the WAL grew to 1.7 GB in one benchmark run. When the checkpointer finds the WAL
//!   past that size, the writer, between two groups, runs `wal_checkpoint(RESTART)`: it
//!   copies what is left (about its last group) and makes its next group start the WAL over.
//!   So the writer pays one group's copy per 128 MiB instead of every group's, and the WAL
//!   stays below about 128 MiB plus a group or two. Leaving it to SQLite's own automatic
//!   checkpoint at that size instead gained nothing measurable: a restart then needs no
//!   reader inside the WAL at the very moment the next group begins, and with busy readers
//!   it kept failing, so the writer copied at every commit.
//! - **The restart waits briefly: [`patience`].** `RESTART` waits for every reader to
//!   leave the WAL, and the writer, which runs it, waits with it: a long read (a CSV
//!   export, a replay) would hold up every write. It waits at most a quarter of the
//!   database's busy timeout, and at most a second; then the group goes on, and the restart
//!   is tried again after the checkpointer's next turn.
//! - **The writer's own automatic checkpoint stays, at four times [`RESTART_BYTES`]**, as
//!   the safety net should the checkpointer fail.
//! - **Durability is SQLite's own**: a checkpoint syncs the WAL before it copies and the
//!   database file after, whoever runs it.
//! - **PostgreSQL has nothing of the kind**: no checkpointer there.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use sqlx::SqliteConnection;
use tokio::sync::mpsc;

/// The jobs a group must hold for its checkpoint to be handed over (one full insert
/// statement's worth: about 300 pages of WAL).
pub(super) const LARGE_GROUP: usize = 2048;

/// The shortest time between two checkpoints of the checkpointer.
pub(super) const PAUSE: Duration = Duration::from_millis(50);

/// The WAL size past which the writer starts it over (see the module doc).
pub(super) const RESTART_BYTES: i64 = 128 << 20;

/// The writer's automatic checkpoint while its checkpoints are handed over, in pages of
/// [`crate::store::SQLITE_PAGE_SIZE`]: four times [`RESTART_BYTES`], the safety net.
pub(super) const WRITER_CHECKPOINT_PAGES: u64 =
    4 * RESTART_BYTES as u64 / crate::store::SQLITE_PAGE_SIZE as u64;

/// SQLite's own automatic checkpoint, in pages (its default).
const SQLITE_CHECKPOINT_PAGES: u64 = 1000;

/// The writer's side: which checkpoints are whose, and the nudge after a commit. Dropping
/// it stops the checkpointer, which closes its connection.
pub(super) struct Checkpoints {
    nudge: mpsc::Sender<()>,
    handed_over: bool,
    /// Set by the checkpointer when the WAL has grown past [`RESTART_BYTES`].
    restart: Arc<AtomicBool>,
}

impl Checkpoints {
    /// Starts the checkpointer on `conn` (a connection of its own, on the writer's
    /// database), as a task on the current runtime.
    pub(super) fn start(conn: SqliteConnection) -> Checkpoints {
        let (nudge, nudged) = mpsc::channel(1);
        let restart = Arc::new(AtomicBool::new(false));
        tokio::spawn(run(conn, nudged, restart.clone(), RESTART_BYTES));
        Checkpoints { nudge, handed_over: false, restart }
    }

    /// Before a group of `jobs` jobs on the writer's connection `db`: hands its checkpoint
    /// over if it is large, takes it back if it is small.
    pub(super) async fn before(&mut self, db: &mut SqliteConnection, jobs: usize) -> Result<(), sqlx::Error> {
        let large = jobs >= LARGE_GROUP;
        if large != self.handed_over {
            let pages = if large { WRITER_CHECKPOINT_PAGES } else { SQLITE_CHECKPOINT_PAGES };
            let sql = format!("PRAGMA wal_autocheckpoint = {pages}");
            sqlx::raw_sql(sqlx::AssertSqlSafe(sql)).execute(&mut *db).await?;
            self.handed_over = large;
        }
        if self.restart.swap(false, Ordering::Relaxed) {
            start_over(db).await?;
        }
        Ok(())
    }

    /// After a group: the checkpointer's turn if the group `committed` and its checkpoint
    /// was handed over. A failed group costs the writer its connection, and the new one
    /// runs SQLite's own checkpoints.
    pub(super) fn after(&mut self, committed: bool) {
        if !committed {
            self.handed_over = false;
        } else if self.handed_over {
            // Full: a nudge is waiting already, and one is enough.
            let _ = self.nudge.try_send(());
        }
    }
}

/// Copies back what is left and makes the next group start the WAL over, waiting for
/// readers no longer than its [`patience`].
async fn start_over(db: &mut SqliteConnection) -> Result<(), sqlx::Error> {
    let busy: i64 = sqlx::query_scalar("PRAGMA busy_timeout").fetch_one(&mut *db).await?;
    let sql = format!(
        "PRAGMA busy_timeout = {}; PRAGMA wal_checkpoint(RESTART); PRAGMA busy_timeout = {busy}",
        patience(busy)
    );
    sqlx::raw_sql(sqlx::AssertSqlSafe(sql)).execute(&mut *db).await?;
    Ok(())
}

/// How long the writer's restart waits for readers (ms), given its busy timeout: a
/// quarter of it, at most a second.
fn patience(busy_timeout_ms: i64) -> i64 {
    (busy_timeout_ms / 4).min(1000)
}

async fn run(
    mut conn: SqliteConnection,
    mut nudged: mpsc::Receiver<()>,
    restart: Arc<AtomicBool>,
    bytes: i64,
) {
    let page: i64 = match sqlx::query_scalar("PRAGMA page_size").fetch_one(&mut conn).await {
        Ok(page) => page,
        Err(e) => {
            tracing::warn!(error = %e, "the checkpointer cannot start; the writer checkpoints alone");
            return;
        }
    };
    let frames = bytes / page.max(1);
    while nudged.recv().await.is_some() {
        match checkpoint(&mut conn).await {
            Ok(wal) if wal >= frames => restart.store(true, Ordering::Relaxed),
            Ok(_) => {}
            // The writer's own checkpoint covers for a failed one (see the module doc).
            Err(e) => tracing::warn!(error = %e, "checkpoint failed"),
        }
        tokio::time::sleep(PAUSE).await;
    }
}

/// Copies back what no reader still needs, waiting for no one; returns the frames in the
/// WAL.
async fn checkpoint(conn: &mut SqliteConnection) -> Result<i64, sqlx::Error> {
    let (_, frames, _): (i64, i64, i64) =
        sqlx::query_as("PRAGMA wal_checkpoint(PASSIVE)").fetch_one(&mut *conn).await?;
    Ok(frames)
}

#[cfg(test)]
mod tests {
    use std::path::{Path, PathBuf};

    use sqlx::Connection;
    use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode};

    use super::*;

    async fn open(path: &Path) -> SqliteConnection {
        let options = SqliteConnectOptions::new()
            .filename(path)
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .busy_timeout(Duration::from_secs(5));
        SqliteConnection::connect_with(&options).await.unwrap()
    }

    /// Writes one transaction of `rows` rows of 1000 bytes.
    async fn write(db: &mut SqliteConnection, rows: usize) {
        let mut tx = db.begin().await.unwrap();
        for _ in 0..rows {
            sqlx::query("INSERT INTO t (b) VALUES (randomblob(1000))").execute(&mut *tx).await.unwrap();
        }
        tx.commit().await.unwrap();
    }

    async fn autocheckpoint(db: &mut SqliteConnection) -> i64 {
        sqlx::query_scalar("PRAGMA wal_autocheckpoint").fetch_one(db).await.unwrap()
    }

    fn size(path: &Path) -> u64 {
        std::fs::metadata(path).unwrap().len()
    }

    /// A database written by a connection that never checkpoints, and a second connection.
    async fn store() -> (tempfile::TempDir, PathBuf, SqliteConnection, SqliteConnection) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.db");
        let mut writer = open(&path).await;
        sqlx::raw_sql("PRAGMA wal_autocheckpoint = 0; CREATE TABLE t (id INTEGER PRIMARY KEY, b BLOB)")
            .execute(&mut writer)
            .await
            .unwrap();
        let checkpointer = open(&path).await;
        (dir, path, writer, checkpointer)
    }

    /// The writer's side, as [`Checkpoints::start`] makes it, with no checkpointer behind it
    /// and `restart` as the checkpointer left it.
    fn writer_side(restart: bool) -> Checkpoints {
        let (nudge, _) = mpsc::channel(1);
        Checkpoints { nudge, handed_over: false, restart: Arc::new(AtomicBool::new(restart)) }
    }

    /// Ten groups committed, the writer inside the next one while the checkpointer copies,
    /// that group committed, then the writer's side before its next group with `restart`
    /// set or not, and that group written: the frames in the WAL then.
    async fn busy_writer(restart: bool) -> i64 {
        let (_dir, _path, mut writer, mut checkpointer) = store().await;
        for _ in 0..10 {
            write(&mut writer, 20).await;
        }
        let mut tx = writer.begin().await.unwrap();
        sqlx::query("INSERT INTO t (b) VALUES (randomblob(1000))").execute(&mut *tx).await.unwrap();
        checkpoint(&mut checkpointer).await.unwrap();
        tx.commit().await.unwrap();
        writer_side(restart).before(&mut writer, 1).await.unwrap();
        write(&mut writer, 20).await;
        let rows: i64 = sqlx::query_scalar("SELECT count(*) FROM t").fetch_one(&mut writer).await.unwrap();
        assert_eq!(rows, 221);
        checkpoint(&mut writer).await.unwrap()
    }

    #[tokio::test]
    async fn the_writers_restart_starts_the_wal_over_though_it_is_never_idle() {
        let frames = busy_writer(true).await;
        assert!(frames < 15, "the WAL started over: it holds the last group only, not {frames} frames");
    }

    #[tokio::test]
    async fn with_the_checkpointer_alone_a_busy_writer_never_starts_the_wal_over() {
        let frames = busy_writer(false).await;
        assert!(frames > 60, "without the restart the WAL goes on ({frames} frames)");
    }

    #[tokio::test]
    async fn the_checkpointer_asks_for_a_restart_past_the_restart_size_only() {
        for (bytes, asked) in [(50 * 4096, true), (RESTART_BYTES, false)] {
            let (_dir, path, mut writer, checkpointer) = store().await;
            for _ in 0..10 {
                write(&mut writer, 20).await;
            }
            let (nudge, nudged) = mpsc::channel(1);
            let restart = Arc::new(AtomicBool::new(false));
            let task = tokio::spawn(run(checkpointer, nudged, restart.clone(), bytes));
            let before = size(&path);
            nudge.send(()).await.unwrap();
            drop(nudge);
            tokio::time::timeout(Duration::from_secs(10), task)
                .await
                .expect("it stops with the writer")
                .unwrap();
            assert!(size(&path) > before + 150_000, "it copied the WAL back");
            assert_eq!(
                restart.load(Ordering::Relaxed),
                asked,
                "a WAL of about 60 pages, {bytes} bytes to restart"
            );
        }
    }

    #[tokio::test]
    async fn a_restart_gives_up_on_a_long_reader_within_its_patience() {
        let (_dir, path, mut writer, mut checkpointer) = store().await;
        for _ in 0..10 {
            write(&mut writer, 20).await;
        }
        // A reader inside the WAL (a long export, say) keeps the WAL from starting over.
        let mut reader = open(&path).await;
        let mut read = reader.begin().await.unwrap();
        let _: i64 = sqlx::query_scalar("SELECT count(*) FROM t").fetch_one(&mut *read).await.unwrap();
        checkpoint(&mut checkpointer).await.unwrap();
        let started = std::time::Instant::now();
        writer_side(true).before(&mut writer, 1).await.unwrap();
        let waited = started.elapsed();
        // The busy timeout is 5 s: the restart gave up after its patience of 1 s.
        assert!(waited >= Duration::from_millis(900), "it waited for the reader ({waited:?})");
        assert!(waited < Duration::from_millis(3000), "it gave up in time ({waited:?})");
        let busy: i64 = sqlx::query_scalar("PRAGMA busy_timeout").fetch_one(&mut writer).await.unwrap();
        assert_eq!(busy, 5000, "the writer's busy timeout is back");
        write(&mut writer, 20).await;
        read.commit().await.unwrap();
    }

    #[test]
    fn the_patience_is_a_quarter_of_the_busy_timeout_and_at_most_a_second() {
        assert_eq!(patience(5000), 1000);
        assert_eq!(patience(400), 100);
        assert_eq!(patience(0), 0);
    }

    #[tokio::test]
    async fn it_copies_without_waiting_for_the_writer() {
        let (_dir, path, mut writer, mut checkpointer) = store().await;
        for _ in 0..10 {
            write(&mut writer, 20).await;
        }
        // The writer is inside its next group.
        let mut tx = writer.begin().await.unwrap();
        sqlx::query("INSERT INTO t (b) VALUES (randomblob(1000))").execute(&mut *tx).await.unwrap();
        let before = size(&path);
        let copy = checkpoint(&mut checkpointer);
        tokio::time::timeout(Duration::from_secs(2), copy).await.expect("it did not wait").unwrap();
        assert!(size(&path) > before + 150_000, "the committed rows were copied into the database file");
        tx.commit().await.unwrap();
        let rows: i64 = sqlx::query_scalar("SELECT count(*) FROM t").fetch_one(&mut writer).await.unwrap();
        assert_eq!(rows, 201);
    }

    #[tokio::test]
    async fn the_writer_hands_over_large_groups_only_and_nudges_for_them() {
        let (_dir, path, mut writer, checkpointer) = store().await;
        let mut checkpoints = Checkpoints::start(checkpointer);
        checkpoints.before(&mut writer, LARGE_GROUP - 1).await.unwrap();
        assert_eq!(autocheckpoint(&mut writer).await, 0, "a small group changes nothing (the test's own 0)");
        write(&mut writer, 200).await;
        checkpoints.after(true);
        tokio::time::sleep(PAUSE * 2).await;
        let small = size(&path);
        assert!(small < 100_000, "not nudged for a small group: the rows stay in the WAL ({small} bytes)");

        checkpoints.before(&mut writer, LARGE_GROUP).await.unwrap();
        assert_eq!(autocheckpoint(&mut writer).await, WRITER_CHECKPOINT_PAGES as i64);
        write(&mut writer, 50).await;
        checkpoints.after(true);
        let copied = async {
            while size(&path) < small + 200_000 {
                tokio::time::sleep(Duration::from_millis(10)).await;
            }
        };
        tokio::time::timeout(Duration::from_secs(10), copied)
            .await
            .expect("nudged, the checkpointer copies the WAL back");

        checkpoints.before(&mut writer, 1).await.unwrap();
        assert_eq!(autocheckpoint(&mut writer).await, SQLITE_CHECKPOINT_PAGES as i64);
    }
}
