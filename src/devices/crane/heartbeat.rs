//! The 4-step heartbeat (D0 rackd, D200 crane): rackd answers the crane's 0 with 1 and its
//! 1 with 0, at most once per period; the crane is lost when its word stays the same for
//! the loss timeout. Pure logic over instants, so it is tested without sockets.

use std::time::Duration;

use tokio::time::Instant;

/// rackd's side of the heartbeat.
#[derive(Debug)]
pub struct Heartbeat {
    period: Duration,
    timeout: Duration,
    seen: Option<u16>,
    changed_at: Instant,
    written: Option<u16>,
    written_at: Option<Instant>,
}

impl Heartbeat {
    /// A heartbeat that writes at most every `period` and declares the crane lost after
    /// `timeout` without change; the clock starts at `now`.
    pub fn new(period: Duration, timeout: Duration, now: Instant) -> Heartbeat {
        Heartbeat { period, timeout, seen: None, changed_at: now, written: None, written_at: None }
    }

    /// Takes rackd's own word as found in the PLC (after a restart).
    pub fn found(&mut self, written: u16) {
        self.written = Some(written);
    }

    /// Takes the crane's word read at `now`; returns the word to write to D0, if any.
    pub fn observe(&mut self, crane: u16, now: Instant) -> Option<u16> {
        if self.seen != Some(crane) {
            self.seen = Some(crane);
            self.changed_at = now;
        }
        let want = u16::from(crane == 0);
        let due = self.written_at.is_none_or(|at| now.duration_since(at) >= self.period);
        (self.written != Some(want) && due).then_some(want)
    }

    /// Records that `word` was written at `now`.
    pub fn wrote(&mut self, word: u16, now: Instant) {
        self.written = Some(word);
        self.written_at = Some(now);
    }

    /// Starts the loss clock again at `now`: after the link was down rackd could not see
    /// the word move, so the crane gets a whole timeout to show it moves.
    pub fn restart(&mut self, now: Instant) {
        self.changed_at = now;
    }

    /// The crane's word has not moved for the loss timeout.
    pub fn is_lost(&self, now: Instant) -> bool {
        now.duration_since(self.changed_at) >= self.timeout
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn answers_each_step_and_detects_a_stall() {
        let t0 = Instant::now();
        let ms = Duration::from_millis;
        let mut h = Heartbeat::new(ms(100), ms(1000), t0);
        assert_eq!(h.observe(0, t0), Some(1)); // step 1
        h.wrote(1, t0);
        assert_eq!(h.observe(0, t0 + ms(50)), None); // crane not answered yet
        assert_eq!(h.observe(1, t0 + ms(60)), None); // step 3 waits for the period
        assert_eq!(h.observe(1, t0 + ms(100)), Some(0));
        h.wrote(0, t0 + ms(100));
        assert!(!h.is_lost(t0 + ms(900)));
        // The crane stops answering: its word stays 1.
        assert_eq!(h.observe(1, t0 + ms(1000)), None);
        assert!(!h.is_lost(t0 + ms(1000)));
        assert!(h.is_lost(t0 + ms(1060)));
        // It moves again: found at once.
        assert_eq!(h.observe(0, t0 + ms(1100)), Some(1));
        assert!(!h.is_lost(t0 + ms(1100)));
    }

    #[test]
    fn restart_keeps_the_word_found() {
        let t0 = Instant::now();
        let mut h = Heartbeat::new(Duration::ZERO, Duration::from_secs(1), t0);
        h.found(1);
        assert_eq!(h.observe(0, t0), None);
        assert_eq!(h.observe(1, t0), Some(0));
    }
}
