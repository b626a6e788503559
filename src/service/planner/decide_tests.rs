//! The planner's decisions on made-up racks and queues.

use std::collections::BTreeSet;

use super::decide::{Decision, Memory, Plan, Verdict, check, decide};
use super::rack::{Cell, Rack};
use crate::config::devices::{Planner, Station};
use crate::domain::time::from_ms;
use crate::domain::{Job, JobSpec, Location, NewJob, Priority};
use crate::wire::motion::{Motion, Spot};

fn at(bay: u16, level: u16, position: u16) -> Location {
    Location { aisle: 2, row: 1, bay, level, position }
}

fn job(id: i64, priority: u8, spec: JobSpec) -> Job {
    let new = NewJob {
        spec,
        reference: None,
        priority: Priority::try_from(priority as i64).unwrap(),
        barcode: None,
        device: Some("crane1".into()),
        serves: None,
        terms: Default::default(),
    };
    new.accepted(id, 0)
}

/// Bays 1..=20, levels 1..=4, both depths, `full` holding boxes; aisle 2 double-deep.
fn rack(full: &[Location]) -> Rack {
    let mut cells = Vec::new();
    for bay in 1..=20 {
        for level in 1..=4 {
            for position in 1..=2 {
                let l = at(bay, level, position);
                cells.push((l, Cell { occupied: full.contains(&l), ..Cell::default() }));
            }
        }
    }
    Rack::from_cells(cells, &BTreeSet::from([2]))
}

fn plan(strategy: Planner) -> Plan {
    Plan {
        strategy,
        motion: Motion::default(),
        inbound: Station { row: 2, bay: 0, level: 1, side: 1 },
        outbound: Station { row: 1, bay: 0, level: 1, side: 1 },
        max_overtaken: 3,
        deadline_margin_s: 30,
    }
}

/// When the tests decide (Unix ms).
const NOW: i64 = 1_800_000_000_000;

fn run(plan: &Plan, memory: &mut Memory, jobs: &[Job], rack: &Rack) -> Decision {
    let all: Vec<&Job> = jobs.iter().collect();
    decide(plan, memory, &all, &all, rack, NOW)
}

/// `job`, due `secs` seconds after [`NOW`].
fn due(mut job: Job, secs: i64) -> Job {
    job.deadline = Some(from_ms(NOW + secs * 1000));
    job
}

#[test]
fn a_retrieve_behind_a_box_gets_a_relocation_first() {
    let r = rack(&[at(5, 2, 1), at(5, 2, 2)]);
    let jobs = [job(1, 10, JobSpec::Retrieve { from: at(5, 2, 2) })];
    let decision = run(&plan(Planner::Fifo), &mut Memory::default(), &jobs, &r);
    let Decision::Relocate { serves, from, to } = decision else { panic!("{decision:?}") };
    assert_eq!((serves, from), (1, at(5, 2, 1)));
    assert!(!r.occupied(to) && to != at(5, 2, 2), "to a free place: {to:?}");
    assert_eq!(to.position, 2, "far first: {to:?}");
    assert!(to.bay.abs_diff(5) <= 1, "near the box it moves: {to:?}");
}

#[test]
fn a_retrieve_behind_a_box_that_leaves_anyway_waits() {
    let r = rack(&[at(5, 2, 1), at(5, 2, 2)]);
    let far = job(2, 0, JobSpec::Retrieve { from: at(5, 2, 2) });
    let near = job(3, 10, JobSpec::Retrieve { from: at(5, 2, 1) });
    assert_eq!(check(&far, &r, &[&far, &near]), Verdict::Behind(3));
    let decision = run(&plan(Planner::Travel), &mut Memory::default(), &[far, near], &r);
    assert_eq!(decision, Decision::Run(3), "the near box goes first, though the far job has priority 0");
}

#[test]
fn a_put_near_waits_for_the_job_that_fills_or_picks_the_far_place() {
    let r = rack(&[at(8, 3, 2)]);
    let store = job(1, 0, JobSpec::Store { to: at(8, 3, 1) });
    // The far box is wanted by a younger retrieve of lower priority: the store, though
    // older and of priority 0, waits, and the retrieve runs first under either planner.
    let retrieve = job(2, 10, JobSpec::Retrieve { from: at(8, 3, 2) });
    assert_eq!(check(&store, &r, &[&store, &retrieve]), Verdict::Behind(2));
    for planner in [Planner::Fifo, Planner::Travel] {
        let jobs = [store.clone(), retrieve.clone()];
        assert_eq!(run(&plan(planner), &mut Memory::default(), &jobs, &r), Decision::Run(2), "{planner:?}");
    }
    // Once the far box is gone the store goes: the wait ends with the job it waits for.
    assert_eq!(check(&store, &rack(&[]), &[&store]), Verdict::Go);
    // A move out of the far place counts as a pick; a store into it as a fill.
    let out = job(3, 10, JobSpec::Move { from: at(8, 3, 2), to: at(12, 1, 2) });
    assert_eq!(check(&store, &r, &[&store, &out]), Verdict::Behind(3));
    let fill = job(4, 10, JobSpec::Store { to: at(8, 3, 2) });
    assert_eq!(check(&store, &rack(&[]), &[&store, &fill]), Verdict::Behind(4));
    // A job elsewhere does not hold it, and a single-deep aisle has no such rule.
    let elsewhere = job(5, 10, JobSpec::Retrieve { from: at(9, 3, 2) });
    assert_eq!(check(&store, &r, &[&store, &elsewhere]), Verdict::Go);
    let shallow = Rack::from_cells(r.locations(), &BTreeSet::new());
    assert_eq!(check(&store, &shallow, &[&store, &retrieve]), Verdict::Go);
}

#[test]
fn stores_far_behind_a_box_relocate_and_puts_into_a_box_are_refused() {
    let r = rack(&[at(6, 1, 1), at(7, 1, 1)]);
    let far = job(1, 10, JobSpec::Store { to: at(6, 1, 2) });
    assert_eq!(check(&far, &r, &[&far]), Verdict::Relocate(at(6, 1, 1)));
    let into_box = job(2, 10, JobSpec::Store { to: at(7, 1, 1) });
    let decision = run(&plan(Planner::Travel), &mut Memory::default(), &[into_box], &r);
    assert!(matches!(decision, Decision::Refuse { job: 2, .. }), "{decision:?}");
    let shallow = Rack::from_cells(r.locations(), &BTreeSet::new());
    assert_eq!(check(&far, &shallow, &[&far]), Verdict::Go, "single-deep aisles have no rules");
    let swap = job(3, 10, JobSpec::Move { from: at(6, 1, 1), to: at(6, 1, 2) });
    assert_eq!(check(&swap, &r, &[&swap]), Verdict::Go, "a move out of the near box clears its own way");
}

#[test]
fn travel_takes_the_nearest_pick_and_fifo_the_oldest() {
    let r = rack(&[at(18, 1, 1), at(3, 1, 1)]);
    let jobs = [
        job(1, 10, JobSpec::Retrieve { from: at(18, 1, 1) }),
        job(2, 10, JobSpec::Retrieve { from: at(3, 1, 1) }),
    ];
    let mut memory = Memory { at: Some(Spot { bay: 4, level: 1 }), ..Memory::default() };
    assert_eq!(run(&plan(Planner::Travel), &mut memory, &jobs, &r), Decision::Run(2));
    assert_eq!(memory.at, Some(Spot { bay: 0, level: 1 }), "a retrieve ends at the station");
    assert_eq!(memory.overtaken.get(&1), Some(&1));
    let mut memory = Memory { at: Some(Spot { bay: 4, level: 1 }), ..Memory::default() };
    assert_eq!(run(&plan(Planner::Fifo), &mut memory, &jobs, &r), Decision::Run(1));
}

#[test]
fn after_a_retrieve_a_store_after_a_store_the_nearest_retrieve() {
    let r = rack(&[at(15, 1, 1)]);
    let jobs = [
        job(1, 10, JobSpec::Retrieve { from: at(15, 1, 1) }),
        job(2, 10, JobSpec::Store { to: at(14, 1, 2) }),
    ];
    let mut memory = Memory { at: Some(Spot { bay: 0, level: 1 }), ..Memory::default() };
    let p = plan(Planner::Travel);
    assert_eq!(run(&p, &mut memory, &jobs, &r), Decision::Run(2), "at the station: the store");
    assert_eq!(run(&p, &mut memory, &jobs[..1], &r), Decision::Run(1));
}

#[test]
fn priority_zero_still_goes_first() {
    let r = rack(&[at(20, 4, 1), at(1, 1, 1)]);
    let jobs = [
        job(1, 10, JobSpec::Retrieve { from: at(1, 1, 1) }),
        job(2, 0, JobSpec::Retrieve { from: at(20, 4, 1) }),
    ];
    let mut memory = Memory { at: Some(Spot { bay: 1, level: 1 }), ..Memory::default() };
    assert_eq!(run(&plan(Planner::Travel), &mut memory, &jobs, &r), Decision::Run(2));
}

#[test]
fn nothing_starves_under_the_travel_planner() {
    // A far retrieve among a stream of near ones, each new one nearer than it: it still
    // goes within max_overtaken (3) decisions.
    let full: Vec<Location> = (1..=10).map(|b| at(b, 1, 1)).chain([at(20, 4, 1)]).collect();
    let r = rack(&full);
    let p = plan(Planner::Travel);
    let mut memory = Memory { at: Some(Spot { bay: 0, level: 1 }), ..Memory::default() };
    let mut queue = vec![job(1, 10, JobSpec::Retrieve { from: at(20, 4, 1) })];
    let mut ran = Vec::new();
    for id in 2..=10 {
        queue.push(job(id, 10, JobSpec::Retrieve { from: at(id as u16, 1, 1) }));
        let Decision::Run(chosen) = run(&p, &mut memory, &queue, &r) else { panic!() };
        queue.retain(|j| j.id != chosen);
        ran.push(chosen);
    }
    let turn = ran.iter().position(|&id| id == 1).expect("the far job ran");
    assert!(turn <= 3, "it ran as decision {turn}: {ran:?}");
}

#[test]
fn a_starved_retrieve_goes_behind_the_store_that_leads_to_it() {
    // At the station, retrieve 1 (bay 20) is starved; store 3 puts at bay 19: the store
    // goes first (a dual cycle, not an empty run to bay 20), then retrieve 1, before the
    // nearer retrieve 2.
    let r = rack(&[at(20, 4, 1), at(2, 1, 1)]);
    let p = plan(Planner::Travel);
    let jobs = [
        job(1, 10, JobSpec::Retrieve { from: at(20, 4, 1) }),
        job(2, 10, JobSpec::Retrieve { from: at(2, 1, 1) }),
        job(3, 10, JobSpec::Store { to: at(19, 4, 2) }),
    ];
    let overtaken = [(1, 3)].into_iter().collect();
    let mut memory = Memory { at: Some(Spot { bay: 0, level: 1 }), overtaken, ..Memory::default() };
    assert_eq!(run(&p, &mut memory, &jobs, &r), Decision::Run(3));
    assert_eq!(memory.due, Some(1));
    assert_eq!(run(&p, &mut memory, &jobs[..2], &r), Decision::Run(1));
    assert_eq!(memory.due, None);
    // Without a job that leads nearer, the starved one goes at once.
    let mut memory = Memory { at: Some(Spot { bay: 0, level: 1 }), ..Memory::default() };
    memory.overtaken.insert(1, 3);
    assert_eq!(run(&p, &mut memory, &jobs[..2], &r), Decision::Run(1));
}

#[test]
fn a_store_left_to_rackd_gets_the_nearest_far_place_in_its_zones() {
    use crate::domain::{Class, Zone};
    let r = rack(&[at(1, 1, 2)]);
    let p = plan(Planner::Travel);
    let anywhere = job(1, 10, JobSpec::Putaway { zones: vec![Zone::aisle(2)], class: None });
    let mut memory = Memory::default();
    let decision = run(&p, &mut memory, std::slice::from_ref(&anywhere), &r);
    // Bay 1 level 1 far holds a box: its near is the nearest place (far ones go first only
    // within one bay and level).
    assert_eq!(decision, Decision::Place { job: 1, to: at(1, 1, 1) });
    assert_eq!(memory.at, Some(Spot { bay: 1, level: 1 }));
    let empty = rack(&[]);
    let decision = run(&p, &mut Memory::default(), std::slice::from_ref(&anywhere), &empty);
    assert_eq!(decision, Decision::Place { job: 1, to: at(1, 1, 2) }, "far before near");
    let high =
        job(2, 10, JobSpec::Putaway { zones: vec![Zone { level: Some(4), ..Zone::aisle(2) }], class: None });
    assert_eq!(run(&p, &mut Memory::default(), &[high], &r), Decision::Place { job: 2, to: at(1, 4, 2) });
    let slow = job(3, 10, JobSpec::Putaway { zones: vec![Zone::aisle(2)], class: Some(Class::C) });
    let Decision::Place { to, .. } = run(&p, &mut Memory::default(), &[slow], &r) else { panic!() };
    assert!(to.bay >= 10, "class C goes to the far third: {to:?}");
    let full: Vec<Location> = (1..=4).flat_map(|level| [at(3, level, 1), at(3, level, 2)]).collect();
    let nowhere =
        job(4, 10, JobSpec::Putaway { zones: vec![Zone { bay: Some(3), ..Zone::aisle(2) }], class: None });
    assert_eq!(
        run(&p, &mut Memory::default(), &[nowhere], &rack(&full)),
        Decision::Wait,
        "a full zone waits"
    );
}

#[test]
fn the_job_a_relocation_serves_goes_right_after_it() {
    // Retrieve 2 (far, bay 5) needs a relocation; choosing it passes over retrieve 1 (bay 20,
    // level 4) once more, and that makes 1 starved. 2 still goes next, from beside its
    // location, and 1 right after: not a run across the aisle and back.
    let (near, far) = (at(5, 1, 1), at(5, 1, 2));
    let p = plan(Planner::Travel);
    let jobs =
        [job(1, 10, JobSpec::Retrieve { from: at(20, 4, 1) }), job(2, 10, JobSpec::Retrieve { from: far })];
    let overtaken = [(1, p.max_overtaken - 1)].into_iter().collect();
    let mut memory = Memory { at: Some(Spot { bay: 5, level: 1 }), overtaken, ..Memory::default() };
    let decision = run(&p, &mut memory, &jobs, &rack(&[at(20, 4, 1), near, far]));
    let Decision::Relocate { serves: 2, from, to } = decision else { panic!("{decision:?}") };
    assert_eq!(from, near);
    assert_eq!(memory.overtaken.get(&1), Some(&p.max_overtaken), "1 is starved now");
    let moved = rack(&[at(20, 4, 1), to, far]);
    assert_eq!(run(&p, &mut memory, &jobs, &moved), Decision::Run(2), "the served job first");
    assert_eq!(run(&p, &mut memory, &jobs[..1], &moved), Decision::Run(1), "then the starved one");
}

#[test]
fn a_relocation_weighs_its_empty_runs_not_its_fork_cycles() {
    // Retrieve 1 is seven bays away; retrieve 2 is a level above the crane but behind a box.
    // The relocation's fork cycles are spent whenever it runs, so only the runs count: to
    // the box in the way, and from where it goes back to the far box. Here they are shorter.
    let (near, far, other) = (at(5, 2, 1), at(5, 2, 2), at(12, 1, 1));
    let p = plan(Planner::Travel);
    let jobs = [job(1, 10, JobSpec::Retrieve { from: other }), job(2, 10, JobSpec::Retrieve { from: far })];
    let from = Spot { bay: 5, level: 1 };
    let mut memory = Memory { at: Some(from), ..Memory::default() };
    let decision = run(&p, &mut memory, &jobs, &rack(&[other, near, far]));
    let Decision::Relocate { serves: 2, from: moved, to } = decision else { panic!("{decision:?}") };
    assert_eq!(moved, near);
    assert!(to.bay.abs_diff(5) + to.level.abs_diff(2) == 1, "the box goes next door: {to}");
    // With the only free places at the far end of the aisle, the run back from there
    // outweighs the nearer pick: retrieve 1 goes first.
    let full: Vec<Location> = (1..=19)
        .flat_map(|bay| (1..=4).flat_map(move |level| [at(bay, level, 1), at(bay, level, 2)]))
        .collect();
    let mut memory = Memory { at: Some(from), ..Memory::default() };
    assert_eq!(run(&p, &mut memory, &jobs, &rack(&full)), Decision::Run(1));
}

/// Retrieve 1 (bay 3) is the travel choice of a crane at bay 2; retrieve 2 (bay 20, level 4)
/// would end about 42 s from now if it went first, 64 s if it went after retrieve 1 (the
/// motion model's defaults).
fn near_and_far(far_due_s: i64) -> (Rack, [Job; 2], Memory) {
    let r = rack(&[at(3, 1, 1), at(20, 4, 1)]);
    let jobs = [
        job(1, 10, JobSpec::Retrieve { from: at(3, 1, 1) }),
        due(job(2, 10, JobSpec::Retrieve { from: at(20, 4, 1) }), far_due_s),
    ];
    (r, jobs, Memory { at: Some(Spot { bay: 2, level: 1 }), ..Memory::default() })
}

#[test]
fn a_far_job_whose_deadline_is_at_risk_goes_before_a_near_one() {
    let p = plan(Planner::Travel);
    // Due in 85 s, less the 30 s margin: 55 s, and after retrieve 1 it would end at 64 s.
    let (r, jobs, mut memory) = near_and_far(85);
    assert_eq!(run(&p, &mut memory, &jobs, &r), Decision::Run(2));
    assert_eq!(memory.at, Some(Spot { bay: 0, level: 1 }));
    // Due in 120 s it has slack, and costs no travel: the near job goes first.
    let (r, jobs, mut memory) = near_and_far(120);
    assert_eq!(run(&p, &mut memory, &jobs, &r), Decision::Run(1));
}

#[test]
fn the_deadline_margin_is_honoured() {
    // Retrieve 2 due in 85 s would end at 64 s after retrieve 1: at risk only when the
    // margin is more than 21 s.
    for (margin, first) in [(0, 1), (15, 1), (25, 2), (30, 2)] {
        let p = Plan { deadline_margin_s: margin, ..plan(Planner::Travel) };
        let (r, jobs, mut memory) = near_and_far(85);
        assert_eq!(run(&p, &mut memory, &jobs, &r), Decision::Run(first), "margin {margin} s");
    }
}

#[test]
fn slack_deadlines_leave_the_travel_decisions_as_they_were() {
    // A stream of stores and retrieves (near positions, so the rack never holds one back),
    // decided to the end twice: without deadlines, and with deadlines a day away in the
    // opposite of the jobs' order. Every decision and what the planner remembers match.
    let mut seed = 7_u32;
    let mut draw = |n: u32| {
        seed = seed.wrapping_mul(1_103_515_245).wrapping_add(12_345);
        (seed >> 16) % n
    };
    let mut places: Vec<(u16, u16)> = (1..=20).flat_map(|b| (1..=4).map(move |l| (b, l))).collect();
    let mut full = Vec::new();
    let mut specs = Vec::new();
    for i in 0..30 {
        let (bay, level) = places.swap_remove(draw(places.len() as u32) as usize);
        let l = at(bay, level, 1);
        if i % 3 == 0 {
            specs.push(JobSpec::Store { to: l });
        } else {
            full.push(l);
            specs.push(JobSpec::Retrieve { from: l });
        }
    }
    let r = rack(&full);
    let p = plan(Planner::Travel);
    let decisions = |deadlines: bool| {
        let mut memory = Memory { at: Some(Spot { bay: 0, level: 1 }), ..Memory::default() };
        let (mut queue, mut seen) = (Vec::new(), Vec::new());
        let mut arrivals = (1..).zip(&specs);
        loop {
            // A queue of eight, topped up after each decision, then drained.
            while queue.len() < 8
                && let Some((id, spec)) = arrivals.next()
            {
                let new = job(id, 10, spec.clone());
                queue.push(if deadlines { due(new, 86_400 - id) } else { new });
            }
            if queue.is_empty() {
                return seen;
            }
            let Decision::Run(chosen) = run(&p, &mut memory, &queue, &r) else { panic!() };
            queue.retain(|j| j.id != chosen);
            let mut overtaken: Vec<(i64, u32)> = memory.overtaken.clone().into_iter().collect();
            overtaken.sort();
            seen.push((chosen, memory.at, memory.due, overtaken));
        }
    };
    let plain = decisions(false);
    assert_eq!(plain.len(), specs.len());
    assert_eq!(decisions(true), plain);
}

#[test]
fn jobs_at_risk_go_in_deadline_order() {
    // None of them can make it; the one already late goes first, then the others by
    // deadline, then the nearest job, which has none.
    let r = rack(&[at(3, 1, 1), at(10, 1, 1), at(14, 2, 1), at(18, 3, 1), at(20, 4, 1)]);
    let mut queue = vec![
        job(1, 10, JobSpec::Retrieve { from: at(3, 1, 1) }),
        due(job(2, 10, JobSpec::Retrieve { from: at(18, 3, 1) }), 60),
        due(job(3, 10, JobSpec::Retrieve { from: at(10, 1, 1) }), 40),
        due(job(4, 10, JobSpec::Retrieve { from: at(14, 2, 1) }), 50),
        due(job(5, 10, JobSpec::Retrieve { from: at(20, 4, 1) }), -10),
    ];
    let p = plan(Planner::Travel);
    let mut memory = Memory { at: Some(Spot { bay: 2, level: 1 }), ..Memory::default() };
    let mut ran = Vec::new();
    while !queue.is_empty() {
        let Decision::Run(chosen) = run(&p, &mut memory, &queue, &r) else { panic!() };
        queue.retain(|j| j.id != chosen);
        ran.push(chosen);
    }
    assert_eq!(ran, [5, 3, 4, 2, 1]);
}

#[test]
fn priority_outranks_a_deadline() {
    // Retrieve 2 is late, and nearer, but retrieve 1 has the better priority.
    let r = rack(&[at(18, 1, 1), at(2, 1, 1)]);
    let jobs = [
        job(1, 5, JobSpec::Retrieve { from: at(18, 1, 1) }),
        due(job(2, 10, JobSpec::Retrieve { from: at(2, 1, 1) }), -60),
    ];
    let mut memory = Memory { at: Some(Spot { bay: 2, level: 1 }), ..Memory::default() };
    assert_eq!(run(&plan(Planner::Travel), &mut memory, &jobs, &r), Decision::Run(1));
}

#[test]
fn a_deadline_at_risk_outranks_a_starved_job_but_not_fifo() {
    // Retrieve 1 is starved. Retrieve 2, due in 80 s less 30, ends 27 s from now if it goes
    // first, 70 s after retrieve 1: it goes first.
    let r = rack(&[at(20, 4, 1), at(5, 1, 1), at(2, 1, 1)]);
    let jobs = [
        job(1, 10, JobSpec::Retrieve { from: at(20, 4, 1) }),
        due(job(2, 10, JobSpec::Retrieve { from: at(5, 1, 1) }), 80),
        job(3, 10, JobSpec::Retrieve { from: at(2, 1, 1) }),
    ];
    let start = || {
        let overtaken = [(1, 3)].into_iter().collect();
        Memory { at: Some(Spot { bay: 0, level: 1 }), overtaken, ..Memory::default() }
    };
    let mut memory = start();
    assert_eq!(run(&plan(Planner::Travel), &mut memory, &jobs, &r), Decision::Run(2));
    assert_eq!(memory.due, None);
    // Due in 120 s it has slack: the starved job goes. Fifo weighs no deadline: the oldest.
    let mut slack = jobs.clone();
    slack[1] = due(slack[1].clone(), 120);
    assert_eq!(run(&plan(Planner::Travel), &mut start(), &slack, &r), Decision::Run(1));
    assert_eq!(run(&plan(Planner::Fifo), &mut start(), &jobs, &r), Decision::Run(1));
}
