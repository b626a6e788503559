//! The narrow port through which a device task gets its work and says what became of it.
//!
//! Devices never read the store to learn what to do: the service's dispatcher keeps every
//! device's unfinished jobs in memory (the job writer hands it each commit) and answers
//! here. The trait lives with the devices, which use it, and is implemented above them by
//! the service, so dependencies point down.

use std::collections::HashSet;

use async_trait::async_trait;

use crate::domain::{Job, Report};

/// What a device may ask of the dispatcher; one port per device.
#[async_trait]
pub trait Port: Send + Sync {
    /// Every job of this device that has not ended, oldest first (what recovery after a
    /// restart reconciles with the machine).
    fn unfinished(&self) -> Vec<Job>;

    /// One job of this device as it stands, while it has not ended.
    fn job(&self, id: i64) -> Option<Job>;

    /// The queued jobs this device should start now, best first, at most `free` of them,
    /// leaving out `holding` (jobs the device already holds but has not confirmed); none
    /// while the device is paused.
    fn next(&self, free: usize, holding: &HashSet<i64>) -> Vec<Job>;

    /// The one job an idle single-task device (a crane) should start now, after whatever
    /// its planner had to do first: a job it made to clear the way (a relocation), or none.
    /// Without a planner, the best of [`Port::next`].
    async fn next_task(&self) -> Result<Option<Job>, ReportError> {
        Ok(self.next(1, &HashSet::new()).into_iter().next())
    }

    /// Completes when new work may be waiting (a job queued for this device, a resume, a
    /// job ended that others waited behind).
    async fn work_waiting(&self);

    /// Records what the device reports, all reports in one commit; answers each job as
    /// stored afterwards, in the same order.
    async fn report(&self, reports: Vec<Report>) -> Result<Vec<Job>, ReportError>;
}

/// Why a report could not be recorded.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// rackd is shutting down: the job writer has stopped.
    #[error("the job writer has stopped")]
    Stopped,
    /// The job does not exist (a report for a job the device does not hold).
    #[error("job {0} does not exist")]
    NotFound(i64),
    /// The store failed; nothing of the report was recorded.
    #[error("the job store failed: {0}")]
    Store(#[source] Box<dyn std::error::Error + Send + Sync>),
}
