//! Moving a job to the state a device reports, through every transition in between.
//!
//! A device may report a task finished before rackd saw it start, or (after a restart)
//! already finished while rackd still has the job queued. [`advance`] walks the state
//! machine from where the job is to where the device says it is, recording each step, so
//! every device adapter follows work the same way.

use crate::domain::{Failure, JobState, Transition};
use crate::store::Job;
use crate::store::writer::{Change, WriteError, Writer};

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
        Reported::Cancelled if state == Running => vec![RequestCancel, Cancel],
        Reported::Cancelled => vec![Cancel],
    }
}

/// Records what the device reports for `job`, with `cause` in its history; returns the job
/// as stored afterwards.
pub async fn advance(writer: &Writer, job: &Job, to: Reported, cause: &str) -> Result<Job, WriteError> {
    let mut current = job.clone();
    for transition in path(job.state, &to) {
        let change = Change::Transition {
            transition,
            cause: cause.to_owned(),
            expect: None,
            failure: match &to {
                Reported::Failed(f) => Some(f.clone()),
                _ => None,
            },
            forced: matches!(to, Reported::Finished { forced: true }),
        };
        current = writer.change(job.id, change).await?;
    }
    Ok(current)
}

#[cfg(test)]
mod tests {
    use super::*;
    use JobState::*;
    use Transition::*;

    #[test]
    fn paths_walk_every_step() {
        assert_eq!(path(Queued, &Reported::Finished { forced: false }), vec![Dispatch, Complete]);
        assert_eq!(path(Queued, &Reported::Running), vec![Dispatch, Start]);
        assert_eq!(path(Running, &Reported::Running), vec![]);
        assert_eq!(path(Cancelling, &Reported::Cancelled), vec![Cancel]);
        assert_eq!(path(Completed, &Reported::Cancelled), vec![]);
        let fail = Failure { kind: "x".into(), code: None, text: "y".into() };
        assert_eq!(path(Dispatched, &Reported::Failed(fail)), vec![Fail]);
        // Every path is legal in the state machine.
        for from in JobState::ALL {
            for to in
                [Reported::Taken, Reported::Running, Reported::Finished { forced: true }, Reported::Cancelled]
            {
                let mut s = from;
                for t in path(from, &to) {
                    s = s.apply(t).unwrap_or_else(|e| panic!("{from} -> {to:?}: {e}"));
                }
            }
        }
    }
}
