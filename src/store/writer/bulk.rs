//! An operator's action on many jobs or locations at once ([`Bulk`]): unlock locations,
//! retry failed jobs, cancel queued ones. The writer checks every item against the group's
//! rows first and does all of them in the one commit, or none: a single item that is no
//! longer as the operator saw it (a job retried or dispatched meanwhile, a location
//! unlocked or locked again by another job) refuses the whole action with the list of
//! [`Refusal`]s. A dry run goes through the same check and tells what would be done,
//! writing nothing.
//!
//! Each item is audited as its single action is (`unlock` of `location:…`, `retry` or
//! `cancel` of `job:…`), so the trail of one job or location reads the same whichever way it
//! was done; their shared reason names the bulk action and its size before the operator's.

use crate::domain::{Job, JobState, Location, LocationLock};

/// What a bulk action does to its items.
#[derive(Clone, Debug)]
pub enum BulkAction {
    /// Lift the locks of these locations. With a job, the location must still be locked by
    /// that job's failure (the cause the operator checked); without, locked at all.
    Unlock(Vec<(Location, Option<i64>)>),
    /// Put these failed jobs back in the queue as their next attempt, in id order (the
    /// order they were accepted in, which the dispatcher keeps per location). With
    /// `unlock`, the locks their failures set are lifted in the same commit.
    Retry {
        /// The jobs.
        jobs: Vec<i64>,
        /// Lift the locks these jobs' failures set.
        unlock: bool,
    },
    /// Cancel these queued jobs (the dispatcher withholds them from their devices first,
    /// see `service::dispatch::bulk`).
    Cancel(Vec<i64>),
}

impl BulkAction {
    /// How many items it names.
    pub fn len(&self) -> usize {
        match self {
            BulkAction::Unlock(locations) => locations.len(),
            BulkAction::Retry { jobs, .. } | BulkAction::Cancel(jobs) => jobs.len(),
        }
    }

    /// Whether it names none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// An operator's action on many items, all or nothing (see the module doc).
#[derive(Clone, Debug)]
pub struct Bulk {
    /// What to do.
    pub action: BulkAction,
    /// Only check, and tell what would be done: nothing is written.
    pub dry_run: bool,
    /// The API key's name.
    pub by: String,
    /// Why, if given.
    pub reason: Option<String>,
}

/// What a bulk action did, or would do.
#[derive(Clone, Debug, Default)]
pub struct Bulked {
    /// The jobs retried or cancelled: as they now stand, or (dry run) as they stand.
    pub jobs: Vec<Job>,
    /// The locations unlocked, each with the lock it had.
    pub unlocked: Vec<(Location, LocationLock)>,
    /// Whether it was done (false for a dry run).
    pub applied: bool,
}

/// One item of a bulk action that cannot be done as asked.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum Refusal {
    /// No job has this id.
    #[error("job {0} does not exist")]
    NoJob(i64),
    /// The job is not in the state the action needs.
    #[error("job {id} is {state}, not {wanted}")]
    State {
        /// The job.
        id: i64,
        /// Its state.
        state: JobState,
        /// The state the action needs.
        wanted: JobState,
    },
    /// A device holds the job (it wrote it into a slot or is handing it over): it is no
    /// longer only queued. Found by the dispatcher before the writer is asked.
    #[error("job {id} is being handed to device {device:?} or held by it; cancel it on its own")]
    Held {
        /// The job.
        id: i64,
        /// The device.
        device: String,
    },
    /// The location is not locked (any more).
    #[error("location {} is not locked", slashed(.0))]
    NotLocked(Location),
    /// The location is locked, but not by the cause the operator checked.
    #[error("location {} is locked by {}, not by job {expected}", slashed(.location), cause(.lock))]
    OtherCause {
        /// The location.
        location: Location,
        /// The job whose lock was expected.
        expected: i64,
        /// The lock it has.
        lock: LocationLock,
    },
}

impl Refusal {
    /// The item refused, as the audit log names it (`job:ID`, `location:A/R/B/L/P`).
    pub fn item(&self) -> String {
        match self {
            Refusal::NoJob(id) | Refusal::State { id, .. } | Refusal::Held { id, .. } => format!("job:{id}"),
            Refusal::NotLocked(l) | Refusal::OtherCause { location: l, .. } => {
                format!("location:{}", slashed(l))
            }
        }
    }
}

/// A location as people write it: `A/R/B/L/P`.
fn slashed(l: &Location) -> String {
    format!("{}/{}/{}/{}/{}", l.aisle, l.row, l.bay, l.level, l.position)
}

/// Who or what holds a lock: `job N` or `KEY by hand`.
fn cause(lock: &LocationLock) -> String {
    match lock.job {
        Some(job) => format!("job {job}"),
        None => format!("{} by hand", lock.by),
    }
}

/// The refusals, in a message: how many, then each (the first 20).
pub fn describe(refusals: &[Refusal]) -> String {
    const SHOWN: usize = 20;
    let mut text = format!(
        "nothing was done: {} item{} cannot be done as asked: ",
        refusals.len(),
        if refusals.len() == 1 { "" } else { "s" }
    );
    let shown: Vec<String> = refusals.iter().take(SHOWN).map(ToString::to_string).collect();
    text.push_str(&shown.join("; "));
    if refusals.len() > SHOWN {
        text.push_str(&format!("; and {} more", refusals.len() - SHOWN));
    }
    text
}
