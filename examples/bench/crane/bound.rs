//! The least crane time per cycle that any order of a workload could reach: the bound
//! `bench crane` prints beside its two planners, so that a planner's figure can be read
//! against what is possible at all, not only against fifo.
//!
//! The bound knows every job from the start (a planner sees only the WMS's backlog) and
//! relaxes everything else in ways that can only lower it:
//! - **each job's own seconds**: its two fork cycles and its loaded run, between the
//!   station and the location the workload names. A putaway store's put is unknown until
//!   rackd chooses it, so it counts as a near fork at the station with no run; so does
//!   the pick of a box such a store brought in. A store the WMS redirects at run time
//!   (a relocation took its place) counts at the place it was drawn for;
//! - **relocations**: only those no order avoids (a far retrieve behind a box of the
//!   starting stock that no job takes away), each at two near fork cycles and no run;
//! - **empty travel**: an optimal assignment of where each job ends to where a job
//!   begins, by the crane's move times (the Hungarian method, `kuhn_munkres_min` of the
//!   `pathfinding` crate, a dev-dependency: the service never needs it). Any order is such
//!   an assignment: the runs to, during and from a relocation between two jobs are at
//!   least the run between the two, since the crane's move time is a metric. The
//!   assignment may also close loops no order could, which only lowers it further.
//!
//! With the relocations a planner actually ran (their forks and loaded runs measured by
//! the simulator), the jobs' own seconds and the least empty travel give a second, closer
//! bound: what that planner could reach with its relocations as they were and perfect
//! foresight of every job.

use std::collections::{HashMap, HashSet};

use pathfinding::kuhn_munkres::kuhn_munkres_min;
use pathfinding::matrix::Matrix;
use rackd::wire::motion::{Motion, Spot};

use super::{Order, Workload};

/// Where the crane picks up and drops at the station (bay 0, level 1: both stations of
/// the crane's spec lie there, inbound on row 2 and outbound on row 1).
pub(crate) const STATION: Spot = Spot { bay: 0, level: 1 };

/// The least seconds of a workload, in three parts.
pub struct Bound {
    /// Jobs in the workload.
    pub jobs: usize,
    /// The jobs' own fork cycles and loaded runs.
    pub own_secs: f64,
    /// Relocations no order of the workload avoids.
    pub relocations: usize,
    /// Their fork cycles.
    pub relocation_secs: f64,
    /// The least empty travel of any order.
    pub empty_secs: f64,
}

impl Bound {
    /// The bound of `workload` under `motion`.
    pub fn of(workload: &Workload, motion: &Motion) -> Bound {
        let legs = legs(workload, motion);
        let relocations = unavoidable_relocations(workload);
        Bound {
            jobs: legs.len(),
            own_secs: legs.iter().map(|l| l.own_secs).sum(),
            relocations,
            relocation_secs: relocations as f64 * 2.0 * motion.fork_near,
            empty_secs: least_empty_secs(&legs, motion),
        }
    }

    /// Crane seconds per job: the least any order could take.
    pub fn per_cycle(&self) -> f64 {
        (self.own_secs + self.relocation_secs + self.empty_secs) / self.jobs.max(1) as f64
    }
}

/// One job as the crane runs it: where it begins, where it ends and its own seconds.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Leg {
    pub(crate) start: Spot,
    pub(crate) end: Spot,
    pub(crate) own_secs: f64,
}

fn spot([_, bay, level, _]: [u16; 4]) -> Spot {
    Spot { bay, level }
}

/// Each job's leg, the boxes followed from the starting stock through the stores.
pub(crate) fn legs(workload: &Workload, motion: &Motion) -> Vec<Leg> {
    let near = motion.fork_near;
    // Where each box is; None for a box a putaway store brought in.
    let mut cells: HashMap<&str, Option<[u16; 4]>> =
        workload.stock.iter().map(|(cell, barcode)| (barcode.as_str(), Some(*cell))).collect();
    let at_station = Leg { start: STATION, end: STATION, own_secs: 2.0 * near };
    let mut legs = Vec::with_capacity(workload.jobs.len());
    for order in &workload.jobs {
        legs.push(match order {
            Order::Store { barcode, putaway: true, .. } => {
                cells.insert(barcode, None);
                at_station
            }
            Order::Store { cell, barcode, putaway: false } => {
                cells.insert(barcode, Some(*cell));
                let own_secs = near + motion.move_time(STATION, spot(*cell)) + motion.fork_time(cell[3]);
                Leg { start: STATION, end: spot(*cell), own_secs }
            }
            Order::Retrieve(barcode) => match cells.remove(barcode.as_str()).flatten() {
                None => at_station,
                Some(cell) => {
                    let own_secs = motion.fork_time(cell[3]) + motion.move_time(spot(cell), STATION) + near;
                    Leg { start: spot(cell), end: STATION, own_secs }
                }
            },
        });
    }
    legs
}

/// Far retrieves behind a box of the starting stock that no job of the workload takes
/// away: under any order that box is still in front when the far one is wanted.
fn unavoidable_relocations(workload: &Workload) -> usize {
    let stock: HashMap<[u16; 4], &str> = workload.stock.iter().map(|(c, b)| (*c, b.as_str())).collect();
    let retrieved: HashSet<&str> = workload
        .jobs
        .iter()
        .filter_map(|o| match o {
            Order::Retrieve(b) => Some(b.as_str()),
            Order::Store { .. } => None,
        })
        .collect();
    let far_cells = workload.stock.iter().filter(|(cell, _)| cell[3] == 2);
    far_cells
        .filter(|(_, barcode)| retrieved.contains(barcode.as_str()))
        .filter(|([row, bay, level, _], _)| {
            stock.get(&[*row, *bay, *level, 1]).is_some_and(|near| !retrieved.contains(near))
        })
        .count()
}

/// The least seconds of empty travel: an optimal assignment of the jobs' ends (and the
/// crane's start, anywhere) to the jobs' beginnings (and nothing after the last job).
fn least_empty_secs(legs: &[Leg], motion: &Motion) -> f64 {
    let n = legs.len();
    // Whole milliseconds, rounded down, so the bound stays a bound.
    let millis = |from: Spot, to: Spot| (motion.move_time(from, to) * 1000.0).floor() as i64;
    // Row i < n: after job i; row n: the crane's start. Column j < n: before job j; column n: the end.
    let weight =
        |(i, j): (usize, usize)| if i == n || j == n { 0 } else { millis(legs[i].end, legs[j].start) };
    let (total, _) = kuhn_munkres_min(&Matrix::from_fn(n + 1, n + 1, weight));
    total as f64 / 1000.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crane::CraneArgs;

    fn store(cell: [u16; 4], barcode: &str) -> Order {
        Order::Store { cell, barcode: barcode.into(), putaway: false }
    }

    fn retrieve(barcode: &str) -> Order {
        Order::Retrieve(barcode.into())
    }

    #[test]
    fn a_dual_cycle_at_one_spot_needs_no_empty_run() {
        let m = Motion::default();
        let workload = Workload {
            stock: vec![([1, 10, 4, 1], "OLD".into())],
            jobs: vec![store([2, 10, 4, 1], "NEW"), retrieve("OLD")],
        };
        let bound = Bound::of(&workload, &m);
        let run = m.move_time(STATION, Spot { bay: 10, level: 4 });
        assert!(run > 10.0);
        assert_eq!(bound.empty_secs, 0.0, "put, then the pick at the same spot, then the station");
        assert!((bound.own_secs - 2.0 * (2.0 * m.fork_near + run)).abs() < 1e-9);
        assert_eq!(bound.relocations, 0);
        assert!((bound.per_cycle() - (2.0 * m.fork_near + run)).abs() < 1e-9);
    }

    #[test]
    fn two_stores_return_to_the_station_empty() {
        let m = Motion::default();
        let workload =
            Workload { stock: vec![], jobs: vec![store([1, 10, 4, 1], "A"), store([1, 20, 2, 2], "B")] };
        let bound = Bound::of(&workload, &m);
        // One store's put is followed by the other's pick at the station; the crane's
        // start and the end are free, so the nearer put returns.
        let back = m.move_time(Spot { bay: 10, level: 4 }, STATION);
        assert!((bound.empty_secs - (back * 1000.0).floor() / 1000.0).abs() < 1e-9);
    }

    #[test]
    fn a_far_box_behind_one_no_job_takes_needs_a_relocation() {
        let stock = vec![([1, 5, 3, 1], "NEAR".to_owned()), ([1, 5, 3, 2], "FAR".to_owned())];
        let alone = Workload { stock: stock.clone(), jobs: vec![retrieve("FAR")] };
        assert_eq!(Bound::of(&alone, &Motion::default()).relocations, 1);
        let both = Workload { stock, jobs: vec![retrieve("FAR"), retrieve("NEAR")] };
        assert_eq!(Bound::of(&both, &Motion::default()).relocations, 0, "the near one can go first");
    }

    #[test]
    fn a_putaway_box_counts_at_the_station() {
        let m = Motion::default();
        let workload = Workload {
            stock: vec![],
            jobs: vec![
                Order::Store { cell: [1, 30, 9, 2], barcode: "P".into(), putaway: true },
                retrieve("P"),
            ],
        };
        let bound = Bound::of(&workload, &m);
        assert!((bound.own_secs - 4.0 * m.fork_near).abs() < 1e-9);
        assert_eq!(bound.empty_secs, 0.0);
    }

    #[test]
    fn no_order_of_a_drawn_workload_beats_the_bound() {
        let m = Motion::default();
        let args = CraneArgs {
            jobs: 120,
            backlog: 30,
            fill: 0.5,
            time_scale: 1.0,
            seed: 3,
            bays: 20,
            levels: 8,
            max_overtaken: None,
            putaway: 0.3,
        };
        let workload = Workload::draw(&args);
        let bound = Bound::of(&workload, &m);
        let legs = legs(&workload, &m);
        // Three orders: as drawn, backwards, and every store before every retrieve.
        let cost = |order: &[usize]| {
            let empty: f64 = order.windows(2).map(|w| m.move_time(legs[w[0]].end, legs[w[1]].start)).sum();
            bound.own_secs + bound.relocation_secs + empty
        };
        let forwards: Vec<usize> = (0..legs.len()).collect();
        let backwards: Vec<usize> = forwards.iter().rev().copied().collect();
        let mut stores_first = forwards.clone();
        stores_first.sort_by_key(|&i| (legs[i].start != STATION, i));
        for order in [forwards, backwards, stores_first] {
            assert!(bound.per_cycle() * legs.len() as f64 <= cost(&order) + 0.1);
        }
        assert!(bound.empty_secs > 0.0 && bound.relocations > 0, "a drawn workload has both");
    }
}
