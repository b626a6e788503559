//! The one writer of jobs: group commit on a connection of its own.
//!
//! Every change to a job (a submission, a state transition, a new priority) is a
//! [`Command`] sent to one task, which takes everything waiting, applies it in ONE
//! transaction and answers each caller only after the commit is on disk. Under load a single
//! fsync covers hundreds of requests; with one request waiting it commits at once, so a lone
//! request pays no extra latency. One writer also means no lock contention between writers,
//! and ids and event sequence numbers numbered in memory, without gaps.
//!
//! A group is set-based (see [`commit`]): a constant number of statements however many jobs
//! it holds, each carrying all its rows in one parameter. That matters most on SQLite, whose
//! sqlx driver runs a connection on a worker thread and hands every statement over through a
//! channel: the hand-offs, not SQLite, would otherwise set the pace.
mod apply;
mod bulk;
mod checkpoint;
mod commit;
pub use commit::NOTIFY_CHANNEL;
mod durable;
mod load;
mod save;
mod stream;
mod timing;
mod unsure;

use std::sync::Arc;

use tokio::sync::{mpsc, oneshot};
use tokio::task::JoinHandle;

pub use bulk::{Bulk, BulkAction, Bulked, Refusal, describe};
pub use timing::{GroupStats, JobTiming, Observe};

use super::Pool;
use super::alarms::NewAlarm;
use super::events::StoredEvent;
use super::fault::Cause;
use super::jobs::{Job, NewJob};
use crate::domain::state::IllegalTransition;
use crate::domain::{
    Failure, JobState, Location, LocationLock, Pause, Priority, Report, Reported, Target, Transition, Who,
};

/// A change to one stored job.
#[derive(Clone, Debug)]
pub enum Change {
    /// Move the job through the state machine.
    Transition {
        /// What happened.
        transition: Transition,
        /// Why, for the history.
        cause: String,
        /// Only apply if the job is in one of these states (else [`WriteError::Unexpected`]).
        expect: Option<Vec<JobState>>,
        /// The failure reason, for [`Transition::Fail`].
        failure: Option<Failure>,
        /// Forced completion, for [`Transition::Complete`].
        forced: bool,
    },
    /// Give a queued job a new priority.
    Priority(Priority),
    /// What a device reports: every transition from where the job is to where the device
    /// says it is, each in the history, all in the same commit.
    Report {
        /// Where the device says the job is.
        to: Reported,
        /// Why, for the history.
        cause: String,
    },
    /// Put a failed job back in the queue as its next attempt (audited).
    Retry {
        /// The API key's name.
        by: String,
    },
    /// Give a queued store left to rackd (putaway) the location rackd chose; refused with
    /// [`WriteError::Taken`] unless the location is free (no box, no lock, no job holding it).
    Place(Location),
}

impl Change {
    /// Cancel a job that is still queued (refused with [`WriteError::Unexpected`] otherwise).
    pub fn cancel_queued() -> Change {
        Change::Transition {
            transition: Transition::Cancel,
            cause: "cancelled through the API".into(),
            expect: Some(vec![JobState::Queued]),
            failure: None,
            forced: false,
        }
    }
}

/// What one location holds, as an inventory says.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Stock {
    /// Where.
    pub location: Location,
    /// A box is there.
    pub occupied: bool,
    /// The box's barcode, if known (only with `occupied`).
    pub barcode: Option<String>,
}

/// A change that is not a job's: device status, alarms, the log's retention.
#[derive(Clone, Debug)]
pub enum Record {
    /// A device's status changed: a `device.updated` event with `status` (JSON) as data.
    Device {
        /// The device's status, serialized.
        status: String,
    },
    /// An alarm is raised (ignored if the same device and code is already active).
    AlarmRaised(NewAlarm),
    /// The device's active alarm of this kind and code is cleared (ignored if none is
    /// active).
    AlarmCleared {
        /// The device.
        device: String,
        /// The alarm's kind and code.
        key: (crate::domain::AlarmKind, u16),
    },
    /// A device or an aisle is paused or resumed, audited.
    Pause {
        /// What.
        target: Target,
        /// Paused (true) or resumed.
        paused: bool,
        /// Who did it, why and when.
        by: Pause,
    },
    /// A location is locked by hand (audited); one already locked keeps its first lock.
    Lock {
        /// Where.
        location: Location,
        /// Who, why and when.
        lock: LocationLock,
    },
    /// A location is unlocked (audited).
    Unlock {
        /// Where.
        location: Location,
        /// The API key's name.
        by: String,
        /// Why, if given.
        reason: Option<String>,
    },
    /// The store's contents as counted or loaded at commissioning: each location's box,
    /// all or nothing (refused if a job in flight holds one of them), audited.
    Inventory {
        /// What each location holds.
        entries: Vec<Stock>,
        /// The API key's name.
        by: String,
        /// Why, if given.
        reason: Option<String>,
    },
    /// Tell these jobs again: a `job.updated` event for each one still queued, with why it
    /// waits now (the dispatcher's waiting reason changed while the job did not).
    Retell {
        /// The jobs.
        jobs: Vec<i64>,
    },
    /// An operator acknowledges an alarm (audited); refused with [`WriteError::AlarmNotFound`]
    /// or [`WriteError::AlreadyAcknowledged`].
    Acknowledge {
        /// The alarm.
        alarm: i64,
        /// The API key's name.
        by: String,
        /// A note, if given.
        note: Option<String>,
    },
    /// An audit entry for an action whose effect is not in this commit (a job a device
    /// withdrew and reported cancelled, a tag written to a PLC), by whoever the command is
    /// sent as (see [`Writer::record_as`]; `rackd` when sent without).
    Audit {
        /// What was done: `cancel`, `tag`, ...
        action: String,
        /// What it applied to: `job:ID`, `device:ID/TAG`, ...
        target: String,
        /// What came of it, or why.
        reason: Option<String>,
    },
    /// Retention: delete events committed before `before_ms` (Unix ms) that every active
    /// webhook subscription is done with (`through`: the lowest cursor), and any before
    /// `hard_ms` regardless; always keeping the newest so that sequence numbers are never
    /// reused. The webhooks' delivery log goes with the events before `before_ms`.
    Prune {
        /// The cut-off.
        before_ms: i64,
        /// The highest seq every active subscription is done with (`i64::MAX`: none holds).
        through: i64,
        /// Before this, events go even if a subscription still needs them.
        hard_ms: i64,
    },
    /// A webhook subscription's row and its deliveries since the last one (see
    /// [`crate::store::webhooks`]); with `audit`, what an operator did (`pause`, `resume`,
    /// `replay`) and why, audited on `webhook:NAME`.
    Webhook {
        /// The row and the deliveries.
        progress: crate::store::webhooks::Progress,
        /// The operator's action and its reason.
        audit: Option<(String, Option<String>)>,
    },
    /// The configuration was reloaded (audited on `config`, with `reason`): a
    /// `config.reloaded` event with `data` (JSON) as its data.
    Reloaded {
        /// The event's data.
        data: String,
        /// The audit entry's words: the hash and the difference.
        reason: String,
    },
    /// These jobs just passed their deadline: a `job.late` event for each one not ended.
    Late {
        /// The jobs.
        jobs: Vec<i64>,
    },
    /// A sequence is complete (no member may join it any more; the last position is the
    /// highest posted), and with `cancel` cancelled as a whole by `by` (audited); refused
    /// with [`WriteError::Sequence`] for a sequence that does not exist.
    Sequence {
        /// The sequence.
        name: String,
        /// Cancelled as a whole (its queued members are cancelled apart, through the
        /// dispatcher).
        cancel: bool,
    },
    /// Retention: these jobs are in the archive (written and synced, `store::archive`):
    /// delete them and their history, and take them off the counts, in this commit. A job
    /// that is not ended (retried since it was read) stays; one the group's later commands
    /// name is gone for them (404).
    Archived {
        /// The jobs.
        jobs: Vec<i64>,
    },
}

/// How a submitted job was taken.
#[derive(Clone, Debug)]
pub enum Outcome {
    /// Newly stored, with the job as JSON: the data of its `job.updated` event, serialized
    /// once on the writer's thread, which the API answers with as it is (serializing the
    /// job again for the answer was 8% of the CPU of a batch in a profile of `bench intake`).
    Created {
        /// The job.
        job: Job,
        /// The job as JSON, as `serde_json` writes it.
        json: String,
    },
    /// A job with the same reference and the same request already existed.
    Existing(Job),
}

/// Why a write was refused.
#[derive(Clone, Debug, thiserror::Error)]
pub enum WriteError {
    /// No job has this id.
    #[error("job {0} does not exist")]
    NotFound(i64),
    /// A reference is already used by a job with a different request.
    #[error("reference {0:?} is already used by a job with a different request")]
    Conflict(String),
    /// The job is not in a state this change expects.
    #[error("job {id} is {state}")]
    Unexpected {
        /// The job.
        id: i64,
        /// Its current state.
        state: JobState,
    },
    /// The state machine refuses the transition.
    #[error(transparent)]
    Illegal(#[from] IllegalTransition),
    /// The writer has stopped (the server is shutting down).
    #[error("the job writer has stopped")]
    Closed,
    /// The writer's queue is full: a submission is refused at once rather than left
    /// waiting (`intake.queue`).
    #[error("the job writer is overloaded")]
    Overloaded,
    /// No alarm has this id.
    #[error("alarm {0} does not exist")]
    AlarmNotFound(i64),
    /// The alarm was acknowledged before.
    #[error("alarm {id} was already acknowledged by {by}")]
    AlreadyAcknowledged {
        /// The alarm.
        id: i64,
        /// Who acknowledged it.
        by: String,
    },
    /// A location is held by a job in flight, so its contents are that job's to change.
    #[error("location {location} is reserved by job {job}, which is not finished")]
    Reserved {
        /// The location.
        location: Location,
        /// The job.
        job: i64,
    },
    /// A location chosen for a box is no longer free.
    #[error("location {0} is not free: a box, a lock or a job holds it")]
    Taken(Location),
    /// Items of a bulk action cannot be done as asked: nothing of it was written.
    #[error("{}", bulk::describe(.0))]
    Refused(Vec<Refusal>),
    /// A sequence member that cannot join its sequence as asked (its position is taken, the
    /// sequence is complete or cancelled, or names another station): nothing was written.
    #[error("{0}")]
    Sequence(String),
    /// An `after` reference that names no job stored or in the same submission.
    #[error("{0}")]
    UnknownDependency(String),
    /// Jobs of one submission that wait for each other.
    #[error("{0}")]
    DependencyCycle(String),
    /// Sent through a fenced handle ([`Writer::fenced`]) of a node that does not hold the
    /// cluster's lease (any more): nothing was written.
    #[error("this node does not hold the cluster lease (epoch {0:?}): nothing was written")]
    Fenced(Option<i64>),
    /// The database failed; nothing of the request was written.
    #[error("database error: {0}")]
    Database(Arc<sqlx::Error>),
}

/// Called after each commit with every job the commit created or changed, as committed (the
/// dispatcher keeps its queues with it, so devices never read the database for work).
pub type Committed = Arc<dyn Fn(&[&Job]) + Send + Sync>;

/// Called after each commit with the sequences it created or changed, as committed.
pub type Sequenced = Arc<dyn Fn(&[crate::store::sequences::Row]) + Send + Sync>;

/// Called after each commit with the events it appended, in sequence order (the event hub
/// forwards them to subscribers). Only committed events are passed on.
pub type Publish = Arc<dyn Fn(Vec<StoredEvent>) + Send + Sync>;

/// Called after each commit with the locations it locked (`Some`) or unlocked (`None`), so
/// the dispatcher holds back jobs on locked locations: those it leaves locked before
/// [`Committed`], those it leaves unlocked after it (see `durable::locks_and_unlocks`).
pub type Locked = Arc<dyn Fn(&[(Location, Option<LocationLock>)]) + Send + Sync>;

/// Called for each job as a commit writes its `job.updated` event, to fill in why it waits
/// (`Job::waiting`): the dispatcher says, and remembers what it told.
pub type Tell = Arc<dyn Fn(&mut Job) + Send + Sync>;

/// What the writer calls after each commit.
#[derive(Clone, Default)]
pub struct Hooks {
    /// Hands the dispatcher every location locked or unlocked.
    pub locked: Option<Locked>,
    /// Hands every committed job to the dispatcher.
    pub committed: Option<Committed>,
    /// Hands the dispatcher every sequence a commit created or changed, before its jobs.
    pub sequenced: Option<Sequenced>,
    /// Publishes the committed events.
    pub publish: Option<Publish>,
    /// Tells `/metrics` about each group (size, commit time, timed transitions).
    pub observe: Option<Observe>,
    /// Fills in each job's waiting reason before its event is written.
    pub tell: Option<Tell>,
    /// How each group went for the store: committed, or failed for a [`Cause`] of the
    /// store's own (see [`crate::store::fault`]).
    pub stored: Option<Stored>,
    /// Whether each group whose `COMMIT` failed on PostgreSQL landed (see [`unsure`]).
    pub unsure: Option<Settled>,
    /// A group has waited for the database for a second (see `STALL`), or the reading of
    /// an unsure commit cannot reach it; its outcome is told through [`Hooks::stored`]
    /// when it comes.
    pub stalled: Option<Stalled>,
}

/// Called when a group has waited for the database for a second.
pub type Stalled = Arc<dyn Fn() + Send + Sync>;

/// Called with whether a group whose `COMMIT` failed landed, once read.
pub type Settled = Arc<dyn Fn(bool) + Send + Sync>;

/// Called after each group with `Ok` if it committed something, or the [`Cause`] of the
/// store's own failure that failed it or any of its requests (not called for a group that
/// wrote nothing and failed for its requests' own reasons only: see `durable::outcome`).
pub type Stored = Arc<dyn Fn(Result<(), Cause>) + Send + Sync>;

/// What the writer is asked to do. `who` is the API's caller of an audited command: its
/// audit entry (in the same commit) names them and their address.
enum Command {
    Submit { jobs: Vec<NewJob>, who: Option<Who>, reply: oneshot::Sender<Result<Vec<Outcome>, WriteError>> },
    Change { id: i64, change: Change, who: Option<Who>, reply: oneshot::Sender<Result<Job, WriteError>> },
    Reports { reports: Vec<Report>, reply: oneshot::Sender<Vec<Result<Job, WriteError>>> },
    Record { record: Record, who: Option<Who>, reply: oneshot::Sender<Result<(), WriteError>> },
    Bulk { bulk: Bulk, who: Who, reply: oneshot::Sender<Result<Bulked, WriteError>> },
    Adopt { ids: Vec<i64>, reply: oneshot::Sender<Result<Vec<Job>, WriteError>> },
}

/// A command and the cluster epoch it must be committed under, if sent fenced.
struct Sent {
    cmd: Command,
    epoch: Option<i64>,
}

/// The epoch a node's fenced handle acts under now (None: it does not hold the lease).
pub type Epoch = Arc<dyn Fn() -> Option<i64> + Send + Sync>;

/// The handle callers use to send commands to the writer.
#[derive(Clone)]
pub struct Writer {
    tx: mpsc::Sender<Sent>,
    fence: Option<Epoch>,
}

impl Writer {
    /// Takes a connection of its own from `pool` (already migrated) and starts the writer
    /// task. It stops once every handle is dropped and what was sent before is committed;
    /// await the returned handle to know when.
    pub async fn start(
        pool: &Pool,
        max_group: usize,
        queue: usize,
        hooks: Hooks,
    ) -> Result<(Writer, JoinHandle<()>), sqlx::Error> {
        Writer::spawn(pool, max_group, queue, hooks, false).await
    }

    /// As [`Writer::start`], for one of several writers on one database: the nodes of a
    /// cluster, each with its own writer. Each group then takes a lock on the database for
    /// its transaction (a transaction-level advisory lock on PostgreSQL; SQLite's
    /// `BEGIN IMMEDIATE` already is one), so the writers commit one group at a time, and
    /// reads the numbering (ids, event sequence numbers) afresh under it, since the others
    /// number too: ids stay unique and the event log gapless. That costs one or two
    /// statements per group.
    pub async fn start_shared(
        pool: &Pool,
        max_group: usize,
        queue: usize,
        hooks: Hooks,
    ) -> Result<(Writer, JoinHandle<()>), sqlx::Error> {
        Writer::spawn(pool, max_group, queue, hooks, true).await
    }

    async fn spawn(
        pool: &Pool,
        max_group: usize,
        queue: usize,
        hooks: Hooks,
        shared: bool,
    ) -> Result<(Writer, JoinHandle<()>), sqlx::Error> {
        let mut conn = Conn::acquire(pool).await?;
        if let Conn::Postgres(c) = &mut conn {
            unsure::prune(c).await?;
        }
        // A process started after the wall clock stepped back stamps on from the store's
        // newest stamp, not before it (see `domain::time`).
        if let Some(newest) = load::newest_stamp(&mut conn).await? {
            crate::domain::time::not_before(newest);
        }
        let (tx, rx) = mpsc::channel(queue);
        let mut sync = match pool {
            Pool::Sqlite(p) => Some(durable::wal(p.connect_options().get_filename())),
            Pool::Postgres(_) => None,
        };
        // What an earlier run committed and did not sync (it stopped between its commit and
        // its sync) is read as the truth from now on: on disk before anything acts on it.
        match sync.as_mut().map(|s| s()) {
            Some(Err(e)) if e.kind() != std::io::ErrorKind::NotFound => return Err(sqlx::Error::Io(e)),
            _ => {}
        }
        let syncer = durable::Syncer::start(sync, hooks.clone()).map_err(sqlx::Error::Io)?;
        let checkpoints = match pool {
            Pool::Sqlite(p) => Some(checkpoint::Checkpoints::start(p.acquire().await?.detach())),
            Pool::Postgres(_) => None,
        };
        let after = After { syncer, checkpoints };
        let writer = run(pool.clone(), conn, rx, max_group.max(1), hooks, shared, after);
        let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
        let (done, ended) = oneshot::channel::<()>();
        std::thread::Builder::new().name("rackd-writer".into()).spawn(move || {
            runtime.block_on(writer);
            let _ = done.send(());
        })?;
        // Not `spawn_blocking`: a runtime waits for its blocking tasks when dropped, and a
        // writer some handle still holds would keep it waiting. The handle ends with the
        // thread (or its panic, which drops `done`).
        let task = tokio::spawn(async move { drop(ended.await) });
        Ok((Writer { tx, fence: None }, task))
    }

    /// A handle of this writer for what the active node of a cluster decides about the
    /// machines (dispatch, device reports, device state): each command is stamped with the
    /// epoch `epoch` gives when it is sent, and committed only if that epoch still holds the
    /// lease when its group commits (`store::cluster::fence`, in the same transaction);
    /// otherwise, or if `epoch` gives None, it is refused with [`WriteError::Fenced`] and
    /// nothing of it is written.
    pub fn fenced(&self, epoch: Epoch) -> Writer {
        Writer { tx: self.tx.clone(), fence: Some(epoch) }
    }

    /// The command as sent: stamped with the epoch if the handle is fenced.
    fn stamp(&self, cmd: Command) -> Result<Sent, WriteError> {
        match &self.fence {
            None => Ok(Sent { cmd, epoch: None }),
            Some(epoch) => match epoch() {
                Some(e) => Ok(Sent { cmd, epoch: Some(e) }),
                None => Err(WriteError::Fenced(None)),
            },
        }
    }

    /// Whether the writer still takes commands.
    pub fn is_running(&self) -> bool {
        !self.tx.is_closed()
    }

    /// Stores `jobs` all or nothing, answering once they are on disk; refused at once with
    /// [`WriteError::Overloaded`] while the writer's queue is full (the caller says "try
    /// again" instead of holding a request for a queue that does not move).
    pub async fn submit(&self, jobs: Vec<NewJob>) -> Result<Vec<Outcome>, WriteError> {
        self.submit_from(jobs, None).await
    }

    /// As [`Writer::submit`], for a caller of the API: a submission that creates a job is
    /// audited in the same commit (one entry per submission, a batch's naming its count).
    pub async fn submit_as(&self, jobs: Vec<NewJob>, who: Who) -> Result<Vec<Outcome>, WriteError> {
        self.submit_from(jobs, Some(who)).await
    }

    async fn submit_from(&self, jobs: Vec<NewJob>, who: Option<Who>) -> Result<Vec<Outcome>, WriteError> {
        let (reply, answer) = oneshot::channel();
        self.tx.try_send(self.stamp(Command::Submit { jobs, who, reply })?).map_err(|e| match e {
            mpsc::error::TrySendError::Full(_) => WriteError::Overloaded,
            mpsc::error::TrySendError::Closed(_) => WriteError::Closed,
        })?;
        answer.await.map_err(|_| WriteError::Closed)?
    }

    /// Applies `change` to job `id`, answering with the job once it is on disk.
    pub async fn change(&self, id: i64, change: Change) -> Result<Job, WriteError> {
        self.change_from(id, change, None).await
    }

    /// As [`Writer::change`], for a caller of the API: a cancel, a new priority or a retry
    /// is audited in the same commit.
    pub async fn change_as(&self, id: i64, change: Change, who: Who) -> Result<Job, WriteError> {
        self.change_from(id, change, Some(who)).await
    }

    async fn change_from(&self, id: i64, change: Change, who: Option<Who>) -> Result<Job, WriteError> {
        let (reply, answer) = oneshot::channel();
        self.tx
            .send(self.stamp(Command::Change { id, change, who, reply })?)
            .await
            .map_err(|_| WriteError::Closed)?;
        answer.await.map_err(|_| WriteError::Closed)?
    }

    /// Records what a device reports of several jobs in one commit, answering each job as
    /// stored afterwards (or why its report was refused), once they are on disk.
    pub async fn report(&self, reports: Vec<Report>) -> Result<Vec<Result<Job, WriteError>>, WriteError> {
        let (reply, answer) = oneshot::channel();
        self.tx
            .send(self.stamp(Command::Reports { reports, reply })?)
            .await
            .map_err(|_| WriteError::Closed)?;
        answer.await.map_err(|_| WriteError::Closed)
    }

    /// Reads jobs another node committed, in this writer's order: they go to the
    /// [`Committed`] hook as they stand when their group runs, after every commit of this
    /// writer sent before and before any sent after, so what the hook is handed never goes
    /// back in time (a job this node ended meanwhile comes as ended). Nothing is written.
    pub async fn adopt(&self, ids: Vec<i64>) -> Result<Vec<Job>, WriteError> {
        let (reply, answer) = oneshot::channel();
        self.tx
            .send(Sent { cmd: Command::Adopt { ids, reply }, epoch: None })
            .await
            .map_err(|_| WriteError::Closed)?;
        answer.await.map_err(|_| WriteError::Closed)?
    }

    /// Records a change that is not a job's, answering once it is on disk.
    pub async fn record(&self, record: Record) -> Result<(), WriteError> {
        self.record_from(record, None).await
    }

    /// As [`Writer::record`], for a caller of the API: its audit entries carry the caller's
    /// address (the record names who already).
    pub async fn record_as(&self, record: Record, who: Who) -> Result<(), WriteError> {
        self.record_from(record, Some(who)).await
    }

    /// Checks an operator's bulk action item by item and does all of it in one commit, or
    /// none of it ([`WriteError::Refused`]), audited as `who`; a dry run only checks.
    /// Answers once it is on disk.
    pub async fn bulk(&self, bulk: Bulk, who: Who) -> Result<Bulked, WriteError> {
        let (reply, answer) = oneshot::channel();
        self.tx
            .send(self.stamp(Command::Bulk { bulk, who, reply })?)
            .await
            .map_err(|_| WriteError::Closed)?;
        answer.await.map_err(|_| WriteError::Closed)?
    }

    async fn record_from(&self, record: Record, who: Option<Who>) -> Result<(), WriteError> {
        let (reply, answer) = oneshot::channel();
        self.tx
            .send(self.stamp(Command::Record { record, who, reply })?)
            .await
            .map_err(|_| WriteError::Closed)?;
        answer.await.map_err(|_| WriteError::Closed)?
    }
}

/// The writer's own connection, on either engine.
pub(crate) enum Conn {
    Sqlite(sqlx::SqliteConnection),
    Postgres(sqlx::PgConnection),
}

impl Conn {
    /// A connection of the pool's, taken out of it for good. On SQLite its commits do not
    /// wait for the disk (`synchronous=NORMAL`): the writer syncs the WAL itself before it
    /// answers anything (see [`durable`]).
    async fn acquire(pool: &Pool) -> Result<Conn, sqlx::Error> {
        Ok(match pool {
            Pool::Sqlite(p) => {
                let mut conn = p.acquire().await?.detach();
                sqlx::raw_sql("PRAGMA synchronous = NORMAL").execute(&mut conn).await?;
                Conn::Sqlite(conn)
            }
            Pool::Postgres(p) => Conn::Postgres(p.acquire().await?.detach()),
        })
    }
}

/// What follows a commit: the sync and the answers, and on SQLite the checkpoint of a
/// large group.
struct After {
    syncer: durable::Syncer,
    checkpoints: Option<checkpoint::Checkpoints>,
}

impl Command {
    /// The jobs the command writes: a large group's checkpoint is handed over (see
    /// [`checkpoint`]).
    fn jobs(&self) -> usize {
        match self {
            Command::Submit { jobs, .. } => jobs.len(),
            Command::Reports { reports, .. } => reports.len(),
            Command::Adopt { ids, .. } => ids.len(),
            Command::Bulk { bulk, .. } => bulk.action.len(),
            Command::Change { .. } | Command::Record { .. } => 1,
        }
    }
}

/// Commits `group` on `conn`, a large group's checkpoint handed over first (see
/// [`checkpoint`]).
async fn write(
    conn: &mut Conn,
    checkpoints: Option<&mut checkpoint::Checkpoints>,
    group: &[Sent],
    carry: &mut commit::Carry,
    tell: Option<&Tell>,
    shared: bool,
) -> Result<(Vec<apply::Answer>, apply::Out), commit::Failed> {
    if let (Conn::Sqlite(c), Some(checkpoints)) = (&mut *conn, checkpoints) {
        checkpoints.before(c, group.iter().map(|s| s.cmd.jobs()).sum()).await?;
    }
    commit::commit(conn, group, carry, tell, shared).await
}

/// How long a group (with its reconnection and, on PostgreSQL, the reading of an unsure
/// commit) may take before the store is told stalled: a database that does not answer (a
/// partition, a server restarting) then shows at once in `/readyz`, the health and the
/// WebSocket's `store` message, rather than when the TCP connection gives up. Groups take
/// milliseconds; a second is far beyond a healthy one's worst (a SQLite checkpoint of a
/// large WAL is a few hundred ms on a slow disk).
const STALL: std::time::Duration = std::time::Duration::from_secs(1);

/// Runs `work`, telling `stalled` once if it is not done within [`STALL`]; the work goes on.
async fn watched<T>(work: impl std::future::Future<Output = T>, stalled: Option<&Stalled>) -> T {
    tokio::pin!(work);
    tokio::select! {
        out = &mut work => return out,
        _ = tokio::time::sleep(STALL) => {}
    }
    tracing::warn!("a group of the job writer has waited for the database for a second");
    if let Some(stalled) = stalled {
        stalled();
    }
    work.await
}

/// The writer: take what waits, commit it, hand it to the [`durable::Syncer`] (which
/// answers once it is on disk), repeat until every handle is gone.
///
/// It runs on a thread of its own, on a runtime of its own, not among the server's tasks:
/// a group waits on the database several times (each statement is a hand-off to the
/// connection: on SQLite, to sqlx's worker thread), and each time the writer is woken it
/// would otherwise queue behind HTTP requests for one of the server's threads. Measured with
/// `bench intake` (six alternating pairs): single POSTs 13,780 a second against 12,480 as a
/// task (+10%), a group's transaction 1.95 ms against 2.3; batches unchanged. The hooks run
/// on the syncer's thread; they only hand things over (channels, locks, atomics).
///
/// After a failed group the connection is replaced by a fresh one from the pool, so a
/// database server that restarted (or a connection that broke) costs the groups in flight,
/// not every group after them. A group whose `COMMIT` failed on PostgreSQL is first settled
/// by reading whether it landed (see [`unsure`]).
async fn run(
    pool: Pool,
    db: Conn,
    mut rx: mpsc::Receiver<Sent>,
    max_group: usize,
    hooks: Hooks,
    shared: bool,
    After { syncer, mut checkpoints }: After,
) {
    let mut carry = commit::Carry::default();
    let mut db = Some(db);
    let mut group = Vec::with_capacity(max_group);
    while rx.recv_many(&mut group, max_group).await > 0 {
        if syncer.failed() {
            // What this writer committed may not be on disk: nothing more is built on it.
            durable::refuse(std::mem::take(&mut group), &durable::stopped());
            break;
        }
        let started = std::time::Instant::now();
        let work = async {
            if db.is_none() {
                db = Conn::acquire(&pool)
                    .await
                    .inspect_err(|e| tracing::error!(error = %e, "the job writer cannot reconnect"))
                    .ok();
            }
            if shared {
                carry.next = None;
            }
            let result = match db.as_mut() {
                Some(conn) => {
                    write(conn, checkpoints.as_mut(), &group, &mut carry, hooks.tell.as_ref(), shared).await
                }
                None => Err(sqlx::Error::PoolTimedOut.into()),
            };
            match result {
                Ok(done) => Ok(done),
                Err(commit::Failed::Sure(e)) => Err(e),
                Err(commit::Failed::Unsure(unsure)) => {
                    let unreachable = || hooks.stalled.as_ref().map_or((), |stalled| stalled());
                    let landed = unsure::landed(&pool, &unsure, || rx.is_closed(), unreachable).await;
                    if let (Some(landed), Some(told)) = (landed, hooks.unsure.as_ref()) {
                        told(landed);
                    }
                    match landed {
                        Some(true) => {
                            carry.landed(&unsure);
                            db = None;
                            Ok((unsure.answers, unsure.out))
                        }
                        _ => Err(unsure.error),
                    }
                }
            }
        };
        let result = watched(work, hooks.stalled.as_ref()).await;
        if result.is_err() || db.is_none() {
            db = None;
            carry.lost(result.is_err());
        }
        if let Some(checkpoints) = checkpoints.as_mut() {
            checkpoints.after(result.is_ok());
        }
        tracing::trace!(
            requests = group.len(),
            micros = started.elapsed().as_micros() as u64,
            "group committed"
        );
        syncer.send(durable::Done { group: std::mem::take(&mut group), result, started });
    }
    rx.close();
    while let Ok(sent) = rx.try_recv() {
        durable::refuse(vec![sent], &durable::stopped());
    }
    syncer.finish();
}
