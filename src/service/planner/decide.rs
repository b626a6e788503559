//! The crane planner's decision, pure: of the jobs the dispatcher's order rules allow now,
//! which one the idle crane runs next, or what must happen first.
//!
//! Each candidate is checked against the rack first ([`check`]):
//! - a task whose far location has a box in front of it (pick far, or put far, with near
//!   occupied) waits while another unfinished job will take that box away, and otherwise
//!   needs a relocation: a `move` of the near box to a place [`putaway::choose`] picks;
//! - a put into a location that holds a box, or a pick from one that holds none (double-deep
//!   aisles, where rackd keeps the rack's contents), is never sent: the job fails with the
//!   reason, nothing sent (the crane would raise 7091/7095 or 7069/7070);
//! - a put near in front of a far location another unfinished job will fill, or pick from,
//!   waits for that job (putting near first would wall the far location in, and the box
//!   put would then have to be relocated for it);
//! - everything else can go.
//!
//! Then one is chosen. `fifo` takes the first in the order rules' order (priority, then
//! age). `travel` keeps priorities (only jobs of the best priority present compete, so a
//! priority 0 job still goes first) and among them takes the one with the least empty
//! travel: the run from where the crane stands to the job's pick (for a job that needs a
//! relocation first: to the box in the way, plus the run from where that box goes back to
//! the job's own pick; the relocation's fork cycles are spent whenever it runs, so they do
//! not weigh against it), plus, for a job that ends in the rack (a store), the run from its
//! end to the nearest pick the other open jobs need.
//! That second term makes dual command cycles: after a retrieve (the crane at the station)
//! a store whose put lies near a waiting retrieve, then that retrieve. Ties go to the older
//! job. A job passed over `max_overtaken` times by younger ones of its priority goes next,
//! so nothing starves: at once, or one job later when one job brings the crane nearer to it
//! than it stands (a store whose put lies near a starved retrieve makes a dual cycle of it
//! instead of an empty run; [`Memory::due`] holds it for the next decision). The job a
//! relocation serves is held the same way: it goes right after the relocation (unless a job
//! of a better priority came meanwhile), from beside its location, and not after a job far
//! away that the relocation's own turn left starved.
//!
//! Deadlines weigh in `travel` only (`fifo` stays priority, then age), within the best
//! priority: a priority never yields to a deadline. The choice above (at priority 0: the
//! oldest) stands if, once it has run, every candidate of the group with a deadline still
//! ends by its deadline less `deadline_margin_s`, run in earliest-deadline order, each
//! taking its estimated crane seconds (`Travel::estimate`: the motion model's empty run
//! from where the crane will stand, a relocation it needs, its own loaded run and fork
//! cycles). Otherwise the candidate with the earliest deadline goes: a deadline at risk
//! outranks a starved job and the job held for the next decision (which then competes
//! again), since aging only bounds how long travel may pass a job over, and a deadline says
//! how long it may take. A job with slack costs no travel: when no deadline is at risk the
//! decision is the one above, memory and all. A job already late is always at risk, so the
//! group runs in deadline order until none is; jobs without a deadline wait meanwhile.
//! The estimate leaves out what the motion model does not know: the hand-over and the
//! acknowledgement (STB/ACK, the polls between), a station slow to clear, relocations a
//! later job will need, jobs that are not candidates now (behind another, a sequence member
//! not yet due, a worse priority) and jobs yet to come. The margin is there for those.

use std::collections::{HashMap, HashSet};

use super::putaway::{self, Want, spot};
use super::rack::Rack;
use super::refusal::picks_from;
use crate::config::devices::{Planner, Station};
use crate::domain::time::to_ms;
use crate::domain::{Class, Job, JobSpec, Location, Zone};
use crate::wire::motion::{Motion, Spot};

/// A crane's planning settings.
#[derive(Clone, Debug)]
pub struct Plan {
    /// How the next job is picked.
    pub strategy: Planner,
    /// The crane's motion, to weigh travel.
    pub motion: Motion,
    /// Where a store picks.
    pub inbound: Station,
    /// Where a retrieve puts.
    pub outbound: Station,
    /// Times a job may be passed over by younger ones before it goes next.
    pub max_overtaken: u32,
    /// Seconds before its deadline by which the travel planner wants a job ended.
    pub deadline_margin_s: u32,
}

/// What the planner remembers between decisions.
#[derive(Clone, Debug, Default)]
pub struct Memory {
    /// Where the crane stands once its last task ends.
    pub at: Option<Spot>,
    /// Times each queued job was passed over by a younger one of its priority.
    pub overtaken: HashMap<i64, u32>,
    /// Why the last decision left each of these jobs waiting.
    pub waits: HashMap<i64, Wait>,
    /// A job that goes at the next decision (travel planner): a starved one, after the job
    /// that brings the crane nearest to it; or the one the last decision's relocation serves.
    pub due: Option<i64>,
}

/// Why the planner left a job waiting.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wait {
    /// Another unfinished job takes the box in front of it, or fills a far place behind
    /// the near one it puts into, first.
    Behind(i64),
    /// No free location: for a store left to rackd in its zones, or for the box a
    /// relocation would move.
    NoPlace,
}

/// What the crane should do next.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Decision {
    /// Hand this job over.
    Run(i64),
    /// First move the box at `from` (near) to `to`, for job `serves`.
    Relocate {
        /// The job the relocation clears the way for.
        serves: i64,
        /// The blocking near location.
        from: Location,
        /// Where its box goes.
        to: Location,
    },
    /// Give this store left to rackd the location chosen for it, then hand it over.
    Place {
        /// The job.
        job: i64,
        /// Where its box goes.
        to: Location,
    },
    /// Fail this job without sending it: the rack makes it impossible.
    Refuse {
        /// The job.
        job: i64,
        /// Why, for the job's failure.
        text: String,
    },
    /// Nothing can start now.
    Wait,
}

/// What the rack allows a job.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// It can be sent.
    Go,
    /// The box at this near location must go first, and no job will take it: relocate it.
    Relocate(Location),
    /// The box at the near location goes with this unfinished job first.
    Behind(i64),
    /// It can never run as asked.
    Impossible(String),
}

/// What the rack allows `job` now, given every unfinished job of the crane.
pub fn check(job: &Job, rack: &Rack, unfinished: &[&Job]) -> Verdict {
    let Some(spec) = job.spec() else { return Verdict::Go };
    let (pick, put) = ends(&spec);
    if let Some(p) = pick.filter(|p| rack.is_deep(p.aisle) && p.bay != 0 && !rack.occupied(*p)) {
        return Verdict::Impossible(format!("location {p} holds no box: rackd does not send a pick from it"));
    }
    if let Some(near) = pick.and_then(|p| rack.blocker(p)) {
        return behind_or_relocate(job.id, near, unfinished);
    }
    // The put sees the rack after the pick: a box picked is no longer in the way.
    let holds = |l: Location| Some(l) != pick && rack.occupied(l);
    if let Some(q) = put.filter(|q| rack.is_deep(q.aisle) && q.bay != 0) {
        if holds(q) {
            let text = format!("location {q} holds a box: rackd does not send a put into it");
            return Verdict::Impossible(text);
        }
        let near = Rack::near_of(q);
        if rack.is_far(q) && holds(near) {
            return behind_or_relocate(job.id, near, unfinished);
        }
        let far = Rack::far_of(q);
        // A put near waits for the job that fills the far location behind it, or that
        // picks the box there: a box put in front first would wall either in.
        if !rack.is_far(q)
            && let Some(other) = unfinished.iter().find(|j| j.id != job.id && fills_or_empties(j, far))
        {
            return Verdict::Behind(other.id);
        }
    }
    Verdict::Go
}

fn behind_or_relocate(id: i64, near: Location, unfinished: &[&Job]) -> Verdict {
    let taker = unfinished.iter().find(|j| j.id != id && j.spec().is_some_and(|s| picks_from(&s, near)));
    match taker {
        Some(j) => Verdict::Behind(j.id),
        None => Verdict::Relocate(near),
    }
}

/// Whether `job` puts a box into `l` or picks the box there.
fn fills_or_empties(job: &Job, l: Location) -> bool {
    job.spec().is_some_and(|s| {
        picks_from(&s, l) || matches!(s, JobSpec::Store { to } | JobSpec::Move { to, .. } if to == l)
    })
}

/// Where a job picks and where it puts, when it does (a station is neither stock nor
/// blocked).
fn ends(spec: &JobSpec) -> (Option<Location>, Option<Location>) {
    match *spec {
        JobSpec::Store { to } => (None, Some(to)),
        JobSpec::Retrieve { from } => (Some(from), None),
        JobSpec::Move { from, to } => (Some(from), Some(to)),
        _ => (None, None),
    }
}

/// Chooses among `candidates` (the order rules' eligible jobs, best first) for the idle
/// crane; `unfinished` is every job of the crane not ended; `memory` is updated; `now_ms`
/// is the time (Unix ms) deadlines are weighed against, passed in so that the decision
/// stays pure.
pub fn decide(
    plan: &Plan,
    memory: &mut Memory,
    candidates: &[&Job],
    unfinished: &[&Job],
    rack: &Rack,
    now_ms: i64,
) -> Decision {
    let mut open: Vec<Candidate> = Vec::new();
    memory.waits.clear();
    for job in candidates {
        match check(job, rack, unfinished) {
            Verdict::Go => open.push((job, None)),
            Verdict::Relocate(near) => open.push((job, Some(near))),
            Verdict::Behind(id) => drop(memory.waits.insert(job.id, Wait::Behind(id))),
            Verdict::Impossible(text) => return Decision::Refuse { job: job.id, text },
        }
    }
    let busy: HashSet<Location> =
        unfinished.iter().filter_map(|j| j.spec()).flat_map(|s| s.locations()).collect();
    // Where each box rackd places goes: a store left to rackd, the near box of a job that
    // needs a relocation. A job with no such place waits.
    let places: HashMap<i64, Location> = open
        .iter()
        .filter_map(|(job, near)| match (near, job.spec()) {
            (Some(near), _) => Some((job.id, target(plan, rack, &busy, job, *near)?)),
            (None, Some(JobSpec::Putaway { zones, class })) => {
                Some((job.id, place(plan, rack, &busy, &zones, class)?))
            }
            _ => None,
        })
        .collect();
    open.retain(|(job, near)| {
        let placed = places.contains_key(&job.id)
            || (near.is_none() && !matches!(job.spec(), Some(JobSpec::Putaway { .. })));
        if !placed {
            memory.waits.insert(job.id, Wait::NoPlace);
        }
        placed
    });
    let Some(&(job, near)) = pick(plan, memory, &open, &places, now_ms) else { return Decision::Wait };
    if memory.due == Some(job.id) {
        memory.due = None;
    }
    let live: HashSet<i64> = unfinished.iter().map(|j| j.id).collect();
    memory.overtaken.retain(|id, _| live.contains(id));
    for (other, _) in &open {
        if other.id < job.id && other.priority == job.priority {
            *memory.overtaken.entry(other.id).or_default() += 1;
        }
    }
    memory.overtaken.remove(&job.id);
    match near {
        None if places.contains_key(&job.id) => {
            let to = places[&job.id];
            memory.at = Some(spot(to));
            Decision::Place { job: job.id, to }
        }
        None => {
            memory.at = job.spec().map(|s| end_spot(plan, &s));
            Decision::Run(job.id)
        }
        Some(from) => {
            let to = places[&job.id];
            memory.at = Some(spot(to));
            // The job it serves goes next, from beside its location, before any job the
            // relocation's own turn left starved.
            memory.due = Some(job.id);
            Decision::Relocate { serves: job.id, from, to }
        }
    }
}

/// A candidate: the job, and the near box to relocate first, if any.
type Candidate<'a> = (&'a Job, Option<Location>);

fn pick<'a>(
    plan: &Plan,
    memory: &mut Memory,
    open: &'a [Candidate<'a>],
    places: &HashMap<i64, Location>,
    now_ms: i64,
) -> Option<&'a Candidate<'a>> {
    let best = open.iter().map(|(j, _)| j.priority).min()?;
    let group: Vec<&Candidate> = open.iter().filter(|(j, _)| j.priority == best).collect();
    let oldest = group.iter().copied().min_by_key(|(j, _)| j.id)?;
    if plan.strategy == Planner::Fifo {
        return Some(oldest);
    }
    let from = memory.at.unwrap_or(station_spot(plan.outbound));
    let travel = Travel { plan, places, from };
    // Priority 0 goes by age and leaves a job due for later, as it always did.
    let (choice, due) = if best == 0 {
        (oldest, memory.due)
    } else {
        let due = memory.due.take();
        by_travel(&travel, &memory.overtaken, &group, open, due)?
    };
    // A deadline at risk outranks the travel choice and the job it would have held for
    // next (a starved one, or the one a relocation serves, then competes again).
    if let Some(head) = at_risk(&travel, &group, choice, now_ms) {
        return Some(head);
    }
    memory.due = due;
    Some(choice)
}

/// The travel planner's choice among `group` (one priority), and the job it holds to go
/// at the next decision, if any; `due` is the job the last decision held.
fn by_travel<'a>(
    travel: &Travel,
    overtaken: &HashMap<i64, u32>,
    group: &[&'a Candidate<'a>],
    open: &'a [Candidate<'a>],
    due: Option<i64>,
) -> Option<(&'a Candidate<'a>, Option<i64>)> {
    let plan = travel.plan;
    if let Some(due) = due.and_then(|id| group.iter().find(|(j, _)| j.id == id)) {
        return Some((due, None));
    }
    let station = station_spot(plan.inbound);
    let starved =
        group.iter().filter(|(j, _)| overtaken.get(&j.id).copied().unwrap_or(0) >= plan.max_overtaken);
    if let Some(oldest) = starved.min_by_key(|(j, _)| j.id) {
        // It goes next, or right after the one job that brings the crane nearer to it than
        // it stands now (a store whose put lies near a starved retrieve: a dual cycle).
        let target = travel.first(oldest);
        let via = |c: &Candidate| travel.end(c).map(|e| travel.empty(c) + plan.motion.move_time(e, target));
        let lead = group
            .iter()
            .filter(|c| c.0.id != oldest.0.id && c.1.is_none())
            .filter_map(|c| Some((*c, via(c)?)))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        return match lead {
            Some((lead, cost)) if cost < travel.empty(oldest) => Some((lead, Some(oldest.0.id))),
            _ => Some((oldest, None)),
        };
    }
    // The picks in the rack the open jobs will need (retrieves, moves, relocations).
    let picks: Vec<(i64, Spot)> =
        open.iter().map(|c| (c.0.id, travel.first(c))).filter(|(_, p)| *p != station).collect();
    let cost = |c: &Candidate| {
        // A job that ends in the rack (a store) also weighs the empty run from its end to
        // the nearest pick it leaves for next: that is what pairs a store with a retrieve.
        let end = travel.end(c);
        let next = end.filter(|e| *e != station).map_or(0.0, |e| {
            picks
                .iter()
                .filter(|(id, _)| *id != c.0.id)
                .map(|(_, p)| plan.motion.move_time(e, *p))
                .fold(f64::INFINITY, f64::min)
        });
        let next =
            if next.is_finite() { next } else { plan.motion.move_time(end.unwrap_or(station), station) };
        travel.empty(c) + next
    };
    let choice = group.iter().min_by(|a, b| cost(a).total_cmp(&cost(b)).then(a.0.id.cmp(&b.0.id)))?;
    Some((choice, None))
}

/// The earliest-deadline candidate of `group`, if running `choice` first and then every
/// candidate with a deadline in earliest-deadline order (each taking its [`Travel::estimate`],
/// from `now_ms`) leaves one ending later than its deadline less the margin; None when the
/// choice stands.
fn at_risk<'a>(
    travel: &Travel,
    group: &[&'a Candidate<'a>],
    choice: &'a Candidate<'a>,
    now_ms: i64,
) -> Option<&'a Candidate<'a>> {
    let mut edf: Vec<(&Candidate, i64)> =
        group.iter().filter_map(|c| Some((*c, to_ms(c.0.deadline?)))).collect();
    edf.sort_by_key(|(c, deadline)| (*deadline, c.0.id));
    let head = edf.first()?.0;
    if head.0.id == choice.0.id {
        return None;
    }
    let margin_ms = i64::from(travel.plan.deadline_margin_s) * 1000;
    let rest = edf.iter().filter(|(c, _)| c.0.id != choice.0.id).map(|&(c, d)| (c, Some(d)));
    let (mut at, mut ends_ms) = (travel.from, now_ms as f64);
    for (c, deadline) in std::iter::once((choice, choice.0.deadline.map(to_ms))).chain(rest) {
        let (secs, end) = travel.estimate(c, at);
        (at, ends_ms) = (end, ends_ms + secs * 1000.0);
        if deadline.is_some_and(|d| ends_ms > (d - margin_ms) as f64) {
            return Some(head);
        }
    }
    None
}

/// The crane's empty runs, from where it stands, for the travel planner.
struct Travel<'a> {
    plan: &'a Plan,
    places: &'a HashMap<i64, Location>,
    from: Spot,
}

impl Travel<'_> {
    /// Where the crane first goes for a candidate.
    fn first(&self, (job, near): &Candidate) -> Spot {
        pick_spot(self.plan, job, *near)
    }

    /// The empty run to a candidate's pick. A job that needs a relocation first also makes
    /// the empty run from where the relocation puts the box back to its own pick; the
    /// relocation's fork cycles and loaded run are not counted, since they are the same
    /// whenever it runs.
    fn empty(&self, c: &Candidate) -> f64 {
        let motion = &self.plan.motion;
        let back = match (c.1, self.places.get(&c.0.id)) {
            (Some(_), Some(put)) => motion.move_time(spot(*put), pick_spot(self.plan, c.0, None)),
            _ => 0.0,
        };
        motion.move_time(self.from, self.first(c)) + back
    }

    /// Where the crane stands once a candidate ends (None for one that needs a relocation
    /// first: the decision is the relocation).
    fn end(&self, (job, near): &Candidate) -> Option<Spot> {
        match (near, self.places.get(&job.id)) {
            (Some(_), _) => None,
            (None, Some(place)) => Some(spot(*place)),
            (None, None) => job.spec().map(|s| end_spot(self.plan, &s)),
        }
    }

    /// The crane seconds a candidate is estimated to take when it starts at `at`, and where
    /// the crane then stands: its empty runs ([`Travel::empty`]), then a relocation's loaded
    /// run and fork cycles if it needs one, then its own loaded run and a fork cycle at each
    /// end (none for a travel). What the motion model says and nothing else: no hand-over
    /// (STB/ACK, the polls between), no acknowledgement, no wait for a station to clear, no
    /// relocation a later job will need, no job not among the candidates now.
    fn estimate(&self, c: &Candidate, at: Spot) -> (f64, Spot) {
        let (plan, motion) = (self.plan, &self.plan.motion);
        let place = self.places.get(&c.0.id).copied();
        let mut secs = Travel { from: at, ..*self }.empty(c);
        if let (Some(near), Some(to)) = (c.1, place) {
            secs += motion.move_time(spot(near), spot(to))
                + motion.fork_time(near.position)
                + motion.fork_time(to.position);
        }
        // A store left to rackd goes where it was placed (it never needs a relocation).
        let spec = match (c.0.spec(), place) {
            (Some(JobSpec::Putaway { .. }), Some(to)) => Some(JobSpec::Store { to }),
            (spec, _) => spec,
        };
        let Some(spec) = spec else { return (secs, at) };
        let station = |s: Station| (station_spot(s), 0);
        let stock = |l: Location| (spot(l), l.position);
        let transfer = match spec {
            JobSpec::Store { to } => Some((station(plan.inbound), stock(to))),
            JobSpec::Retrieve { from } => Some((stock(from), station(plan.outbound))),
            JobSpec::Move { from, to } => Some((stock(from), stock(to))),
            _ => None,
        };
        if let Some(((p, p_at), (q, q_at))) = transfer {
            secs += motion.move_time(p, q) + motion.fork_time(p_at) + motion.fork_time(q_at);
        }
        (secs, end_spot(plan, &spec))
    }
}

/// Where the crane first goes for a job: its pick (the inbound station for a store), the
/// near box to relocate, or a travel's target.
fn pick_spot(plan: &Plan, job: &Job, near: Option<Location>) -> Spot {
    if let Some(n) = near {
        return spot(n);
    }
    match job.spec() {
        Some(JobSpec::Store { .. } | JobSpec::Putaway { .. }) | None => station_spot(plan.inbound),
        Some(JobSpec::Retrieve { from } | JobSpec::Move { from, .. }) => spot(from),
        Some(
            JobSpec::Travel { to } | JobSpec::Clear { location: to } | JobSpec::Light { location: to, .. },
        ) => spot(to),
    }
}

/// Where the crane stands once the job ends.
fn end_spot(plan: &Plan, spec: &JobSpec) -> Spot {
    match *spec {
        JobSpec::Retrieve { .. } => station_spot(plan.outbound),
        JobSpec::Store { to } | JobSpec::Move { to, .. } | JobSpec::Travel { to } => spot(to),
        JobSpec::Clear { location } | JobSpec::Light { location, .. } => spot(location),
        JobSpec::Putaway { .. } => station_spot(plan.inbound),
    }
}

fn station_spot(s: Station) -> Spot {
    Spot { bay: s.bay, level: s.level }
}

/// Where the box of a store left to rackd goes: from the inbound station, in its zones.
fn place(
    plan: &Plan,
    rack: &Rack,
    busy: &HashSet<Location>,
    zones: &[Zone],
    class: Option<Class>,
) -> Option<Location> {
    let station = station_spot(plan.inbound);
    let aisle = zones.first()?.aisle;
    let want = Want { aisle, from: station, station, class, zones, busy };
    putaway::choose(rack, &plan.motion, &want)
}

/// Where the box at `near` goes so that `job` can run.
fn target(plan: &Plan, rack: &Rack, busy: &HashSet<Location>, job: &Job, near: Location) -> Option<Location> {
    let mut busy = busy.clone();
    busy.extend(job.spec().map(|s| s.locations()).unwrap_or_default());
    busy.insert(Rack::far_of(near));
    let zones = [Zone::aisle(near.aisle)];
    let station = station_spot(plan.inbound);
    let want = Want { aisle: near.aisle, from: spot(near), station, class: None, zones: &zones, busy: &busy };
    putaway::choose(rack, &plan.motion, &want)
}
