//! One group applied in memory: submissions planned, changes put through the state machine,
//! their effects on locations, alarms, controls and the audit log worked out, every row to
//! write and every event to append collected. Nothing here touches the database: [`super::load`]
//! reads what a group needs first, [`super::save`] writes what it produced after. The
//! records (what a group changes besides jobs: pauses, locks, inventory, alarms) are applied
//! in [`record`].

mod bulk;
mod record;
mod terms;

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::net::IpAddr;

use super::timing::{self, JobTiming};
use super::{Change, Command, Outcome, WriteError};
use crate::domain::report::path;
use crate::domain::time::{from_ms, to_ms};
use crate::domain::{Failure, JobState, LightColor, Location, LocationLock, Pause, Transition, Who};
use crate::store::alarms;
use crate::store::controls::AuditEntry;
use crate::store::counts::Counts;
use crate::store::events::StoredEvent;
use crate::store::jobs::{Job, NewJob};
use crate::store::locations::{self, LocationState};
use crate::store::rollups::{self, fold::End};
use crate::store::sequences;

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
    Bulked(Result<super::Bulked, WriteError>),
    Failed(WriteError),
    /// Jobs read as committed, written nothing (see `Writer::adopt`).
    Adopted(Vec<Job>),
}

impl Answer {
    /// The jobs this answer created or changed.
    pub(super) fn jobs(&self) -> Vec<&Job> {
        match self {
            Answer::Submitted(Ok(outcomes)) => outcomes
                .iter()
                .filter_map(|o| match o {
                    Outcome::Created { job, .. } => Some(job),
                    Outcome::Existing(_) => None,
                })
                .collect(),
            Answer::Changed(Ok(job)) => vec![job],
            Answer::Reported(jobs) => jobs.iter().filter_map(|r| r.as_ref().ok()).collect(),
            Answer::Adopted(jobs) => jobs.iter().collect(),
            Answer::Bulked(Ok(done)) if done.applied => done.jobs.iter().collect(),
            _ => Vec::new(),
        }
    }

    /// The errors this answer carries.
    pub(super) fn errors(&self) -> Vec<&WriteError> {
        match self {
            Answer::Submitted(Err(e))
            | Answer::Changed(Err(e))
            | Answer::Bulked(Err(e))
            | Answer::Refused(e)
            | Answer::Failed(e) => vec![e],
            Answer::Reported(jobs) => jobs.iter().filter_map(|r| r.as_ref().err()).collect(),
            _ => Vec::new(),
        }
    }
}

/// What a group produced besides its answers, handed on after the commit.
#[derive(Default)]
pub(super) struct Out {
    /// The events it appended, in sequence order.
    pub(super) events: Vec<StoredEvent>,
    /// The locations it locked (`Some`) or unlocked.
    pub(super) locks: Vec<(Location, Option<LocationLock>)>,
    /// Timed transitions, for `/metrics`.
    pub(super) timings: Vec<JobTiming>,
    /// Statements the group's transaction ran, `BEGIN` and `COMMIT` included.
    pub(super) statements: usize,
    /// Of `statements`, those that wrote (every one of `save` and `stream`: they run only
    /// with rows to write). A group without any changed nothing, so its `COMMIT` did not
    /// reach the disk (SQLite writes nothing to the WAL for it).
    pub(super) writes: usize,
    /// What it changed in the counts of jobs and active alarms (see [`Group::counted`]).
    pub(super) counts: Counts,
    /// What its transitions add to the rollups (see [`crate::store::rollups`]).
    pub(super) moves: Vec<rollups::Move>,
    /// The sequences it created or changed, as they end up.
    pub(super) sequences: Vec<sequences::Row>,
}

/// The next id of each numbered table, allocated here (one writer: no gaps, no races).
#[derive(Clone, Copy, Debug)]
pub(super) struct Next {
    pub(super) job: i64,
    pub(super) seq: i64,
    pub(super) audit: i64,
    pub(super) alarm: i64,
}

/// What a group reads before it is applied (see [`super::load`]).
#[derive(Default)]
pub(super) struct Loaded {
    /// Stored jobs with the references the group's submissions use, with their requests.
    pub(super) by_reference: HashMap<String, (String, Job)>,
    /// Stored jobs the group's changes name.
    pub(super) jobs: HashMap<i64, Job>,
    /// The locations the group may touch.
    pub(super) locations: HashMap<Location, locations::Row>,
    /// When each loaded job entered its latest `queued` or `dispatched` state (Unix ms).
    pub(super) starts: HashMap<i64, i64>,
    /// Every active alarm (only when the group raises or clears one), and the alarms its
    /// acknowledgements name, by id.
    pub(super) alarms: BTreeMap<i64, alarms::Row>,
    /// Stored jobs the group's submissions name in `after`, by reference.
    pub(super) after: HashMap<String, Job>,
    /// The sequences the group's submissions and records name, with their members.
    pub(super) sequences: BTreeMap<String, sequences::Stored>,
}

/// One history entry to write.
#[derive(serde::Serialize)]
pub(super) struct History {
    pub(super) job_id: i64,
    pub(super) state: &'static str,
    pub(super) cause: String,
    pub(super) at: i64,
}

/// What one group leaves to the next: its map of jobs, emptied but still allocated. A
/// group of batches maps tens of thousands of jobs (about 30 MB for 32,000); allocated anew
/// for each group, its pages were faulted in one by one as the jobs went in, about a tenth
/// of the batch phase's CPU in a profile (the kernel zeroing fresh pages). A map with room
/// for more than [`Spare::MOST`] jobs is let go: what a group keeps for the next is at most
/// about 46 MB (a job takes 352 bytes in the map), the room 64 clients' batches of 1000
/// jobs need at once (114,688 jobs); a larger burst does not pin its memory.
#[derive(Default)]
pub(super) struct Spare {
    jobs: HashMap<i64, Job>,
}

impl Spare {
    /// The most jobs a map kept for the next group may have room for.
    const MOST: usize = 1 << 17;
}

/// A group being applied: what it read, how that changed, and what to write.
pub(super) struct Group {
    pub(super) now: i64,
    pub(super) next: Next,
    /// Stored jobs by reference, with their requests (as loaded).
    known: HashMap<String, (String, Job)>,
    /// Jobs this group created, by reference (their requests are in `created`, the jobs in
    /// `jobs`): kept apart so that creating a job copies it once, not three times.
    created_refs: HashMap<String, i64>,
    /// Every job loaded or created, as it now is.
    pub(super) jobs: HashMap<i64, Job>,
    /// The state of each job loaded, as stored before this group.
    was: HashMap<i64, JobState>,
    /// Jobs created by this group, with their canonical requests, in id order.
    pub(super) created: BTreeMap<i64, String>,
    /// Stored jobs this group changed.
    pub(super) changed: BTreeSet<i64>,
    pub(super) locations: HashMap<Location, locations::Row>,
    /// Locations this group changed.
    pub(super) touched: BTreeSet<Location>,
    starts: HashMap<i64, i64>,
    /// The alarms loaded, and those raised by this group, as they now are.
    pub(super) alarms: BTreeMap<i64, alarms::Row>,
    /// Alarms raised by this group.
    pub(super) raised: BTreeSet<i64>,
    /// The alarms loaded that were active before this group.
    was_active: BTreeSet<i64>,
    /// Stored alarms this group changed (cleared, acknowledged).
    pub(super) alarms_changed: BTreeSet<i64>,
    /// Fills in why a job waits, before its event is made.
    tell: Option<super::Tell>,
    /// Pauses set (`Some`) or lifted (`None`) by this group, by target key, as they end up.
    pub(super) controls: BTreeMap<String, Option<Pause>>,
    pub(super) audit: Vec<AuditEntry>,
    /// The group's submissions that created jobs, by caller: audited together at the end
    /// of the group (see [`Group::audit_submissions`]).
    submitted: Vec<Submitted>,
    pub(super) history: Vec<History>,
    /// Retention: events before this time go, through this seq, and any before the last.
    pub(super) prune: Option<(i64, i64, i64)>,
    /// Webhook subscriptions' rows and deliveries, in the order recorded.
    pub(super) webhooks: Vec<crate::store::webhooks::Progress>,
    /// Retention: jobs moved to the archive, deleted with this group (id, device, state).
    pub(super) archived: Vec<(i64, Option<String>, JobState)>,
    /// Stored jobs the group's submissions name in `after`, by reference.
    after: HashMap<String, Job>,
    /// The sequences loaded, and those this group created, as they now are.
    pub(super) sequences: BTreeMap<String, sequences::Stored>,
    /// Sequences this group created or changed.
    pub(super) sequences_changed: BTreeSet<String>,
    /// Members this group added: sequence, position, job.
    pub(super) new_members: Vec<(String, u32, i64)>,
    pub(super) out: Out,
}

impl Group {
    /// A group starting from what it read, its maps sized for the jobs `cmds` may create
    /// (grown submission by submission, the map of jobs moved every job it held each time
    /// it doubled: a seventh of the writer's time in a profile of the batch phase), the map
    /// of jobs the one `spare` holds.
    pub(super) fn new(
        loaded: Loaded,
        next: Next,
        now: i64,
        tell: Option<super::Tell>,
        cmds: &[&Command],
        spare: &mut Spare,
    ) -> Group {
        let new: usize =
            cmds.iter().map(|c| if let Command::Submit { jobs, .. } = *c { jobs.len() } else { 0 }).sum();
        let mut jobs = std::mem::take(&mut spare.jobs);
        jobs.reserve(loaded.jobs.len() + new);
        let was = loaded.jobs.values().map(|j| (j.id, j.state)).collect();
        jobs.extend(loaded.jobs);
        let was_active = loaded.alarms.values().filter(|a| a.cleared_at.is_none()).map(|a| a.id).collect();
        let mut starts = loaded.starts;
        starts.reserve(new);
        Group {
            now,
            next,
            known: loaded.by_reference,
            created_refs: HashMap::with_capacity(new),
            jobs,
            was,
            created: BTreeMap::new(),
            changed: BTreeSet::new(),
            locations: loaded.locations,
            touched: BTreeSet::new(),
            starts,
            alarms: loaded.alarms,
            raised: BTreeSet::new(),
            was_active,
            alarms_changed: BTreeSet::new(),
            tell,
            controls: BTreeMap::new(),
            audit: Vec::new(),
            submitted: Vec::new(),
            history: Vec::with_capacity(new),
            prune: None,
            webhooks: Vec::new(),
            archived: Vec::new(),
            after: loaded.after,
            sequences: loaded.sequences,
            sequences_changed: BTreeSet::new(),
            new_members: Vec::new(),
            out: Out { events: Vec::with_capacity(new), ..Out::default() },
        }
    }

    /// Hands the group's map of jobs, emptied, to the next group (see [`Spare`]); the group
    /// is done with its jobs.
    pub(super) fn recycle(&mut self, spare: &mut Spare) {
        let mut jobs = std::mem::take(&mut self.jobs);
        if jobs.capacity() <= Spare::MOST {
            jobs.clear();
            spare.jobs = jobs;
        }
    }

    /// Notes in `out.counts` what the group changed in the counts of jobs by device and
    /// state and of active alarms by device and class (see [`crate::store::counts`]): its
    /// new jobs as they end up, each stored job it moved out of the state it was stored in
    /// and into the one it ends in, each alarm it raised and left active, and each stored
    /// active alarm it cleared. Called once the group's commands are applied.
    pub(super) fn counted(&mut self) {
        self.out.sequences =
            self.sequences_changed.iter().filter_map(|n| Some(self.sequences.get(n)?.row.clone())).collect();
        let mut counts = Counts::default();
        for job in self.created.keys().filter_map(|id| self.jobs.get(id)) {
            counts.job(job.device.as_deref(), job.state, 1);
        }
        for id in &self.changed {
            if let (Some(job), Some(&was)) = (self.jobs.get(id), self.was.get(id))
                && job.state != was
            {
                counts.job(job.device.as_deref(), was, -1);
                counts.job(job.device.as_deref(), job.state, 1);
            }
        }
        for (_, device, state) in &self.archived {
            counts.job(device.as_deref(), *state, -1);
        }
        for alarm in self.raised.iter().filter_map(|id| self.alarms.get(id)) {
            if alarm.cleared_at.is_none() {
                counts.alarm(&alarm.device, &alarm.class, 1);
            }
        }
        for id in self.alarms_changed.intersection(&self.was_active) {
            if let Some(alarm) = self.alarms.get(id).filter(|a| a.cleared_at.is_some()) {
                counts.alarm(&alarm.device, &alarm.class, -1);
            }
        }
        self.out.counts = counts;
    }

    /// Whether the group read a job that holds one of its submissions' references.
    pub(super) fn read_stored(&self) -> bool {
        !self.known.is_empty()
    }

    /// Applies one command and answers it.
    pub(super) fn command(&mut self, cmd: &Command) -> Answer {
        match cmd {
            Command::Submit { jobs, who, .. } => Answer::Submitted(self.submit(jobs, who.as_ref())),
            Command::Change { id, change, who, .. } => Answer::Changed(self.apply(*id, change, who.as_ref())),
            Command::Reports { reports, .. } => Answer::Reported(
                reports
                    .iter()
                    .map(|r| {
                        let change = Change::Report { to: r.to.clone(), cause: r.cause.clone() };
                        self.apply(r.job, &change, None)
                    })
                    .collect(),
            ),
            Command::Record { record, who, .. } => match self.record(record, who.as_ref()) {
                Ok(()) => Answer::Recorded,
                Err(e) => Answer::Refused(e),
            },
            Command::Bulk { bulk, who, .. } => Answer::Bulked(self.bulk(bulk, who)),
            Command::Adopt { ids, .. } => {
                Answer::Adopted(ids.iter().filter_map(|id| self.jobs.get(id)).cloned().collect())
            }
        }
    }

    /// Fills in how late `job` is, and why it waits, if the dispatcher says.
    fn tell(&self, job: &mut Job) {
        job.late_by_s = job.late_at(self.now);
        if let Some(tell) = &self.tell {
            tell(job);
        }
    }

    /// Stores one submission, all or nothing: a reference used with a different request
    /// refuses the whole submission before anything of it is written. Sent by `who`, a
    /// submission that created a job is audited: `submit` of `job:ID`, or of
    /// `jobs:FIRST-LAST` for a batch (a submission's new jobs have consecutive ids), whose
    /// reason names its count. One that only repeated stored jobs changed nothing and is not.
    fn submit(&mut self, jobs: &[NewJob], who: Option<&Who>) -> Result<Vec<Outcome>, WriteError> {
        let mut outcomes = Vec::with_capacity(jobs.len());
        let mut created: Vec<(String, Job, String)> = Vec::with_capacity(jobs.len());
        let mut local: HashMap<&str, usize> = HashMap::with_capacity(jobs.len());
        // Which request each created job comes from, when any request has terms.
        let terms = jobs.iter().any(|j| !j.terms.is_plain());
        let mut index: Vec<usize> = Vec::new();
        for (i, new) in jobs.iter().enumerate() {
            let request = new.canonical();
            if let Some(reference) = new.reference.as_deref() {
                let seen = match local.get(reference) {
                    Some(&i) => Some((&created[i].0, &created[i].1)),
                    None => self.seen(reference),
                };
                if let Some((stored, job)) = seen {
                    if *stored != request {
                        return Err(WriteError::Conflict(reference.to_owned()));
                    }
                    outcomes.push(Outcome::Existing(job.clone()));
                    continue;
                }
                local.insert(reference, created.len());
            }
            let mut job = new.accepted(self.next.job + created.len() as i64, self.now);
            self.tell(&mut job);
            // The job as JSON once: its event's data, and the answer's (see `Outcome`).
            let json = to_json(&job);
            outcomes.push(Outcome::Created { job: job.clone(), json: json.clone() });
            created.push((request, job, json));
            if terms {
                index.push(i);
            }
        }
        if terms {
            let new: Vec<(usize, &Job)> = index.iter().copied().zip(created.iter().map(|c| &c.1)).collect();
            let staged = self.check_terms(jobs, &new)?;
            self.stage(staged);
        }
        let ids = created.first().zip(created.last()).map(|(a, b)| (a.1.id, b.1.id));
        self.next.job += created.len() as i64;
        for (request, job, json) in created {
            self.history(job.id, JobState::Queued, "accepted");
            self.append("job.updated", json);
            if let Some(r) = &job.reference {
                self.created_refs.insert(r.clone(), job.id);
            }
            self.created.insert(job.id, request);
            self.jobs.insert(job.id, job);
        }
        if let (Some(who), Some(ids)) = (who, ids) {
            let same = |s: &&mut Submitted| s.name == who.name && s.client == who.client;
            match self.submitted.iter_mut().find(same) {
                Some(s) => s.add(jobs.len(), ids),
                None => self.submitted.push(Submitted::new(who, jobs.len(), ids)),
            }
        }
        Ok(outcomes)
    }

    /// Audits the group's submissions: one entry per caller (key and address) that created
    /// jobs in this group, written with it. A caller's one request is an entry of its own
    /// (`submit` of `job:ID`, or of `jobs:FIRST-LAST` for a batch, whose reason names its
    /// count); several requests of one caller in one group commit share one entry, whose
    /// target lists the ranges of their jobs and whose reason counts them. One entry per
    /// request cost 15% more CPU per single POST in `bench intake` (an audit row per job
    /// posted alone); one per caller and group is about one row per commit. Not published
    /// as `audit.recorded`: each new job's `job.updated` tells of it already.
    pub(super) fn audit_submissions(&mut self) {
        for s in std::mem::take(&mut self.submitted) {
            let (target, reason) = s.described();
            let entry = self.audit_entry(&s.name, s.client, "submit", &target, reason.as_deref());
            self.audit.push(entry);
        }
    }

    /// The request and the job (as it now is) that already use `reference`.
    fn seen(&self, reference: &str) -> Option<(&String, &Job)> {
        if let Some(id) = self.created_refs.get(reference) {
            return self.created.get(id).zip(self.jobs.get(id));
        }
        self.known.get(reference).map(|(request, job)| (request, job))
    }

    /// Applies one change to a job, with its effects on the location model; sent by `who`,
    /// a cancel, a new priority or a retry is audited.
    fn apply(&mut self, id: i64, change: &Change, who: Option<&Who>) -> Result<Job, WriteError> {
        let Some(mut job) = self.jobs.get(&id).cloned() else { return Err(WriteError::NotFound(id)) };
        let result = self.change(&mut job, change, who);
        // What was applied before a refusal stays, as each step is saved when it is made.
        if let Some(stored) = self.jobs.get_mut(&id) {
            *stored = job.clone();
        }
        result.map(|()| job)
    }

    fn change(&mut self, job: &mut Job, change: &Change, who: Option<&Who>) -> Result<(), WriteError> {
        let id = job.id;
        let client = who.and_then(|w| w.client);
        match change {
            Change::Transition { transition, cause, expect, failure, forced } => {
                if expect.as_ref().is_some_and(|states| !states.contains(&job.state)) {
                    return Err(WriteError::Unexpected { id, state: job.state });
                }
                self.step(job, *transition, cause, failure.as_ref(), *forced)?;
                if let Some(who) = who {
                    let action = if *transition == Transition::Cancel { "cancel" } else { "transition" };
                    self.audit(&who.name, client, action, &format!("job:{id}"), None);
                }
                Ok(())
            }
            Change::Report { to, cause } => {
                for transition in path(job.state, to) {
                    self.step(job, transition, cause, to.failure(), to.forced())?;
                }
                Ok(())
            }
            Change::Retry { by } => {
                let cause = format!("retried by {by} (attempt {})", job.attempt + 1);
                self.step(job, Transition::Retry, &cause, None, false)?;
                self.audit(by, client, "retry", &format!("job:{id}"), None);
                Ok(())
            }
            Change::Place(to) => {
                if job.state != JobState::Queued || job.to.is_some() || job.zones.is_none() {
                    return Err(WriteError::Unexpected { id, state: job.state });
                }
                let free = self
                    .locations
                    .get(to)
                    .is_some_and(|r| !r.occupied && r.reserved_by.is_none() && r.locked_at.is_none());
                if !free {
                    return Err(WriteError::Taken(*to));
                }
                job.to = Some(*to);
                self.save(job, &format!("putaway: rackd chose {to}"));
                Ok(())
            }
            Change::Priority(p) => {
                if job.state != JobState::Queued {
                    return Err(WriteError::Unexpected { id, state: job.state });
                }
                let cause = format!("priority {} -> {}", job.priority, p.get());
                job.priority = p.get();
                self.save(job, &cause);
                if let Some(who) = who {
                    self.audit(&who.name, client, "priority", &format!("job:{id}"), Some(&cause));
                }
                Ok(())
            }
        }
    }

    /// Moves `job` through one transition and saves it, with the transition's effects on
    /// the location model: a dispatch reserves the job's locations, an end releases them
    /// (and a completion changes their contents).
    fn step(
        &mut self,
        job: &mut Job,
        transition: Transition,
        cause: &str,
        failure: Option<&Failure>,
        forced: bool,
    ) -> Result<(), WriteError> {
        let (id, now) = (job.id, self.now);
        let was = job.state;
        job.state = job.state.apply(transition)?;
        // Read before `save` notes this transition's own history entry.
        let since = self.starts.get(&id).copied();
        if transition == Transition::Dispatch || job.state.is_terminal() {
            let since = self.starts.get(&id).copied().unwrap_or(to_ms(job.created_at));
            let (kind, elapsed) = (job.kind, timing::between(since, now));
            self.out.timings.push(if transition == Transition::Dispatch {
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
        self.rollup(job, was, since);
        if transition == Transition::Dispatch
            && let Some(spec) = job.spec()
        {
            for l in spec.locations() {
                if let Some(row) = self.locations.get_mut(&l) {
                    row.reserved_by = Some(id);
                    self.touched.insert(l);
                }
            }
            self.location_events(&spec.locations());
        }
        if job.state.is_terminal() {
            // Released before the events are made, so that they show the location free.
            let spec = job.spec();
            let mut touched = match (job.state, &spec) {
                (JobState::Completed, Some(spec)) => self.complete(spec, job.barcode.as_deref()),
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
                    if self.lock(l, &lock) {
                        self.out.locks.push((l, Some(lock.clone())));
                        touched.push(l);
                    }
                }
            }
            let held: Vec<Location> = self
                .locations
                .iter_mut()
                .filter(|(_, row)| row.reserved_by == Some(id))
                .map(|(l, row)| {
                    row.reserved_by = None;
                    *l
                })
                .collect();
            for l in held {
                self.touched.insert(l);
                if !touched.contains(&l) {
                    touched.push(l);
                }
            }
            self.location_events(&touched);
        }
        self.save(job, cause);
        Ok(())
    }

    /// Notes what the transition of `job` from `was` adds to the rollups; `since` is when
    /// it entered its latest `queued` or `dispatched` state (its dispatch, if it was on its
    /// device).
    fn rollup(&mut self, job: &Job, was: JobState, since: Option<i64>) {
        let on = i64::from(job.state.on_device()) - i64::from(was.on_device());
        let end = match job.state {
            JobState::Completed => {
                Some(End::Completed(since.filter(|_| was.on_device()).map(|s| (self.now - s).max(0))))
            }
            JobState::Failed => {
                Some(End::Failed(job.failure.as_ref().map_or("unknown", |f| f.kind.as_str()).to_owned()))
            }
            _ => None,
        };
        if on == 0 && end.is_none() {
            return;
        }
        let scopes = rollups::scopes(job.device.as_deref(), job.spec().as_ref());
        self.out.moves.push(rollups::Move {
            at: self.now,
            kind: job.kind.as_str().to_owned(),
            scopes,
            on,
            end,
        });
    }

    /// Notes the job's new row, a history entry and a `job.updated` event.
    fn save(&mut self, job: &mut Job, cause: &str) {
        job.updated_at = from_ms(self.now);
        if !self.created.contains_key(&job.id) {
            self.changed.insert(job.id);
        }
        self.history(job.id, job.state, cause);
        self.tell(job);
        self.event("job.updated", job);
    }

    fn history(&mut self, id: i64, state: JobState, cause: &str) {
        if matches!(state, JobState::Queued | JobState::Dispatched) {
            self.starts.insert(id, self.now);
        }
        self.history.push(History {
            job_id: id,
            state: state.as_str(),
            cause: cause.to_owned(),
            at: self.now,
        });
    }

    /// Locks `l` unless it is locked already (the first reason stands); whether it did.
    fn lock(&mut self, l: Location, lock: &LocationLock) -> bool {
        match self.locations.get_mut(&l) {
            Some(row) if row.locked_at.is_none() => {
                row.locked_at = Some(to_ms(lock.at));
                row.locked_by = Some(lock.by.clone());
                row.lock_reason = Some(lock.reason.clone());
                row.lock_job = lock.job;
                row.updated_at = self.now;
                self.touched.insert(l);
                true
            }
            _ => false,
        }
    }

    /// Lifts the lock of `l`, if it has one, with its `location.updated` event; whether it
    /// did.
    fn unlock(&mut self, l: Location) -> bool {
        match self.locations.get_mut(&l) {
            Some(row) if row.locked_at.is_some() => {
                (row.locked_at, row.locked_by, row.lock_reason, row.lock_job) = (None, None, None, None);
                row.updated_at = self.now;
            }
            _ => return false,
        }
        self.touched.insert(l);
        self.out.locks.push((l, None));
        self.location_events(&[l]);
        true
    }

    /// Applies what a completed job did to the locations it touched; returns them.
    ///
    /// store: the target is occupied with the job's barcode; retrieve and clear: the
    /// location is empty; move: the box (and its barcode) goes from source to target;
    /// light: the light's state; travel: nothing.
    fn complete(&mut self, spec: &crate::domain::JobSpec, barcode: Option<&str>) -> Vec<Location> {
        use crate::domain::JobSpec;
        match *spec {
            JobSpec::Store { to } => {
                self.set_box(to, true, barcode.map(str::to_owned));
                vec![to]
            }
            JobSpec::Retrieve { from: l } | JobSpec::Clear { location: l } => {
                self.set_box(l, false, None);
                vec![l]
            }
            JobSpec::Move { from, to } => {
                let moved = match barcode {
                    Some(b) => Some(b.to_owned()),
                    None => self.locations.get(&from).and_then(|r| r.barcode.clone()),
                };
                self.set_box(from, false, None);
                self.set_box(to, true, moved);
                vec![from, to]
            }
            JobSpec::Light { location, color, on } => {
                if let Some(row) = self.locations.get_mut(&location) {
                    match color {
                        LightColor::Red => row.red = on,
                        LightColor::Green => row.green = on,
                    }
                    row.updated_at = self.now;
                    self.touched.insert(location);
                }
                vec![location]
            }
            JobSpec::Travel { .. } | JobSpec::Putaway { .. } => Vec::new(),
        }
    }

    fn set_box(&mut self, l: Location, occupied: bool, barcode: Option<String>) {
        if let Some(row) = self.locations.get_mut(&l) {
            (row.occupied, row.barcode, row.updated_at) = (occupied, barcode, self.now);
            self.touched.insert(l);
        }
    }

    /// Notes an audit entry (by `by`, from the address `client`) and its `audit.recorded`
    /// event.
    fn audit(&mut self, by: &str, client: Option<IpAddr>, action: &str, target: &str, reason: Option<&str>) {
        let entry = self.audit_entry(by, client, action, target, reason);
        self.event("audit.recorded", &entry);
        self.audit.push(entry);
    }

    /// A numbered audit entry, not yet noted.
    fn audit_entry(
        &mut self,
        by: &str,
        client: Option<IpAddr>,
        action: &str,
        target: &str,
        reason: Option<&str>,
    ) -> AuditEntry {
        let entry = AuditEntry {
            id: self.next.audit,
            at: from_ms(self.now),
            by: by.to_owned(),
            client: client.map(|ip| ip.to_string()),
            action: action.to_owned(),
            target: target.to_owned(),
            reason: reason.map(str::to_owned),
        };
        self.next.audit += 1;
        entry
    }

    /// A `location.updated` event for each of `locations` the layout has (as they now are).
    fn location_events(&mut self, locations: &[Location]) {
        for l in locations {
            if let Some(row) = self.locations.get(l) {
                let state = LocationState::from(row.clone());
                self.event("location.updated", &state);
            }
        }
    }

    /// Appends an event with `data` serialized.
    fn event(&mut self, kind: &str, data: &impl serde::Serialize) {
        self.append(kind, to_json(data));
    }

    fn append(&mut self, kind: &str, data: String) {
        let seq = self.next.seq;
        self.next.seq += 1;
        self.out.events.push(StoredEvent { seq, at: self.now, kind: kind.to_owned(), data });
    }
}

/// One caller's submissions in a group that created jobs.
struct Submitted {
    name: String,
    client: Option<IpAddr>,
    /// Requests.
    requests: usize,
    /// Jobs asked for, new or stored already.
    asked: usize,
    /// The new jobs' ids, as ranges (a submission's new jobs have consecutive ids).
    ranges: Vec<(i64, i64)>,
}

impl Submitted {
    fn new(who: &Who, asked: usize, ids: (i64, i64)) -> Submitted {
        Submitted { name: who.name.clone(), client: who.client, requests: 1, asked, ranges: vec![ids] }
    }

    fn add(&mut self, asked: usize, (first, last): (i64, i64)) {
        self.requests += 1;
        self.asked += asked;
        match self.ranges.last_mut() {
            Some(range) if range.1 + 1 == first => range.1 = last,
            _ => self.ranges.push((first, last)),
        }
    }

    /// The entry's target and reason.
    fn described(&self) -> (String, Option<String>) {
        let new: i64 = self.ranges.iter().map(|(a, b)| b - a + 1).sum();
        let stored = self.asked as i64 - new;
        let stored = if stored > 0 { format!(" ({stored} stored already)") } else { String::new() };
        let ranges: Vec<String> = self
            .ranges
            .iter()
            .map(|&(a, b)| if a == b { a.to_string() } else { format!("{a}-{b}") })
            .collect();
        match (self.requests, self.asked) {
            (1, 1) => (format!("job:{}", ranges[0]), None),
            (1, asked) => (format!("jobs:{}", ranges[0]), Some(format!("a batch of {asked} jobs{stored}"))),
            (requests, _) => (
                format!("jobs:{}", ranges.join(",")),
                Some(format!("{requests} submissions in one commit, {new} new jobs{stored}")),
            ),
        }
    }
}

/// One of our own values as JSON: an event's data (for a new job, also its answer).
fn to_json(data: &impl serde::Serialize) -> String {
    // Serializing our own types to JSON cannot fail (no maps with non-string keys).
    serde_json::to_string(data).unwrap_or_else(|_| "null".into())
}

/// A location as audited: `location:A/R/B/L/P`.
fn location_key(l: Location) -> String {
    format!("location:{}/{}/{}/{}/{}", l.aisle, l.row, l.bay, l.level, l.position)
}

#[cfg(test)]
mod tests;
