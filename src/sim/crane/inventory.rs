//! The simulated crane's own inventory: which rack cells hold a load, so it can refuse the
//! impossible as a real double-deep crane does (business alarms 7069/7070, 7091..7098).
//!
//! A cell is `[row, bay, level, side]` as in the task words: row 1 is the left row (alarm
//! codes 7069, 7091..7094), any other row the right one (7070, 7095..7098); side 1 is the
//! near position, 2 (and beyond) far. Bay 0 is the pick-and-drop station: an inexhaustible
//! source for picks and a sink for puts, never inventory (such cells are ignored).
//!
//! The rules, checked by the engine at the moment the forks would act:
//! - pick far while the near cell of the same row, bay and level holds a load: 7094 / 7098
//!   (before the fork cycle);
//! - pick from an empty cell: 7069 / 7070 (after the fork cycle, as the catalogue says: no
//!   load on the platform after retracting);
//! - put near into an occupied near cell: 7091 / 7095; put far while near is occupied:
//!   7092 / 7096; put far into an occupied far cell: 7093 / 7097 (before the fork cycle).

use std::collections::BTreeSet;

/// A rack cell: row, bay, level, side.
pub type Cell = [u16; 4];

/// Reads an inventory file: a JSON array of [row, bay, level, side].
pub fn read_cells(path: &std::path::Path) -> anyhow::Result<Vec<Cell>> {
    use anyhow::Context;
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text)
        .with_context(|| format!("{}: expected a JSON array of [row, bay, level, side]", path.display()))
}

/// Whether a cell is a station (bay 0), which is never inventory.
pub fn is_station(cell: Cell) -> bool {
    cell[1] == 0
}

fn left(cell: Cell) -> bool {
    cell[0] == 1
}

fn near_of(cell: Cell) -> Cell {
    [cell[0], cell[1], cell[2], 1]
}

/// The occupied cells.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Inventory {
    cells: BTreeSet<Cell>,
}

impl Inventory {
    /// An inventory holding these cells (stations dropped).
    pub fn new(cells: impl IntoIterator<Item = Cell>) -> Inventory {
        Inventory { cells: cells.into_iter().filter(|c| !is_station(*c)).collect() }
    }

    /// The occupied cells, in order.
    pub fn cells(&self) -> Vec<Cell> {
        self.cells.iter().copied().collect()
    }

    /// Whether a cell holds a load (a station always does, as a source).
    pub fn holds(&self, cell: Cell) -> bool {
        is_station(cell) || self.cells.contains(&cell)
    }

    /// Puts a load into a cell; false if it was occupied already or is a station.
    pub fn put(&mut self, cell: Cell) -> bool {
        !is_station(cell) && self.cells.insert(cell)
    }

    /// Takes the load out of a cell; false if it was empty or is a station.
    pub fn take(&mut self, cell: Cell) -> bool {
        !is_station(cell) && self.cells.remove(&cell)
    }

    /// The alarm for a pick the forks cannot reach (far behind an occupied near), if any.
    pub fn pick_blocked(&self, cell: Cell) -> Option<u16> {
        let far_behind_load = !is_station(cell) && cell[3] >= 2 && self.cells.contains(&near_of(cell));
        far_behind_load.then_some(if left(cell) { 7094 } else { 7098 })
    }

    /// The alarm for a pick that found nothing (seen after retracting).
    pub fn no_load(cell: Cell) -> u16 {
        if left(cell) { 7069 } else { 7070 }
    }

    /// The alarm for a put the cell cannot take, if any.
    pub fn put_blocked(&self, cell: Cell) -> Option<u16> {
        if is_station(cell) {
            return None;
        }
        let base = if left(cell) { 7091 } else { 7095 };
        let near_full = self.cells.contains(&near_of(cell));
        if cell[3] < 2 {
            near_full.then_some(base)
        } else if near_full {
            Some(base + 1)
        } else {
            self.cells.contains(&cell).then_some(base + 2)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_impossible_move_has_its_code_and_possible_ones_none() {
        for (row, off) in [(1u16, 0u16), (2, 4)] {
            let near = [row, 4, 2, 1];
            let far = [row, 4, 2, 2];
            let only_near = Inventory::new([near]);
            let only_far = Inventory::new([far]);
            let both = Inventory::new([near, far]);
            let empty = Inventory::default();
            assert_eq!(only_near.put_blocked(near), Some(7091 + off));
            assert_eq!(only_near.put_blocked(far), Some(7092 + off));
            assert_eq!(only_far.put_blocked(far), Some(7093 + off));
            assert_eq!(only_near.pick_blocked(far), Some(7094 + off));
            assert_eq!(both.pick_blocked(far), Some(7094 + off));
            assert!(!empty.holds(near) && only_far.holds(far));
            assert_eq!(Inventory::no_load(near), if row == 1 { 7069 } else { 7070 });
            // Possible: put near before a loaded far, put into an empty lane, pick near, pick
            // far with near empty.
            assert_eq!(only_far.put_blocked(near), None);
            assert_eq!(empty.put_blocked(far), None);
            assert_eq!(both.pick_blocked(near), None);
            assert_eq!(only_far.pick_blocked(far), None);
        }
    }

    #[test]
    fn stations_are_a_source_and_a_sink_never_inventory() {
        let station = [2, 0, 1, 1];
        let mut inv = Inventory::new([station, [1, 1, 1, 1]]);
        assert_eq!(inv.cells(), vec![[1, 1, 1, 1]]);
        assert!(inv.holds(station) && !inv.holds([1, 2, 1, 1]));
        assert_eq!((inv.pick_blocked(station), inv.put_blocked(station)), (None, None));
        assert!(!inv.put(station) && !inv.take(station));
        assert!(inv.take([1, 1, 1, 1]) && !inv.take([1, 1, 1, 1]));
        assert!(inv.put([1, 1, 1, 2]) && !inv.put([1, 1, 1, 2]));
    }
}
