//! The pure arithmetic of a link's health: the retransmission timer ([`RttEstimator`]) and
//! the degraded judgement over recent requests ([`LossWindow`]). No I/O and no clock: the
//! caller hands in round trips and outcomes, so both are tested on their own.
//!
//! # The timer (RFC 6298)
//! - Before the first sample the timeout is the configured one (the ceiling): nothing is
//!   known of the device yet, and a too-short first guess would look like loss.
//! - The first sample `R` sets `SRTT = R`, `RTTVAR = R/2`; each later one
//!   `RTTVAR = 3/4 RTTVAR + 1/4 |SRTT - R|`, then `SRTT = 7/8 SRTT + 1/8 R`.
//! - `RTO = SRTT + max(G, 4 RTTVAR)` with a clock granularity `G` of 1 ms, clamped between
//!   the floor (`min_timeout_ms`) and the ceiling (`timeout_ms`). The floor keeps a link that
//!   answered in microseconds a few times from timing out on the first scheduling hiccup.
//! - An attempt that times out doubles the RTO (RFC 6298 5.5), up to the ceiling, and the
//!   doubled value stays until the next sample: a device that became slow is found again
//!   (the doubled timeout lets its reply in) instead of being timed out for ever.
//! - Karn's rule is the caller's: it only hands in a round trip it can attribute to one
//!   transmission (see [`super::retry::Retry::succeeded`]).

use std::collections::VecDeque;
use std::time::Duration;

/// Clock granularity `G` of RFC 6298.
const GRANULARITY: Duration = Duration::from_millis(1);

/// The smoothed round trip and its variation, and the timeout they give.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct RttEstimator {
    floor: Duration,
    ceiling: Duration,
    srtt: Option<Duration>,
    rttvar: Duration,
    rto: Duration,
}

impl RttEstimator {
    /// An estimator with no sample yet: the timeout is `ceiling`. A floor above the ceiling
    /// is taken as the ceiling.
    pub fn new(floor: Duration, ceiling: Duration) -> Self {
        RttEstimator { floor: floor.min(ceiling), ceiling, srtt: None, rttvar: Duration::ZERO, rto: ceiling }
    }

    /// Takes one measured round trip.
    pub fn sample(&mut self, r: Duration) {
        match self.srtt {
            None => {
                self.srtt = Some(r);
                self.rttvar = r / 2;
            }
            Some(srtt) => {
                let diff = srtt.abs_diff(r);
                self.rttvar = self.rttvar * 3 / 4 + diff / 4;
                self.srtt = Some(srtt * 7 / 8 + r / 8);
            }
        }
        let srtt = self.srtt.unwrap_or(r);
        self.rto = self.clamp(srtt + (self.rttvar * 4).max(GRANULARITY));
    }

    /// An attempt timed out: the timeout doubles, up to the ceiling, until the next sample.
    pub fn backed_off(&mut self) {
        self.rto = self.clamp(self.rto.saturating_mul(2));
    }

    /// The timeout for the next attempt.
    pub fn timeout(&self) -> Duration {
        self.rto
    }

    /// The smoothed round trip, once there was a sample.
    pub fn srtt(&self) -> Option<Duration> {
        self.srtt
    }

    fn clamp(&self, d: Duration) -> Duration {
        d.max(self.floor).min(self.ceiling)
    }
}

/// When a link counts as degraded: the share of recent requests that needed a retry (or
/// failed) rises above `above`; it counts as healthy again only once the share falls to
/// `below` or less (hysteresis, so a link near the threshold does not flap).
#[derive(Clone, Debug)]
pub(crate) struct LossWindow {
    window: usize,
    above: f64,
    below: f64,
    recent: VecDeque<bool>,
    troubled: usize,
    degraded: bool,
}

impl LossWindow {
    /// A window of the last `window` requests (at least 1).
    pub fn new(window: u32, above: f64, below: f64) -> Self {
        let window = (window as usize).max(1);
        LossWindow {
            window,
            above,
            below,
            recent: VecDeque::with_capacity(window),
            troubled: 0,
            degraded: false,
        }
    }

    /// Records one finished request (`troubled`: it needed a retry or failed) and returns
    /// whether the link is degraded now. Judged only over a full window, so one unlucky
    /// request at start does not flag a device.
    pub fn record(&mut self, troubled: bool) -> bool {
        if self.recent.len() == self.window && self.recent.pop_front() == Some(true) {
            self.troubled -= 1;
        }
        self.recent.push_back(troubled);
        self.troubled += usize::from(troubled);
        if self.recent.len() == self.window {
            let share = self.troubled as f64 / self.window as f64;
            if share > self.above {
                self.degraded = true;
            } else if share <= self.below {
                self.degraded = false;
            }
        }
        self.degraded
    }

    /// Whether the link is degraded.
    pub fn degraded(&self) -> bool {
        self.degraded
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: fn(u64) -> Duration = Duration::from_millis;

    #[test]
    fn the_timeout_starts_at_the_ceiling_and_follows_samples() {
        let mut e = RttEstimator::new(MS(20), MS(300));
        assert_eq!((e.timeout(), e.srtt()), (MS(300), None), "nothing known yet");
        e.sample(MS(100));
        // SRTT 100, RTTVAR 50: 100 + 200.
        assert_eq!((e.timeout(), e.srtt()), (MS(300), Some(MS(100))));
        e.sample(MS(100));
        // RTTVAR 37.5: 100 + 150.
        assert_eq!(e.timeout(), MS(250));
        for _ in 0..50 {
            e.sample(MS(100));
        }
        assert!(e.timeout() < MS(110) && e.timeout() >= MS(101), "{:?}", e.timeout());
    }

    #[test]
    fn fast_links_stop_at_the_floor_and_timeouts_back_off_to_the_ceiling() {
        let mut e = RttEstimator::new(MS(20), MS(300));
        for _ in 0..20 {
            e.sample(Duration::from_micros(200));
        }
        assert_eq!(e.timeout(), MS(20), "the floor");
        e.backed_off();
        assert_eq!(e.timeout(), MS(40));
        for _ in 0..5 {
            e.backed_off();
        }
        assert_eq!(e.timeout(), MS(300), "never past the ceiling");
        e.sample(Duration::from_micros(200));
        assert!(e.timeout() < MS(300), "a sample ends the back-off");
        assert_eq!(RttEstimator::new(MS(500), MS(300)).timeout(), MS(300), "floor above ceiling");
        let mut odd = RttEstimator::new(MS(500), MS(300));
        odd.sample(MS(1));
        assert_eq!(odd.timeout(), MS(300), "no panic, the ceiling wins");
    }

    #[test]
    fn a_variable_link_gets_room_above_its_mean() {
        let mut e = RttEstimator::new(MS(1), MS(10_000));
        for i in 0..100 {
            e.sample(MS(if i % 2 == 0 { 10 } else { 50 }));
        }
        let srtt = e.srtt().unwrap();
        assert!(srtt > MS(20) && srtt < MS(40), "{srtt:?}");
        assert!(e.timeout() > MS(50), "above the slow replies: {:?}", e.timeout());
    }

    #[test]
    fn degraded_needs_a_full_window_and_clears_with_hysteresis() {
        let mut w = LossWindow::new(10, 0.2, 0.05);
        for _ in 0..9 {
            assert!(!w.record(true), "not judged before the window is full");
        }
        assert!(w.record(true), "10 of 10");
        // Back to clean: 3 of 10 troubled is still above `below`.
        for _ in 0..7 {
            assert!(w.record(false));
        }
        assert!(w.degraded(), "30% > 5%");
        for _ in 0..2 {
            assert!(w.record(false), "20%, then 10%: still above 5%");
        }
        assert!(!w.record(false), "0% clears it");
        // 2 of 10 is at the threshold, not above it.
        assert!(!w.record(true) && !w.record(true));
        assert!(w.record(true), "3 of 10 > 20%");
        assert_eq!(LossWindow::new(0, 0.1, 0.0).window, 1, "a zero window is one request");
    }
}
