//! The distribution of a link's round trips, as bucket counts: what `/metrics` serves as a
//! histogram per device.
//!
//! Decisions:
//! - **Kept where round trips are measured.** The link's health takes every round trip it
//!   can attribute to one transmission (Karn's rule, see `retry.rs`) for its adaptive timer;
//!   the same sample lands here, so the histogram and the timer see the same replies. A
//!   reply to a retried request without an id gives no sample (which attempt it answers is
//!   unknown), nor does a request that timed out (its cost is in the timeout counter).
//! - **Totals, copied with the link's counters.** The buckets travel in [`super::LinkStats`]
//!   (left out of the JSON: an array of counts means nothing to a reader of a device's
//!   status), so `/metrics` reads them from the same status snapshot as the counters, with
//!   no second bookkeeping path and no registry handle in the transport.
//! - **Fixed buckets** from 0.5 ms (Modbus UDP on a LAN) to 2 s (a slow serial line at
//!   its longest timeout): one fixed-size array, so copying it costs no allocation.

use std::time::Duration;

/// Upper bounds of the buckets, in seconds (a last, unbounded one follows).
pub const BOUNDS: [f64; 12] = [0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0];

/// Round trips counted by bucket, with their sum.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RoundTrips {
    /// Round trips per bucket (not cumulative): `counts[i]` fell in `(BOUNDS[i-1], BOUNDS[i]]`;
    /// the last one above every bound.
    pub counts: [u64; BOUNDS.len() + 1],
    /// The sum of every round trip, in seconds.
    pub sum_seconds: f64,
}

impl RoundTrips {
    /// Counts one round trip.
    pub fn observe(&mut self, rtt: Duration) {
        let seconds = rtt.as_secs_f64();
        let i = BOUNDS.iter().position(|&b| seconds <= b).unwrap_or(BOUNDS.len());
        self.counts[i] += 1;
        self.sum_seconds += seconds;
    }

    /// Every round trip counted.
    pub fn count(&self) -> u64 {
        self.counts.iter().sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_round_trip_lands_in_the_first_bucket_that_holds_it() {
        let mut r = RoundTrips::default();
        r.observe(Duration::from_micros(300));
        r.observe(Duration::from_micros(500));
        r.observe(Duration::from_millis(15));
        r.observe(Duration::from_secs(3));
        assert_eq!(r.counts[0], 2, "0.5 ms is the first bucket's own bound");
        assert_eq!(r.counts[5], 1, "15 ms: above 10 ms, up to 20 ms");
        assert_eq!(r.counts[BOUNDS.len()], 1, "above every bound");
        assert_eq!(r.count(), 4);
        assert!((r.sum_seconds - 3.0158).abs() < 1e-9, "{}", r.sum_seconds);
    }
}
