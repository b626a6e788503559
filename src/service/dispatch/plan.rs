//! The dispatcher's side of the crane planner: it asks [`CranePlanner`] what the idle crane
//! does next and carries that out before anything reaches the crane: a relocation is
//! committed as a job of its own (a `move` naming the job it serves) and handed out first; a
//! job the rack makes impossible fails with the reason, nothing sent.

use std::collections::HashSet;

use super::report_error;
use crate::devices::port::{Port, ReportError};
use crate::domain::{Failure, FailureKind, Job, JobSpec, Priority, Report, Reported};
use crate::service::planner::{CranePlanner, Decision};
use crate::store::jobs::NewJob;
use crate::store::writer::{Change, Outcome, WriteError, Writer};

/// The next task of the crane `device` as its planner decides, after what must come first;
/// the crane's `port` offers its jobs and takes its reports, `writer` commits what the
/// planner adds.
pub(super) async fn next_task(
    port: &dyn Port,
    device: &str,
    writer: &Writer,
    planner: &CranePlanner,
) -> Result<Option<Job>, ReportError> {
    // A refusal ends a job and the choice is made again among the others; a place taken
    // meanwhile is chosen again. Bounded: a crane polls again soon anyway.
    if planner.unchanged_since_wait() {
        return Ok(None);
    }
    for _ in 0..ROUNDS {
        let seen = planner.commits();
        let candidates = port.next(usize::MAX, &HashSet::new());
        if candidates.is_empty() {
            return Ok(None);
        }
        let unfinished = port.unfinished();
        let rack = planner.rack().await.map_err(|e| ReportError::Store(Box::new(e)))?;
        let (c, u): (Vec<&Job>, Vec<&Job>) = (candidates.iter().collect(), unfinished.iter().collect());
        match planner.decide(&c, &u, &rack) {
            Decision::Run(id) => return Ok(candidates.into_iter().find(|j| j.id == id)),
            Decision::Wait => {
                planner.waited(seen);
                return Ok(None);
            }
            Decision::Place { job, to } => match writer.change(job, Change::Place(to)).await {
                Ok(placed) => return Ok(Some(placed)),
                // Taken since the rack was read (an inventory load): choose again.
                Err(WriteError::Taken(_)) => continue,
                Err(e) => return Err(report_error(e)),
            },
            Decision::Refuse { job, text } => {
                let failure = Failure { kind: FailureKind::Unsupported, code: None, text };
                let cause = "the rack makes the task impossible: nothing sent to the crane";
                port.report(vec![Report::new(job, Reported::Failed(failure), cause)]).await?;
            }
            Decision::Relocate { serves, from, to } => {
                let priority = candidates.iter().find(|j| j.id == serves).map_or(Priority::DEFAULT, |j| {
                    Priority::try_from(i64::from(j.priority)).unwrap_or(Priority::DEFAULT)
                });
                tracing::info!(serves, %from, %to, "relocating the box in front of a far location");
                let relocation = NewJob {
                    spec: JobSpec::Move { from, to },
                    reference: None,
                    priority,
                    barcode: None,
                    device: Some(device.to_owned()),
                    serves: Some(serves),
                    terms: Default::default(),
                };
                let outcome = writer.submit(vec![relocation]).await.map_err(report_error)?;
                return Ok(outcome.into_iter().find_map(|o| match o {
                    Outcome::Created { job, .. } => Some(job),
                    Outcome::Existing(_) => None,
                }));
            }
        }
    }
    Ok(None)
}

/// Decisions made in one call at most.
const ROUNDS: usize = 16;
