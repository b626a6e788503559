//! The simulated crane's behaviour over its D registers: heartbeat answer, STB/ACK
//! hand-over, motion through the action states, completion and its acknowledgement,
//! cancel, homing, alarms and forced completion. Pure: it works on a [`Bank`] and an
//! instant, so every step is deterministic.
//!
//! It also watches the WCS keep the interface's rules and counts each breach in
//! [`Engine::violations`] (tests assert none): a strobe raised while ACK is still 1, a
//! strobe raised for a task (mode 1/2) while the crane holds one (latched or running, D208
//! set, D223 set, or homing), and task words D8..D17 changed while the strobe is up.
//! [`Engine::hold`] freezes its side of the hand-over at a chosen step, so a test can stop
//! and restart the WCS with the crane at exactly that step.

use std::collections::HashMap;
use std::time::Duration;

use tokio::time::Instant;

use crate::protocols::mc3e::{Bank, Device};

/// Transfer: pick phase then put phase.
const TRANSFER: [u16; 16] = [1, 2, 3, 4, 5, 6, 7, 8, 11, 12, 13, 14, 15, 16, 17, 18];
/// Travel: only the travel states.
const TRAVEL: [u16; 2] = [1, 2];

/// The crane's heartbeat alarm.
const HEARTBEAT_ALARM: u16 = 7020;

fn d(bank: &Bank, n: u32) -> u16 {
    bank.word(Device::D, n)
}

fn set(bank: &mut Bank, n: u32, v: u16) {
    bank.set_word(Device::D, n, v);
}

/// What the crane took at hand-over step 2, applied at step 4.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Taken {
    /// A task, with its words D8..D17 as taken.
    Task([u16; 10]),
    Cancel,
    Refused,
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

/// A task in motion.
#[derive(Clone, Debug)]
struct Motion {
    states: &'static [u16],
    index: usize,
    from: [u16; 4],
    to: [u16; 4],
}

/// The crane's memory of what it is doing, next to its registers.
#[derive(Debug)]
pub struct Engine {
    /// Time of each action state.
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
    taken: Option<Taken>,
    motion: Option<Motion>,
    next_step: Instant,
    homing_until: Option<Instant>,
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
            motion: None,
            next_step: Instant::now(),
            homing_until: None,
            received: HashMap::new(),
            cancels: 0,
            refused: 0,
            violations: Vec::new(),
            last_stb: 0,
            strobed_words: None,
        }
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
        self.motion(bank, now);
        if d(bank, 223) != 0 && d(bank, 22) != 0 {
            self.acknowledged(bank, now);
        }
        if self.homing_until.is_some_and(|t| now >= t) {
            self.homing_until = None;
            set(bank, 203, 0);
            set(bank, 220, 0);
            set(bank, 221, 0);
        }
    }

    /// The spec's other half of the heartbeat: the crane raises 7020 when the WCS stalls.
    fn watchdog(&mut self, bank: &mut Bank, now: Instant) {
        let Some(limit) = self.wcs_timeout else { return };
        let word = d(bank, 0);
        if self.wcs_seen != Some(word) {
            self.wcs_seen = Some(word);
            self.wcs_changed = now;
            if d(bank, 205) == HEARTBEAT_ALARM {
                set(bank, 205, 0);
            }
        } else if now.duration_since(self.wcs_changed) >= limit && d(bank, 205) == 0 {
            set(bank, 205, HEARTBEAT_ALARM);
        }
    }

    fn busy(&self, bank: &Bank) -> bool {
        self.motion.is_some()
            || self.taken.is_some()
            || self.starting.is_some()
            || d(bank, 223) != 0
            || d(bank, 208) != 0
            || self.homing_until.is_some()
    }

    /// Counts the WCS's breaches of the hand-over rules (see the module doc).
    fn check_interface(&mut self, bank: &Bank) {
        let stb = d(bank, 21);
        let words: Vec<u16> = (8..18).map(|n| d(bank, n)).collect();
        if stb != 0 && self.last_stb == 0 {
            if d(bank, 225) != 0 {
                self.violations
                    .push(format!("strobe raised for task {} while ACK (D225) is still 1", words[0]));
            }
            if matches!(words[1], 1 | 2) && self.busy(bank) {
                self.violations.push(format!(
                    "task {} (mode {}) strobed while the crane holds a task (D208 {}, D203 {}, D223 {})",
                    words[0],
                    words[1],
                    d(bank, 208),
                    d(bank, 203),
                    d(bank, 223)
                ));
            }
            self.strobed_words = Some(words);
        } else if stb != 0 && self.strobed_words.as_ref() != Some(&words) {
            self.violations.push(format!("task words D8..D17 changed to {words:?} while STB = 1"));
            self.strobed_words = Some(words);
        }
        self.last_stb = stb;
    }

    fn handshake(&mut self, bank: &mut Bank, now: Instant) {
        if !self.handshake_on {
            return;
        }
        match (d(bank, 21), d(bank, 225)) {
            (1, 0) if self.hold != Some(Hold::BeforeAck) => {
                let mut words = [0u16; 10];
                for (k, w) in words.iter_mut().enumerate() {
                    *w = d(bank, 8 + k as u32);
                }
                let taken = if words[1] == 3 {
                    self.cancels += 1;
                    Taken::Cancel
                } else if self.busy(bank) || !matches!(words[1], 1 | 2) {
                    self.refused += 1;
                    Taken::Refused
                } else {
                    *self.received.entry(words[0]).or_default() += 1;
                    if !self.late_start {
                        echo(bank, &words);
                    }
                    Taken::Task(words)
                };
                self.taken = Some(taken);
                set(bank, 225, 1);
            }
            (0, 1) if self.hold != Some(Hold::BeforeStart) => {
                set(bank, 225, 0);
                match self.taken.take() {
                    Some(Taken::Task(words)) if self.late_start => {
                        self.starting = Some((words, now + self.step))
                    }
                    Some(Taken::Task(words)) => {
                        echo(bank, &words);
                        self.start(bank, now);
                    }
                    Some(Taken::Cancel) => self.cancel(bank, now),
                    _ => {}
                }
            }
            _ => {}
        }
    }

    fn start(&mut self, bank: &mut Bank, now: Instant) {
        let word = |k: u32| d(bank, k);
        let from = [word(210), word(211), word(212), word(213)];
        let to = [word(214), word(215), word(216), word(217)];
        let states: &'static [u16] = if word(209) == 1 { &TRAVEL } else { &TRANSFER };
        set(bank, 203, states[0]);
        self.motion = Some(Motion { states, index: 0, from, to });
        self.next_step = now + self.step;
    }

    /// Mode 3: a task under way (or halted by an alarm) ends in state 40; the alarm clears.
    fn cancel(&mut self, bank: &mut Bank, _now: Instant) {
        if self.motion.take().is_some() {
            set(bank, 205, 0);
            set(bank, 206, 0);
            set(bank, 203, 40);
            set(bank, 223, 40);
        } else if super::is_business(d(bank, 205)) {
            set(bank, 205, 0);
        }
    }

    fn motion(&mut self, bank: &mut Bank, now: Instant) {
        if d(bank, 205) != 0 || now < self.next_step {
            return;
        }
        if self.motion.is_none() {
            return;
        }
        self.next_step = now + self.step;
        let Some(m) = self.motion.as_mut() else { return };
        m.index += 1;
        let Some(&state) = m.states.get(m.index) else {
            let to = m.to;
            self.motion = None;
            place(bank, to);
            set(bank, 203, 20);
            set(bank, 223, 20);
            return;
        };
        set(bank, 203, state);
        match state {
            3 => place(bank, m.from),
            7 => set(bank, 206, 1),
            13 => place(bank, m.to),
            17 => set(bank, 206, 0),
            _ => {}
        }
    }

    fn acknowledged(&mut self, bank: &mut Bank, now: Instant) {
        let cancelled = d(bank, 203) == 40;
        set(bank, 223, 0);
        for n in 208..218 {
            set(bank, n, 0);
        }
        if cancelled {
            set(bank, 203, 100);
            self.homing_until = Some(now + self.step);
        } else {
            set(bank, 203, 0);
        }
    }

    /// The "force complete" button: the task under way ends in state 30.
    pub fn force_complete(&mut self, bank: &mut Bank) -> bool {
        let Some(m) = self.motion.take() else { return false };
        place(bank, m.to);
        set(bank, 205, 0);
        set(bank, 206, 0);
        set(bank, 203, 30);
        set(bank, 223, 30);
        true
    }
}

/// Shows task words in D208..D217.
fn echo(bank: &mut Bank, words: &[u16; 10]) {
    for (k, w) in words.iter().enumerate() {
        set(bank, 208 + k as u32, *w);
    }
}

/// Puts the axes at a coordinate: travel = bay x 1000, lift = level x 500.
fn place(bank: &mut Bank, at: [u16; 4]) {
    set(bank, 220, at[1].saturating_mul(1000));
    set(bank, 221, at[2].saturating_mul(500));
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(e: &mut Engine, bank: &mut Bank, now: &mut Instant, ticks: usize) {
        for _ in 0..ticks {
            *now += Duration::from_millis(10);
            e.tick(bank, *now);
        }
    }

    #[test]
    fn a_transfer_runs_through_the_handshake_to_completion() {
        let mut bank = Bank::default();
        let mut e = Engine::new(Duration::from_millis(10));
        let mut now = Instant::now();
        for (k, w) in [5u16, 2, 2, 0, 1, 1, 1, 3, 2, 1].iter().enumerate() {
            bank.set_word(Device::D, 8 + k as u32, *w);
        }
        bank.set_word(Device::D, 21, 1);
        e.tick(&mut bank, now);
        assert_eq!((d(&bank, 225), d(&bank, 208)), (1, 5));
        bank.set_word(Device::D, 21, 0);
        e.tick(&mut bank, now);
        assert_eq!((d(&bank, 225), d(&bank, 203)), (0, 1));
        run(&mut e, &mut bank, &mut now, 20);
        assert_eq!((d(&bank, 203), d(&bank, 223), d(&bank, 220)), (20, 20, 3000));
        bank.set_word(Device::D, 22, 1);
        e.tick(&mut bank, now);
        assert_eq!((d(&bank, 203), d(&bank, 223), d(&bank, 208)), (0, 0, 0));
        assert_eq!(e.received[&5], 1);
    }

    fn strobe(e: &mut Engine, bank: &mut Bank, now: Instant, words: [u16; 10]) {
        for (k, w) in words.iter().enumerate() {
            bank.set_word(Device::D, 8 + k as u32, *w);
        }
        bank.set_word(Device::D, 21, 1);
        e.tick(bank, now);
    }

    #[test]
    fn a_hold_freezes_the_hand_over_at_its_step_and_breaches_are_counted() {
        let mut bank = Bank::default();
        let mut e = Engine::new(Duration::from_millis(10));
        let now = Instant::now();
        e.hold = Some(Hold::BeforeAck);
        strobe(&mut e, &mut bank, now, [5, 1, 0, 0, 0, 0, 1, 3, 1, 1]);
        assert_eq!(d(&bank, 225), 0, "held before step 2");
        e.hold = Some(Hold::BeforeStart);
        e.tick(&mut bank, now);
        assert_eq!((d(&bank, 225), d(&bank, 208)), (1, 5), "latched");
        bank.set_word(Device::D, 21, 0);
        e.tick(&mut bank, now);
        assert_eq!((d(&bank, 225), d(&bank, 203)), (1, 0), "held before step 4: not started");
        assert!(e.violations.is_empty(), "{:?}", e.violations);
        // A WCS that hands over another task now breaks the scheme twice over.
        strobe(&mut e, &mut bank, now, [6, 2, 0, 0, 0, 0, 1, 3, 1, 1]);
        assert_eq!(e.violations.len(), 2, "{:?}", e.violations);
        bank.set_word(Device::D, 15, 9);
        e.tick(&mut bank, now);
        assert_eq!(e.violations.len(), 3, "words changed under the strobe: {:?}", e.violations);
        bank.set_word(Device::D, 21, 0);
        e.hold = None;
        e.tick(&mut bank, now);
        assert_eq!((d(&bank, 225), d(&bank, 203)), (0, 1), "released: starts the task it latched");
        assert_eq!(e.received.get(&6), None, "the second task was never taken");
    }

    #[test]
    fn the_watchdog_raises_7020_when_the_wcs_stalls_and_clears_it_when_it_moves() {
        let mut bank = Bank::default();
        let mut e = Engine::new(Duration::from_millis(10));
        e.wcs_timeout = Some(Duration::from_millis(100));
        let mut now = Instant::now();
        run(&mut e, &mut bank, &mut now, 5);
        assert_eq!(d(&bank, 205), 0);
        run(&mut e, &mut bank, &mut now, 10);
        assert_eq!(d(&bank, 205), HEARTBEAT_ALARM);
        bank.set_word(Device::D, 0, 1);
        run(&mut e, &mut bank, &mut now, 1);
        assert_eq!(d(&bank, 205), 0);
    }

    #[test]
    fn an_alarm_halts_and_a_cancel_ends_in_40() {
        let mut bank = Bank::default();
        let mut e = Engine::new(Duration::from_millis(10));
        let mut now = Instant::now();
        bank.set_word(Device::D, 8, 9);
        bank.set_word(Device::D, 9, 2);
        bank.set_word(Device::D, 21, 1);
        e.tick(&mut bank, now);
        bank.set_word(Device::D, 21, 0);
        e.tick(&mut bank, now);
        run(&mut e, &mut bank, &mut now, 3);
        bank.set_word(Device::D, 205, 7069);
        let halted = d(&bank, 203);
        run(&mut e, &mut bank, &mut now, 5);
        assert_eq!(d(&bank, 203), halted);
        bank.set_word(Device::D, 9, 3);
        bank.set_word(Device::D, 21, 1);
        e.tick(&mut bank, now);
        bank.set_word(Device::D, 21, 0);
        e.tick(&mut bank, now);
        assert_eq!((d(&bank, 203), d(&bank, 223), d(&bank, 205)), (40, 40, 0));
        bank.set_word(Device::D, 22, 1);
        e.tick(&mut bank, now);
        assert_eq!(d(&bank, 203), 100);
        run(&mut e, &mut bank, &mut now, 2);
        assert_eq!(d(&bank, 203), 0);
    }
}
