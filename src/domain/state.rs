//! The job state machine: one type, one transition function.
//!
//! ```text
//! queued ──dispatch──▶ dispatched ──start──▶ running ──complete──▶ completed
//!   │                      │                    │      └─fail────▶ failed
//!   └─cancel──▶ cancelled ◀┴─cancel             └─request_cancel─▶ cancelling ──▶ cancelled
//! ```
//! Any non-terminal state may fail; a device may report completion of work it had already
//! finished before a poll saw it running (dispatched → completed) or before a cancel reached
//! it (cancelling → completed). Terminal states never change, with one exception an
//! operator asks for: a failed job may be retried (failed → queued), a new attempt of the
//! same job with its history kept.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// Where a job is in its life.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum JobState {
    /// Accepted and stored, waiting for its device.
    Queued,
    /// Handed to the device, which confirmed it.
    Dispatched,
    /// The device reports the job under way.
    Running,
    /// A cancel is under way on the device.
    Cancelling,
    /// Finished (possibly forced; see the job's `forced`).
    Completed,
    /// Ended without doing its work; see the job's `failure`.
    Failed,
    /// Cancelled before or while running.
    Cancelled,
}

/// What happened to a job.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Transition {
    /// The device confirmed it took the job.
    Dispatch,
    /// The device reports the job running.
    Start,
    /// The device reports the job finished.
    Complete,
    /// The job could not be done.
    Fail,
    /// A cancel was sent to the device.
    RequestCancel,
    /// The job is cancelled (at once while queued, or confirmed by the device).
    Cancel,
    /// An operator puts a failed job back in the queue as a new attempt.
    Retry,
}

/// The class of a failure: what the operator has to look at.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum FailureKind {
    /// The device reported a fault of its own (a shelf PLC's failure kind 1).
    DeviceFault,
    /// The device refused the task: its data disagrees with rackd's (failure kind 2).
    Rejected,
    /// A business alarm stopped the task (crane D205), and it was cancelled.
    Alarm,
    /// The device no longer holds the task rackd gave it.
    Lost,
    /// The device cannot run this job at all (nothing was sent).
    Unsupported,
}

impl FailureKind {
    /// Every kind.
    pub const ALL: [FailureKind; 5] = [
        FailureKind::DeviceFault,
        FailureKind::Rejected,
        FailureKind::Alarm,
        FailureKind::Lost,
        FailureKind::Unsupported,
    ];

    /// The kind's name as the API writes it.
    pub fn as_str(self) -> &'static str {
        match self {
            FailureKind::DeviceFault => "device_fault",
            FailureKind::Rejected => "rejected",
            FailureKind::Alarm => "alarm",
            FailureKind::Lost => "lost",
            FailureKind::Unsupported => "unsupported",
        }
    }

    /// The kind with this name.
    pub fn parse(text: &str) -> Option<FailureKind> {
        FailureKind::ALL.into_iter().find(|k| k.as_str() == text)
    }

    /// Whether a job failing this way leaves its locations untrustworthy, so they lock
    /// until a person checks them: the device lost the task, faulted, refused it for
    /// disagreeing data, or an alarm stopped it. (`unsupported` sent nothing.)
    pub fn locks(self) -> bool {
        !matches!(self, FailureKind::Unsupported)
    }
}

impl std::fmt::Display for FailureKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Why a job failed: who failed it, the device's own code if any, and a text.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
pub struct Failure {
    /// The class of failure.
    pub kind: FailureKind,
    /// The device's own code (PLC failure kind, crane alarm code), if it gave one.
    pub code: Option<i64>,
    /// What happened, for people.
    pub text: String,
}

/// An illegal transition, rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("a {from} job cannot {transition:?}")]
pub struct IllegalTransition {
    /// The state the job was in.
    pub from: JobState,
    /// The transition that was refused.
    pub transition: Transition,
}

impl JobState {
    /// All states, in life order.
    pub const ALL: [JobState; 7] = [
        Self::Queued,
        Self::Dispatched,
        Self::Running,
        Self::Cancelling,
        Self::Completed,
        Self::Failed,
        Self::Cancelled,
    ];

    /// The state's name as the API writes it.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Queued => "queued",
            Self::Dispatched => "dispatched",
            Self::Running => "running",
            Self::Cancelling => "cancelling",
            Self::Completed => "completed",
            Self::Failed => "failed",
            Self::Cancelled => "cancelled",
        }
    }

    /// Parses a state from its API name.
    pub fn parse(text: &str) -> Option<JobState> {
        Self::ALL.into_iter().find(|s| s.as_str() == text)
    }

    /// Whether the job is over; a terminal state never changes.
    pub fn is_terminal(self) -> bool {
        matches!(self, Self::Completed | Self::Failed | Self::Cancelled)
    }

    /// Whether the job is on its device (handed to it and not yet back or over): the
    /// time its device (and aisle) counts as busy.
    pub fn on_device(self) -> bool {
        matches!(self, Self::Dispatched | Self::Running | Self::Cancelling)
    }

    /// The one transition function: the state after `t`, or why `t` is illegal here.
    pub fn apply(self, t: Transition) -> Result<JobState, IllegalTransition> {
        use JobState::*;
        use Transition::*;
        let next = match (self, t) {
            (Failed, Retry) => Some(Queued),
            (s, _) if s.is_terminal() => None,
            (Queued, Dispatch) => Some(Dispatched),
            (Dispatched, Start) => Some(Running),
            (Dispatched | Running | Cancelling, Complete) => Some(Completed),
            (_, Fail) => Some(Failed),
            (Dispatched | Running, RequestCancel) => Some(Cancelling),
            (Queued | Dispatched | Cancelling, Cancel) => Some(Cancelled),
            _ => None,
        };
        next.ok_or(IllegalTransition { from: self, transition: t })
    }
}

impl std::fmt::Display for JobState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::JobState::*;
    use super::Transition::*;
    use super::*;

    const ALL_T: [Transition; 7] = [Dispatch, Start, Complete, Fail, RequestCancel, Cancel, Retry];

    #[test]
    fn the_normal_life() {
        let s = Queued.apply(Dispatch).unwrap().apply(Start).unwrap().apply(Complete).unwrap();
        assert_eq!(s, Completed);
    }

    #[test]
    fn terminal_states_never_change_but_a_failed_job_may_be_retried() {
        for s in [Completed, Failed, Cancelled] {
            for t in ALL_T {
                if (s, t) == (Failed, Retry) {
                    assert_eq!(s.apply(t), Ok(Queued));
                } else {
                    assert!(s.apply(t).is_err(), "{s} accepted {t:?}");
                }
            }
        }
        for s in [Queued, Dispatched, Running, Cancelling, Completed, Cancelled] {
            assert!(s.apply(Retry).is_err(), "only a failed job is retried, not a {s} one");
        }
    }

    #[test]
    fn illegal_transitions_are_rejected() {
        assert!(Queued.apply(Start).is_err());
        assert!(Queued.apply(Complete).is_err());
        assert!(Queued.apply(RequestCancel).is_err());
        assert!(Running.apply(Dispatch).is_err());
        assert!(Running.apply(Cancel).is_err());
        assert!(Cancelling.apply(Start).is_err());
    }

    #[test]
    fn names_round_trip() {
        for s in JobState::ALL {
            assert_eq!(JobState::parse(s.as_str()), Some(s));
        }
    }
}
