//! The dispatcher: which job runs next, on which device, cancels, and operators' actions
//! on many jobs at once ([`bulk`]).
//!
//! The job writer hands every committed job to the [`Queues`] (in memory, one queue per
//! device); each device task asks its [`Port`](crate::devices::port::Port) for the best
//! jobs it can start ([`order::next_jobs`]: priority, then age, never overtaking an older
//! job on the same location) and reports what became of them through the same port, one
//! commit per report round. Pausing is control state kept here, apart from what devices
//! report: a paused device is simply offered no work. Why each queued job waits is
//! worked out beside those decisions, never instead of them ([`waiting`]). A cancel
//! withholds the jobs it decides on from their devices, each cancel its own hold
//! ([`withhold`]).

pub mod bulk;
pub mod cancel;
pub mod control;
pub mod gate;
pub mod order;
mod plan;
pub mod queues;
pub mod release;
pub mod waiting;
pub mod withhold;

use crate::store::Pool;

pub use bulk::{BulkError, FailedJobs, MAX_BULK, QueuedJobs};
pub use cancel::CancelError;
pub use control::{Actor, ControlError};
pub use queues::{Control, Queues, Setup};
pub use withhold::Withheld;

use crate::devices::port::ReportError;
use crate::domain::Target;
use crate::store::writer::{WriteError, Writer};
use crate::store::{controls, jobs, locations};

/// A writer's error as a device's port reports it.
fn report_error(e: WriteError) -> ReportError {
    match e {
        WriteError::Closed => ReportError::Stopped,
        WriteError::NotFound(id) => ReportError::NotFound(id),
        other => ReportError::Store(Box::new(other)),
    }
}

/// The dispatcher as the API uses it: cancels and control state.
#[derive(Clone)]
pub struct Dispatcher {
    queues: Queues,
    writer: Writer,
    pool: Pool,
}

impl Dispatcher {
    /// The dispatcher over `queues` (already handed to the writer as its hook).
    pub fn new(queues: Queues, writer: Writer, pool: Pool) -> Dispatcher {
        Dispatcher { queues, writer, pool }
    }

    /// Fills the queues with the unfinished jobs the store holds for `devices` (at start,
    /// before any device runs).
    pub async fn load<'a>(&self, devices: impl IntoIterator<Item = &'a str>) -> Result<(), sqlx::Error> {
        for device in devices {
            let unfinished = jobs::unfinished(&self.pool, device).await?;
            self.queues.load(device, unfinished);
        }
        Ok(())
    }

    /// Restores what operators set before the restart (at start, before any device runs):
    /// paused devices and aisles, locked locations. A pause of a device no longer
    /// configured is left in the store and logged.
    pub async fn restore(&self) -> Result<(), sqlx::Error> {
        for (target, pause) in controls::paused(&self.pool).await? {
            match target {
                Target::Device(id) => {
                    if self.queues.set_paused(&id, Some(pause)) {
                        tracing::info!(device = %id, "paused before the restart: stays paused");
                    } else {
                        tracing::warn!(device = %id, "a paused device is no longer configured");
                    }
                }
                Target::Aisle(aisle) => {
                    tracing::info!(aisle, "paused before the restart: stays paused");
                    self.queues.set_aisle_paused(aisle, Some(pause));
                }
            }
        }
        let locks: Vec<_> =
            locations::locked(&self.pool).await?.into_iter().map(|(l, lock)| (l, Some(lock))).collect();
        if !locks.is_empty() {
            tracing::info!(locations = locks.len(), "locked locations wait for a person");
        }
        self.queues.locked(&locks);
        Ok(())
    }

    /// The queues.
    pub fn queues(&self) -> &Queues {
        &self.queues
    }
}

#[cfg(test)]
mod withhold_tests;
