//! The figures of one run, from the simulators' timelines and counters and the WMS's
//! record (what each means: the module doc of `site.rs`).

use std::collections::{BTreeMap, HashMap};
use std::time::Instant;

use hdrhistogram::Histogram;
use rackd::sim::crane::{Pair, TaskKind, TaskTimes};
use rackd::wire::motion::Motion;
use rackd::wire::task_id_for;

use super::Mode;
use super::offline::{Due, Offline};
use super::run::Run;
use super::workload::Workload;
use crate::crane::bound::STATION;

/// Inversions at the stations: pairs of one sequence's members that arrive higher
/// position first.
#[derive(Clone, Debug, Default)]
pub struct Inversions {
    /// Both members from one aisle.
    pub within: usize,
    /// From two aisles.
    pub across: usize,
    /// Pairs of members from one aisle, and from two: what could be inverted.
    pub pairs: (usize, usize),
    /// By station: within, across.
    pub by_station: BTreeMap<u16, (usize, usize)>,
}

/// Deadlines met and missed, and the offline schedule's.
#[derive(Clone, Debug, Default)]
pub struct Deadlines {
    /// Jobs with a deadline, and of them tight ones.
    pub jobs: (usize, usize),
    /// Missed: tight, with slack.
    pub missed: (usize, usize),
    /// Missed by the offline schedule (`offline.rs`).
    pub offline: usize,
    /// No schedule misses fewer.
    pub at_least: usize,
    /// Missed by rackd, met by the offline schedule.
    pub offline_met: usize,
    /// How late each missed deadline ended, simulated seconds (infinite: not completed).
    pub late_by: Vec<f64>,
}

/// What one run comes to.
pub struct Figures {
    /// Jobs that ended otherwise, in words.
    pub failed: Vec<String>,
    /// Jobs completed per simulated hour, summed over the cranes (see `site.rs`).
    pub throughput: f64,
    /// The cranes' busy seconds over their spans (from the start to each one's last
    /// completion).
    pub busy: f64,
    /// The cranes' seconds between a job becoming due and the crane taking it (the
    /// dispatch latency, simulated), over their spans.
    pub dispatch: f64,
    /// Metres of empty travel, over the site.
    pub empty_m: f64,
    /// Of the stores, the share a retrieve followed (a dual cycle: the crane goes from the
    /// put to the next pick instead of back to the station empty).
    pub dual: f64,
    /// Inversions at the stations.
    pub inversions: Inversions,
    /// Deadlines.
    pub deadlines: Deadlines,
    /// Dispatch latency, microseconds of real time.
    pub latency: Histogram<u64>,
    /// rackd's CPU seconds per wall second while the workload ran, with the cranes
    /// online and idle, and per job completed.
    pub cpu: (f64, f64, f64),
    /// The simulators' CPU seconds per wall second while the workload ran, and idle.
    pub sims_cpu: (f64, f64),
}

impl Figures {
    /// The figures of `run`.
    pub fn of(run: &Run, workload: &Workload, motion: &Motion) -> Figures {
        let timeline = Timeline::of(run, workload);
        let failed: Vec<String> = run
            .jobs
            .iter()
            .enumerate()
            .filter(|(_, p)| p.ended != "completed")
            .map(|(j, p)| format!("J{j} (job {}, aisle {}): {}", p.id, workload.jobs[j].aisle, p.ended))
            .collect();
        let completed = run.jobs.len() - failed.len();
        let mut throughput = 0.0;
        let (mut busy, mut span) = (0.0, 0.0);
        for (c, crane) in run.cranes.iter().enumerate() {
            let ends: Vec<f64> = (0..workload.jobs.len())
                .filter(|&j| usize::from(workload.jobs[j].aisle) == c + 1)
                .filter_map(|j| timeline.completed(j))
                .collect();
            let last = ends.iter().copied().fold(0.0, f64::max);
            if last > 0.0 {
                throughput += ends.len() as f64 * 3600.0 / last;
            }
            (busy, span) = (busy + crane.stats.busy_secs, span + last);
        }
        let (wall, idle) = (run.wall.as_secs_f64(), super::run::IDLE.as_secs_f64());
        let latency = latency(run, &timeline, workload);
        let waited = latency.mean() * latency.len() as f64;
        Figures {
            failed,
            throughput,
            busy: busy / f64::max(span, f64::EPSILON),
            dispatch: waited / 1e6 * run.clock.scale / f64::max(span, f64::EPSILON),
            empty_m: run.cranes.iter().map(|c| c.stats.travel_empty_m).sum(),
            dual: dual_share(run),
            inversions: inversions(&timeline, workload),
            deadlines: deadlines(run, &timeline, workload, motion),
            latency,
            cpu: (run.cpu.rackd() / wall, run.idle.rackd() / idle, run.cpu.rackd() / completed.max(1) as f64),
            sims_cpu: (run.cpu.sims / wall, run.idle.sims / idle),
        }
    }
}

/// Each job's task on its crane.
struct Timeline<'a> {
    run: &'a Run,
    tasks: Vec<Option<&'a TaskTimes>>,
}

impl<'a> Timeline<'a> {
    fn of(run: &'a Run, workload: &Workload) -> Timeline<'a> {
        let by_number: Vec<HashMap<u16, &TaskTimes>> =
            run.cranes.iter().map(|c| c.tasks.iter().map(|t| (t.number, t)).collect()).collect();
        let tasks = (0..workload.jobs.len())
            .map(|j| {
                let crane = &by_number[usize::from(workload.jobs[j].aisle) - 1];
                crane.get(&task_id_for(run.jobs[j].id)).copied()
            })
            .collect();
        Timeline { run, tasks }
    }

    /// When job `j`'s crane completed it.
    fn completed_at(&self, j: usize) -> Option<Instant> {
        self.tasks[j]?.ended.filter(|(_, state)| *state == 20).map(|(at, _)| at.into_std())
    }

    /// The same, in simulated seconds from the start.
    fn completed(&self, j: usize) -> Option<f64> {
        self.completed_at(j).map(|at| self.run.clock.sim(at))
    }
}

fn inversions(timeline: &Timeline, workload: &Workload) -> Inversions {
    let mut found = Inversions::default();
    for sequence in &workload.sequences {
        let station = workload.station(sequence.station);
        let arrivals: Vec<(u16, f64)> = sequence
            .members
            .iter()
            .map(|&j| {
                let aisle = workload.jobs[j].aisle;
                (aisle, timeline.completed(j).unwrap_or(f64::INFINITY) + station.transit(aisle))
            })
            .collect();
        let one = Inversions::of(&arrivals);
        let counts = found.by_station.entry(sequence.station).or_default();
        (counts.0, counts.1) = (counts.0 + one.within, counts.1 + one.across);
        (found.within, found.across) = (found.within + one.within, found.across + one.across);
        found.pairs = (found.pairs.0 + one.pairs.0, found.pairs.1 + one.pairs.1);
    }
    found
}

impl Inversions {
    /// The inversions of one sequence whose members, position 1 first, come from these
    /// aisles at these instants.
    fn of(arrivals: &[(u16, f64)]) -> Inversions {
        let mut found = Inversions::default();
        for (p, &(aisle_p, at_p)) in arrivals.iter().enumerate() {
            for &(aisle_q, at_q) in &arrivals[p + 1..] {
                let (pairs, inverted) = if aisle_p == aisle_q {
                    (&mut found.pairs.0, &mut found.within)
                } else {
                    (&mut found.pairs.1, &mut found.across)
                };
                *pairs += 1;
                *inverted += usize::from(at_q < at_p);
            }
        }
        found
    }
}

fn deadlines(run: &Run, timeline: &Timeline, workload: &Workload, motion: &Motion) -> Deadlines {
    let mut found = Deadlines::default();
    for aisle in 1..=workload.aisles {
        let mine: Vec<usize> =
            (0..workload.jobs.len()).filter(|&j| workload.jobs[j].aisle == aisle).collect();
        let with: Vec<(usize, f64)> =
            mine.iter().filter_map(|&j| run.jobs[j].deadline.map(|d| (j, d))).collect();
        let due: Vec<Due> = with
            .iter()
            .map(|&(j, deadline)| {
                let leg = &workload.jobs[j].leg;
                let ends = mine.iter().filter(|&&k| k != j).map(|&k| workload.jobs[k].leg.end);
                let empty = ends
                    .chain([STATION])
                    .map(|end| motion.move_time(end, leg.start))
                    .fold(f64::INFINITY, f64::min);
                Due { release: run.clock.sim(run.jobs[j].answered), deadline, work: leg.own_secs + empty }
            })
            .collect();
        let offline = Offline::of(&due);
        found.offline += offline.misses();
        found.at_least += offline.at_least;
        for (&(j, deadline), offline_missed) in with.iter().zip(&offline.missed) {
            let tight = workload.jobs[j].deadline.is_some_and(|d| d.tight);
            found.jobs = (found.jobs.0 + 1, found.jobs.1 + usize::from(tight));
            let late_by = timeline.completed(j).map_or(f64::INFINITY, |end| end - deadline);
            if late_by > 0.0 {
                found.late_by.push(late_by);
                if tight {
                    found.missed.0 += 1;
                } else {
                    found.missed.1 += 1;
                }
                found.offline_met += usize::from(!offline_missed);
            }
        }
    }
    found
}

/// From the moment a job could have gone to its crane (posted, the crane done with the task
/// before, and in a run with sequences the member before it delivered and the transit
/// difference passed) to the crane taking it.
fn latency(run: &Run, timeline: &Timeline, workload: &Workload) -> Histogram<u64> {
    let mut hist = Histogram::<u64>::new(3).expect("a histogram");
    let job_of: HashMap<(u16, u16), usize> = (0..workload.jobs.len())
        .map(|j| ((workload.jobs[j].aisle, task_id_for(run.jobs[j].id)), j))
        .collect();
    for (aisle, crane) in (1..).zip(&run.cranes) {
        let mut free: Option<Instant> = None;
        for task in &crane.tasks {
            let Some(&j) = job_of.get(&(aisle, task.number)) else { continue };
            let mut due = run.jobs[j].answered;
            due = due.max(free.unwrap_or(due));
            if let Some(before) = released_after(run, timeline, workload, j) {
                due = due.max(before);
            }
            let received = task.received.into_std();
            hist.record(received.saturating_duration_since(due).as_micros() as u64).ok();
            free = task.ended.map(|(at, _)| at.into_std());
        }
    }
    hist
}

/// When a sequence member may go by the rule across aisles, in a run that posts sequences.
fn released_after(run: &Run, timeline: &Timeline, workload: &Workload, j: usize) -> Option<Instant> {
    let member = workload.jobs[j].member.filter(|m| run.mode == Mode::Orders && m.position > 1)?;
    let sequence = &workload.sequences[member.sequence];
    let before = sequence.members[member.position as usize - 2];
    let station = workload.station(sequence.station);
    let gap = station.transit(workload.jobs[before].aisle) - station.transit(workload.jobs[j].aisle);
    let at = timeline.completed_at(before)?;
    Some(at + std::time::Duration::from_secs_f64(gap.max(0.0) / run.clock.scale))
}

/// Stores followed by a retrieve, over all stores, on every crane.
fn dual_share(run: &Run) -> f64 {
    let (mut dual, mut stores) = (0, 0);
    for crane in &run.cranes {
        for (pair, runs) in &crane.stats.empty_by_pair {
            if pair.before == Some(TaskKind::Store) {
                stores += runs.tasks;
                dual += runs.tasks
                    * u32::from(*pair == Pair { before: Some(TaskKind::Store), next: TaskKind::Retrieve });
            }
        }
    }
    f64::from(dual) / f64::from(stores.max(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_inversion_is_a_pair_whose_higher_position_arrives_first() {
        // Positions 1..4: aisle 1 at 100, aisle 2 at 90 (before 1: across), aisle 1 at 95
        // (before 1: within; after 2), aisle 3 at 200.
        let found = Inversions::of(&[(1, 100.0), (2, 90.0), (1, 95.0), (3, 200.0)]);
        assert_eq!((found.within, found.across, found.pairs), (1, 1, (1, 5)));
        let none = Inversions::of(&[(1, 10.0), (2, 10.0), (1, 11.0)]);
        assert_eq!((none.within, none.across), (0, 0), "arriving together is in order");
    }
}
