//! A committed group waits here until it is on disk; only then is it answered and its
//! hooks run. Meanwhile the writer goes on with the next group.
//!
//! On SQLite the writer's connection commits with `synchronous=NORMAL`: its `COMMIT` writes
//! the group to the WAL file and returns without waiting for the disk. This thread then
//! syncs the WAL (`fdatasync`), once for every group committed since its last sync. After
//! that it answers those groups in commit order, publishes their events and hands their
//! jobs to the dispatcher. The disk's wait (0.7 ms a sync on this project's machine) then
//! overlaps the next group's work instead of stalling it.
//!
//! On PostgreSQL a `COMMIT` is on disk when it returns (`synchronous_commit=on`), so there is
//! nothing to sync. Its groups still go through this thread, so the answers and hooks of
//! one group overlap the next group there too.
//!
//! Decisions:
//! - **Nothing acts on a commit before it is on disk.** Every answer (a 201, a dispatch's
//!   go-ahead to a device, a report's acknowledgement), every event and every hook waits
//!   for the sync, and a sync covers every commit written before it. A device is only ever
//!   sent what a synced commit decided, whatever it read. So a power cut loses only what
//!   nobody was told, as with `synchronous=FULL`.
//! - **Readers may see a commit a moment before its sync.** This holds for the API's
//!   `GET`s and the planner's reading of the rack. It is the same for any SQLite reader
//!   and a PostgreSQL standby. The WebSocket replay (`?since=`) stops at the last published
//!   event ([`crate::service::events::Hub::published`]), so the event log a subscriber
//!   follows never runs ahead of what is on disk.
//! - **A failed sync stops the writer**, as a failed fsync stops PostgreSQL. The kernel may
//!   have dropped the pages it could not write, so nothing built on them may be answered.
//!   The groups waiting for that sync fail, and so does every command after it.
//!   `/readyz` and `GET /api/v1/health` then report that the writer has stopped. Restart rackd once
//!   the disk is fixed: SQLite recovers from what the disk holds.
//! - **The WAL is synced through a file handle of rackd's own.** Opening the `-wal` file
//!   next to the database is safe: SQLite takes its locks on the database and `-shm`
//!   files, never on the WAL. The handle is kept open, not closed after each sync. When
//!   the WAL file is new (first commit, or another inode after SQLite removed and
//!   recreated it), the folder is synced once too, so the file's name is on disk as well.

use std::collections::HashMap;
use std::fs::File;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::Instant;

use super::apply::{Answer, Out};
use super::timing::GroupStats;
use super::{Command, Hooks, Sent, WriteError};
use crate::domain::{Location, LocationLock};
use crate::store::counts::Counts;
use crate::store::fault::Cause;
use crate::store::jobs::Job;

/// Makes every commit written so far durable.
pub(super) type Sync = Box<dyn FnMut() -> std::io::Result<()> + Send>;

/// A group the writer is done with: committed (or failed), not yet answered.
pub(super) struct Done {
    pub(super) group: Vec<Sent>,
    pub(super) result: Result<(Vec<Answer>, Out), sqlx::Error>,
    pub(super) started: Instant,
}

/// The thread that syncs, then answers (see the module doc).
pub(super) struct Syncer {
    tx: mpsc::Sender<Done>,
    thread: JoinHandle<()>,
    failed: Arc<AtomicBool>,
}

impl Syncer {
    /// Starts the thread; `sync` is None when a commit is durable as it returns.
    pub(super) fn start(sync: Option<Sync>, hooks: Hooks) -> std::io::Result<Syncer> {
        let (tx, rx) = mpsc::channel();
        let failed = Arc::new(AtomicBool::new(false));
        let flag = failed.clone();
        let thread = std::thread::Builder::new()
            .name("rackd-sync".into())
            .spawn(move || run(rx, sync, hooks, flag))?;
        Ok(Syncer { tx, thread, failed })
    }

    /// Hands a group over, to be answered once it is on disk.
    pub(super) fn send(&self, done: Done) {
        if let Err(mpsc::SendError(done)) = self.tx.send(done) {
            // The thread is gone (it only ends when this handle does, or by a panic in a
            // hook): nothing syncs any more, so the writer stops, and this group is
            // answered here rather than left waiting.
            self.failed.store(true, Ordering::Release);
            deliver(&Hooks::default(), done, Some(&stopped()));
        }
    }

    /// Whether a sync failed: the writer must stop (see the module doc).
    pub(super) fn failed(&self) -> bool {
        self.failed.load(Ordering::Acquire)
    }

    /// Waits until every group handed over is answered.
    pub(super) fn finish(self) {
        drop(self.tx);
        if self.thread.join().is_err() {
            tracing::error!("the writer's sync thread panicked");
        }
    }
}

/// The error a command gets once a sync has failed.
pub(super) fn stopped() -> WriteError {
    let e = std::io::Error::other("a sync of the database failed earlier; rackd stopped writing");
    WriteError::Database(Arc::new(sqlx::Error::Io(e)))
}

fn run(rx: mpsc::Receiver<Done>, mut sync: Option<Sync>, hooks: Hooks, failed: Arc<AtomicBool>) {
    while let Ok(first) = rx.recv() {
        // Every group committed by now is in the WAL: one sync covers them all.
        let round: Vec<Done> = std::iter::once(first).chain(rx.try_iter()).collect();
        let wrote = round.iter().any(|d| d.result.is_ok());
        let error = if failed.load(Ordering::Acquire) {
            Some(stopped())
        } else {
            match sync.as_mut().filter(|_| wrote).map(|s| s()) {
                Some(Err(e)) => {
                    tracing::error!(
                        error = %e,
                        "syncing the database failed; rackd stops writing (restart it once the disk is fixed)"
                    );
                    failed.store(true, Ordering::Release);
                    Some(WriteError::Database(Arc::new(sqlx::Error::Io(e))))
                }
                _ => None,
            }
        };
        for done in round {
            deliver(&hooks, done, error.as_ref());
        }
    }
}

/// Answers a group and runs its hooks; with `error` (its sync failed), fails it instead.
fn deliver(hooks: &Hooks, done: Done, error: Option<&WriteError>) {
    let Done { group, result, started } = done;
    let result = match (result, error) {
        (Ok(_), Some(e)) => Err(e.clone()),
        (Ok(ok), None) => Ok(ok),
        (Err(e), _) => Err(WriteError::Database(Arc::new(e))),
    };
    let wrote = result.as_ref().is_ok_and(|(_, out)| out.writes > 0);
    let timings = result.as_ref().map(|(_, out)| out.timings.as_slice()).unwrap_or_default();
    let statements = result.as_ref().map_or(0, |(_, out)| out.statements);
    let none = Counts::default();
    let counts = result.as_ref().map_or(&none, |(_, out)| &out.counts);
    if let Some(observe) = &hooks.observe {
        let took = started.elapsed();
        observe(&GroupStats { commands: group.len(), statements, took, jobs: timings, counts });
    }
    let (answers, unlocks, sequences) = match result {
        Ok((answers, out)) => {
            let (locks, unlocks) = locks_and_unlocks(out.locks);
            if let Some(locked) = hooks.locked.as_ref().filter(|_| !locks.is_empty()) {
                locked(&locks);
            }
            if let Some(publish) = hooks.publish.as_ref().filter(|_| !out.events.is_empty()) {
                publish(out.events);
            }
            (answers, unlocks, out.sequences)
        }
        Err(e) => {
            tracing::error!(error = %e, requests = group.len(), "group commit failed");
            (group.iter().map(|_| Answer::Failed(e.clone())).collect(), Vec::new(), Vec::new())
        }
    };
    if let Some(stored) = &hooks.stored
        && let Some(outcome) = outcome(&answers, wrote)
    {
        stored(outcome);
    }
    if let Some(sequenced) = hooks.sequenced.as_ref().filter(|_| !sequences.is_empty()) {
        sequenced(&sequences);
    }
    if let Some(committed) = &hooks.committed {
        let jobs: Vec<&Job> = answers.iter().flat_map(Answer::jobs).collect();
        if !jobs.is_empty() {
            committed(&jobs);
        }
    }
    if let Some(locked) = hooks.locked.as_ref().filter(|_| !unlocks.is_empty()) {
        locked(&unlocks);
    }
    for (Sent { cmd, .. }, answer) in group.into_iter().zip(answers) {
        reply(cmd, answer);
    }
}

/// How a group went for the store: the cause of the first of its answers that failed for
/// the store's own reason (the whole group's failure is every answer's); else committed, if
/// it `wrote`. A group that wrote nothing (its requests refused for their own reasons, or
/// with nothing to change) tells nothing: its `COMMIT` never reached the disk, so it is no
/// sign that the store commits again, and the store stays faulted while every write fails.
/// A stall told meanwhile (see `STALL`) is ended by the next group that writes, the `store`
/// alarm's own record at the latest.
fn outcome(answers: &[Answer], wrote: bool) -> Option<Result<(), Cause>> {
    let cause = |e: &WriteError| match e {
        WriteError::Database(e) => Cause::of(e),
        _ => None,
    };
    match answers.iter().flat_map(Answer::errors).find_map(cause) {
        Some(c) => Some(Err(c)),
        None => wrote.then_some(Ok(())),
    }
}

/// A commit's lock changes as the dispatcher is handed them: the locations it leaves
/// locked, before its jobs, and those it leaves unlocked, after them (each location as the
/// commit leaves it, its last change). A job that failed and locked its location is then
/// never seen gone with the location still free, and a failed job retried in the commit
/// that unlocks its location is back in its queue, ahead of the later jobs there, before
/// the location frees: otherwise a device could take a later job on the location first.
fn locks_and_unlocks(changes: Vec<(Location, Option<LocationLock>)>) -> (Vec<LockChange>, Vec<LockChange>) {
    let last: HashMap<Location, usize> = changes.iter().enumerate().map(|(i, (l, _))| (*l, i)).collect();
    changes
        .into_iter()
        .enumerate()
        .filter(|(i, (l, _))| last.get(l) == Some(i))
        .map(|(_, change)| change)
        .partition(|(_, lock)| lock.is_some())
}

/// A lock (`Some`) or unlock of a location.
type LockChange = (Location, Option<LocationLock>);

/// Sends a command its answer.
fn reply(cmd: Command, answer: Answer) {
    match (cmd, answer) {
        (Command::Submit { reply, .. }, Answer::Submitted(r)) => drop(reply.send(r)),
        (Command::Change { reply, .. }, Answer::Changed(r)) => drop(reply.send(r)),
        (Command::Record { reply, .. }, Answer::Recorded) => drop(reply.send(Ok(()))),
        (Command::Record { reply, .. }, Answer::Refused(e)) => drop(reply.send(Err(e))),
        (Command::Reports { reply, .. }, Answer::Reported(r)) => drop(reply.send(r)),
        (Command::Adopt { reply, .. }, Answer::Adopted(jobs)) => drop(reply.send(Ok(jobs))),
        (Command::Bulk { reply, .. }, Answer::Bulked(r)) => drop(reply.send(r)),
        (Command::Bulk { reply, .. }, Answer::Failed(e)) => drop(reply.send(Err(e))),
        (Command::Bulk { reply, .. }, _) => drop(reply.send(Err(WriteError::Closed))),
        (Command::Adopt { reply, .. }, Answer::Failed(e)) => drop(reply.send(Err(e))),
        (Command::Adopt { reply, .. }, _) => drop(reply.send(Err(WriteError::Closed))),
        (Command::Reports { reply, reports }, Answer::Failed(e)) => {
            drop(reply.send(reports.iter().map(|_| Err(e.clone())).collect()))
        }
        (Command::Reports { reply, reports }, _) => {
            drop(reply.send(reports.iter().map(|_| Err(WriteError::Closed)).collect()))
        }
        (Command::Submit { reply, .. }, Answer::Failed(e)) => drop(reply.send(Err(e))),
        (Command::Change { reply, .. }, Answer::Failed(e)) => drop(reply.send(Err(e))),
        (Command::Record { reply, .. }, Answer::Failed(e)) => drop(reply.send(Err(e))),
        (Command::Submit { reply, .. }, _) => drop(reply.send(Err(WriteError::Closed))),
        (Command::Change { reply, .. }, _) => drop(reply.send(Err(WriteError::Closed))),
        (Command::Record { reply, .. }, _) => drop(reply.send(Err(WriteError::Closed))),
    }
}

/// Answers every command of `group` with `error`, writing nothing.
pub(super) fn refuse(group: Vec<Sent>, error: &WriteError) {
    for Sent { cmd, .. } in group {
        reply(cmd, Answer::Failed(error.clone()));
    }
}

/// The sync of a SQLite database's WAL file (`PATH-wal`), and of its folder whenever the
/// WAL file is a new one.
pub(super) fn wal(database: &Path) -> Sync {
    let mut name = database.as_os_str().to_owned();
    name.push("-wal");
    let path = PathBuf::from(name);
    let folder = match database.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_owned(),
        _ => PathBuf::from("."),
    };
    let mut open: Option<(File, u64)> = None;
    Box::new(move || {
        let inode = std::fs::metadata(&path)?.ino();
        if open.as_ref().is_none_or(|(_, i)| *i != inode) {
            let file = File::open(&path)?;
            let inode = file.metadata()?.ino();
            file.sync_data()?;
            File::open(&folder)?.sync_all()?;
            open = Some((file, inode));
            return Ok(());
        }
        open.as_ref().map_or(Ok(()), |(file, _)| file.sync_data())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;
    use tokio::sync::oneshot;

    fn record(reply: oneshot::Sender<Result<(), WriteError>>) -> Sent {
        let record = super::super::Record::Prune { before_ms: 0, through: i64::MAX, hard_ms: 0 };
        Sent { cmd: Command::Record { record, who: None, reply }, epoch: None }
    }

    fn done(group: Vec<Sent>) -> Done {
        let answers = group.iter().map(|_| Answer::Recorded).collect();
        Done { group, result: Ok((answers, Out::default())), started: Instant::now() }
    }

    /// A sync that tells when it starts and waits to be let through.
    fn gated() -> (Sync, mpsc::Receiver<()>, mpsc::Sender<()>, Arc<Mutex<u32>>) {
        let (entered_tx, entered) = mpsc::channel();
        let (gate, gate_rx) = mpsc::channel::<()>();
        let syncs = Arc::new(Mutex::new(0));
        let counted = syncs.clone();
        let sync: Sync = Box::new(move || {
            entered_tx.send(()).map_err(std::io::Error::other)?;
            gate_rx.recv().map_err(std::io::Error::other)?;
            *counted.lock().unwrap() += 1;
            Ok(())
        });
        (sync, entered, gate, syncs)
    }

    #[test]
    fn a_group_is_answered_only_after_a_sync_and_one_sync_covers_what_waits() {
        let (sync, entered, gate, syncs) = gated();
        let syncer = Syncer::start(Some(sync), Hooks::default()).unwrap();
        let (a, mut a_rx) = oneshot::channel();
        syncer.send(done(vec![record(a)]));
        entered.recv().unwrap();
        // Two more groups commit while the first one's sync is under way.
        let (b, mut b_rx) = oneshot::channel();
        let (c, mut c_rx) = oneshot::channel();
        syncer.send(done(vec![record(b)]));
        syncer.send(done(vec![record(c)]));
        assert!(a_rx.try_recv().is_err(), "answered before its sync");
        gate.send(()).unwrap();
        assert!(matches!(a_rx.blocking_recv(), Ok(Ok(()))));
        entered.recv().unwrap();
        assert!(b_rx.try_recv().is_err() && c_rx.try_recv().is_err(), "answered before their sync");
        gate.send(()).unwrap();
        syncer.finish();
        assert!(matches!(b_rx.try_recv(), Ok(Ok(()))) && matches!(c_rx.try_recv(), Ok(Ok(()))));
        assert_eq!(*syncs.lock().unwrap(), 2, "b and c share one sync");
    }

    #[test]
    fn only_a_group_that_wrote_tells_that_the_store_commits() {
        let io = WriteError::Database(Arc::new(sqlx::Error::Io(std::io::Error::other("EIO"))));
        let refused = || Answer::Failed(WriteError::NotFound(7));
        assert_eq!(outcome(&[Answer::Recorded], true), Some(Ok(())));
        assert_eq!(outcome(&[refused()], false), None, "a commit of nothing is no sign");
        assert_eq!(outcome(&[refused(), Answer::Recorded], true), Some(Ok(())));
        assert_eq!(outcome(&[refused(), Answer::Failed(io)], false), Some(Err(Cause::Io)));
    }

    #[test]
    fn a_failed_sync_fails_its_groups_and_every_later_one_without_publishing() {
        let published = Arc::new(Mutex::new(0));
        let seen = published.clone();
        let hooks = Hooks {
            publish: Some(Arc::new(move |events: Vec<_>| *seen.lock().unwrap() += events.len())),
            ..Hooks::default()
        };
        let sync: Sync = Box::new(|| Err(std::io::Error::from_raw_os_error(5)));
        let syncer = Syncer::start(Some(sync), hooks).unwrap();
        let (a, a_rx) = oneshot::channel();
        let mut first = done(vec![record(a)]);
        if let Ok((_, out)) = &mut first.result {
            out.events.push(crate::store::events::StoredEvent {
                seq: 1,
                at: 0,
                kind: "job.updated".into(),
                data: "{}".into(),
            });
        }
        syncer.send(first);
        assert!(matches!(a_rx.blocking_recv(), Ok(Err(WriteError::Database(_)))));
        assert!(syncer.failed(), "the writer is told to stop");
        let (b, b_rx) = oneshot::channel();
        syncer.send(done(vec![record(b)]));
        syncer.finish();
        assert!(matches!(b_rx.blocking_recv(), Ok(Err(WriteError::Database(_)))));
        assert_eq!(*published.lock().unwrap(), 0, "nothing of a group that may not be on disk is published");
    }

    #[test]
    fn locks_reach_the_dispatcher_before_the_jobs_and_unlocks_after_them() {
        let calls = Arc::new(Mutex::new(Vec::<String>::new()));
        let (seen, told) = (calls.clone(), calls.clone());
        let hooks = Hooks {
            locked: Some(Arc::new(move |changes: &[(Location, Option<LocationLock>)]| {
                let text: Vec<String> = changes
                    .iter()
                    .map(|(l, lock)| format!("{}{}", l.bay, if lock.is_some() { "+" } else { "-" }))
                    .collect();
                seen.lock().unwrap().push(text.join(" "));
            })),
            committed: Some(Arc::new(move |jobs: &[&Job]| {
                told.lock().unwrap().push(format!("jobs {}", jobs.len()))
            })),
            ..Hooks::default()
        };
        let at = |bay| Location { aisle: 1, row: 1, bay, level: 1, position: 1 };
        let lock = LocationLock {
            by: "rackd".into(),
            reason: "lost".into(),
            job: Some(1),
            at: crate::domain::time::from_ms(0),
        };
        let job = crate::domain::NewJob {
            spec: crate::domain::JobSpec::Store { to: at(1) },
            reference: None,
            priority: Default::default(),
            barcode: None,
            device: None,
            serves: None,
            terms: Default::default(),
        }
        .accepted(1, 0);
        let (reply, _answer) = oneshot::channel();
        let change = super::super::Change::Priority(Default::default());
        let group = vec![Sent { cmd: Command::Change { id: 1, change, who: None, reply }, epoch: None }];
        let out = Out {
            // 2 is locked then unlocked, 3 unlocked then locked: each as the commit leaves it.
            locks: vec![
                (at(1), Some(lock.clone())),
                (at(2), Some(lock.clone())),
                (at(3), None),
                (at(2), None),
                (at(3), Some(lock)),
                (at(4), None),
            ],
            ..Out::default()
        };
        let done = Done { group, result: Ok((vec![Answer::Changed(Ok(job))], out)), started: Instant::now() };
        deliver(&hooks, done, None);
        assert_eq!(*calls.lock().unwrap(), ["1+ 3+", "jobs 1", "2- 4-"]);
    }

    #[test]
    fn the_wal_sync_follows_a_new_wal_file() {
        let dir = tempfile::tempdir().unwrap();
        let db = dir.path().join("site.db");
        let mut sync = wal(&db);
        assert!(sync().is_err(), "no WAL yet: nothing to sync is an error, not a silent success");
        std::fs::write(dir.path().join("site.db-wal"), b"first").unwrap();
        sync().unwrap();
        sync().unwrap();
        std::fs::remove_file(dir.path().join("site.db-wal")).unwrap();
        std::fs::write(dir.path().join("site.db-wal"), b"second").unwrap();
        sync().unwrap();
    }
}
