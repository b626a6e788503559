//! The lease's rules on each side, on the node's own monotonic clock (pure: the loop in
//! the parent module feeds them instants; the timing argument is there).

use std::time::Duration;

use tokio::time::Instant;

use crate::store::cluster::LeaseRow;

/// A cluster's lease timing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Timing {
    /// How long a renewal lets the active node drive (`lease_ms`).
    pub lease: Duration,
    /// What a standby waits beyond the lease before it takes over (`margin_ms`).
    pub margin: Duration,
}

impl Timing {
    /// `lease` with the default margin, a fifth of it.
    pub fn new(lease: Duration) -> Timing {
        Timing { lease, margin: lease / 5 }
    }

    /// How often the active node renews: three tries within a lease.
    pub fn renew_every(&self) -> Duration {
        self.lease / 3
    }

    /// How often a standby reads the lease.
    pub fn poll_every(&self) -> Duration {
        self.lease / 10
    }
}

/// The active node's term: its epoch, and until when it may drive.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Holding {
    /// The fencing token.
    pub epoch: i64,
    until: Instant,
}

impl Holding {
    /// The term that began with a takeover sent at `sent`.
    pub fn new(epoch: i64, sent: Instant, timing: Timing) -> Holding {
        Holding { epoch, until: sent + timing.lease }
    }

    /// A renewal sent at `sent` committed.
    pub fn renewed(&mut self, sent: Instant, timing: Timing) {
        self.until = self.until.max(sent + timing.lease);
    }

    /// Whether it may still drive at `now`.
    pub fn valid(&self, now: Instant) -> bool {
        now < self.until
    }

    /// The instant it must stop, unless renewed.
    pub fn until(&self) -> Instant {
        self.until
    }
}

/// A standby's watch over the lease row.
#[derive(Clone, Debug, Default)]
pub struct Watch {
    seen: Option<(Option<LeaseRow>, Instant)>,
}

impl Watch {
    /// The row as read at `now`; a change restarts the wait.
    pub fn observe(&mut self, row: Option<LeaseRow>, now: Instant) {
        if self.seen.as_ref().is_none_or(|(before, _)| *before != row) {
            self.seen = Some((row, now));
        }
    }

    /// The row as last seen (None: nobody ever held the lease, or nothing read yet).
    pub fn seen(&self) -> Option<&LeaseRow> {
        self.seen.as_ref().and_then(|(row, _)| row.as_ref())
    }

    /// Whether the lease may be taken at `now`: nobody ever held it, its holder let go of
    /// it, or the row has stood still for `lease + margin` by this node's clock.
    pub fn may_take(&self, now: Instant, timing: Timing) -> bool {
        match &self.seen {
            None => false,
            Some((None, _)) => true,
            Some((Some(row), _)) if row.released => true,
            Some((Some(_), since)) => now >= *since + timing.lease + timing.margin,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(epoch: i64, beat: i64) -> Option<LeaseRow> {
        Some(LeaseRow { holder: "a".into(), epoch, beat, released: false, renewed_at: 0 })
    }

    #[test]
    fn the_active_node_stops_a_lease_after_the_last_renewal_it_sent() {
        let t = Timing::new(Duration::from_millis(5000));
        let t0 = Instant::now();
        let mut h = Holding::new(1, t0, t);
        assert!(h.valid(t0 + Duration::from_millis(4999)));
        assert!(!h.valid(t0 + t.lease));
        h.renewed(t0 + Duration::from_secs(2), t);
        assert!(h.valid(t0 + Duration::from_millis(6999)) && !h.valid(t0 + Duration::from_secs(7)));
        // A late answer to an older renewal never shortens nor stretches it past its send.
        h.renewed(t0 + Duration::from_secs(1), t);
        assert_eq!(h.until(), t0 + Duration::from_secs(7));
    }

    #[test]
    fn a_standby_waits_lease_plus_margin_of_stillness_by_its_own_clock() {
        let t = Timing::new(Duration::from_millis(5000));
        let s = Instant::now();
        let mut w = Watch::default();
        assert!(!w.may_take(s, t), "nothing read yet");
        w.observe(row(1, 7), s);
        assert!(!w.may_take(s + Duration::from_millis(5999), t));
        // A renewal restarts the wait.
        w.observe(row(1, 8), s + Duration::from_secs(3));
        assert!(!w.may_take(s + Duration::from_secs(6), t));
        w.observe(row(1, 8), s + Duration::from_secs(8));
        assert!(!w.may_take(s + Duration::from_millis(8999), t));
        assert!(w.may_take(s + Duration::from_secs(9), t));
        assert_eq!(w.seen().map(|r| r.beat), Some(8), "the takeover is a compare-and-set on what it saw");
    }

    #[test]
    fn a_free_or_released_lease_is_taken_at_once() {
        let t = Timing::new(Duration::from_millis(5000));
        let s = Instant::now();
        let mut w = Watch::default();
        w.observe(None, s);
        assert!(w.may_take(s, t));
        let mut released = row(3, 1);
        released.as_mut().unwrap().released = true;
        w.observe(released, s);
        assert!(w.may_take(s, t));
    }

    #[test]
    fn the_active_node_stops_before_any_standby_may_start() {
        // The worst case of the argument: the standby saw the row at the very instant the
        // renewal was sent.
        let t = Timing::new(Duration::from_millis(5000));
        let t0 = Instant::now();
        let h = Holding::new(4, t0, t);
        let mut w = Watch::default();
        w.observe(row(4, 0), t0);
        let mut at = t0;
        while !w.may_take(at, t) {
            at += Duration::from_millis(1);
        }
        assert!(!h.valid(at) && at - h.until() >= t.margin);
    }
}
