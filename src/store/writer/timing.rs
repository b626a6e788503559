//! What the writer tells `/metrics` after each commit: the group's size and commit time,
//! how long jobs took to the transitions worth a histogram, and what it changed in the
//! counts of jobs and alarms ([`crate::store::counts`]).
//!
//! Decisions:
//! - **Timed where transitions are applied, told after the commit.** The writer is the one
//!   place every transition goes through; a transition's timing is noted while the group is
//!   applied and handed on only once the group is on disk, so a group that rolled back is
//!   never counted.
//! - **Queued since** the job's latest `queued` history entry (its acceptance, or the retry
//!   that queued it again); **dispatched since** its latest `dispatched` entry. A job that
//!   ends without having been dispatched in its current attempt (cancelled while queued)
//!   is timed from its `queued` entry. The group reads these times for the jobs its changes
//!   name in one statement, never for submissions (the intake path).
//! - The store does not know Prometheus: it calls a hook ([`Observe`]) that the API's
//!   metrics provide, as the dispatcher and event hub get theirs.

use std::sync::Arc;
use std::time::Duration;

use crate::domain::{JobKind, JobState};
use crate::store::counts::Counts;

/// How long a job took to one of the transitions timed for `/metrics`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum JobTiming {
    /// The job was dispatched after waiting this long in the queue.
    Dispatched {
        /// Its kind.
        kind: JobKind,
        /// Time from queued to dispatched.
        waited: Duration,
    },
    /// The job ended in `state`.
    Ended {
        /// Its kind.
        kind: JobKind,
        /// `completed`, `failed` or `cancelled`.
        state: JobState,
        /// Time from dispatched (or, never dispatched in this attempt, from queued) to the end.
        took: Duration,
    },
}

/// One commit, as the writer reports it after the fact.
#[derive(Debug)]
pub struct GroupStats<'a> {
    /// Commands applied together in one transaction.
    pub commands: usize,
    /// Statements its transaction ran, `BEGIN` and `COMMIT` included (the same for a group
    /// of one job and one of thousands: the writer is set-based).
    pub statements: usize,
    /// Time to apply and commit them (the fsync included).
    pub took: Duration,
    /// The timed transitions the commit made durable (none when it failed).
    pub jobs: &'a [JobTiming],
    /// What the commit changed in the counts of jobs and active alarms (nothing when it
    /// failed; see [`crate::store::counts`]).
    pub counts: &'a Counts,
}

/// Called after each group with what it did (see the module doc).
pub type Observe = Arc<dyn Fn(&GroupStats<'_>) + Send + Sync>;

/// The time from `since` to `now` (Unix ms); zero if the clock went back.
pub(super) fn between(since: i64, now: i64) -> Duration {
    Duration::from_millis(now.saturating_sub(since).max(0) as u64)
}
