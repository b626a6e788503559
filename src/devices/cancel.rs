//! What a device answers when asked to cancel one of its jobs.
//!
//! The rules of a cancel live in the service ([`crate::service::dispatch`]); a device
//! answers only the part it alone knows: whether it holds the job, and whether the machine
//! can still give it up.

use crate::devices::port::ReportError;
use crate::domain::JobState;
use crate::protocols::PlcError;

/// A cancel the device carried out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Withdrawal {
    /// The device does not hold the job: it is still only queued, and the device will not
    /// take it while the cancel is decided (the dispatcher withholds it).
    NotHeld,
    /// The device withdrew the task, or handed the machine its cancel, and recorded it.
    Done,
}

/// Why a device cannot cancel a job it holds.
#[derive(Debug, thiserror::Error)]
pub enum CancelRefusal {
    /// This kind of device runs no jobs.
    #[error("this device runs no jobs")]
    NoJobs,
    /// The machine runs the task and cannot stop it (a shelf PLC).
    #[error("the machine is running it, and a shelf PLC cannot stop a running task")]
    Running,
    /// The task ended on the machine; the end is recorded at the next poll.
    #[error("it has already ended on the machine; that is recorded at the next poll")]
    Ended,
    /// Withdrawing tasks from slots is switched off for this device.
    #[error("it is in slot {slot} and withdrawing tasks is disabled for this device")]
    WithdrawOff {
        /// The slot (from 1).
        slot: usize,
    },
    /// The machine took the task while it was being withdrawn.
    #[error("the machine took it while it was being withdrawn")]
    TakenMeanwhile,
    /// The slot no longer holds the task (it is followed as lost at the next poll).
    #[error("slot {slot} no longer holds task {task}")]
    Gone {
        /// The slot (from 1).
        slot: usize,
        /// The task id rackd wrote.
        task: u16,
    },
    /// rackd has the job past queued, but the device does not hold it.
    #[error("it is {0} but the device does not hold it")]
    NotHeld(JobState),
    /// The machine did not take the cancel through its hand-over in time: try again.
    #[error("the machine did not take the cancel in time")]
    NotTaken,
    /// The machine did not answer or refused the request: try again.
    #[error("the machine did not answer: {0}")]
    Link(#[from] PlcError),
    /// The cancel could not be recorded.
    #[error(transparent)]
    Report(#[from] ReportError),
}
