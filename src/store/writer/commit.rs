//! One group, one transaction: plan submissions in memory, apply changes, write the rows.

use std::collections::HashMap;

use rusqlite::{OptionalExtension, Transaction, params};

use super::timing::{self, JobTiming};
use super::{Change, Command, Outcome, Record, WriteError};
use crate::domain::report::path;
use crate::domain::time::{from_ms, now_ms, to_ms};
use crate::domain::{Failure, JobState, Location, LocationLock, Transition};
use crate::store::events::StoredEvent;
use crate::store::jobs::{COLUMNS, Job, JobRow, NewJob};
use crate::store::locations;
use crate::store::{alarms, controls};

/// What the writer answers for one command.
// One answer per command of a group, alive until it is sent: their size does not matter,
// and boxing the job would cost an allocation per change.
#[allow(clippy::large_enum_variant)]
pub(super) enum Answer {
    Submitted(Result<Vec<Outcome>, WriteError>),
    Changed(Result<Job, WriteError>),
    Reported(Vec<Result<Job, WriteError>>),
    Recorded,
    Refused(WriteError),
    Failed(WriteError),
}

impl Answer {
    /// The jobs this answer created or changed.
    pub(super) fn jobs(&self) -> Vec<&Job> {
        match self {
            Answer::Submitted(Ok(outcomes)) => outcomes
                .iter()
                .filter_map(|o| match o {
                    Outcome::Created(job) => Some(job),
                    Outcome::Existing(_) => None,
                })
                .collect(),
            Answer::Changed(Ok(job)) => vec![job],
            Answer::Reported(jobs) => jobs.iter().filter_map(|r| r.as_ref().ok()).collect(),
            _ => Vec::new(),
        }
    }
}

/// What a group produced besides its answers.
#[derive(Default)]
pub(super) struct Out {
    /// The events it appended, in sequence order.
    pub(super) events: Vec<StoredEvent>,
    /// The locations it locked (`Some`) or unlocked.
    pub(super) locks: Vec<(Location, Option<LocationLock>)>,
    /// Timed transitions, for `/metrics`.
    pub(super) timings: Vec<JobTiming>,
    /// Fills in why a job waits, before its event is written.
    tell: Option<super::Tell>,
}

impl Out {
    fn tell(&self, job: &mut Job) {
        if let Some(tell) = &self.tell {
            tell(job);
        }
    }
}

type Events = Out;

/// Applies a group in one transaction; any database error rolls back the whole group.
/// `next_id` is the writer's id counter, read from the table when unknown. Returns the
/// answers, and the events and lock changes of the group.
pub(super) fn commit(
    db: &mut rusqlite::Connection,
    group: &[Command],
    next_id: &mut Option<i64>,
    tell: Option<super::Tell>,
) -> rusqlite::Result<(Vec<Answer>, Out)> {
    let tx = db.transaction_with_behavior(rusqlite::TransactionBehavior::Immediate)?;
    let now = now_ms();
    let mut id = match *next_id {
        Some(id) => id,
        None => tx.query_row("SELECT COALESCE(MAX(id), 0) + 1 FROM jobs", [], |r| r.get(0))?,
    };
    let mut known: HashMap<String, (String, Job)> = HashMap::new();
    let mut answers = Vec::with_capacity(group.len());
    let mut events = Out { tell, ..Out::default() };
    let ev = &mut events;
    for cmd in group {
        answers.push(match cmd {
            Command::Submit { jobs, .. } => {
                Answer::Submitted(submit(&tx, jobs, &mut known, &mut id, now, ev)?)
            }
            Command::Change { id, change, .. } => Answer::Changed(apply(&tx, *id, change, now, ev)?),
            Command::Reports { reports, .. } => {
                let mut jobs = Vec::with_capacity(reports.len());
                for r in reports {
                    let change = Change::Report { to: r.to.clone(), cause: r.cause.clone() };
                    jobs.push(apply(&tx, r.job, &change, now, ev)?);
                }
                Answer::Reported(jobs)
            }
            Command::Record { record, .. } => match self::record(&tx, record, now, ev)? {
                Ok(()) => Answer::Recorded,
                Err(e) => Answer::Refused(e),
            },
        });
    }
    tx.commit()?;
    *next_id = Some(id);
    Ok((answers, events))
}

/// Records a change that is not a job's; the inner error refuses it.
fn record(
    tx: &Transaction<'_>,
    record: &Record,
    now: i64,
    events: &mut Events,
) -> rusqlite::Result<Result<(), WriteError>> {
    match record {
        Record::Device { status } => events.events.push(append(tx, "device.updated", status.clone(), now)?),
        Record::Pause { target, paused, by } => {
            controls::set(tx, target, paused.then_some(by))?;
            let action = if *paused { "pause" } else { "resume" };
            let entry = controls::append(tx, &by.by, action, &target.key(), by.reason.as_deref(), now)?;
            event(tx, "audit.recorded", &entry, now, events)?;
        }
        Record::Lock { location, lock } => {
            let entry =
                controls::append(tx, &lock.by, "lock", &location_key(*location), Some(&lock.reason), now)?;
            event(tx, "audit.recorded", &entry, now, events)?;
            if locations::lock(tx, *location, lock, now)? {
                events.locks.push((*location, Some(lock.clone())));
                location_events(tx, &[*location], now, events)?;
            }
        }
        Record::Unlock { location, by, reason } => {
            let entry = controls::append(tx, by, "unlock", &location_key(*location), reason.as_deref(), now)?;
            event(tx, "audit.recorded", &entry, now, events)?;
            if locations::unlock(tx, *location, now)? {
                events.locks.push((*location, None));
                location_events(tx, &[*location], now, events)?;
            }
        }
        Record::AlarmRaised(new) => {
            if let Some(alarm) = alarms::raise(tx, new, now)? {
                event(tx, "alarm.raised", &alarm, now, events)?;
            }
        }
        Record::AlarmCleared { device, key } => {
            if let Some(alarm) = alarms::clear(tx, device, *key, now)? {
                event(tx, "alarm.cleared", &alarm, now, events)?;
            }
        }
        Record::Prune { before_ms } => {
            tx.prepare_cached("DELETE FROM events WHERE at < ?1 AND seq < (SELECT MAX(seq) FROM events)")?
                .execute([before_ms])?;
        }
        Record::Retell { jobs } => {
            let sql = format!("SELECT {COLUMNS} FROM jobs WHERE id = ?1");
            for &id in jobs {
                let row =
                    tx.prepare_cached(&sql)?.query_row([id], |r| JobRow::from_rusqlite(r, 0)).optional()?;
                let Some(row) = row else { continue };
                let mut job =
                    Job::try_from(row).map_err(|e| rusqlite::Error::ToSqlConversionFailure(e.into()))?;
                // A job that moved on meanwhile was told by its own commit.
                if job.state == JobState::Queued {
                    events.tell(&mut job);
                    event(tx, "job.updated", &job, now, events)?;
                }
            }
        }
        Record::Acknowledge { alarm, by, note } => {
            let alarm = match alarms::acknowledge(tx, *alarm, by, now)? {
                alarms::Acknowledged::Done(alarm) => alarm,
                alarms::Acknowledged::NotFound => return Ok(Err(WriteError::AlarmNotFound(*alarm))),
                alarms::Acknowledged::Before(by) => {
                    return Ok(Err(WriteError::AlreadyAcknowledged { id: *alarm, by }));
                }
            };
            let entry = controls::append(
                tx,
                by,
                "acknowledge",
                &format!("alarm:{}", alarm.id),
                note.as_deref(),
                now,
            )?;
            event(tx, "audit.recorded", &entry, now, events)?;
            event(tx, "alarm.updated", &alarm, now, events)?;
        }
    }
    Ok(Ok(()))
}

/// The stored request and job with this reference, looked up once per group.
fn lookup<'k>(
    tx: &Transaction<'_>,
    known: &'k mut HashMap<String, (String, Job)>,
    reference: &str,
) -> rusqlite::Result<Option<&'k (String, Job)>> {
    if !known.contains_key(reference) {
        let sql = format!("SELECT request, {COLUMNS} FROM jobs WHERE reference = ?1");
        let found = tx
            .prepare_cached(&sql)?
            .query_row([reference], |r| Ok((r.get::<_, String>(0)?, JobRow::from_rusqlite(r, 1)?)))
            .optional()?;
        match found {
            Some((request, row)) => {
                let job =
                    Job::try_from(row).map_err(|e| rusqlite::Error::ToSqlConversionFailure(e.into()))?;
                known.insert(reference.to_owned(), (request, job));
            }
            None => return Ok(None),
        }
    }
    Ok(known.get(reference))
}

/// Stores one submission, all or nothing: a reference used with a different request
/// refuses the whole submission before anything of it is written.
fn submit(
    tx: &Transaction<'_>,
    jobs: &[NewJob],
    known: &mut HashMap<String, (String, Job)>,
    next_id: &mut i64,
    now: i64,
    events: &mut Events,
) -> rusqlite::Result<Result<Vec<Outcome>, WriteError>> {
    let mut outcomes = Vec::with_capacity(jobs.len());
    let mut created: Vec<(String, Job)> = Vec::new();
    let mut local: HashMap<&str, usize> = HashMap::new();
    for new in jobs {
        let request = new.canonical();
        if let Some(reference) = new.reference.as_deref() {
            let seen = match local.get(reference) {
                Some(&i) => Some(&created[i]),
                None => lookup(tx, known, reference)?,
            };
            if let Some((stored, job)) = seen {
                if *stored != request {
                    return Ok(Err(WriteError::Conflict(reference.to_owned())));
                }
                outcomes.push(Outcome::Existing(job.clone()));
                continue;
            }
            local.insert(reference, created.len());
        }
        let mut job = new.accepted(*next_id + created.len() as i64, now);
        events.tell(&mut job);
        outcomes.push(Outcome::Created(job.clone()));
        created.push((request, job));
    }
    *next_id += created.len() as i64;
    for (request, job) in created {
        insert_job(tx, &request, &job)?;
        history(tx, job.id, JobState::Queued, "accepted", now)?;
        event(tx, "job.updated", &job, now, events)?;
        if let Some(r) = job.reference.clone() {
            known.insert(r, (request, job));
        }
    }
    Ok(Ok(outcomes))
}

fn insert_job(tx: &Transaction<'_>, request: &str, job: &Job) -> rusqlite::Result<()> {
    let spec = serde_json::to_string(&job.spec()).unwrap_or_default();
    let created = to_ms(job.created_at);
    tx.prepare_cached(
        "INSERT INTO jobs (id, reference, kind, priority, barcode, spec, request, device, state, \
         created_at, updated_at) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?10)",
    )?
    .execute(params![
        job.id,
        job.reference,
        job.kind.as_str(),
        job.priority,
        job.barcode,
        spec,
        request,
        job.device,
        job.state.as_str(),
        created
    ])?;
    Ok(())
}

fn history(tx: &Transaction<'_>, id: i64, state: JobState, cause: &str, now: i64) -> rusqlite::Result<()> {
    tx.prepare_cached("INSERT INTO job_history (job_id, state, cause, at) VALUES (?1, ?2, ?3, ?4)")?
        .execute(params![id, state.as_str(), cause, now])?;
    Ok(())
}

/// Appends an event with `data` serialized to the log and to `events`.
fn event(
    tx: &Transaction<'_>,
    kind: &str,
    data: &impl serde::Serialize,
    now: i64,
    events: &mut Events,
) -> rusqlite::Result<()> {
    let data = serde_json::to_string(data).map_err(|e| rusqlite::Error::ToSqlConversionFailure(e.into()))?;
    events.events.push(append(tx, kind, data, now)?);
    Ok(())
}

/// A `location.updated` event for each of `locations` (as they now are).
fn location_events(
    tx: &Transaction<'_>,
    locations: &[Location],
    now: i64,
    events: &mut Events,
) -> rusqlite::Result<()> {
    for &l in locations {
        if let Some(state) = locations::state(tx, l)? {
            event(tx, "location.updated", &state, now, events)?;
        }
    }
    Ok(())
}

/// Appends an event to the log; its sequence number is the row id, gapless because only
/// committed rows take one and this thread is the only writer.
fn append(tx: &Transaction<'_>, kind: &str, data: String, now: i64) -> rusqlite::Result<StoredEvent> {
    tx.prepare_cached("INSERT INTO events (type, data, at) VALUES (?1, ?2, ?3)")?
        .execute(params![kind, data, now])?;
    Ok(StoredEvent { seq: tx.last_insert_rowid(), at: now, kind: kind.to_owned(), data })
}

/// Applies one change to a stored job, with its effects on the location model.
fn apply(
    tx: &Transaction<'_>,
    id: i64,
    change: &Change,
    now: i64,
    events: &mut Events,
) -> rusqlite::Result<Result<Job, WriteError>> {
    let sql = format!("SELECT {COLUMNS} FROM jobs WHERE id = ?1");
    let row = tx.prepare_cached(&sql)?.query_row([id], |r| JobRow::from_rusqlite(r, 0)).optional()?;
    let Some(row) = row else { return Ok(Err(WriteError::NotFound(id))) };
    let mut job = Job::try_from(row).map_err(|e| rusqlite::Error::ToSqlConversionFailure(e.into()))?;
    match change {
        Change::Transition { transition, cause, expect, failure, forced } => {
            if expect.as_ref().is_some_and(|states| !states.contains(&job.state)) {
                return Ok(Err(WriteError::Unexpected { id, state: job.state }));
            }
            if let Err(e) = step(tx, &mut job, *transition, cause, failure.as_ref(), *forced, now, events)? {
                return Ok(Err(e));
            }
        }
        Change::Report { to, cause } => {
            for transition in path(job.state, to) {
                if let Err(e) = step(tx, &mut job, transition, cause, to.failure(), to.forced(), now, events)?
                {
                    return Ok(Err(e));
                }
            }
        }
        Change::Retry { by } => {
            let cause = format!("retried by {by} (attempt {})", job.attempt + 1);
            if let Err(e) = step(tx, &mut job, Transition::Retry, &cause, None, false, now, events)? {
                return Ok(Err(e));
            }
            let entry = controls::append(tx, by, "retry", &format!("job:{id}"), None, now)?;
            event(tx, "audit.recorded", &entry, now, events)?;
        }
        Change::Priority(p) => {
            if job.state != JobState::Queued {
                return Ok(Err(WriteError::Unexpected { id, state: job.state }));
            }
            let cause = format!("priority {} -> {}", job.priority, p.get());
            job.priority = p.get();
            save(tx, &mut job, &cause, now, events)?;
        }
    }
    Ok(Ok(job))
}

/// Moves `job` through one transition and stores it, with the transition's effects on the
/// location model: a dispatch reserves the job's locations, an end releases them (and a
/// completion changes their contents).
#[allow(clippy::too_many_arguments)]
fn step(
    tx: &Transaction<'_>,
    job: &mut Job,
    transition: Transition,
    cause: &str,
    failure: Option<&Failure>,
    forced: bool,
    now: i64,
    events: &mut Events,
) -> rusqlite::Result<Result<(), WriteError>> {
    let id = job.id;
    job.state = match job.state.apply(transition) {
        Ok(state) => state,
        Err(e) => return Ok(Err(e.into())),
    };
    // Looked up before `save` writes this transition's own history entry.
    if transition == Transition::Dispatch || job.state.is_terminal() {
        let since = timing::last_start(tx, id)?.unwrap_or(to_ms(job.created_at));
        let (kind, elapsed) = (job.kind, timing::between(since, now));
        events.timings.push(if transition == Transition::Dispatch {
            JobTiming::Dispatched { kind, waited: elapsed }
        } else {
            JobTiming::Ended { kind, state: job.state, took: elapsed }
        });
    }
    job.forced = forced && job.state == JobState::Completed;
    if transition == Transition::Fail {
        job.failure = failure.cloned();
    }
    if transition == Transition::Retry {
        job.failure = None;
        job.attempt += 1;
    }
    if transition == Transition::Dispatch
        && let Some(spec) = job.spec()
    {
        locations::reserve(tx, id, &spec.locations())?;
        location_events(tx, &spec.locations(), now, events)?;
    }
    if job.state.is_terminal() {
        // Released before the events are made, so that they show the location free.
        let spec = job.spec();
        let mut touched = match (job.state, &spec) {
            (JobState::Completed, Some(spec)) => locations::complete(tx, spec, job.barcode.as_deref(), now)?,
            _ => Vec::new(),
        };
        if let (Some(f), Some(spec)) = (job.failure.as_ref().filter(|f| f.kind.locks()), &spec) {
            let lock = LocationLock {
                by: "rackd".into(),
                reason: format!("job {id} failed ({}): {}", f.kind, f.text),
                job: Some(id),
                at: from_ms(now),
            };
            for l in spec.locations() {
                if locations::lock(tx, l, &lock, now)? {
                    events.locks.push((l, Some(lock.clone())));
                    touched.push(l);
                }
            }
        }
        if locations::release(tx, id)? > 0 {
            let held = spec.map(|s| s.locations()).unwrap_or_default();
            for l in held {
                if !touched.contains(&l) {
                    touched.push(l);
                }
            }
        }
        location_events(tx, &touched, now, events)?;
    }
    save(tx, job, cause, now, events)?;
    Ok(Ok(()))
}

/// Writes the job's row, a history entry and a `job.updated` event.
fn save(
    tx: &Transaction<'_>,
    job: &mut Job,
    cause: &str,
    now: i64,
    events: &mut Events,
) -> rusqlite::Result<()> {
    job.updated_at = from_ms(now);
    let f = job.failure.as_ref();
    tx.prepare_cached(
        "UPDATE jobs SET state = ?1, priority = ?2, forced = ?3, failure_kind = ?4, failure_code = ?5, \
         failure_text = ?6, updated_at = ?7, attempt = ?9 WHERE id = ?8",
    )?
    .execute(params![
        job.state.as_str(),
        job.priority,
        job.forced,
        f.map(|f| f.kind.as_str()),
        f.and_then(|f| f.code),
        f.map(|f| &f.text),
        now,
        job.id,
        job.attempt
    ])?;
    history(tx, job.id, job.state, cause, now)?;
    events.tell(job);
    event(tx, "job.updated", job, now, events)?;
    Ok(())
}

/// A location as audited: `location:A/R/B/L/P`.
fn location_key(l: Location) -> String {
    format!("location:{}/{}/{}/{}/{}", l.aisle, l.row, l.bay, l.level, l.position)
}
