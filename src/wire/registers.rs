//! The crane's register map (spec: crane-mc3e.md), word by word: what rackd writes at
//! D0..D39, what it reads at D200..D239, and how jobs become task words. No I/O.

use crate::domain::{JobSpec, Location};

/// Words in each block (D0..D39, D200..D239).
pub const BLOCK_WORDS: u16 = 40;

/// Offsets in rackd's block (from `wcs_base`, D0).
pub mod wcs {
    /// Heartbeat.
    pub const HEARTBEAT: u32 = 0;
    /// Task number; the task words run from here for [`super::TASK_WORDS`] words.
    pub const TASK: u32 = 8;
    /// Strobe.
    pub const STB: u32 = 21;
    /// Completion acknowledged.
    pub const ACK: u32 = 22;
}

/// Task words written at once: task number, mode, from (4), to (4).
pub const TASK_WORDS: usize = 10;

/// What the crane shows in D200..D239.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CraneView {
    /// D200.
    pub heartbeat: u16,
    /// D201.
    pub status: u16,
    /// D202.
    pub scheduling: u16,
    /// D203: the action state.
    pub action: u16,
    /// D205: alarm code, 0 = none.
    pub alarm: u16,
    /// D206: load on the platform.
    pub load: u16,
    /// D208: task number echo.
    pub task: u16,
    /// D209: mode echo.
    pub mode: u16,
    /// D220: travel axis position.
    pub travel: u16,
    /// D221: lift axis position.
    pub lift: u16,
    /// D223: completion state, 0 = nothing to acknowledge.
    pub completion: u16,
    /// D225: ACK of the hand-over.
    pub ack: u16,
}

impl CraneView {
    /// Reads the view from the 40 words at D200; None if fewer were read.
    pub fn parse(w: &[u16]) -> Option<CraneView> {
        (w.len() >= BLOCK_WORDS as usize).then(|| CraneView {
            heartbeat: w[0],
            status: w[1],
            scheduling: w[2],
            action: w[3],
            alarm: w[5],
            load: w[6],
            task: w[8],
            mode: w[9],
            travel: w[20],
            lift: w[21],
            completion: w[23],
            ack: w[25],
        })
    }

    /// Idle and clean, as far as the crane's own block tells: no hand-over answered
    /// (ACK D225 = 0), no task (D208 = 0), nothing to acknowledge (D223 = 0), not moving
    /// nor homing (D203 = 0), no alarm. rackd's side (its strobe D21 down, no hand-over of
    /// its own under way) is the adapter's to check.
    pub fn is_idle(&self) -> bool {
        self.ack == 0 && self.task == 0 && self.completion == 0 && self.action == 0 && self.alarm == 0
    }
}

/// The crane's modes (D9).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u16)]
pub enum Mode {
    /// Travel, loaded or empty.
    Travel = 1,
    /// Pick and put (also rack to rack).
    Transfer = 2,
    /// Cancel the task.
    Cancel = 3,
}

impl Mode {
    /// The mode a D9 word names, if any.
    pub fn of(word: u16) -> Option<Mode> {
        match word {
            1 => Some(Mode::Travel),
            2 => Some(Mode::Transfer),
            3 => Some(Mode::Cancel),
            _ => None,
        }
    }
}

/// A crane coordinate: row (1 left, 2 right), bay (0 = station), level, side (1 near, 2 far).
pub type Coord = [u16; 4];

/// The pick-and-drop stations.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Stations {
    /// Where a store picks.
    pub inbound: Coord,
    /// Where a retrieve puts.
    pub outbound: Coord,
}

/// One task as written to D8..D17.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Task {
    /// Task number (from the job id).
    pub number: u16,
    /// Mode.
    pub mode: Mode,
    /// Pick (zeros for travel).
    pub from: Coord,
    /// Put, or the travel target.
    pub to: Coord,
}

impl Task {
    /// The ten words D8..D17.
    pub fn words(&self) -> [u16; TASK_WORDS] {
        let mut w = [0; TASK_WORDS];
        w[0] = self.number;
        w[1] = self.mode as u16;
        w[2..6].copy_from_slice(&self.from);
        w[6..10].copy_from_slice(&self.to);
        w
    }

    /// The task the ten words D8..D17 hold (as found in the PLC after a restart); None if
    /// fewer words, no task number or no known mode.
    pub fn from_words(w: &[u16]) -> Option<Task> {
        let w: &[u16; TASK_WORDS] = w.get(..TASK_WORDS)?.try_into().ok()?;
        let mode = Mode::of(w[1])?;
        let coord = |k: usize| [w[k], w[k + 1], w[k + 2], w[k + 3]];
        (w[0] != 0).then(|| Task { number: w[0], mode, from: coord(2), to: coord(6) })
    }

    /// The cancel (mode 3) of this task: same number and coordinates.
    pub fn cancel(&self) -> Task {
        Task { mode: Mode::Cancel, ..*self }
    }
}

/// A location as crane coordinates (the position is the side).
pub fn coord(l: &Location) -> Coord {
    [l.row, l.bay, l.level, l.position]
}

/// The task for a job: store = transfer from the inbound station, retrieve = transfer to
/// the outbound station, move = transfer rack to rack, travel = mode 1 (from left zero).
pub fn task_for(spec: &JobSpec, number: u16, stations: &Stations) -> Result<Task, &'static str> {
    let (mode, from, to) = match spec {
        JobSpec::Store { to } => (Mode::Transfer, stations.inbound, coord(to)),
        JobSpec::Retrieve { from } => (Mode::Transfer, coord(from), stations.outbound),
        JobSpec::Move { from, to } => (Mode::Transfer, coord(from), coord(to)),
        JobSpec::Travel { to } => (Mode::Travel, [0; 4], coord(to)),
        JobSpec::Clear { .. } => return Err("a stacker crane has no clear task"),
        JobSpec::Light { .. } => return Err("a stacker crane has no lights"),
        JobSpec::Putaway { .. } => return Err("no location was chosen for this store"),
    };
    Ok(Task { number, mode, from, to })
}

/// The action state (D203) in words.
pub fn action_text(state: u16) -> &'static str {
    match state {
        0 => "idle",
        1 => "travelling toward pick, started",
        2 => "travelling toward pick",
        3 => "at pick, about to extend forks",
        4 | 14 => "extending forks",
        5 => "forks extended, about to lift",
        6 => "lifting pallet",
        7 => "lifted, about to retract",
        8 => "retracting with load",
        11 => "pallet taken, about to travel toward put",
        12 => "travelling toward put",
        13 => "at put, about to extend forks",
        15 => "forks extended, about to lower",
        16 => "lowering pallet",
        17 => "lowered, about to retract",
        18 => "retracting empty",
        20 => "task complete, waiting for acknowledgement",
        30 => "task force-completed, waiting for acknowledgement",
        40 => "task cancelled, waiting for acknowledgement",
        100 => "homing",
        _ => "unknown action state",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn loc(row: u16, bay: u16, level: u16, position: u16) -> Location {
        Location { aisle: 2, row, bay, level, position }
    }

    const ST: Stations = Stations { inbound: [2, 0, 1, 1], outbound: [1, 0, 1, 1] };

    #[test]
    fn jobs_map_to_modes_and_coordinates() {
        let t = task_for(&JobSpec::Store { to: loc(1, 5, 3, 2) }, 7, &ST).unwrap();
        assert_eq!(t.words(), [7, 2, 2, 0, 1, 1, 1, 5, 3, 2]);
        let t = task_for(&JobSpec::Retrieve { from: loc(2, 20, 8, 1) }, 8, &ST).unwrap();
        assert_eq!(t.words(), [8, 2, 2, 20, 8, 1, 1, 0, 1, 1]);
        let t = task_for(&JobSpec::Move { from: loc(1, 1, 1, 1), to: loc(2, 2, 2, 2) }, 9, &ST).unwrap();
        assert_eq!(t.words(), [9, 2, 1, 1, 1, 1, 2, 2, 2, 2]);
        let t = task_for(&JobSpec::Travel { to: loc(1, 4, 2, 1) }, 10, &ST).unwrap();
        assert_eq!(t.words(), [10, 1, 0, 0, 0, 0, 1, 4, 2, 1]);
        assert_eq!(t.cancel().words()[1], 3);
        assert_eq!(Task::from_words(&t.words()), Some(t));
        assert_eq!(Task::from_words(&t.cancel().words()), Some(t.cancel()));
        assert_eq!(Task::from_words(&[0, 2, 0, 0, 0, 0, 0, 0, 0, 0]), None, "no task number");
        assert_eq!(Task::from_words(&[5, 4, 0, 0, 0, 0, 0, 0, 0, 0]), None, "no such mode");
        assert_eq!(Task::from_words(&[5, 2]), None, "too few words");
        assert!(task_for(&JobSpec::Clear { location: loc(1, 1, 1, 1) }, 1, &ST).is_err());
    }

    #[test]
    fn view_reads_the_right_words() {
        let mut w = [0u16; 40];
        w[0] = 1;
        w[3] = 12;
        w[5] = 7069;
        w[6] = 1;
        w[8] = 42;
        w[20] = 5000;
        w[21] = 1500;
        w[23] = 20;
        w[25] = 1;
        let v = CraneView::parse(&w).unwrap();
        assert_eq!((v.heartbeat, v.action, v.alarm, v.load, v.task), (1, 12, 7069, 1, 42));
        assert_eq!((v.travel, v.lift, v.completion, v.ack), (5000, 1500, 20, 1));
        assert!(!v.is_idle());
        assert!(CraneView::parse(&w[..39]).is_none());
        assert!(CraneView::parse(&[0; 40]).unwrap().is_idle());
        let mut w = [0u16; 40];
        w[25] = 1;
        assert!(!CraneView::parse(&w).unwrap().is_idle(), "a crane that answered ACK holds a hand-over");
    }
}
