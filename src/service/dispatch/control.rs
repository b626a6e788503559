//! What operators do besides jobs: pause and resume a device or an aisle, lock and unlock
//! a location, retry a failed job. Each is stored with who, when and why (an audit entry
//! in the same commit) before it takes effect here, so a restart restores exactly what
//! operators were told.

use crate::domain::time::{from_ms, now_ms};
use crate::domain::{Job, JobState, Location, LocationLock, Pause, Target, Who};
use crate::store::writer::{Change, Record, Stock, WriteError};

use super::Dispatcher;

/// Why an operator's action was refused.
#[derive(Debug, thiserror::Error)]
pub enum ControlError {
    /// No such job, device or location.
    #[error("{0} does not exist")]
    NotFound(String),
    /// A retry of a job that has not failed.
    #[error("job {id} is {state}; only a failed job can be retried")]
    NotFailed {
        /// The job.
        id: i64,
        /// Its state.
        state: JobState,
    },
    /// The store failed; nothing changed.
    #[error("the store failed: {0}")]
    Store(#[source] WriteError),
}

impl From<WriteError> for ControlError {
    fn from(e: WriteError) -> Self {
        match e {
            WriteError::NotFound(id) => ControlError::NotFound(format!("job {id}")),
            WriteError::Illegal(e) => ControlError::NotFailed { id: 0, state: e.from },
            other => ControlError::Store(other),
        }
    }
}

/// Who acts, from where, and why.
#[derive(Clone, Debug)]
pub struct Actor {
    /// The API key's name (`anonymous` without keys).
    pub by: String,
    /// The client's address, when known.
    pub client: Option<std::net::IpAddr>,
    /// Why, as given.
    pub reason: Option<String>,
}

impl Actor {
    /// Who acts, as audited.
    pub fn who(&self) -> Who {
        Who { name: self.by.clone(), client: self.client }
    }

    fn now(&self) -> Pause {
        Pause { by: self.by.clone(), reason: self.reason.clone(), at: from_ms(now_ms()) }
    }
}

impl Dispatcher {
    /// Pauses or resumes a device or an aisle (an aisle must hold locations of the layout;
    /// the caller checks).
    pub async fn set_paused(&self, target: Target, paused: bool, actor: &Actor) -> Result<(), ControlError> {
        if let Target::Device(id) = &target
            && !self.queues.has(id)
        {
            return Err(ControlError::NotFound(format!("device {id:?}")));
        }
        let by = actor.now();
        let record = Record::Pause { target: target.clone(), paused, by: by.clone() };
        self.writer.record_as(record, actor.who()).await?;
        let pause = paused.then_some(by);
        match target {
            Target::Device(id) => drop(self.queues.set_paused(&id, pause)),
            Target::Aisle(aisle) => self.queues.set_aisle_paused(aisle, pause),
        }
        Ok(())
    }

    /// Locks a location by hand (the caller checks it is in the layout); one already
    /// locked keeps its first lock.
    pub async fn lock(&self, location: Location, actor: &Actor) -> Result<(), ControlError> {
        let lock = LocationLock {
            by: actor.by.clone(),
            reason: actor.reason.clone().unwrap_or_default(),
            job: None,
            at: from_ms(now_ms()),
        };
        Ok(self.writer.record_as(Record::Lock { location, lock }, actor.who()).await?)
    }

    /// Sets what locations hold, as counted or loaded at commissioning (all or nothing).
    pub async fn inventory(&self, entries: Vec<Stock>, actor: &Actor) -> Result<(), ControlError> {
        let record = Record::Inventory { entries, by: actor.by.clone(), reason: actor.reason.clone() };
        Ok(self.writer.record_as(record, actor.who()).await?)
    }

    /// Unlocks a location: jobs waiting on it may go.
    pub async fn unlock(&self, location: Location, actor: &Actor) -> Result<(), ControlError> {
        let record = Record::Unlock { location, by: actor.by.clone(), reason: actor.reason.clone() };
        Ok(self.writer.record_as(record, actor.who()).await?)
    }

    /// Puts a failed job back in the queue as its next attempt, history kept.
    pub async fn retry(&self, id: i64, actor: &Actor) -> Result<Job, ControlError> {
        match self.writer.change_as(id, Change::Retry { by: actor.by.clone() }, actor.who()).await {
            Ok(job) => Ok(job),
            Err(WriteError::Illegal(e)) => Err(ControlError::NotFailed { id, state: e.from }),
            Err(e) => Err(e.into()),
        }
    }
}
