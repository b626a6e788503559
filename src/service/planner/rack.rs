//! The rack as the planner sees it: what each location of a crane's aisles holds now (the
//! location model, updated when jobs complete and by inventory loads), which job has it
//! reserved, whether it is locked, and which aisles are double-deep.
//!
//! The double-deep rules read it: in an aisle with `depth = 2`, position 1 is near and 2 is
//! far behind it, and the crane's fork reaches far only past an empty near. A task that
//! picks far or puts far while near holds a box, that puts into a box, is what raises the
//! crane's business alarms 7091..7098; [`Rack::blocker`] and [`Rack::occupied`] say so
//! before anything is sent.

use std::collections::{BTreeSet, HashMap};

use crate::domain::Location;
use crate::store::locations::LocationState;

/// One location as the planner needs it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Cell {
    /// A box is there.
    pub occupied: bool,
    /// The unfinished job that has it reserved (it is on the crane).
    pub reserved_by: Option<i64>,
    /// Locked by a person or a failed job.
    pub locked: bool,
}

/// The locations of a crane's aisles.
#[derive(Clone, Debug, Default)]
pub struct Rack {
    cells: HashMap<Location, Cell>,
    deep: BTreeSet<u16>,
}

impl Rack {
    /// A rack from the location model; `deep` are the aisles with `depth = 2`.
    pub fn new(states: &[LocationState], deep: &BTreeSet<u16>) -> Rack {
        let cells = states
            .iter()
            .map(|s| {
                let cell =
                    Cell { occupied: s.occupied, reserved_by: s.reserved_by, locked: s.lock.is_some() };
                (s.location(), cell)
            })
            .collect();
        Rack { cells, deep: deep.clone() }
    }

    /// A rack from cells (tests, and the planner's own what-if copies).
    pub fn from_cells(cells: impl IntoIterator<Item = (Location, Cell)>, deep: &BTreeSet<u16>) -> Rack {
        Rack { cells: cells.into_iter().collect(), deep: deep.clone() }
    }

    /// The location's cell; a location the model lacks (a station) is an empty cell.
    pub fn cell(&self, l: Location) -> Cell {
        self.cells.get(&l).copied().unwrap_or_default()
    }

    /// Whether a box is at `l`.
    pub fn occupied(&self, l: Location) -> bool {
        self.cell(l).occupied
    }

    /// Every location, in order.
    pub fn locations(&self) -> impl Iterator<Item = (Location, Cell)> + '_ {
        let mut all: Vec<_> = self.cells.iter().map(|(l, c)| (*l, *c)).collect();
        all.sort_unstable_by_key(|(l, _)| *l);
        all.into_iter()
    }

    /// Whether `l` is in a double-deep aisle and far (position 2).
    pub fn is_far(&self, l: Location) -> bool {
        self.deep.contains(&l.aisle) && l.position >= 2 && l.bay != 0
    }

    /// Whether `aisle` is double-deep.
    pub fn is_deep(&self, aisle: u16) -> bool {
        self.deep.contains(&aisle)
    }

    /// The near location in front of a far one.
    pub fn near_of(l: Location) -> Location {
        Location { position: 1, ..l }
    }

    /// The far location behind a near one.
    pub fn far_of(l: Location) -> Location {
        Location { position: 2, ..l }
    }

    /// The near location whose box stands in the way of the fork reaching `l`, if any:
    /// `l` is far in a double-deep aisle and its near holds a box.
    pub fn blocker(&self, l: Location) -> Option<Location> {
        let near = Self::near_of(l);
        (self.is_far(l) && self.occupied(near)).then_some(near)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(bay: u16, level: u16, position: u16) -> Location {
        Location { aisle: 2, row: 1, bay, level, position }
    }

    #[test]
    fn near_blocks_far_only_in_deep_aisles() {
        let deep = BTreeSet::from([2]);
        let cells = [(at(3, 1, 1), Cell { occupied: true, ..Cell::default() })];
        let rack = Rack::from_cells(cells, &deep);
        assert_eq!(rack.blocker(at(3, 1, 2)), Some(at(3, 1, 1)));
        assert_eq!(rack.blocker(at(3, 1, 1)), None, "near is never blocked");
        assert_eq!(rack.blocker(at(4, 1, 2)), None, "an empty near does not block");
        let shallow = Rack::from_cells(cells, &BTreeSet::new());
        assert_eq!(shallow.blocker(at(3, 1, 2)), None, "single-deep: no rules");
    }
}
