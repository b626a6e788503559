//! What the simulated crane did, counted for a benchmark ([`super::CraneSim::stats`], the
//! `stats` text command). Times are simulated seconds (real seconds x the time scale);
//! distances come from the motion model, so they stay 0 without one.

use std::collections::BTreeMap;
use std::fmt;

use serde::{Serialize, Serializer};

use super::inventory::{Cell, is_station};

/// The crane's counters since it started.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct CraneStats {
    /// Tasks that ended in state 20 (complete), transfers and travels alike.
    pub cycles: u32,
    /// Tasks that ended in state 40 (cancelled).
    pub cancelled: u32,
    /// Tasks that ended in state 30 (force-completed).
    pub forced: u32,
    /// Simulated seconds spent running action states 1..18 and homing (state 100); time
    /// halted under an alarm, idle time and hand-overs do not count.
    pub busy_secs: f64,
    /// Of `busy_secs`, the seconds travelling to the pick with the platform empty (action
    /// states 1 and 2 of a transfer, and a travel task).
    pub empty_secs: f64,
    /// Of `busy_secs`, the seconds travelling to the put with a load (states 11 and 12).
    pub loaded_secs: f64,
    /// Of `busy_secs`, the seconds of fork cycles (states 3..8 and 13..18).
    pub fork_secs: f64,
    /// Metres along the travel axis with a load on the platform (D206 = 1).
    pub travel_loaded_m: f64,
    /// Metres along the travel axis with the platform empty (D206 = 0).
    pub travel_empty_m: f64,
    /// Metres along the lift axis, loaded and empty together.
    pub lift_m: f64,
    /// Of `empty_secs`, the tasks and seconds of each pair of tasks in a row: the empty run
    /// to a task's pick depends on where the one before left the crane. A task is counted
    /// when it starts, its seconds as it runs.
    pub empty_by_pair: BTreeMap<Pair, Runs>,
    /// Business alarms raised, by code: by the inventory rules, and by hand
    /// ([`super::CraneSim::raise_alarm`], the `alarm` command).
    pub alarms: BTreeMap<u16, u32>,
}

impl CraneStats {
    /// Counts a business alarm (other codes are not counted).
    pub fn alarm(&mut self, code: u16) {
        if super::is_business(code) {
            *self.alarms.entry(code).or_default() += 1;
        }
    }

    /// Counts a task that starts.
    pub fn began(&mut self, pair: Pair) {
        self.empty_by_pair.entry(pair).or_default().tasks += 1;
    }

    /// Counts `secs` spent in action state `state` of a task, which follows `pair.before`.
    pub fn spent(&mut self, state: u16, secs: f64, pair: Pair) {
        self.busy_secs += secs;
        match state {
            1 | 2 => {
                self.empty_secs += secs;
                self.empty_by_pair.entry(pair).or_default().secs += secs;
            }
            11 | 12 => self.loaded_secs += secs,
            3..=8 | 13..=18 => self.fork_secs += secs,
            _ => {}
        }
    }

    /// Counts a move of `dx` metres of travel and `dy` of lift.
    pub fn moved(&mut self, dx: f64, dy: f64, loaded: bool) {
        if loaded {
            self.travel_loaded_m += dx.abs();
        } else {
            self.travel_empty_m += dx.abs();
        }
        self.lift_m += dy.abs();
    }
}

/// What a task does, as the crane sees it from its cells (bay 0 is the station). Named in
/// text (and in JSON, inside a [`Pair`]) by its `Display`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum TaskKind {
    /// A transfer from the station into the rack.
    Store,
    /// A transfer from the rack to the station.
    Retrieve,
    /// A transfer within the rack (a relocation, or a move).
    Move,
    /// A transfer from a station to a station.
    Pass,
    /// A travel task (D209 = 1): no transfer.
    Travel,
}

impl TaskKind {
    /// The kind of a task from `from` to `to` (`travel`: a travel task).
    pub fn of(from: Cell, to: Cell, travel: bool) -> TaskKind {
        match (travel, is_station(from), is_station(to)) {
            (true, _, _) => TaskKind::Travel,
            (false, true, true) => TaskKind::Pass,
            (false, true, false) => TaskKind::Store,
            (false, false, true) => TaskKind::Retrieve,
            (false, false, false) => TaskKind::Move,
        }
    }
}

impl fmt::Display for TaskKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let name = match self {
            TaskKind::Store => "store",
            TaskKind::Retrieve => "retrieve",
            TaskKind::Move => "move",
            TaskKind::Pass => "pass",
            TaskKind::Travel => "travel",
        };
        f.write_str(name)
    }
}

/// Two tasks in a row: the one before (None: the crane's first task) and the next.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Pair {
    /// The task before.
    pub before: Option<TaskKind>,
    /// The task that follows it.
    pub next: TaskKind,
}

impl fmt::Display for Pair {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.before {
            Some(before) => write!(f, "{before} -> {}", self.next),
            None => write!(f, "first {}", self.next),
        }
    }
}

/// A pair as a map key in JSON: its text.
impl Serialize for Pair {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

/// Tasks of one pair, and their empty seconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Runs {
    /// Tasks started.
    pub tasks: u32,
    /// Simulated seconds of empty travel to their picks.
    pub secs: f64,
}

impl fmt::Display for CraneStats {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "cycles {} cancelled {} forced {} busy {:.1} s (empty {:.1} s, loaded {:.1} s, forks {:.1} s) travel loaded {:.1} m empty {:.1} m lift {:.1} m alarms",
            self.cycles,
            self.cancelled,
            self.forced,
            self.busy_secs,
            self.empty_secs,
            self.loaded_secs,
            self.fork_secs,
            self.travel_loaded_m,
            self.travel_empty_m,
            self.lift_m
        )?;
        if self.alarms.is_empty() {
            return write!(f, " none");
        }
        for (code, n) in &self.alarms {
            write!(f, " {code}x{n}")?;
        }
        Ok(())
    }
}
