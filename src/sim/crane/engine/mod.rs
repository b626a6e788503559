//! The simulated crane's behaviour over its D registers: heartbeat answer, STB/ACK
//! hand-over (`handover.rs`), motion through the action states (`run.rs`), completion and
//! its acknowledgement, cancel, homing (`ending.rs`), alarms and forced completion. Pure:
//! it works on a [`Bank`] and an instant, so every step is deterministic.
//!
//! It also watches the WCS keep the interface's rules and counts each breach in
//! [`Engine::violations`] (tests assert none): a strobe raised while ACK is still 1, a
//! strobe raised for a task (mode 1/2) while the crane holds one (latched or running, D208
//! set, D223 set, or homing), and task words D8..D17 changed while the strobe is up.
//! [`Engine::hold`] freezes its side of the hand-over at a chosen step, so a test can stop
//! and restart the WCS with the crane at exactly that step.
//!
//! Time: without a motion model every action state (and homing) takes `step`; with one
//! ([`Engine::set_motion`]) the states take the model's times, divided by the time scale
//! (simulated seconds per real second; `step` is divided by it too). Time halted under an
//! alarm does not count: the state resumes where it stopped once the alarm clears.
//!
//! Where the crane stands, with a motion model: it starts at the stations (bay 0, level 1),
//! stands where its last task ended, stops where a cancel catches it, and homes to bay 0,
//! level 1 after a cancel is acknowledged. D220/D221 show its travel and lift position in
//! centimetres from the origin (bay 0, level 0: level 1 of the default model is at 150 cm),
//! updated at every tick while it moves. Without a model they jump as they always did:
//! travel = bay x 1000, lift = level x 500, at the pick, at the put, and 0 after homing.

mod ending;
mod handover;
#[cfg(test)]
mod model_tests;
mod run;
#[cfg(test)]
mod tests;

use std::collections::HashMap;
use std::time::Duration;

use tokio::time::Instant;

use super::inventory::{Cell, Inventory};
use super::stats::{CraneStats, TaskKind};
use super::timeline::Timeline;
use crate::protocols::mc3e::{Bank, Device};
use crate::wire::motion::{Motion, Spot};
use ending::Homing;
use run::Run;

/// The crane's heartbeat alarm.
const HEARTBEAT_ALARM: u16 = 7020;

/// Where the crane homes to and starts from (the stations' bay and level).
const HOME: Spot = Spot { bay: 0, level: 1 };

fn d(bank: &Bank, n: u32) -> u16 {
    bank.word(Device::D, n)
}

fn set(bank: &mut Bank, n: u32, v: u16) {
    bank.set_word(Device::D, n, v);
}

/// Where the crane's side of the hand-over stops while held (tests staging a WCS cut at
/// one step).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Hold {
    /// Step 2 withheld: the crane does not take the data (ACK stays 0).
    BeforeAck,
    /// Step 4 withheld: the crane took the data (ACK = 1, D208 set) but does not see the
    /// strobe go down, so neither clears ACK nor starts.
    BeforeStart,
}

/// The crane's memory of what it is doing, next to its registers.
#[derive(Debug)]
pub struct Engine {
    /// Time of each action state without a motion model (and of homing).
    pub step: Duration,
    /// Whether it answers the WCS's heartbeat.
    pub heartbeat_on: bool,
    /// Whether it answers the strobe (off: a crane deaf to hand-overs).
    pub handshake_on: bool,
    /// Where its side of the hand-over stops, if held.
    pub hold: Option<Hold>,
    /// A slow crane program: it shows the task words (D208..D217) only when it starts the
    /// task, and starts one `step` after it cleared ACK (step 4), so for that step its
    /// block shows nothing of the task it holds. The spec leaves both moments open.
    pub late_start: bool,
    /// A task taken and ACK cleared, to start at that instant (`late_start`).
    starting: Option<([u16; 10], Instant)>,
    /// The crane's watchdog on the WCS heartbeat (D0): alarm 7020 when D0 stays the same
    /// this long; cleared by the crane once D0 moves again. None: no watchdog.
    pub wcs_timeout: Option<Duration>,
    wcs_seen: Option<u16>,
    wcs_changed: Instant,
    taken: Option<handover::Taken>,
    run: Option<Run>,
    homing: Option<Homing>,
    /// The motion model, if any (see the module doc).
    model: Option<Motion>,
    /// Simulated seconds per real second (1: real time).
    pub time_scale: f64,
    /// Where the crane stands, metres (travel, lift); used with a motion model.
    pos: (f64, f64),
    /// The occupied cells, if tracked (None: every pick finds a load, every put fits).
    pub inventory: Option<Inventory>,
    /// Counters for a benchmark.
    pub stats: CraneStats,
    /// Each task's instants, when recorded (None: not recorded).
    pub timeline: Option<Timeline>,
    /// The kind of the last task started, for the stats' pairs.
    last_kind: Option<TaskKind>,
    /// Tasks received (mode 1 or 2 hand-overs) per task number.
    pub received: HashMap<u16, u32>,
    /// Cancels (mode 3) received.
    pub cancels: u32,
    /// Hand-overs refused because the crane was busy.
    pub refused: u32,
    /// Each breach of the interface by the WCS, in words, in order.
    pub violations: Vec<String>,
    /// The strobe (D21) at the last tick, to see it rise.
    last_stb: u16,
    /// The task words D8..D17 when the strobe rose.
    strobed_words: Option<Vec<u16>>,
}

impl Engine {
    /// An idle crane whose action states take `step` each.
    pub fn new(step: Duration) -> Engine {
        Engine {
            step,
            heartbeat_on: true,
            handshake_on: true,
            hold: None,
            late_start: false,
            starting: None,
            wcs_timeout: None,
            wcs_seen: None,
            wcs_changed: Instant::now(),
            taken: None,
            run: None,
            homing: None,
            model: None,
            time_scale: 1.0,
            pos: (0.0, 0.0),
            inventory: None,
            stats: CraneStats::default(),
            timeline: None,
            last_kind: None,
            received: HashMap::new(),
            cancels: 0,
            refused: 0,
            violations: Vec::new(),
            last_stb: 0,
            strobed_words: None,
        }
    }

    /// Moves by a motion model (None: `step` per state); the crane stands at home.
    pub fn set_motion(&mut self, model: Option<Motion>) {
        self.model = model;
        self.pos = model.map_or((0.0, 0.0), |m| m.metres(HOME));
    }

    /// The motion model, if any.
    pub fn motion(&self) -> Option<&Motion> {
        self.model.as_ref()
    }

    /// Where the crane stands, metres along the travel and lift axes (a motion model's).
    pub fn position(&self) -> (f64, f64) {
        self.pos
    }

    /// Advances the crane to `now`.
    pub fn tick(&mut self, bank: &mut Bank, now: Instant) {
        if self.heartbeat_on {
            match (d(bank, 0), d(bank, 200)) {
                (1, 0) => set(bank, 200, 1),
                (0, 1) => set(bank, 200, 0),
                _ => {}
            }
        }
        self.watchdog(bank, now);
        self.check_interface(bank);
        self.handshake(bank, now);
        if let Some((words, at)) = self.starting
            && now >= at
        {
            self.starting = None;
            echo(bank, &words);
            self.start(bank, now);
        }
        self.drive(bank, now);
        if d(bank, 223) != 0 && d(bank, 22) != 0 {
            self.acknowledged(bank, now);
        }
        self.home(bank, now);
        if self.model.is_some() {
            set(bank, 220, centimetres(self.pos.0));
            set(bank, 221, centimetres(self.pos.1));
        }
    }

    fn busy(&self, bank: &Bank) -> bool {
        self.run.is_some()
            || self.taken.is_some()
            || self.starting.is_some()
            || d(bank, 223) != 0
            || d(bank, 208) != 0
            || self.homing.is_some()
    }

    /// Raises a business alarm of the crane's own and counts it.
    fn raise(&mut self, bank: &mut Bank, code: u16) {
        set(bank, 205, code);
        self.stats.alarm(code);
    }

    /// Moves the crane's position, counting the distance by the load on the platform.
    fn move_to(&mut self, bank: &Bank, to: (f64, f64)) {
        self.stats.moved(to.0 - self.pos.0, to.1 - self.pos.1, d(bank, 206) != 0);
        self.pos = to;
    }

    /// Counts a business alarm raised from outside (by hand).
    pub fn count_alarm(&mut self, code: u16) {
        self.stats.alarm(code);
    }

    /// The occupied cells, if tracked.
    pub fn cells(&self) -> Option<Vec<Cell>> {
        self.inventory.as_ref().map(Inventory::cells)
    }
}

/// Shows task words in D208..D217.
fn echo(bank: &mut Bank, words: &[u16; 10]) {
    for (k, w) in words.iter().enumerate() {
        set(bank, 208 + k as u32, *w);
    }
}

/// The spot of a coordinate.
fn spot(at: Cell) -> Spot {
    Spot { bay: at[1], level: at[2] }
}

/// Simulated time in `real` time at `scale` simulated seconds per second (exact at 1).
fn scaled(real: Duration, scale: f64) -> Duration {
    if scale == 1.0 { real } else { real.mul_f64(scale) }
}

/// A duration of `secs` simulated seconds (0 if not a positive finite number).
fn seconds(secs: f64) -> Duration {
    Duration::try_from_secs_f64(secs).unwrap_or(Duration::ZERO)
}

/// Metres as D220/D221 show them: centimetres, clamped to a word.
fn centimetres(m: f64) -> u16 {
    (m * 100.0).round().clamp(0.0, u16::MAX as f64) as u16
}
