//! Which queued jobs a device should take next.
//!
//! Queued jobs go by priority (lower first), then age; but a job may not overtake an older
//! unfinished job that touches one of its locations (a retrieve must not run before the
//! store into the same place that was accepted first). This is a pure function over the
//! device's unfinished jobs, so it is tested on its own and used for every device kind.

use std::collections::HashSet;

use crate::domain::{Job, JobState, Location};

/// The queued jobs that may start now, best first, at most `free` of them.
///
/// `by_age` holds the device's non-terminal jobs (queued or on the device) in id order;
/// `held` are queued jobs that may not be handed out (the device holds them unconfirmed,
/// or a cancel is deciding their fate): they still keep later jobs off their locations.
pub fn next_jobs<'a>(
    by_age: impl IntoIterator<Item = &'a Job>,
    held: &HashSet<i64>,
    free: usize,
) -> Vec<&'a Job> {
    let mut touched: HashSet<Location> = HashSet::new();
    let mut eligible = Vec::new();
    for job in by_age {
        let locations = job.spec().map(|s| s.locations()).unwrap_or_default();
        let blocked = locations.iter().any(|l| touched.contains(l));
        if job.state == JobState::Queued && !blocked && !held.contains(&job.id) {
            eligible.push(job);
        }
        touched.extend(locations);
    }
    eligible.sort_by_key(|j| (j.priority, j.id));
    eligible.truncate(free);
    eligible
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::domain::{JobSpec, NewJob, Priority};

    fn loc(bay: u16) -> Location {
        Location { aisle: 1, row: 1, bay, level: 1, position: 1 }
    }

    fn job(id: i64, priority: u8, spec: JobSpec, state: JobState) -> Job {
        let new = NewJob {
            spec,
            reference: None,
            priority: Priority::try_from(priority as i64).unwrap(),
            barcode: None,
            device: None,
            serves: None,
            terms: Default::default(),
        };
        let mut j = new.accepted(id, 0);
        j.state = state;
        j
    }

    #[test]
    fn priority_then_age() {
        let jobs = [
            job(1, 10, JobSpec::Store { to: loc(1) }, JobState::Queued),
            job(2, 0, JobSpec::Store { to: loc(2) }, JobState::Queued),
            job(3, 10, JobSpec::Store { to: loc(3) }, JobState::Queued),
        ];
        let none = HashSet::new();
        let ids: Vec<_> = next_jobs(&jobs, &none, 5).iter().map(|j| j.id).collect();
        assert_eq!(ids, vec![2, 1, 3]);
        assert_eq!(next_jobs(&jobs, &none, 1).len(), 1);
        let ids: Vec<_> = next_jobs(&jobs, &HashSet::from([2]), 5).iter().map(|j| j.id).collect();
        assert_eq!(ids, vec![1, 3], "a held job is not handed out");
    }

    #[test]
    fn same_location_runs_in_acceptance_order() {
        let jobs = [
            job(1, 10, JobSpec::Store { to: loc(1) }, JobState::Dispatched),
            job(2, 0, JobSpec::Retrieve { from: loc(1) }, JobState::Queued),
            job(3, 5, JobSpec::Move { from: loc(2), to: loc(1) }, JobState::Queued),
            job(4, 5, JobSpec::Store { to: loc(2) }, JobState::Queued),
            job(5, 9, JobSpec::Store { to: loc(4) }, JobState::Queued),
        ];
        let ids: Vec<_> = next_jobs(&jobs, &HashSet::new(), 5).iter().map(|j| j.id).collect();
        assert_eq!(ids, vec![5], "2 waits for 1; 3 waits for 1 (to) ; 4 waits for 3 (loc 2)");
        let ids: Vec<_> = next_jobs(&jobs[2..], &HashSet::from([3]), 5).iter().map(|j| j.id).collect();
        assert_eq!(ids, vec![5], "a held job still keeps later ones off its locations");
    }
}
