//! How a task ends: completion acknowledged (D22), cancel (mode 3) and the homing after it
//! (state 100), and the "force complete" button (state 30).

use std::time::Duration;

use tokio::time::Instant;

use super::{Engine, HOME, d, run, scaled, seconds, set, spot};
use crate::protocols::mc3e::Bank;

/// State 100 under way: from where, how long and how far in (simulated time).
#[derive(Clone, Debug)]
pub(super) struct Homing {
    from: (f64, f64),
    length: Duration,
    elapsed: Duration,
    clock: Instant,
}

impl Engine {
    /// Mode 3: a task under way (or halted by an alarm) ends in state 40; the alarm clears.
    /// A load on the platform goes back where it was picked (the inventory is as before
    /// the task); a load already lowered at the put stays there.
    pub(super) fn cancel(&mut self, bank: &mut Bank, now: Instant) {
        if let Some(run) = self.run.take() {
            if let Some(t) = self.timeline.as_mut() {
                t.ended(d(bank, 208), now, 40);
            }
            if run.picked
                && !run.put
                && let Some(inv) = self.inventory.as_mut()
            {
                inv.put(run.from);
            }
            self.stats.busy_secs += run.elapsed.as_secs_f64();
            self.stats.cancelled += 1;
            set(bank, 205, 0);
            set(bank, 206, 0);
            set(bank, 203, 40);
            set(bank, 223, 40);
        } else if crate::sim::crane::is_business(d(bank, 205)) {
            set(bank, 205, 0);
        }
    }

    pub(super) fn acknowledged(&mut self, bank: &mut Bank, now: Instant) {
        let cancelled = d(bank, 203) == 40;
        set(bank, 223, 0);
        for n in 208..218 {
            set(bank, n, 0);
        }
        if cancelled {
            set(bank, 203, 100);
            let length = match self.model {
                Some(m) => seconds(m.between(self.pos, m.metres(HOME))),
                None => self.step,
            };
            self.homing = Some(Homing { from: self.pos, length, elapsed: Duration::ZERO, clock: now });
        } else {
            set(bank, 203, 0);
        }
    }

    /// State 100: back to the stations, then idle.
    pub(super) fn home(&mut self, bank: &mut Bank, now: Instant) {
        let scale = self.time_scale;
        let Some(h) = self.homing.as_mut() else { return };
        h.elapsed += scaled(now.saturating_duration_since(h.clock), scale);
        h.clock = now;
        let h = h.clone();
        let done = h.elapsed >= h.length;
        if let Some(m) = self.model {
            let home = m.metres(HOME);
            self.move_to(bank, if done { home } else { m.along(h.from, home, h.elapsed.as_secs_f64()) });
        }
        if done {
            self.homing = None;
            self.stats.busy_secs += h.length.as_secs_f64();
            set(bank, 203, 0);
            if self.model.is_none() {
                set(bank, 220, 0);
                set(bank, 221, 0);
            }
        }
    }

    /// The "force complete" button: the task under way ends in state 30, its load carried
    /// by hand to the put (the inventory shows the task done).
    pub fn force_complete(&mut self, bank: &mut Bank) -> bool {
        let Some(run) = self.run.take() else { return false };
        if let Some(inv) = self.inventory.as_mut()
            && run.states.len() > 2
        {
            if !run.picked {
                inv.take(run.from);
            }
            if !run.put {
                inv.put(run.to);
            }
        }
        match self.model {
            Some(m) => self.pos = m.metres(spot(run.to)),
            None => run::place(bank, run.to),
        }
        self.stats.forced += 1;
        set(bank, 205, 0);
        set(bank, 206, 0);
        set(bank, 203, 30);
        set(bank, 223, 30);
        true
    }
}
