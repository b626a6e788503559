//! Where a box goes when rackd chooses: a relocation's target (and a store that leaves the
//! location to rackd).
//!
//! A candidate is a location of the aisle, not a station, with no box, not reserved by a
//! job on the crane, not locked, not touched by any unfinished job (so no later job finds
//! its place taken), and reachable: a far location only behind an empty near one. A near
//! location in front of a far one that an unfinished job will pick or fill is no
//! candidate either: a box there would only have to be relocated for that job.
//!
//! Candidates rank by the crane's travel time from where the box starts (the station for a
//! store, the blocking near location for a relocation), and within one bay and level far
//! before near, so that near stays free for the fork to reach far later. A velocity class
//! splits the aisle's places into three bands by travel time from the station (A the
//! nearest third, then B, then C); a job of a class takes a place in its band first and
//! falls back to the nearest band that has one.

use std::collections::HashSet;

use super::rack::Rack;
use crate::domain::{Class, Location, Zone};
use crate::wire::motion::{Motion, Spot};

/// What a choice must respect.
#[derive(Clone, Debug)]
pub struct Want<'a> {
    /// The aisle.
    pub aisle: u16,
    /// Where the box starts, to rank places by travel time.
    pub from: Spot,
    /// Where the aisle's station is, for the class bands.
    pub station: Spot,
    /// The job's velocity class, if any.
    pub class: Option<Class>,
    /// Where the box may go: a location in one of these (one aisle).
    pub zones: &'a [Zone],
    /// Locations unfinished jobs touch: never chosen.
    pub busy: &'a HashSet<Location>,
}

/// The spot of a location (bay and level).
pub fn spot(l: Location) -> Spot {
    Spot { bay: l.bay, level: l.level }
}

/// The best free location for the box, if the aisle has one.
pub fn choose(rack: &Rack, motion: &Motion, want: &Want) -> Option<Location> {
    let free = |l: Location| {
        let c = rack.cell(l);
        !c.occupied && c.reserved_by.is_none() && !c.locked && !want.busy.contains(&l)
    };
    let candidates: Vec<Location> = rack
        .locations()
        .map(|(l, _)| l)
        .filter(|l| l.aisle == want.aisle && l.bay != 0 && free(*l))
        .filter(|l| want.zones.iter().any(|z| z.contains(*l)))
        .filter(|l| !rack.is_far(*l) || !rack.occupied(Rack::near_of(*l)))
        .filter(|l| !rack.is_deep(l.aisle) || rack.is_far(*l) || !want.busy.contains(&Rack::far_of(*l)))
        .collect();
    let band = want.class.map(|class| (class, bands(rack, motion, want)));
    let key = |l: Location| {
        let miss =
            band.as_ref().map_or(0, |(class, edges)| band_miss(*class, edges, motion, want.station, l));
        (miss, motion.move_time(want.from, spot(l)), u8::from(!rack.is_far(l)), l)
    };
    candidates
        .into_iter()
        .map(key)
        .min_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)).then(a.2.cmp(&b.2)).then(a.3.cmp(&b.3)))
        .map(|k| k.3)
}

/// Travel times from the station at which band B and band C begin.
fn bands(rack: &Rack, motion: &Motion, want: &Want) -> (f64, f64) {
    let mut times: Vec<f64> = rack
        .locations()
        .filter(|(l, _)| l.aisle == want.aisle && l.bay != 0)
        .map(|(l, _)| motion.move_time(want.station, spot(l)))
        .collect();
    times.sort_by(f64::total_cmp);
    let at = |i: usize| times.get(i).copied().unwrap_or(f64::INFINITY);
    (at(times.len() / 3), at(2 * times.len() / 3))
}

/// How many bands `l` lies from the class's own (0: in it).
fn band_miss(class: Class, (b, c): &(f64, f64), motion: &Motion, station: Spot, l: Location) -> u8 {
    let t = motion.move_time(station, spot(l));
    let band = if t < *b {
        0
    } else if t < *c {
        1
    } else {
        2
    };
    (band as i8 - class as i8).unsigned_abs()
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;

    use super::*;
    use crate::service::planner::rack::Cell;

    fn at(bay: u16, level: u16, position: u16) -> Location {
        Location { aisle: 2, row: 1, bay, level, position }
    }

    fn rack(bays: u16, full: &[Location]) -> Rack {
        let mut cells = Vec::new();
        for bay in 1..=bays {
            for level in 1..=2 {
                for position in 1..=2 {
                    let l = at(bay, level, position);
                    cells.push((l, Cell { occupied: full.contains(&l), ..Cell::default() }));
                }
            }
        }
        Rack::from_cells(cells, &BTreeSet::from([2]))
    }

    const AISLE: [Zone; 1] = [Zone { aisle: 2, row: None, bay: None, level: None, position: None }];

    fn want(busy: &HashSet<Location>, class: Option<Class>) -> Want<'_> {
        let station = Spot { bay: 0, level: 1 };
        Want { aisle: 2, from: station, station, class, zones: &AISLE, busy }
    }

    #[test]
    fn far_before_near_nearest_first() {
        let m = Motion::default();
        let none = HashSet::new();
        assert_eq!(choose(&rack(5, &[]), &m, &want(&none, None)), Some(at(1, 1, 2)));
        let far_taken = rack(5, &[at(1, 1, 2)]);
        assert_eq!(choose(&far_taken, &m, &want(&none, None)), Some(at(1, 1, 1)), "then its near");
        let near_taken = rack(5, &[at(1, 1, 1)]);
        let chosen = choose(&near_taken, &m, &want(&none, None)).unwrap();
        assert_ne!(chosen, at(1, 1, 2), "never far behind a box");
        assert_eq!(chosen.position, 2);
    }

    #[test]
    fn busy_reserved_and_locked_places_are_skipped() {
        let m = Motion::default();
        let busy = HashSet::from([at(1, 1, 2)]);
        let chosen = choose(&rack(5, &[]), &m, &want(&busy, None)).unwrap();
        assert_eq!(chosen, at(1, 2, 2), "neither the busy far place nor the near one in front of it");
        let mut cells: Vec<_> = rack(1, &[]).locations().collect();
        for (_, c) in &mut cells {
            c.locked = true;
        }
        let locked = Rack::from_cells(cells, &BTreeSet::from([2]));
        assert_eq!(choose(&locked, &m, &want(&HashSet::new(), None)), None);
    }

    #[test]
    fn classes_take_their_band() {
        let m = Motion::default();
        let none = HashSet::new();
        let r = rack(30, &[]);
        let a = choose(&r, &m, &want(&none, Some(Class::A))).unwrap();
        let c = choose(&r, &m, &want(&none, Some(Class::C))).unwrap();
        assert!(a.bay < 5, "A is nearest: {a:?}");
        assert!(c.bay >= 20, "C is in the far third: {c:?}");
        let upper = [Zone { level: Some(2), ..AISLE[0] }];
        let chosen = choose(&r, &m, &Want { zones: &upper, ..want(&none, None) }).unwrap();
        assert_eq!((chosen.level, chosen.bay, chosen.position), (2, 1, 2), "{chosen:?}");
    }
}
