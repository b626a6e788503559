//! The one writer of jobs: group commit.
//!
//! Every change to a job (a submission, a state transition, a new priority) is a
//! [`Command`] sent to one task, which takes everything waiting, applies it in ONE
//! transaction and answers each caller only after the commit is on disk. Under load a single
//! fsync covers hundreds of requests; with one request waiting it commits at once, so a lone
//! request pays no extra latency. One writer also means no lock contention between writers
//! and job ids that can be allocated without a round trip.

use std::collections::HashMap;
use std::sync::Arc;

use sqlx::{QueryBuilder, Sqlite, SqlitePool, Transaction};
use tokio::sync::{mpsc, oneshot};
use tokio::task::JoinHandle;

use super::jobs::{self, Job, NewJob};
use super::locations;
use super::time::{from_ms, now_ms};
use crate::domain::state::IllegalTransition;
use crate::domain::{Failure, JobState, Priority, Transition};

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
}

/// How a submitted job was taken.
#[derive(Clone, Debug)]
pub enum Outcome {
    /// Newly stored.
    Created(Job),
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
    /// The database failed; nothing of the group was written.
    #[error("database error: {0}")]
    Database(Arc<sqlx::Error>),
}

enum Command {
    Submit { jobs: Vec<NewJob>, reply: oneshot::Sender<Result<Vec<Outcome>, WriteError>> },
    Change { id: i64, change: Change, reply: oneshot::Sender<Result<Job, WriteError>> },
}

/// Called after each commit with every job the commit created or changed (dispatchers use
/// it to hear of new work within milliseconds instead of polling the database).
pub type Wake = Arc<dyn Fn(&Job) + Send + Sync>;

/// The handle callers use to send commands to the writer task.
#[derive(Clone)]
pub struct Writer {
    tx: mpsc::Sender<Command>,
}

impl Writer {
    /// Starts the writer task. It stops once every handle is dropped and what was sent
    /// before is committed; await the returned handle to know when.
    pub fn start(
        pool: SqlitePool,
        max_group: usize,
        queue: usize,
        wake: Option<Wake>,
    ) -> (Writer, JoinHandle<()>) {
        let (tx, rx) = mpsc::channel(queue);
        let task = tokio::spawn(run(pool, rx, max_group, wake));
        (Writer { tx }, task)
    }

    /// Stores `jobs` all or nothing, answering once they are on disk.
    pub async fn submit(&self, jobs: Vec<NewJob>) -> Result<Vec<Outcome>, WriteError> {
        let (reply, answer) = oneshot::channel();
        self.tx.send(Command::Submit { jobs, reply }).await.map_err(|_| WriteError::Closed)?;
        answer.await.map_err(|_| WriteError::Closed)?
    }

    /// Applies `change` to job `id`, answering with the job once it is on disk.
    pub async fn change(&self, id: i64, change: Change) -> Result<Job, WriteError> {
        let (reply, answer) = oneshot::channel();
        self.tx.send(Command::Change { id, change, reply }).await.map_err(|_| WriteError::Closed)?;
        answer.await.map_err(|_| WriteError::Closed)?
    }
}

async fn run(pool: SqlitePool, mut rx: mpsc::Receiver<Command>, max_group: usize, wake: Option<Wake>) {
    let mut group = Vec::with_capacity(max_group);
    while rx.recv_many(&mut group, max_group).await > 0 {
        let results = match commit(&pool, &group).await {
            Ok(results) => results,
            Err(e) => {
                tracing::error!(error = %e, requests = group.len(), "group commit failed");
                let e = WriteError::Database(Arc::new(e));
                group.iter().map(|_| Answer::Failed(e.clone())).collect()
            }
        };
        if let Some(wake) = &wake {
            for answer in &results {
                match answer {
                    Answer::Submitted(Ok(outcomes)) => outcomes.iter().for_each(|o| {
                        if let Outcome::Created(job) = o {
                            wake(job)
                        }
                    }),
                    Answer::Changed(Ok(job)) => wake(job),
                    _ => {}
                }
            }
        }
        for (cmd, result) in group.drain(..).zip(results) {
            match (cmd, result) {
                (Command::Submit { reply, .. }, Answer::Submitted(r)) => drop(reply.send(r)),
                (Command::Change { reply, .. }, Answer::Changed(r)) => drop(reply.send(r)),
                (Command::Submit { reply, .. }, Answer::Failed(e)) => drop(reply.send(Err(e))),
                (Command::Change { reply, .. }, Answer::Failed(e)) => drop(reply.send(Err(e))),
                _ => unreachable!("answers are made in command order"),
            }
        }
    }
}

enum Answer {
    Submitted(Result<Vec<Outcome>, WriteError>),
    Changed(Result<Job, WriteError>),
    Failed(WriteError),
}

/// Applies a group in one transaction; any database error rolls back the whole group.
async fn commit(pool: &SqlitePool, group: &[Command]) -> Result<Vec<Answer>, sqlx::Error> {
    let mut tx = pool.begin().await?;
    let now = now_ms();
    let mut next_id: i64 =
        sqlx::query_scalar("SELECT COALESCE(MAX(id), 0) + 1 FROM jobs").fetch_one(&mut *tx).await?;
    let references: Vec<&str> = group
        .iter()
        .flat_map(|c| match c {
            Command::Submit { jobs, .. } => jobs.iter().filter_map(|j| j.reference.as_deref()).collect(),
            Command::Change { .. } => Vec::new(),
        })
        .collect();
    let mut known: HashMap<String, (String, Job)> = HashMap::new();
    for chunk in references.chunks(500) {
        for (request, job) in jobs::by_references(&mut *tx, chunk).await? {
            known.insert(job.reference.clone().unwrap_or_default(), (request, job));
        }
    }
    let mut pending = Pending::default();
    let mut answers = Vec::with_capacity(group.len());
    for cmd in group {
        answers.push(match cmd {
            Command::Submit { jobs, .. } => {
                Answer::Submitted(plan(jobs, &mut known, &mut next_id, now, &mut pending))
            }
            Command::Change { id, change, .. } => {
                pending.flush(&mut tx).await?;
                Answer::Changed(apply(&mut tx, *id, change, now).await?)
            }
        });
    }
    pending.flush(&mut tx).await?;
    tx.commit().await?;
    Ok(answers)
}

/// Plans the rows of one submission, all or nothing.
fn plan(
    jobs: &[NewJob],
    known: &mut HashMap<String, (String, Job)>,
    next_id: &mut i64,
    now: i64,
    pending: &mut Pending,
) -> Result<Vec<Outcome>, WriteError> {
    let mut outcomes = Vec::with_capacity(jobs.len());
    let mut created: Vec<(String, Job)> = Vec::new();
    let mut local: HashMap<&str, usize> = HashMap::new();
    for new in jobs {
        let request = new.canonical();
        if let Some(reference) = new.reference.as_deref() {
            let seen = local.get(reference).map(|&i| &created[i]).or_else(|| known.get(reference));
            if let Some((stored, job)) = seen {
                if *stored != request {
                    return Err(WriteError::Conflict(reference.to_owned()));
                }
                outcomes.push(Outcome::Existing(job.clone()));
                continue;
            }
            local.insert(reference, created.len());
        }
        let job = new.accepted(*next_id + created.len() as i64, now);
        outcomes.push(Outcome::Created(job.clone()));
        created.push((request, job));
    }
    *next_id += created.len() as i64;
    for (request, job) in created {
        if let Some(r) = &job.reference {
            known.insert(r.clone(), (request.clone(), job.clone()));
        }
        pending.history.push((job.id, JobState::Queued, "accepted".to_owned(), now));
        pending.events.push(("job.updated", serde_json::to_string(&job).unwrap_or_default(), now));
        pending.jobs.push((request, job));
    }
    Ok(outcomes)
}

/// Applies one change to a stored job.
async fn apply(
    tx: &mut Transaction<'_, Sqlite>,
    id: i64,
    change: &Change,
    now: i64,
) -> Result<Result<Job, WriteError>, sqlx::Error> {
    let Some(mut job) = jobs::get(&mut **tx, id).await? else {
        return Ok(Err(WriteError::NotFound(id)));
    };
    let cause = match change {
        Change::Transition { transition, cause, expect, failure, forced } => {
            if expect.as_ref().is_some_and(|states| !states.contains(&job.state)) {
                return Ok(Err(WriteError::Unexpected { id, state: job.state }));
            }
            job.state = match job.state.apply(*transition) {
                Ok(state) => state,
                Err(e) => return Ok(Err(e.into())),
            };
            job.forced = *forced && job.state == JobState::Completed;
            if *transition == Transition::Fail {
                job.failure = failure.clone();
            }
            cause.clone()
        }
        Change::Priority(p) => {
            if job.state != JobState::Queued {
                return Ok(Err(WriteError::Unexpected { id, state: job.state }));
            }
            let cause = format!("priority {} -> {}", job.priority, p.get());
            job.priority = p.get();
            cause
        }
    };
    job.updated_at = from_ms(now);
    let mut pending = Pending::default();
    if let (Change::Transition { transition: Transition::Dispatch, .. }, Some(spec)) = (change, job.spec()) {
        locations::reserve(&mut **tx, id, &spec.locations(), true).await?;
    }
    if job.state.is_terminal() {
        if let (JobState::Completed, Some(spec)) = (job.state, job.spec()) {
            for l in locations::complete(&mut **tx, &spec, job.barcode.as_deref(), now).await? {
                if let Some(state) = locations::get(&mut **tx, l).await? {
                    let data = serde_json::to_string(&state).unwrap_or_default();
                    pending.events.push(("location.updated", data, now));
                }
            }
        }
        locations::reserve(&mut **tx, id, &[], false).await?;
    }
    let f = job.failure.as_ref();
    sqlx::query(
        "UPDATE jobs SET state = ?, priority = ?, forced = ?, failure_kind = ?, failure_code = ?, \
         failure_text = ?, updated_at = ? WHERE id = ?",
    )
    .bind(job.state.as_str())
    .bind(job.priority as i64)
    .bind(job.forced)
    .bind(f.map(|f| f.kind.clone()))
    .bind(f.and_then(|f| f.code))
    .bind(f.map(|f| f.text.clone()))
    .bind(now)
    .bind(id)
    .execute(&mut **tx)
    .await?;
    pending.history.push((id, job.state, cause, now));
    pending.events.push(("job.updated", serde_json::to_string(&job).unwrap_or_default(), now));
    pending.flush(tx).await?;
    Ok(Ok(job))
}

/// Rows planned in memory, written with multi-row INSERTs.
#[derive(Default)]
struct Pending {
    jobs: Vec<(String, Job)>,
    history: Vec<(i64, JobState, String, i64)>,
    events: Vec<(&'static str, String, i64)>,
}

/// Rows per INSERT statement; keeps bound parameters well under SQLite's limit of 32766.
const ROWS_PER_INSERT: usize = 1000;

impl Pending {
    async fn flush(&mut self, tx: &mut Transaction<'_, Sqlite>) -> Result<(), sqlx::Error> {
        for chunk in self.jobs.chunks(ROWS_PER_INSERT) {
            let mut q = QueryBuilder::<Sqlite>::new(
                "INSERT INTO jobs (id, reference, kind, priority, barcode, spec, request, device, \
                 state, created_at, updated_at) ",
            );
            q.push_values(chunk, |mut row, (request, job)| {
                let spec = serde_json::to_string(&job.spec()).unwrap_or_default();
                let created = super::time::to_ms(job.created_at);
                row.push_bind(job.id)
                    .push_bind(job.reference.clone())
                    .push_bind(job.kind.as_str())
                    .push_bind(job.priority as i64)
                    .push_bind(job.barcode.clone())
                    .push_bind(spec)
                    .push_bind(request.clone())
                    .push_bind(job.device.clone())
                    .push_bind(job.state.as_str())
                    .push_bind(created)
                    .push_bind(created);
            });
            q.build().execute(&mut **tx).await?;
        }
        for chunk in self.history.chunks(ROWS_PER_INSERT) {
            let mut q = QueryBuilder::<Sqlite>::new("INSERT INTO job_history (job_id, state, cause, at) ");
            q.push_values(chunk, |mut row, (id, state, cause, at)| {
                row.push_bind(*id).push_bind(state.as_str()).push_bind(cause.clone()).push_bind(*at);
            });
            q.build().execute(&mut **tx).await?;
        }
        for chunk in self.events.chunks(ROWS_PER_INSERT) {
            let mut q = QueryBuilder::<Sqlite>::new("INSERT INTO events (type, data, at) ");
            q.push_values(chunk, |mut row, (kind, data, at)| {
                row.push_bind(*kind).push_bind(data.clone()).push_bind(*at);
            });
            q.build().execute(&mut **tx).await?;
        }
        self.jobs.clear();
        self.history.clear();
        self.events.clear();
        Ok(())
    }
}
