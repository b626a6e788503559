//! A task in motion: the action states one after the other, each for its time (`step`, or
//! the motion model's: states 1, 2 and 11, 12 share the travel to the pick and to the put
//! half and half, states 3..8 and 13..18 share the fork cycle there in sixths); the axes
//! moving along the travel legs; the load taken at state 7 and set down at 17; and the
//! inventory's gates, checked as a state ends, that halt the task with a business alarm
//! (see [`super::super::inventory`]):
//! - leaving 3 (about to extend the forks at the pick): far pick behind a load, 7094/7098;
//! - leaving 8 (retracted at the pick) with nothing on the platform: 7069/7070;
//! - leaving 13 (about to extend the forks at the put): 7091..7093/7095..7097.
//!
//! A halted task stays in that state with its time stopped; if a person clears the alarm
//! instead of the WCS cancelling, the gate is checked again and raises it again.

use std::time::Duration;

use tokio::time::Instant;

use super::{Engine, d, scaled, seconds, set, spot};
use crate::protocols::mc3e::Bank;
use crate::sim::crane::inventory::{Cell, Inventory, is_station};
use crate::sim::crane::stats::{Pair, TaskKind};

/// Transfer: pick phase then put phase.
const TRANSFER: [u16; 16] = [1, 2, 3, 4, 5, 6, 7, 8, 11, 12, 13, 14, 15, 16, 17, 18];
/// Travel: only the travel states.
const TRAVEL: [u16; 2] = [1, 2];

/// A travel leg: from, to (metres) and its simulated seconds.
#[derive(Clone, Copy, Debug)]
struct Leg {
    from: (f64, f64),
    to: (f64, f64),
    secs: f64,
}

/// A task in motion.
#[derive(Clone, Debug)]
pub(super) struct Run {
    pub(super) states: &'static [u16],
    index: usize,
    pub(super) from: Cell,
    pub(super) to: Cell,
    /// Simulated time spent in the current state.
    pub(super) elapsed: Duration,
    /// The real instant up to which `elapsed` counts.
    clock: Instant,
    /// The travel leg under way, with a motion model.
    leg: Option<Leg>,
    /// Whether the load was taken from the pick (D206 = 1 since state 7).
    pub(super) picked: bool,
    /// Whether the load was set down at the put (state 17).
    pub(super) put: bool,
    /// This task's kind and that of the task before it, for the stats.
    pair: Pair,
}

impl Run {
    fn state(&self) -> u16 {
        self.states[self.index]
    }

    /// Where the current phase works: the pick in states 1..8 of a transfer, else the put
    /// (or the travel target).
    fn target(&self) -> Cell {
        if self.states.len() > 2 && self.state() < 10 { self.from } else { self.to }
    }
}

impl Engine {
    /// Starts the task whose words D209..D217 show.
    pub(super) fn start(&mut self, bank: &mut Bank, now: Instant) {
        let word = |k: u32| d(bank, k);
        let from = [word(210), word(211), word(212), word(213)];
        let to = [word(214), word(215), word(216), word(217)];
        let travel = word(209) == 1;
        if let Some(t) = self.timeline.as_mut() {
            t.started(word(208), now);
        }
        let states: &'static [u16] = if travel { &TRAVEL } else { &TRANSFER };
        set(bank, 203, states[0]);
        let next = TaskKind::of(from, to, travel);
        let pair = Pair { before: self.last_kind.replace(next), next };
        self.stats.began(pair);
        let mut run = Run {
            states,
            index: 0,
            from,
            to,
            elapsed: Duration::ZERO,
            clock: now,
            leg: None,
            picked: false,
            put: false,
            pair,
        };
        self.begin_leg(&mut run);
        self.run = Some(run);
    }

    /// Runs the task under way up to `now`, unless an alarm halts it.
    pub(super) fn drive(&mut self, bank: &mut Bank, now: Instant) {
        let Some(mut run) = self.run.take() else { return };
        let dt = scaled(now.saturating_duration_since(run.clock), self.time_scale);
        run.clock = now;
        if d(bank, 205) == 0 {
            run.elapsed += dt;
            if !self.advance(bank, &mut run, now) {
                return;
            }
        }
        self.follow(bank, &run);
        self.run = Some(run);
    }

    /// Goes through the states whose time is up (one per tick without a motion model, as
    /// the crane always did); false once the task completed.
    fn advance(&mut self, bank: &mut Bank, run: &mut Run, now: Instant) -> bool {
        loop {
            let length = self.length(run);
            if run.elapsed < length {
                return true;
            }
            if let Some(code) = self.gate(run) {
                run.elapsed = length;
                self.raise(bank, code);
                return true;
            }
            self.stats.spent(run.state(), length.as_secs_f64(), run.pair);
            run.elapsed = if self.model.is_some() { run.elapsed - length } else { Duration::ZERO };
            run.index += 1;
            let Some(&state) = run.states.get(run.index) else {
                // The time left over went past the end: the task ended that much earlier.
                let ended = now.checked_sub(run.elapsed.div_f64(self.time_scale)).unwrap_or(now);
                self.complete(bank, run, ended);
                return false;
            };
            set(bank, 203, state);
            self.enter(bank, run, state);
            if self.model.is_none() {
                return true;
            }
        }
    }

    /// The simulated length of the current state.
    fn length(&self, run: &Run) -> Duration {
        let Some(m) = self.model else { return self.step };
        match run.state() {
            1 | 2 | 11 | 12 => seconds(run.leg.map_or(0.0, |l| l.secs) / 2.0),
            _ => seconds(m.fork_time(run.target()[3]) / 6.0),
        }
    }

    /// The business alarm that stops the current state from ending, if any.
    fn gate(&self, run: &Run) -> Option<u16> {
        let inv = self.inventory.as_ref()?;
        match run.state() {
            3 => inv.pick_blocked(run.from),
            8 if !run.picked => Some(Inventory::no_load(run.from)),
            13 => inv.put_blocked(run.to),
            _ => None,
        }
    }

    fn enter(&mut self, bank: &mut Bank, run: &mut Run, state: u16) {
        match state {
            3 | 13 => {
                self.arrive(bank, run);
                if self.model.is_none() {
                    place(bank, run.target());
                }
            }
            7 => {
                let found = match self.inventory.as_mut() {
                    Some(inv) => is_station(run.from) || inv.take(run.from),
                    None => true,
                };
                if found {
                    run.picked = true;
                    set(bank, 206, 1);
                }
            }
            11 => self.begin_leg(run),
            17 => {
                set(bank, 206, 0);
                run.put = true;
                if let Some(inv) = self.inventory.as_mut() {
                    inv.put(run.to);
                }
            }
            _ => {}
        }
    }

    fn complete(&mut self, bank: &mut Bank, run: &mut Run, at: Instant) {
        self.arrive(bank, run);
        if let Some(t) = self.timeline.as_mut() {
            t.ended(d(bank, 208), at, 20);
        }
        if self.model.is_none() {
            place(bank, run.to);
        }
        self.stats.cycles += 1;
        set(bank, 203, 20);
        set(bank, 223, 20);
    }

    /// Starts the travel leg toward the current phase's target (with a motion model).
    fn begin_leg(&self, run: &mut Run) {
        if let Some(m) = self.model {
            let to = m.metres(spot(run.target()));
            run.leg = Some(Leg { from: self.pos, to, secs: m.between(self.pos, to) });
        }
    }

    /// Ends the travel leg under way: the crane stands at its end.
    fn arrive(&mut self, bank: &Bank, run: &mut Run) {
        if let Some(leg) = run.leg.take() {
            self.move_to(bank, leg.to);
        }
    }

    /// Moves the axes along the leg under way to where it stands now.
    fn follow(&mut self, bank: &Bank, run: &Run) {
        let (Some(m), Some(leg)) = (self.model, run.leg) else { return };
        let before = if matches!(run.state(), 2 | 12) { seconds(leg.secs / 2.0) } else { Duration::ZERO };
        self.move_to(bank, m.along(leg.from, leg.to, (before + run.elapsed).as_secs_f64()));
    }
}

/// Puts the axes at a coordinate without a motion model: travel = bay x 1000, lift =
/// level x 500.
pub(super) fn place(bank: &mut Bank, at: Cell) {
    set(bank, 220, at[1].saturating_mul(1000));
    set(bank, 221, at[2].saturating_mul(500));
}
