//! An operator's bulk action applied in memory: every item checked against the group's rows
//! first, then all of them done, or none (see [`crate::store::writer::Bulk`]).

use std::collections::BTreeSet;

use super::{Group, location_key};
use crate::domain::{JobState, Location, LocationLock, Transition, Who};
use crate::store::locations::LocationState;
use crate::store::writer::{Bulk, BulkAction, Bulked, Refusal, WriteError};

impl Group {
    /// Checks every item of `bulk`, then (unless it is a dry run) does them all, audited as
    /// `who`: the jobs in id order, then the unlocks. Refused whole if any item is.
    pub(super) fn bulk(&mut self, bulk: &Bulk, who: &Who) -> Result<Bulked, WriteError> {
        let refusals = self.refusals(&bulk.action);
        if !refusals.is_empty() {
            return Err(WriteError::Refused(refusals));
        }
        let (jobs, unlock): (BTreeSet<i64>, BTreeSet<Location>) = match &bulk.action {
            BulkAction::Unlock(locations) => (BTreeSet::new(), locations.iter().map(|(l, _)| *l).collect()),
            BulkAction::Retry { jobs, unlock } => {
                let ids: BTreeSet<i64> = jobs.iter().copied().collect();
                let lifted = if *unlock { self.locked_by(&ids) } else { BTreeSet::new() };
                (ids, lifted)
            }
            BulkAction::Cancel(jobs) => (jobs.iter().copied().collect(), BTreeSet::new()),
        };
        let unlocked: Vec<(Location, LocationLock)> =
            unlock.iter().filter_map(|l| Some((*l, self.lock_of(l)?))).collect();
        if !bulk.dry_run {
            let reason = reason(bulk);
            let client = who.client;
            for id in &jobs {
                let Some(mut job) = self.jobs.get(id).cloned() else { continue };
                let (transition, action, cause) = match bulk.action {
                    BulkAction::Cancel(_) => {
                        (Transition::Cancel, "cancel", "cancelled through the API (bulk)".to_owned())
                    }
                    _ => (
                        Transition::Retry,
                        "retry",
                        format!("retried by {} (attempt {})", bulk.by, job.attempt + 1),
                    ),
                };
                self.step(&mut job, transition, &cause, None, false)?;
                self.jobs.insert(*id, job);
                self.audit(&bulk.by, client, action, &format!("job:{id}"), Some(&reason));
            }
            for l in &unlock {
                self.audit(&bulk.by, client, "unlock", &location_key(*l), Some(&reason));
                self.unlock(*l);
            }
        }
        let jobs = jobs.iter().filter_map(|id| self.jobs.get(id).cloned()).collect();
        Ok(Bulked { jobs, unlocked, applied: !bulk.dry_run })
    }

    /// Every item of `action` that cannot be done as asked, in the order named.
    fn refusals(&self, action: &BulkAction) -> Vec<Refusal> {
        let state = |id: &i64, wanted: JobState| match self.jobs.get(id) {
            None => Some(Refusal::NoJob(*id)),
            Some(job) if job.state != wanted => Some(Refusal::State { id: *id, state: job.state, wanted }),
            Some(_) => None,
        };
        match action {
            BulkAction::Unlock(locations) => locations
                .iter()
                .filter_map(|(l, expected)| match (self.lock_of(l), expected) {
                    (None, _) => Some(Refusal::NotLocked(*l)),
                    (Some(lock), Some(job)) if lock.job != Some(*job) => {
                        Some(Refusal::OtherCause { location: *l, expected: *job, lock })
                    }
                    _ => None,
                })
                .collect(),
            BulkAction::Retry { jobs, .. } => {
                jobs.iter().filter_map(|id| state(id, JobState::Failed)).collect()
            }
            BulkAction::Cancel(jobs) => jobs.iter().filter_map(|id| state(id, JobState::Queued)).collect(),
        }
    }

    /// The locations of `jobs` locked by the failure of one of them.
    fn locked_by(&self, jobs: &BTreeSet<i64>) -> BTreeSet<Location> {
        let mut locked = BTreeSet::new();
        for id in jobs {
            let places = self.jobs.get(id).and_then(|j| j.spec()).map(|s| s.locations()).unwrap_or_default();
            for l in places {
                if self.locations.get(&l).is_some_and(|r| r.locked_at.is_some() && r.lock_job == Some(*id)) {
                    locked.insert(l);
                }
            }
        }
        locked
    }

    /// The lock `l` has, if any.
    fn lock_of(&self, l: &Location) -> Option<LocationLock> {
        self.locations.get(l).and_then(|row| LocationState::from(row.clone()).lock)
    }
}

/// The reason audited with each item: the action and its size, then the operator's reason.
fn reason(bulk: &Bulk) -> String {
    let (what, item) = match &bulk.action {
        BulkAction::Unlock(_) => ("unlock", "location"),
        BulkAction::Retry { unlock: false, .. } => ("retry", "job"),
        BulkAction::Retry { unlock: true, .. } => ("unlock and retry", "job"),
        BulkAction::Cancel(_) => ("cancel", "job"),
    };
    let n = bulk.action.len();
    let s = if n == 1 { "" } else { "s" };
    match &bulk.reason {
        Some(r) => format!("bulk {what} of {n} {item}{s}: {r}"),
        None => format!("bulk {what} of {n} {item}{s}"),
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Answer, Command, Group, Loaded, Next, Spare};
    use super::*;
    use crate::domain::time::from_ms;
    use crate::domain::{Failure, JobSpec, NewJob};
    use crate::store::locations::Row;

    fn at(bay: u16) -> Location {
        Location { aisle: 1, row: 1, bay, level: 1, position: 1 }
    }

    /// Jobs 1..=3 storing into bays 1..=3: 1 and 2 failed as lost (locking their bay),
    /// 3 queued; bay 4 locked by hand.
    fn loaded() -> Loaded {
        let mut loaded = Loaded::default();
        for id in 1..=3 {
            let new = NewJob {
                spec: JobSpec::Store { to: at(id as u16) },
                reference: None,
                priority: Default::default(),
                barcode: None,
                device: Some("shelf1".into()),
                serves: None,
                terms: Default::default(),
            };
            let mut job = new.accepted(id, 0);
            if id < 3 {
                job.state = JobState::Failed;
                job.failure =
                    Some(Failure { kind: crate::domain::FailureKind::Lost, code: None, text: "gone".into() });
            }
            loaded.jobs.insert(id, job);
        }
        for bay in 1..=4u16 {
            let lock_job = (bay < 3).then_some(bay as i64);
            let locked = bay != 3;
            let row = Row {
                aisle: 1,
                row: 1,
                bay: bay as i64,
                level: 1,
                position: 1,
                occupied: false,
                barcode: None,
                red: false,
                green: false,
                reserved_by: None,
                updated_at: 0,
                locked_at: locked.then_some(0),
                locked_by: locked.then(|| if lock_job.is_some() { "rackd".into() } else { "ops".into() }),
                lock_reason: locked.then(|| "check".into()),
                lock_job,
            };
            loaded.locations.insert(at(bay), row);
        }
        loaded
    }

    fn run(action: BulkAction, dry_run: bool) -> (Group, Result<Bulked, WriteError>) {
        let bulk = Bulk { action, dry_run, by: "ops".into(), reason: Some("checked".into()) };
        let who = Who { name: "ops".into(), client: None };
        let cmd = Command::Bulk { bulk, who, reply: tokio::sync::oneshot::channel().0 };
        let next = Next { job: 10, seq: 1, audit: 1, alarm: 1 };
        let mut group = Group::new(loaded(), next, 1_000, None, &[&cmd], &mut Spare::default());
        let Answer::Bulked(result) = group.command(&cmd) else { panic!("not a bulk answer") };
        (group, result)
    }

    #[test]
    fn one_refused_item_refuses_the_whole_action_and_changes_nothing() {
        let (group, result) = run(BulkAction::Retry { jobs: vec![2, 1, 3, 9], unlock: true }, false);
        let Err(WriteError::Refused(refusals)) = result else { panic!("{result:?}") };
        assert_eq!(
            refusals,
            [Refusal::State { id: 3, state: JobState::Queued, wanted: JobState::Failed }, Refusal::NoJob(9)]
        );
        assert!(group.out.events.is_empty() && group.audit.is_empty() && group.changed.is_empty());
        assert!(group.out.locks.is_empty());

        let (_, result) =
            run(BulkAction::Unlock(vec![(at(1), Some(2)), (at(3), None), (at(4), None)]), false);
        let Err(WriteError::Refused(refusals)) = result else { panic!("{result:?}") };
        assert!(matches!(refusals[0], Refusal::OtherCause { expected: 2, .. }), "{refusals:?}");
        assert_eq!(refusals[1], Refusal::NotLocked(at(3)));
        assert_eq!(refusals.len(), 2, "a lock by hand is unlocked when listed without a job");
        assert!(refusals[0].to_string().contains("locked by job 1, not by job 2"), "{}", refusals[0]);
    }

    #[test]
    fn a_dry_run_tells_and_writes_nothing() {
        let (group, result) = run(BulkAction::Retry { jobs: vec![2, 1], unlock: true }, true);
        let done = result.unwrap();
        assert!(!done.applied);
        assert_eq!(
            done.jobs.iter().map(|j| (j.id, j.state)).collect::<Vec<_>>(),
            [(1, JobState::Failed), (2, JobState::Failed)]
        );
        assert_eq!(done.unlocked.iter().map(|(l, _)| *l).collect::<Vec<_>>(), [at(1), at(2)]);
        assert!(group.out.events.is_empty() && group.audit.is_empty() && group.out.locks.is_empty());
        assert!(group.locations[&at(1)].locked_at.is_some());
    }

    #[test]
    fn retry_with_unlock_queues_in_id_order_and_lifts_only_their_own_locks() {
        let (group, result) = run(BulkAction::Retry { jobs: vec![2, 1], unlock: true }, false);
        let done = result.unwrap();
        assert!(done.applied);
        let jobs: Vec<(i64, JobState, u32)> = done.jobs.iter().map(|j| (j.id, j.state, j.attempt)).collect();
        assert_eq!(jobs, [(1, JobState::Queued, 2), (2, JobState::Queued, 2)]);
        assert_eq!(
            group.out.locks.iter().map(|(l, lock)| (*l, lock.is_none())).collect::<Vec<_>>(),
            [(at(1), true), (at(2), true)]
        );
        assert!(group.locations[&at(4)].locked_at.is_some(), "a lock by hand stays");
        let audit: Vec<(&str, &str)> =
            group.audit.iter().map(|a| (a.action.as_str(), a.target.as_str())).collect();
        assert_eq!(
            audit,
            [
                ("retry", "job:1"),
                ("retry", "job:2"),
                ("unlock", "location:1/1/1/1/1"),
                ("unlock", "location:1/1/2/1/1")
            ]
        );
        assert!(
            group
                .audit
                .iter()
                .all(|a| a.reason.as_deref() == Some("bulk unlock and retry of 2 jobs: checked"))
        );
        let updated = group.out.events.iter().filter(|e| e.kind == "job.updated").count();
        assert_eq!(updated, 2);
        assert_eq!(from_ms(1_000), done.jobs[0].updated_at);
    }

    #[test]
    fn cancel_cancels_queued_jobs_only() {
        let (_, result) = run(BulkAction::Cancel(vec![3, 1]), false);
        let Err(WriteError::Refused(refusals)) = result else { panic!("{result:?}") };
        assert_eq!(refusals, [Refusal::State { id: 1, state: JobState::Failed, wanted: JobState::Queued }]);
        let (group, result) = run(BulkAction::Cancel(vec![3]), false);
        assert_eq!(result.unwrap().jobs[0].state, JobState::Cancelled);
        assert_eq!(group.audit[0].action, "cancel");
    }
}
