//! A link's health: its adaptive timeout, whether it is degraded, and its counters, kept
//! per client (one client = one device) and shown in the device's status as [`LinkStats`].
//!
//! Decisions:
//! - **One place.** Every client runs its requests through [`super::retry::Retry`], which feeds
//!   this: round trips, timeouts, retries and finished requests. Links report only what
//!   the retry loop cannot see: replies they dropped, and why ([`LinkHealth::dropped`]).
//! - **Adaptive timeouts** follow RFC 6298 ([`super::rtt`]), between `min_timeout` and the
//!   configured timeout. Connecting and sending keep the configured timeout: only the wait
//!   for a reply adapts, so a TCP connect to a far device is not cut at 20 ms.
//! - **Degraded** is a warning, not a stop: the share of the last `degraded_window`
//!   requests that needed a retry or failed rose above `degraded_above`, and has not yet
//!   fallen to `degraded_below`. The device keeps working.
//! - **Counters** are totals since the client was built; the device status copies them
//!   after each request as contact bookkeeping, so they never wake watchers by themselves
//!   (only `degraded` flipping does).
//! - **Round trips** that feed the timer are also counted by bucket ([`RoundTrips`]), for
//!   the request latency histogram of `/metrics`.
//! - A request abandoned by its caller (its future dropped) counts as a request, but its
//!   outcome is unknown, so it does not enter the degraded window.

use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use serde::Serialize;
use utoipa::ToSchema;

use super::policy::RetryPolicy;
use super::round_trips::RoundTrips;
use super::rtt::{LossWindow, RttEstimator};
use crate::capture::Recorder;
use crate::protocols::{DropReason, Dropped};

/// A link's health as the device status shows it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, ToSchema)]
pub struct LinkStats {
    /// Too many recent requests needed a retry or failed: the device works, but its link
    /// is lossy (a warning, raised as an alarm by the service).
    pub degraded: bool,
    /// Requests asked of the link since rackd started.
    pub requests: u64,
    /// Resends after a timeout or a bad reply.
    pub retries: u64,
    /// Attempts that got no reply in time.
    pub timeouts: u64,
    /// Replies dropped as stale: late replies to earlier requests, or replies to another
    /// function, command or size.
    pub stale: u64,
    /// Replies dropped as foreign: another transaction id or PDU reference, another unit.
    pub foreign: u64,
    /// Replies that could not be decoded.
    pub malformed: u64,
    /// Smoothed round trip in milliseconds (none until a first clean reply).
    pub srtt_ms: Option<f64>,
    /// The reply timeout the next attempt gets, in milliseconds.
    pub timeout_ms: f64,
    /// Round trips of clean replies by bucket, for `/metrics` (not in the JSON).
    #[serde(skip)]
    pub round_trips: RoundTrips,
}

/// Totals and the per-request tally of dropped replies.
#[derive(Debug)]
struct State {
    rtt: RttEstimator,
    round_trips: RoundTrips,
    window: LossWindow,
    requests: u64,
    retries: u64,
    timeouts: u64,
    stale: u64,
    foreign: u64,
    malformed: u64,
    /// Replies dropped during the current request, by [`DropReason`] index.
    this_request: [u32; 6],
    /// Time the current request's first attempt spent holding the line before its send.
    held: Duration,
}

/// What holding the line did ([`StreamLink::settle`](super::StreamLink::settle)).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Settled {
    /// Replies that arrived while the line was held, dropped.
    pub replies: u64,
    /// How long the line was held.
    pub held: Duration,
}

/// The health of one link, shared by its client and the client's link.
#[derive(Debug)]
pub(crate) struct LinkHealth {
    policy: RetryPolicy,
    state: Mutex<State>,
    /// The link's flight recorder: the retry loop marks attempts and counts timeouts there.
    recorder: Option<Arc<Recorder>>,
}

const REASONS: [DropReason; 6] = [
    DropReason::TransactionId,
    DropReason::PduReference,
    DropReason::Unit,
    DropReason::LengthZero,
    DropReason::Stale,
    DropReason::Malformed,
];

impl LinkHealth {
    /// A link with no history under `policy`.
    pub fn new(policy: RetryPolicy) -> Self {
        let t = policy.tuning;
        LinkHealth {
            policy,
            state: Mutex::new(State {
                rtt: RttEstimator::new(t.min_timeout, policy.timeout),
                round_trips: RoundTrips::default(),
                window: LossWindow::new(t.degraded_window, t.degraded_above, t.degraded_below),
                requests: 0,
                retries: 0,
                timeouts: 0,
                stale: 0,
                foreign: 0,
                malformed: 0,
                this_request: [0; 6],
                held: Duration::ZERO,
            }),
            recorder: None,
        }
    }

    /// The same health, with the link's flight recorder.
    pub fn recording(mut self, recorder: Option<Arc<Recorder>>) -> Self {
        self.recorder = recorder;
        self
    }

    /// The link's flight recorder, if any.
    pub fn recorder(&self) -> Option<&Arc<Recorder>> {
        self.recorder.as_ref()
    }

    /// The policy.
    pub fn policy(&self) -> &RetryPolicy {
        &self.policy
    }

    fn state(&self) -> MutexGuard<'_, State> {
        // Plain numbers: still usable after a panic elsewhere.
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// A request begins ([`super::retry::Retry::start`]).
    pub(super) fn begin_request(&self) {
        let mut s = self.state();
        s.requests += 1;
        s.this_request = [0; 6];
        s.held = Duration::ZERO;
    }

    /// The reply timeout for the next attempt.
    pub fn timeout(&self) -> Duration {
        self.state().rtt.timeout()
    }

    /// A reply arrived but was dropped for `reason`.
    pub fn dropped(&self, reason: DropReason) {
        self.dropped_n(reason, 1);
    }

    /// `n` replies arrived but were dropped for `reason`.
    pub fn dropped_n(&self, reason: DropReason, n: u64) {
        if n == 0 {
            return;
        }
        let mut s = self.state();
        match reason {
            DropReason::TransactionId | DropReason::PduReference | DropReason::Unit => s.foreign += n,
            DropReason::Stale => s.stale += n,
            DropReason::LengthZero | DropReason::Malformed => s.malformed += n,
        }
        let i = REASONS.iter().position(|&r| r == reason).unwrap_or(0);
        s.this_request[i] = s.this_request[i].saturating_add(n.min(u32::MAX as u64) as u32);
    }

    /// The commonest reason replies were dropped during the current request.
    pub(super) fn dropped_this_request(&self) -> Option<Dropped> {
        let s = self.state();
        let (i, &count) = s.this_request.iter().enumerate().max_by_key(|&(_, &n)| n)?;
        (count > 0).then(|| Dropped { count, reason: REASONS[i] })
    }

    /// The line was held before a send (see [`super::StreamLink::settle`]); replies that
    /// arrived meanwhile were dropped as stale. The hold is not part of a round trip.
    pub fn settled(&self, settled: Settled) {
        self.dropped_n(DropReason::Stale, settled.replies);
        self.state().held += settled.held;
    }

    pub(super) fn held(&self) -> Duration {
        self.state().held
    }

    pub(super) fn retried(&self) {
        self.state().retries += 1;
    }

    pub(super) fn timed_out(&self) {
        if let Some(r) = &self.recorder {
            r.timed_out();
        }
        let mut s = self.state();
        s.timeouts += 1;
        s.rtt.backed_off();
    }

    pub(super) fn malformed(&self) {
        self.state().malformed += 1;
    }

    pub(super) fn sample(&self, rtt: Duration) {
        let mut s = self.state();
        s.rtt.sample(rtt);
        s.round_trips.observe(rtt);
    }

    /// A request finished; `troubled` if it needed a retry or failed.
    pub(super) fn finished(&self, troubled: bool) {
        let mut s = self.state();
        let was = s.window.degraded();
        let now = s.window.record(troubled);
        if now != was {
            tracing::warn!(degraded = now, "link health changed");
        }
    }

    /// The health now.
    pub fn stats(&self) -> LinkStats {
        let s = self.state();
        LinkStats {
            degraded: s.window.degraded(),
            requests: s.requests,
            retries: s.retries,
            timeouts: s.timeouts,
            stale: s.stale,
            foreign: s.foreign,
            malformed: s.malformed,
            srtt_ms: s.rtt.srtt().map(|d| d.as_secs_f64() * 1000.0),
            timeout_ms: s.rtt.timeout().as_secs_f64() * 1000.0,
            round_trips: s.round_trips,
        }
    }
}
