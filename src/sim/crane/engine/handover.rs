//! The crane's side of the interface with the WCS: the heartbeat watchdog, the STB/ACK
//! hand-over (spec steps 1..4) and the breaches of it counted as violations.

use tokio::time::Instant;

use super::{Engine, HEARTBEAT_ALARM, Hold, d, echo, set};
use crate::protocols::mc3e::Bank;

/// What the crane took at hand-over step 2, applied at step 4.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Taken {
    /// A task, with its words D8..D17 as taken.
    Task([u16; 10]),
    Cancel,
    Refused,
}

impl Engine {
    /// The spec's other half of the heartbeat: the crane raises 7020 when the WCS stalls.
    pub(super) fn watchdog(&mut self, bank: &mut Bank, now: Instant) {
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

    /// Counts the WCS's breaches of the hand-over rules (see the module doc).
    pub(super) fn check_interface(&mut self, bank: &Bank) {
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

    pub(super) fn handshake(&mut self, bank: &mut Bank, now: Instant) {
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
                    if let Some(t) = self.timeline.as_mut() {
                        t.received(words[0], now);
                    }
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
}
