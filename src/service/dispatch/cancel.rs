//! Cancelling a job: the rules in one place.
//!
//! - no such job: [`CancelError::NotFound`] (404);
//! - the job has ended: [`CancelError::Ended`] (409);
//! - the job waits for a configured device: the dispatcher withholds it (no device takes
//!   it from now on), then asks the device, whose task alone hands work over, whether it
//!   holds it. Not held: cancelled at once. Held: the device withdraws it or hands the
//!   machine a cancel, or says why it cannot ([`CancelError::Refused`], 409, with the
//!   device's reason). A device that does not answer, or whose link fails meanwhile, is
//!   [`CancelError::Unavailable`] (503);
//! - the job's device is not configured (any more): a queued job is cancelled, one past
//!   queued cannot be withdrawn (409).
//!
//! The hold is this cancel's own ([`super::withhold`]): a guard taken before the device is
//! asked and dropped when the cancel ends, however it ends (its request dropped by a
//! client's timeout included). Another cancel of the same job that ends meanwhile (a bulk
//! cancel refused, a first attempt its client gave up on) does not let the job go, so the
//! device's "not held" stays true until this cancel's commit.
//!
//! No database or driver text reaches the caller: store failures are [`CancelError::Store`]
//! (500, logged by the API), a link failure is only named.

use crate::devices::{CancelRefusal, Devices, Withdrawal};
use crate::domain::{Job, JobState, Who};
use crate::store::jobs;
use crate::store::writer::{Change, Record, WriteError};

use super::Dispatcher;

/// Why a job was not cancelled.
#[derive(Debug, thiserror::Error)]
pub enum CancelError {
    /// No job has this id.
    #[error("job {0} does not exist")]
    NotFound(i64),
    /// The job has ended.
    #[error("job {id} is already {state}")]
    Ended {
        /// The job.
        id: i64,
        /// Its final state.
        state: JobState,
    },
    /// The device holds the job and cannot give it up.
    #[error("job {id} cannot be cancelled: {reason}")]
    Refused {
        /// The job.
        id: i64,
        /// The device's reason.
        reason: CancelRefusal,
    },
    /// The job is past queued and its device is not configured.
    #[error("job {id} is {state} and its device is not configured; it cannot be withdrawn")]
    Unconfigured {
        /// The job.
        id: i64,
        /// Its state.
        state: JobState,
    },
    /// The job's device does not answer (its task stopped, or its link failed).
    #[error("device {device:?} is not available; try again")]
    Unavailable {
        /// The device.
        device: String,
    },
    /// The store failed.
    #[error("the job store failed: {0}")]
    Store(#[source] Box<dyn std::error::Error + Send + Sync>),
}

impl Dispatcher {
    /// Cancels job `id` for `who` by the rules above; answers the job as it stands
    /// afterwards (`cancelled`, or `cancelling` while a machine carries the cancel out).
    ///
    /// A cancel is audited: a queued job's in the commit that cancels it; one the device
    /// withdrew (its task committed that) in a commit of its own right after, naming what
    /// the job became.
    pub async fn cancel(&self, id: i64, devices: &Devices, who: &Who) -> Result<Job, CancelError> {
        let Some(job) = self.queues.find(id) else { return self.cancel_unqueued(id, who).await };
        let device = job.device.clone().unwrap_or_default();
        let Some(handle) = devices.get(&device) else { return self.cancel_unqueued(id, who).await };
        let _withheld = self.queues.withhold(vec![(device.clone(), id)]);
        let answer = handle.cancel(id).await;
        match answer {
            None => Err(CancelError::Unavailable { device: device.clone() }),
            Some(Ok(Withdrawal::NotHeld)) => self.cancel_queued(id, who).await,
            Some(Ok(Withdrawal::Done)) => match self.stored(id).await {
                Ok(job) => {
                    let audit = Record::Audit {
                        action: "cancel".into(),
                        target: format!("job:{id}"),
                        reason: Some(format!("withdrawn from {device}: {}", job.state)),
                    };
                    // The job is cancelled whatever happens to its entry: the answer says so.
                    if let Err(e) = self.writer.record_as(audit, who.clone()).await {
                        tracing::error!(job = id, error = %e, "cancel: the audit entry was not stored");
                    }
                    Ok(job)
                }
                Err(e) => Err(e),
            },
            Some(Err(CancelRefusal::Link(e))) => {
                tracing::warn!(device = %device, job = id, error = %e, "cancel: the machine did not answer");
                Err(CancelError::Unavailable { device: device.clone() })
            }
            Some(Err(CancelRefusal::NotTaken)) => Err(CancelError::Unavailable { device: device.clone() }),
            Some(Err(CancelRefusal::Report(e))) => Err(CancelError::Store(Box::new(e))),
            Some(Err(reason)) => Err(CancelError::Refused { id, reason }),
        }
    }

    /// A job no configured device has: cancelled if still queued.
    async fn cancel_unqueued(&self, id: i64, who: &Who) -> Result<Job, CancelError> {
        match self.cancel_queued(id, who).await {
            Err(CancelError::Refused { reason: CancelRefusal::NotHeld(state), .. }) => {
                Err(CancelError::Unconfigured { id, state })
            }
            other => other,
        }
    }

    /// Cancels a job that is queued.
    async fn cancel_queued(&self, id: i64, who: &Who) -> Result<Job, CancelError> {
        match self.writer.change_as(id, Change::cancel_queued(), who.clone()).await {
            Ok(job) => Ok(job),
            Err(WriteError::NotFound(id)) => Err(CancelError::NotFound(id)),
            Err(WriteError::Unexpected { state, .. }) if state.is_terminal() => {
                Err(CancelError::Ended { id, state })
            }
            Err(WriteError::Unexpected { state, .. }) => {
                Err(CancelError::Refused { id, reason: CancelRefusal::NotHeld(state) })
            }
            Err(e) => Err(CancelError::Store(Box::new(e))),
        }
    }

    /// The job as stored.
    async fn stored(&self, id: i64) -> Result<Job, CancelError> {
        match jobs::get(&self.pool, id).await {
            Ok(Some(job)) => Ok(job),
            Ok(None) => Err(CancelError::NotFound(id)),
            Err(e) => Err(CancelError::Store(Box::new(e))),
        }
    }
}
