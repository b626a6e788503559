//! The deadlines a schedule that knows every job in advance would miss: what `bench site`
//! holds rackd's missed deadlines against.
//!
//! One crane at a time (a job runs only on its aisle's crane), on the jobs with a
//! deadline; the others can always wait until every deadline has passed. The schedule
//! relaxes the crane in ways that can only help it:
//! - **a job's seconds** are its own (forks and the loaded run, as `crane/bound.rs` counts
//!   them) plus the least empty run to its pick from anywhere the crane could stand
//!   before it (the station, or where another of the crane's jobs ends): the bound's
//!   travel relaxation, per job;
//! - **no time between tasks**: no hand-over, no poll;
//! - **preemption**: a job may stop and go on later, as no crane can;
//! - **no sequences**: members run in any order.
//!
//! It knows when each job is posted (its release, as the run posted it) and its deadline.
//! Two figures come out:
//! - [`Offline::missed`], the schedule itself: earliest deadline first among the posted
//!   jobs, a job dropped (missed) as soon as it can no longer end by its deadline. With
//!   preemption, earliest deadline first meets every deadline whenever any schedule could,
//!   so a schedule with no miss is the least; with misses it is one good schedule, not
//!   proved the least;
//! - [`Offline::at_least`], a lower bound on the misses of any schedule: time windows
//!   that do not overlap, each holding jobs posted in it and due in it whose seconds
//!   exceed it, the fewest jobs each window must drop (its largest first), summed over
//!   the best set of windows.

/// One job with a deadline, in simulated seconds from the start of the run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Due {
    /// When it was posted.
    pub release: f64,
    /// When it should have ended.
    pub deadline: f64,
    /// The crane seconds it needs at least.
    pub work: f64,
}

/// What the offline schedule made of one crane's jobs.
#[derive(Clone, Debug, PartialEq)]
pub struct Offline {
    /// For each job, in the order given, whether the schedule missed its deadline.
    pub missed: Vec<bool>,
    /// No schedule misses fewer.
    pub at_least: usize,
}

impl Offline {
    /// The schedule of `jobs` on one crane.
    pub fn of(jobs: &[Due]) -> Offline {
        Offline { missed: edf(jobs), at_least: at_least(jobs) }
    }

    /// Deadlines the schedule missed.
    pub fn misses(&self) -> usize {
        self.missed.iter().filter(|m| **m).count()
    }
}

/// Preemptive earliest deadline first, dropping a job once it cannot end in time.
fn edf(jobs: &[Due]) -> Vec<bool> {
    let mut by_release: Vec<usize> = (0..jobs.len()).collect();
    by_release.sort_by(|&a, &b| jobs[a].release.total_cmp(&jobs[b].release));
    let mut left: Vec<f64> = jobs.iter().map(|j| j.work).collect();
    let mut missed = vec![false; jobs.len()];
    let mut ready: Vec<usize> = Vec::new();
    let (mut next, mut now) = (0, 0.0_f64);
    loop {
        while next < by_release.len() && jobs[by_release[next]].release <= now {
            ready.push(by_release[next]);
            next += 1;
        }
        let Some(k) =
            (0..ready.len()).min_by(|&a, &b| jobs[ready[a]].deadline.total_cmp(&jobs[ready[b]].deadline))
        else {
            match by_release.get(next) {
                Some(&j) => {
                    now = jobs[j].release;
                    continue;
                }
                None => return missed,
            }
        };
        let j = ready[k];
        if now + left[j] > jobs[j].deadline + 1e-9 {
            missed[j] = true;
            ready.swap_remove(k);
            continue;
        }
        let until = by_release.get(next).map_or(f64::INFINITY, |&n| jobs[n].release);
        let ran = left[j].min(until - now);
        (left[j], now) = (left[j] - ran, now + ran);
        if left[j] <= 1e-9 {
            ready.swap_remove(k);
        }
    }
}

/// The lower bound: over windows `[a, b]` between releases and deadlines that do not
/// overlap, the jobs posted and due inside a window must run inside it; those that do not
/// fit are missed under any schedule.
fn at_least(jobs: &[Due]) -> usize {
    let mut points: Vec<f64> = jobs.iter().flat_map(|j| [j.release, j.deadline]).collect();
    points.sort_by(f64::total_cmp);
    points.dedup();
    // best[i]: the most misses proved by windows that end at points[i] or before.
    let mut best = vec![0usize; points.len()];
    for i in 0..points.len() {
        best[i] = if i > 0 { best[i - 1] } else { 0 };
        for h in 0..=i {
            let before = if h > 0 { best[h - 1] } else { 0 };
            best[i] = best[i].max(before + must_drop(jobs, points[h], points[i]));
        }
    }
    best.last().copied().unwrap_or(0)
}

/// The fewest jobs posted at or after `a` and due by `b` that must go for the rest to fit
/// in `b - a`.
fn must_drop(jobs: &[Due], a: f64, b: f64) -> usize {
    let mut works: Vec<f64> =
        jobs.iter().filter(|j| j.release >= a && j.deadline <= b).map(|j| j.work).collect();
    works.sort_by(|x, y| y.total_cmp(x));
    let mut total: f64 = works.iter().sum();
    let mut dropped = 0;
    for w in works {
        if total <= b - a + 1e-9 {
            break;
        }
        total -= w;
        dropped += 1;
    }
    dropped
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crane::SplitMix;

    fn due(release: f64, deadline: f64, work: f64) -> Due {
        Due { release, deadline, work }
    }

    #[test]
    fn a_job_that_cannot_end_in_time_even_alone_is_missed_by_both() {
        let o = Offline::of(&[due(0.0, 100.0, 30.0), due(50.0, 70.0, 40.0)]);
        assert_eq!((o.missed, o.at_least), (vec![false, true], 1));
    }

    #[test]
    fn preemption_lets_an_urgent_job_in() {
        // The long job runs from 0, the urgent one takes 10..30, the long one ends at 110.
        let o = Offline::of(&[due(0.0, 120.0, 100.0), due(10.0, 30.0, 20.0)]);
        assert_eq!((o.misses(), o.at_least), (0, 0));
    }

    #[test]
    fn an_overloaded_window_drops_its_largest_jobs() {
        let jobs =
            [due(0.0, 60.0, 30.0), due(0.0, 60.0, 30.0), due(0.0, 60.0, 25.0), due(100.0, 120.0, 30.0)];
        let o = Offline::of(&jobs);
        assert_eq!(o.at_least, 2, "one of 0..60 and the last, alone");
        assert_eq!(o.misses(), 2);
    }

    /// The least misses, by trying every set of jobs to meet: a set can be met when
    /// earliest deadline first meets it.
    fn least(jobs: &[Due]) -> usize {
        (0u32..1 << jobs.len())
            .filter(|set| {
                let chosen: Vec<Due> =
                    (0..jobs.len()).filter(|i| set & (1 << i) != 0).map(|i| jobs[i]).collect();
                edf(&chosen).iter().all(|m| !m)
            })
            .map(|set| jobs.len() - set.count_ones() as usize)
            .min()
            .unwrap_or(0)
    }

    #[test]
    fn the_bound_never_exceeds_the_least_and_the_schedule_never_beats_it() {
        let mut rng = SplitMix(11);
        let mut tight = (0, 0);
        for _ in 0..300 {
            let jobs: Vec<Due> = (0..8)
                .map(|_| {
                    let release = rng.unit() * 200.0;
                    let work = 10.0 + rng.unit() * 40.0;
                    due(release, release + work + rng.unit() * 60.0, work)
                })
                .collect();
            let o = Offline::of(&jobs);
            let least = least(&jobs);
            assert!(
                o.at_least <= least && least <= o.misses(),
                "{} <= {least} <= {}",
                o.at_least,
                o.misses()
            );
            tight.0 += usize::from(o.at_least == least);
            tight.1 += usize::from(o.misses() == least);
        }
        assert!(tight.0 > 200 && tight.1 > 200, "both are the least on most draws: {tight:?} of 300");
    }
}
