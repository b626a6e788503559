//! What the simulated shelf holds and has seen: boxes, lights, and the counts the tests
//! and the operator read. The same whatever protocol the PLC speaks.

use std::collections::{BTreeMap, HashMap};
use std::time::Instant;

use crate::domain::Location;
use crate::wire::slot::{Command, Task};

/// The shelf's contents and the simulator's counters.
#[derive(Debug, Default)]
pub(super) struct World {
    /// Boxes on the shelf and their barcodes ("" when unlabelled).
    pub inventory: BTreeMap<Location, String>,
    /// Lights by (location, "red" | "green"): on or off.
    pub lights: BTreeMap<(Location, &'static str), bool>,
    /// Writes into busy slots (rule 1 broken).
    pub violations: u64,
    /// Tasks withdrawn before they ran.
    pub withdrawals: u64,
    /// How many times each task id reached a slot.
    pub received: HashMap<u16, u32>,
    /// When each task id last reached a slot.
    pub received_at: HashMap<u16, Instant>,
    /// Tasks finished (state 2).
    pub completed: u64,
    /// Tasks failed (state 3).
    pub failed: u64,
}

/// Why the PLC refuses a task: the WCS's data disagrees with its own (failure kind 2).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Disagrees;

impl World {
    /// Carries out a task on the shelf, or says the PLC refuses it: retrieve from an empty
    /// position, store into a full one, move from empty or into full, an unknown command.
    pub fn perform(&mut self, task: &Task) -> Result<(), Disagrees> {
        let inv = &mut self.inventory;
        match (Command::from_code(task.command), task.from, task.to) {
            (Some(Command::Store), _, Some(to)) if !inv.contains_key(&to) => {
                inv.insert(to, task.barcode.clone());
            }
            (Some(Command::Retrieve), Some(from), _) if inv.contains_key(&from) => {
                inv.remove(&from);
            }
            (Some(Command::Move), Some(from), Some(to))
                if inv.contains_key(&from) && !inv.contains_key(&to) =>
            {
                let b = inv.remove(&from).unwrap_or_default();
                inv.insert(to, if task.barcode.is_empty() { b } else { task.barcode.clone() });
            }
            (Some(Command::Clear), Some(at), _) => {
                inv.remove(&at);
            }
            (
                Some(c @ (Command::GreenOn | Command::GreenOff | Command::RedOn | Command::RedOff)),
                Some(at),
                None,
            ) => {
                let color = if matches!(c, Command::RedOn | Command::RedOff) { "red" } else { "green" };
                self.lights.insert((at, color), matches!(c, Command::GreenOn | Command::RedOn));
            }
            _ => return Err(Disagrees),
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(position: u16) -> Location {
        Location { aisle: 1, row: 2, bay: 2, level: 4, position }
    }

    fn task(command: Command, from: Option<Location>, to: Option<Location>, barcode: &str) -> Task {
        Task { id: 1, priority: 1, barcode: barcode.into(), command: command as u16, from, to }
    }

    #[test]
    fn performs_what_agrees_with_the_shelf_and_refuses_the_rest() {
        let mut w = World::default();
        assert_eq!(w.perform(&task(Command::Retrieve, Some(at(1)), None, "")), Err(Disagrees));
        w.perform(&task(Command::Store, None, Some(at(1)), "A")).unwrap();
        assert_eq!(w.perform(&task(Command::Store, None, Some(at(1)), "B")), Err(Disagrees));
        w.perform(&task(Command::Store, None, Some(at(2)), "B")).unwrap();
        assert_eq!(w.perform(&task(Command::Move, Some(at(1)), Some(at(2)), "")), Err(Disagrees));
        w.perform(&task(Command::Move, Some(at(1)), Some(at(3)), "")).unwrap();
        assert_eq!(
            w.inventory.get(&at(3)).map(String::as_str),
            Some("A"),
            "an unlabelled move keeps the box's barcode"
        );
        w.perform(&task(Command::Clear, Some(at(9)), None, "")).unwrap();
        w.perform(&task(Command::Clear, Some(at(2)), None, "")).unwrap();
        w.perform(&task(Command::Retrieve, Some(at(3)), None, "")).unwrap();
        assert!(w.inventory.is_empty());
        w.perform(&task(Command::RedOn, Some(at(5)), None, "")).unwrap();
        w.perform(&task(Command::GreenOff, Some(at(5)), None, "")).unwrap();
        assert_eq!(w.lights.get(&(at(5), "red")), Some(&true));
        assert_eq!(w.lights.get(&(at(5), "green")), Some(&false));
        assert_eq!(w.perform(&task(Command::GreenOn, Some(at(5)), Some(at(6)), "")), Err(Disagrees));
        let unknown = Task { command: 99, ..task(Command::Store, None, Some(at(7)), "") };
        assert_eq!(w.perform(&unknown), Err(Disagrees));
    }
}
