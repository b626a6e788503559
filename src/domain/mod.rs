//! The words of the warehouse: locations, jobs and their states.
//!
//! Parse, don't validate: each type here can only hold a valid value, and its constructor
//! says in one place what valid means.

pub mod alarm;
pub mod control;
pub mod job;
pub mod location;
pub mod putaway;
pub mod report;
pub mod state;
pub mod time;
pub mod values;
pub mod waiting;

pub use alarm::{AlarmClass, AlarmKind};
pub use control::{LocationLock, Pause, Target, Who};
pub use job::{Job, JobKind, JobSpec, LightColor, Member, NewJob, Terms};
pub use location::{AisleLayout, Layout, Location};
pub use putaway::{Class, Zone};
pub use report::{Report, Reported};
pub use state::{Failure, FailureKind, JobState, Transition};
pub use values::{Barcode, Priority};
pub use waiting::{Waiting, WaitingReason};

/// A value that failed its constructor's checks, with a message that says why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct Invalid(pub String);
