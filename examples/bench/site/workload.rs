//! The site and the WMS's stream, drawn once from the seed: every run of `bench site` at
//! one aisle count posts the same jobs in the same order.
//!
//! - **Aisles** 1..=N, each single-deep (2 rows x `--bays` x `--levels`, one position):
//!   the bench measures order, deadlines and rackd's cost, and a double-deep aisle's
//!   relocations would make the WMS's retrieves depend on where rackd moved a box
//!   (`bench crane` covers them). Each starts `--fill` full.
//! - **Jobs**, `--jobs` per aisle, half retrieves of boxes of the starting stock, half
//!   stores to places empty at the start: no place is named twice, so any order the
//!   planner picks is possible.
//! - **Sequences**: a `--sequenced` share of the retrieves, shuffled across the site and
//!   cut into sequences of 2 to 6 members (the last takes what is left, up to 7), each
//!   to one station; so most sequences have
//!   members in several aisles when there are several.
//! - **Deadlines** on a `--deadlines` share of the other jobs, set as the WMS posts the job
//!   (see [`Deadline`]).
//! - **Stations** along the front of the aisles (see [`Station`]).

use crate::crane::bound::{Bound, Leg, legs};
use crate::crane::{Order, SplitMix, Workload as CraneWorkload};
use rackd::wire::motion::Motion;

use super::SiteArgs;

/// Metres between two aisles along the front, where the conveyors run.
const AISLE_PITCH_M: f64 = 3.5;
/// Seconds from an aisle's outbound station onto the front conveyor and off it at a station.
const TRANSIT_FIXED_S: f64 = 15.0;
/// The front conveyor's speed, m/s.
const CONVEYOR_M_S: f64 = 0.5;
/// A tight deadline leaves this many mean jobs' time (the bound's seconds per job) beside
/// the job's own seconds: enough to finish the task under way and run this one next, not
/// enough to wait its turn.
pub const TIGHT_CYCLES: f64 = 2.0;

/// A pick station on the front conveyor, `x` metres from aisle 1's end of it.
#[derive(Clone, Copy, Debug)]
pub struct Station {
    /// Its id, as `[[site.stations]]` names it.
    pub id: u16,
    x: f64,
}

impl Station {
    /// Simulated seconds from aisle `aisle`'s outbound station to this one: on and off the
    /// conveyor, and along it at its speed.
    pub fn transit(&self, aisle: u16) -> f64 {
        let from = (f64::from(aisle) - 1.0) * AISLE_PITCH_M;
        TRANSIT_FIXED_S + (from - self.x).abs() / CONVEYOR_M_S
    }
}

/// What a job does, with its place `[row, bay, level, side]` in its aisle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kind {
    /// From the inbound station to the place.
    Store([u16; 4]),
    /// From the place to the outbound station.
    Retrieve([u16; 4]),
}

/// When a job should have ended: `allowance` simulated seconds after the WMS posts it.
#[derive(Clone, Copy, Debug)]
pub struct Deadline {
    /// Simulated seconds from the post to the deadline.
    pub allowance: f64,
    /// Tight ([`TIGHT_CYCLES`] mean jobs' time beside its own seconds), or with slack
    /// (`--slack` mean jobs' time).
    pub tight: bool,
}

/// A job's place in its sequence.
#[derive(Clone, Copy, Debug)]
pub struct Member {
    /// The sequence (an index into [`Workload::sequences`]).
    pub sequence: usize,
    /// 1, 2, ...
    pub position: u32,
}

/// One job of the stream.
#[derive(Clone, Debug)]
pub struct Job {
    /// Its aisle (and crane).
    pub aisle: u16,
    /// What it does.
    pub kind: Kind,
    /// The box.
    pub barcode: String,
    /// Its crane seconds as the bound counts them: forks and the loaded run.
    pub leg: Leg,
    /// Its deadline, if it has one.
    pub deadline: Option<Deadline>,
    /// Its sequence, if it is a member of one.
    pub member: Option<Member>,
}

/// Retrieves that reach one station in position order.
#[derive(Clone, Debug)]
pub struct Sequence {
    /// The station.
    pub station: u16,
    /// Its jobs (indices into [`Workload::jobs`]), position 1 first.
    pub members: Vec<usize>,
}

/// What the WMS posts in one request.
#[derive(Clone, Copy, Debug)]
pub enum Post {
    /// One job.
    Job(usize),
    /// A whole sequence, in one batch.
    Sequence(usize),
}

/// The site and its stream.
pub struct Workload {
    /// The aisles' count.
    pub aisles: u16,
    /// The stations.
    pub stations: Vec<Station>,
    /// Each aisle's boxes at the start (aisle 1 first).
    pub stock: Vec<Vec<([u16; 4], String)>>,
    /// Every job; a job's reference is `J` and its index.
    pub jobs: Vec<Job>,
    /// The sequences; a sequence's name is `SEQ-` and its index.
    pub sequences: Vec<Sequence>,
    /// The WMS's requests, in the order it sends them.
    pub posts: Vec<Post>,
    /// Each aisle's bound (`crane/bound.rs`) on its share of the jobs.
    pub bounds: Vec<Bound>,
}

impl Workload {
    /// The workload of `aisles` aisles.
    pub fn draw(args: &SiteArgs, aisles: u16, motion: &Motion) -> Workload {
        let mut rng = SplitMix(args.seed ^ u64::from(aisles).rotate_left(32));
        let station_count = args.stations.unwrap_or(usize::from(aisles).div_ceil(10)).max(1);
        let front = f64::from(aisles.max(1)) * AISLE_PITCH_M;
        let stations = (0..station_count)
            .map(|k| Station { id: k as u16 + 1, x: (k as f64 + 0.5) * front / station_count as f64 })
            .collect();
        let mut stock = Vec::new();
        let mut jobs = Vec::new();
        let mut bounds = Vec::new();
        for aisle in 1..=aisles {
            let (boxes, mine) = draw_aisle(args, aisle, &mut rng);
            let orders = CraneWorkload {
                stock: boxes.clone(),
                jobs: mine
                    .iter()
                    .map(|(kind, barcode)| match kind {
                        Kind::Store(cell) => {
                            Order::Store { cell: *cell, barcode: barcode.clone(), putaway: false }
                        }
                        Kind::Retrieve(_) => Order::Retrieve(barcode.clone()),
                    })
                    .collect(),
            };
            let legs = legs(&orders, motion);
            bounds.push(Bound::of(&orders, motion));
            for ((kind, barcode), leg) in mine.into_iter().zip(legs) {
                jobs.push(Job { aisle, kind, barcode, leg, deadline: None, member: None });
            }
            stock.push(boxes);
        }
        let mut workload =
            Workload { aisles, stations, stock, jobs, sequences: Vec::new(), posts: Vec::new(), bounds };
        workload.sequence(args, &mut rng);
        workload.set_deadlines(args, &mut rng);
        workload
    }

    /// Cuts a share of the retrieves into sequences, and orders every post at random.
    fn sequence(&mut self, args: &SiteArgs, rng: &mut SplitMix) {
        let mut sequenced: Vec<usize> = (0..self.jobs.len())
            .filter(|&j| matches!(self.jobs[j].kind, Kind::Retrieve(_)))
            .filter(|_| rng.unit() < args.sequenced)
            .collect();
        shuffle(&mut sequenced, rng);
        let mut rest = sequenced.as_slice();
        while !rest.is_empty() {
            // The last takes what is left rather than leave one member alone.
            let mut size = (2 + rng.below(5)).min(rest.len());
            if rest.len() - size < 2 {
                size = rest.len();
            }
            let (members, tail) = rest.split_at(size);
            rest = tail;
            let sequence = self.sequences.len();
            let station = self.stations[rng.below(self.stations.len())].id;
            for (k, &j) in members.iter().enumerate() {
                self.jobs[j].member = Some(Member { sequence, position: k as u32 + 1 });
            }
            self.sequences.push(Sequence { station, members: members.to_vec() });
        }
        let single = (0..self.jobs.len()).filter(|&j| self.jobs[j].member.is_none()).map(Post::Job);
        self.posts = single.chain((0..self.sequences.len()).map(Post::Sequence)).collect();
        shuffle(&mut self.posts, rng);
    }

    /// Gives a share of the jobs outside sequences a deadline, a share of those tight.
    fn set_deadlines(&mut self, args: &SiteArgs, rng: &mut SplitMix) {
        let cycle = self.mean_cycle();
        for job in self.jobs.iter_mut().filter(|j| j.member.is_none()) {
            if rng.unit() >= args.deadlines {
                continue;
            }
            let tight = rng.unit() < args.tight;
            let beside = if tight { TIGHT_CYCLES * cycle } else { args.slack * cycle };
            job.deadline = Some(Deadline { allowance: job.leg.own_secs + beside, tight });
        }
    }

    /// The bound's crane seconds per job, over the site.
    pub fn mean_cycle(&self) -> f64 {
        let secs: f64 = self.bounds.iter().map(|b| b.per_cycle() * b.jobs as f64).sum();
        secs / self.jobs.len().max(1) as f64
    }

    /// A station by id.
    pub fn station(&self, id: u16) -> &Station {
        self.stations.iter().find(|s| s.id == id).expect("a drawn station")
    }

    /// Jobs with a deadline, tight ones, and sequence members.
    pub fn counts(&self) -> (usize, usize, usize) {
        let deadlines = self.jobs.iter().filter_map(|j| j.deadline);
        let tight = deadlines.clone().filter(|d| d.tight).count();
        (deadlines.count(), tight, self.jobs.iter().filter(|j| j.member.is_some()).count())
    }
}

/// One aisle: its starting stock, and its jobs (half retrieves of that stock, half stores
/// to places empty at the start), in a random order.
#[allow(clippy::type_complexity)]
fn draw_aisle(
    args: &SiteArgs,
    aisle: u16,
    rng: &mut SplitMix,
) -> (Vec<([u16; 4], String)>, Vec<(Kind, String)>) {
    let cells: Vec<[u16; 4]> = cells(args).collect();
    let mut stock = Vec::new();
    let mut free = Vec::new();
    for cell in cells {
        if rng.unit() < args.fill {
            stock.push((cell, format!("A{aisle}-{:04}", stock.len())));
        } else {
            free.push(cell);
        }
    }
    let retrieves = (args.jobs / 2).min(stock.len());
    let stores = (args.jobs - retrieves).min(free.len());
    let mut left = stock.clone();
    let mut jobs = Vec::with_capacity(retrieves + stores);
    for _ in 0..retrieves {
        let (cell, barcode) = left.swap_remove(rng.below(left.len()));
        jobs.push((Kind::Retrieve(cell), barcode));
    }
    for n in 0..stores {
        let cell = free.swap_remove(rng.below(free.len()));
        jobs.push((Kind::Store(cell), format!("A{aisle}-N{n:03}")));
    }
    shuffle(&mut jobs, rng);
    (stock, jobs)
}

/// Every place of an aisle: `[row, bay, level, 1]`.
pub fn cells(args: &SiteArgs) -> impl Iterator<Item = [u16; 4]> + use<> {
    let (bays, levels) = (args.bays, args.levels);
    (1..=2).flat_map(move |row| {
        (1..=bays).flat_map(move |bay| (1..=levels).map(move |level| [row, bay, level, 1]))
    })
}

fn shuffle<T>(items: &mut [T], rng: &mut SplitMix) {
    for i in (1..items.len()).rev() {
        items.swap(i, rng.below(i + 1));
    }
}

#[cfg(test)]
mod tests {
    use std::collections::HashSet;

    use super::*;
    use crate::site::SiteArgs;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        site: SiteArgs,
    }

    fn args(extra: &[&str]) -> SiteArgs {
        Cli::parse_from(["site"].iter().chain(extra)).site
    }

    #[test]
    fn each_job_names_its_own_place_and_each_is_posted_once() {
        let args = args(&["--jobs", "40", "--bays", "20", "--levels", "6"]);
        let w = Workload::draw(&args, 10, &Motion::default());
        assert_eq!((w.jobs.len(), w.stations.len()), (400, 1));
        for aisle in 1..=10u16 {
            let stock: HashSet<[u16; 4]> = w.stock[usize::from(aisle) - 1].iter().map(|(c, _)| *c).collect();
            let mut named = HashSet::new();
            for job in w.jobs.iter().filter(|j| j.aisle == aisle) {
                let (cell, full) = match job.kind {
                    Kind::Retrieve(cell) => (cell, true),
                    Kind::Store(cell) => (cell, false),
                };
                assert_eq!(stock.contains(&cell), full, "a retrieve takes stock, a store an empty place");
                assert!(named.insert(cell), "{cell:?} named twice in aisle {aisle}");
            }
        }
        let mut posted = vec![0; w.jobs.len()];
        for post in &w.posts {
            match *post {
                Post::Job(j) => posted[j] += 1,
                Post::Sequence(s) => w.sequences[s].members.iter().for_each(|&j| posted[j] += 1),
            }
        }
        assert!(posted.iter().all(|&n| n == 1));
    }

    #[test]
    fn sequences_are_retrieves_over_several_aisles_and_deadlines_fall_outside_them() {
        let w = Workload::draw(&args(&[]), 10, &Motion::default());
        let (deadlines, tight, members) = w.counts();
        assert!(members > 50 && deadlines > 50 && tight > 5, "{members} {deadlines} {tight}");
        let mut spread = 0;
        for s in &w.sequences {
            let aisles: HashSet<u16> = s.members.iter().map(|&j| w.jobs[j].aisle).collect();
            assert!((2..=7).contains(&s.members.len()), "{s:?}");
            spread += usize::from(aisles.len() > 1);
            for (k, &j) in s.members.iter().enumerate() {
                let job = &w.jobs[j];
                assert!(matches!(job.kind, Kind::Retrieve(_)) && job.deadline.is_none());
                assert_eq!(job.member.map(|m| m.position), Some(k as u32 + 1));
            }
        }
        assert!(
            spread * 10 >= w.sequences.len() * 8,
            "{spread} of {} over several aisles",
            w.sequences.len()
        );
        let cycle = w.mean_cycle();
        for job in w.jobs.iter().filter(|j| j.deadline.is_some()) {
            let d = job.deadline.unwrap();
            let beside = d.allowance - job.leg.own_secs;
            let want = if d.tight { TIGHT_CYCLES * cycle } else { 40.0 * cycle };
            assert!((beside - want).abs() < 1e-9);
        }
    }

    #[test]
    fn the_transit_grows_with_the_distance_along_the_front() {
        let w = Workload::draw(&args(&["--jobs", "4"]), 40, &Motion::default());
        assert_eq!(w.stations.len(), 4);
        let s = &w.stations[0];
        let near = (1..=40).min_by(|&a, &b| s.transit(a).total_cmp(&s.transit(b))).unwrap();
        assert!(near <= 10 && s.transit(40) > s.transit(20), "station 1 sits by the first ten aisles");
        assert!((s.transit(near + 1) - s.transit(near)).abs() <= AISLE_PITCH_M / CONVEYOR_M_S + 1e-9);
    }
}
