//! Where a device says a job is, and the transitions that bring the job there.
//!
//! A device may report a task finished before rackd saw it start, or (after a restart)
//! already finished while rackd still has the job queued. [`path`] walks the state machine
//! from where the job is to where the device says it is; the job writer records every step
//! of it in one commit, so every device adapter follows work the same way.

use super::{Failure, JobState, Transition};

/// Where a device says a job is.
#[derive(Clone, Debug, PartialEq)]
pub enum Reported {
    /// The device holds the task.
    Taken,
    /// The device is executing it.
    Running,
    /// It finished (forced = completed by hand on the machine).
    Finished {
        /// Completed by force.
        forced: bool,
    },
    /// It failed.
    Failed(Failure),
    /// A cancel was handed to the device; it says later whether the task stopped.
    Cancelling,
    /// It was cancelled on the device.
    Cancelled,
}

/// The transitions from `state` to what the device reports; empty if already there.
pub fn path(state: JobState, to: &Reported) -> Vec<Transition> {
    use JobState::*;
    use Transition::*;
    let dispatch = if state == Queued { vec![Dispatch] } else { vec![] };
    let with = |mut first: Vec<Transition>, last: Transition| {
        first.push(last);
        first
    };
    match to {
        _ if state.is_terminal() => vec![],
        Reported::Taken => dispatch,
        Reported::Running if state == Queued => vec![Dispatch, Start],
        Reported::Running if state == Dispatched => vec![Start],
        Reported::Running => vec![],
        Reported::Finished { .. } => with(dispatch, Complete),
        Reported::Failed(_) => vec![Fail],
        Reported::Cancelling if state == Queued => vec![Dispatch, RequestCancel],
        Reported::Cancelling if state == Cancelling => vec![],
        Reported::Cancelling => vec![RequestCancel],
        Reported::Cancelled if state == Running => vec![RequestCancel, Cancel],
        Reported::Cancelled => vec![Cancel],
    }
}

impl Reported {
    /// The failure reason to record, for [`Reported::Failed`].
    pub fn failure(&self) -> Option<&Failure> {
        match self {
            Reported::Failed(f) => Some(f),
            _ => None,
        }
    }

    /// Whether the job was completed by force on the machine.
    pub fn forced(&self) -> bool {
        matches!(self, Reported::Finished { forced: true })
    }
}

/// What a device reports of one job: where it is now, and why (for the job's history).
#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    /// The job.
    pub job: i64,
    /// Where the device says it is.
    pub to: Reported,
    /// Why, in words, for the history.
    pub cause: String,
}

impl Report {
    /// A report of `to` for `job`, with `cause`.
    pub fn new(job: i64, to: Reported, cause: impl Into<String>) -> Report {
        Report { job, to, cause: cause.into() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::domain::FailureKind;
    use JobState::*;
    use Transition::*;

    #[test]
    fn paths_walk_every_step() {
        assert_eq!(path(Queued, &Reported::Finished { forced: false }), vec![Dispatch, Complete]);
        assert_eq!(path(Queued, &Reported::Running), vec![Dispatch, Start]);
        assert_eq!(path(Running, &Reported::Running), vec![]);
        assert_eq!(path(Cancelling, &Reported::Cancelled), vec![Cancel]);
        assert_eq!(path(Completed, &Reported::Cancelled), vec![]);
        let fail = Failure { kind: FailureKind::Lost, code: None, text: "y".into() };
        assert_eq!(path(Dispatched, &Reported::Failed(fail)), vec![Fail]);
        // Every path is legal in the state machine.
        for from in JobState::ALL {
            for to in [
                Reported::Taken,
                Reported::Running,
                Reported::Finished { forced: true },
                Reported::Cancelling,
                Reported::Cancelled,
            ] {
                let mut s = from;
                for t in path(from, &to) {
                    s = s.apply(t).unwrap_or_else(|e| panic!("{from} -> {to:?}: {e}"));
                }
            }
        }
    }
}
