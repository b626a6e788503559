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
//! goes on with the next group. Measured with `bench intake` (eight ABBA blocks): batches
//! +12%, single POSTs unchanged.
//!
//! Decisions:
//! - **Small groups keep SQLite's own checkpoint.** Measured: with every group's checkpoint
//!   on the checkpointer, batches gained 6% and single POSTs lost 4% (four ABBA blocks, each
//!   the same way). Single POSTs are bound by CPU, so the same copying on another thread
//!   gains them nothing, and the restarts below made their writer wait. So the writer hands
//!   its checkpoints over only for a large group, and takes them back for a small one; each
//!   switch costs one statement (`PRAGMA wal_autocheckpoint`), steady traffic none.
//! - **At most one checkpoint per [`PAUSE`].** Each checkpoint syncs the WAL and the
//!   database file.
//! - **The WAL is restarted past [`RESTART_BYTES`].** SQLite starts the WAL over only when
//!   a write transaction begins with every page already copied back, which a writer that
//!   is never idle does not do while someone else checkpoints: without this the WAL grew to
//!   1.7 GB in one benchmark run. Once the WAL holds more than [`RESTART_BYTES`] and a
//!   passive checkpoint has caught up, `wal_checkpoint(RESTART)` waits for the writer's
//!   current transaction, copies the little that is left, and makes the next transaction
//!   start the WAL over (the writer's `BEGIN` waits for it, within the busy timeout).
//! - **The writer still checkpoints itself past [`WRITER_CHECKPOINT_PAGES`]** while its
//!   checkpoints are handed over (four times the restart size): should the checkpointer
//!   fail, or readers holding old snapshots keep it from finishing, the WAL stays bounded.
//! - **Durability is SQLite's own**: a checkpoint syncs the WAL before it copies and the
//!   database file after, whoever runs it.
//! - **PostgreSQL has nothing of the kind**: no checkpointer there.

use std::time::Duration;

use sqlx::SqliteConnection;
use tokio::sync::mpsc;

/// The jobs a group must hold for its checkpoint to be handed over (one full insert
/// statement's worth: about 300 pages of WAL).
pub(super) const LARGE_GROUP: usize = 2048;

/// The shortest time between two checkpoints of the checkpointer.
pub(super) const PAUSE: Duration = Duration::from_millis(50);

/// The WAL size past which the checkpointer makes SQLite start it over.
pub(super) const RESTART_BYTES: u64 = 128 << 20;

/// The writer's automatic checkpoint while its checkpoints are handed over (in pages of
/// [`crate::store::SQLITE_PAGE_SIZE`]): four times [`RESTART_BYTES`], the safety net.
pub(super) const WRITER_CHECKPOINT_PAGES: u64 = 4 * RESTART_BYTES / crate::store::SQLITE_PAGE_SIZE as u64;

/// SQLite's own automatic checkpoint, in pages (its default).
const SQLITE_CHECKPOINT_PAGES: u64 = 1000;

/// The writer's side: which checkpoints are whose, and the nudge after a commit. Dropping
/// it stops the checkpointer, which closes its connection.
pub(super) struct Checkpoints {
    nudge: mpsc::Sender<()>,
    handed_over: bool,
}

impl Checkpoints {
    /// Starts the checkpointer on `conn` (a connection of its own, on the writer's
    /// database), as a task on the current runtime.
    pub(super) fn start(conn: SqliteConnection) -> Checkpoints {
        let (nudge, nudged) = mpsc::channel(1);
        tokio::spawn(run(conn, nudged, RESTART_BYTES));
        Checkpoints { nudge, handed_over: false }
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

async fn run(mut conn: SqliteConnection, mut nudged: mpsc::Receiver<()>, restart_bytes: u64) {
    let page: i64 = match sqlx::query_scalar("PRAGMA page_size").fetch_one(&mut conn).await {
        Ok(page) => page,
        Err(e) => {
            tracing::warn!(error = %e, "the checkpointer cannot read the page size; the writer checkpoints alone");
            return;
        }
    };
    let restart_frames = (restart_bytes / page.max(1) as u64) as i64;
    while nudged.recv().await.is_some() {
        // The writer's own checkpoint covers for a failed one (see the module doc).
        if let Err(e) = checkpoint(&mut conn, restart_frames).await {
            tracing::warn!(error = %e, "checkpoint failed");
        }
        tokio::time::sleep(PAUSE).await;
    }
}

/// One passive checkpoint, and a restart of the WAL if it holds `restart_frames` pages or
/// more and all of them are copied back.
async fn checkpoint(conn: &mut SqliteConnection, restart_frames: i64) -> Result<(), sqlx::Error> {
    let (_, frames, copied): (i64, i64, i64) =
        sqlx::query_as("PRAGMA wal_checkpoint(PASSIVE)").fetch_one(&mut *conn).await?;
    if frames >= restart_frames && copied == frames {
        let (busy, _, _): (i64, i64, i64) =
            sqlx::query_as("PRAGMA wal_checkpoint(RESTART)").fetch_one(&mut *conn).await?;
        if busy != 0 {
            tracing::debug!(frames, "the WAL was not restarted: a reader holds an old snapshot");
        }
    }
    Ok(())
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

    /// The frames in the WAL, read with a passive checkpoint (which copies them back too).
    async fn frames(db: &mut SqliteConnection) -> i64 {
        let (_, frames, _): (i64, i64, i64) =
            sqlx::query_as("PRAGMA wal_checkpoint(PASSIVE)").fetch_one(&mut *db).await.unwrap();
        frames
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

    /// Ten groups committed, the writer inside the next one, a checkpoint with
    /// `restart_frames` run meanwhile, that group committed and one more written: the frames
    /// in the WAL then.
    async fn busy_writer(restart_frames: i64) -> i64 {
        let (_dir, path, mut writer, mut checkpointer) = store().await;
        for _ in 0..10 {
            write(&mut writer, 20).await;
        }
        let before = size(&path);
        let mut tx = writer.begin().await.unwrap();
        sqlx::query("INSERT INTO t (b) VALUES (randomblob(1000))").execute(&mut *tx).await.unwrap();
        let run = tokio::spawn(async move { checkpoint(&mut checkpointer, restart_frames).await });
        // The passive checkpoint copies what was committed; a restart waits for the writer.
        while size(&path) < before + 150_000 {
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        tx.commit().await.unwrap();
        run.await.unwrap().unwrap();
        write(&mut writer, 20).await;
        let rows: i64 = sqlx::query_scalar("SELECT count(*) FROM t").fetch_one(&mut writer).await.unwrap();
        assert_eq!(rows, 221);
        frames(&mut writer).await
    }

    #[tokio::test]
    async fn a_wal_past_the_restart_size_starts_over_though_the_writer_is_never_idle() {
        let frames = busy_writer(50).await;
        assert!(frames < 15, "after the restart the WAL holds the last write only, not {frames} frames");
    }

    #[tokio::test]
    async fn under_the_restart_size_a_busy_writer_goes_on_in_the_same_wal() {
        let frames = busy_writer(100_000).await;
        assert!(frames > 60, "without a restart the WAL goes on ({frames} frames)");
    }

    #[tokio::test]
    async fn under_the_restart_size_it_copies_without_waiting_for_the_writer() {
        let (_dir, path, mut writer, mut checkpointer) = store().await;
        for _ in 0..10 {
            write(&mut writer, 20).await;
        }
        // The writer is inside its next group (a `RESTART` would wait for it to end).
        let mut tx = writer.begin().await.unwrap();
        sqlx::query("INSERT INTO t (b) VALUES (randomblob(1000))").execute(&mut *tx).await.unwrap();
        let before = size(&path);
        let copy = checkpoint(&mut checkpointer, 100_000);
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
