//! The one retry policy of every client: how many attempts, how long each may take, which
//! failures are worth another attempt, and the error once they are spent. The numbers are a
//! [`RetryPolicy`] (`policy.rs`); this is the loop that keeps to them.
//!
//! Each attempt waits for its reply up to the link's adaptive timeout ([`super::health`]),
//! at most `timeout`; the retry loop feeds the link's health with every outcome. A
//! request's timeout error names the replies dropped while it waited
//! ([`crate::protocols::Dropped`]), so a device answering with the wrong transaction id
//! does not look silent.
//!
//! Modelled on rodbus's split between a request's timeout and the reconnect strategy
//! (`retry.rs` there covers reconnects; here that is [`super::Backoff`]): a request gets
//! `retries + 1` attempts of `timeout` each. Timeouts, lost connections and malformed
//! replies are retried; a device's own error code is an answer and never is. After the last
//! attempt the last failure is reported, a timeout as [`PlcError::Timeout`] with the number
//! of attempts, so "no reply after 3 attempt(s) of 1s each" reads the same for every
//! protocol.
//!
//! The loop is written by each client, not taken as a closure, so the client keeps its own
//! per-request state (transaction ids of earlier attempts) in plain locals:
//!
//! ```text
//! let mut retry = Retry::start(&self.health, "modbus");
//! while let Some(attempt) = retry.next_attempt() {
//!     match link.attempt(&exchange, &attempt).await {
//!         Ok(reply) => {
//!             retry.succeeded();
//!             return Ok(reply);
//!         }
//!         Err(e) => retry.failed(e)?,
//!     }
//! }
//! Err(retry.spent())
//! ```

use std::io;
use std::time::Duration;

use tokio::time::Instant;

use super::health::LinkHealth;
use super::policy::RetryPolicy;
use crate::protocols::{DeviceCode, Dropped, PlcError};

/// Why one attempt produced no answer.
#[derive(Debug)]
pub(crate) enum AttemptError {
    /// Nothing that answers the request arrived in time.
    Timeout,
    /// The carrier failed (connection refused or lost, port gone).
    Io(io::Error),
    /// Something arrived that claims to answer the request but is wrong.
    Malformed(&'static str),
    /// The device answered with its own error code: final, never retried.
    Device(DeviceCode),
}

impl AttemptError {
    /// True when another attempt may succeed: everything but the device's own answer.
    pub fn is_retryable(&self) -> bool {
        !matches!(self, AttemptError::Device(_))
    }

    /// What an attempt ended with, as a retry's note in a capture says it (`after a
    /// timeout`).
    fn as_cause(&self) -> &'static str {
        match self {
            AttemptError::Timeout => "a timeout",
            AttemptError::Io(_) => "a lost connection",
            AttemptError::Malformed(_) => "a malformed reply",
            AttemptError::Device(_) => "a device error",
        }
    }

    /// The error a request reports when this was its last failure after `attempts` tries.
    fn into_plc_error(self, attempts: u32, timeout: Duration, dropped: Option<Dropped>) -> PlcError {
        match self {
            AttemptError::Timeout => PlcError::Timeout { attempts, timeout, dropped },
            AttemptError::Io(e) => PlcError::Connection(e),
            AttemptError::Malformed(what) => PlcError::Malformed(what),
            AttemptError::Device(code) => PlcError::Device(code),
        }
    }

    /// The error of a request whose single, unretried attempt failed (a broadcast).
    pub(crate) fn once(self, policy: &RetryPolicy) -> PlcError {
        self.into_plc_error(1, policy.timeout, None)
    }
}

impl From<io::Error> for AttemptError {
    fn from(e: io::Error) -> Self {
        AttemptError::Io(e)
    }
}

impl From<DeviceCode> for AttemptError {
    fn from(code: DeviceCode) -> Self {
        AttemptError::Device(code)
    }
}

/// One attempt of a request.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Attempt {
    /// 0 for the first attempt, 1 for the first retry, ...
    pub number: u32,
    /// When this attempt stops waiting for its reply.
    pub deadline: Instant,
    /// The policy's timeout, for connecting and sending (which do not adapt).
    pub timeout: Duration,
    /// How long this attempt waits for its reply (the adaptive timeout).
    pub reply_window: Duration,
}

impl Attempt {
    /// True for the first attempt of a request (later ones are retries of it).
    pub fn is_first(&self) -> bool {
        self.number == 0
    }

    /// One attempt outside any retry loop: a broadcast, sent once and never answered.
    pub(crate) fn single(policy: &RetryPolicy) -> Attempt {
        let now = Instant::now();
        Attempt {
            number: 0,
            deadline: now + policy.timeout,
            timeout: policy.timeout,
            reply_window: policy.timeout,
        }
    }

    /// The attempt with its reply window starting now: for links that held the line
    /// before sending, so the hold does not eat the wait for the reply.
    pub fn restarted(&self) -> Attempt {
        Attempt { deadline: Instant::now() + self.reply_window, ..*self }
    }
}

/// The attempts of one request under way ([`Retry::start`]).
#[derive(Debug)]
pub(crate) struct Retry<'a> {
    health: &'a LinkHealth,
    protocol: &'static str,
    made: u32,
    /// When each attempt was sent (for round trips).
    sent: Vec<Instant>,
    last_window: Duration,
    last: Option<AttemptError>,
}

impl<'a> Retry<'a> {
    /// Starts the attempts of one request over a link's `health`; `protocol` names it in
    /// debug logs.
    pub fn start(health: &'a LinkHealth, protocol: &'static str) -> Self {
        health.begin_request();
        Retry {
            health,
            protocol,
            made: 0,
            sent: Vec::new(),
            last_window: health.policy().timeout,
            last: None,
        }
    }

    /// The next attempt, with its deadline from now; `None` once every attempt was made.
    pub fn next_attempt(&mut self) -> Option<Attempt> {
        let policy = self.health.policy();
        if self.made >= policy.attempts() {
            return None;
        }
        if self.made > 0 {
            self.health.retried();
        }
        let now = Instant::now();
        let window = self.health.timeout();
        let attempt = Attempt {
            number: self.made,
            deadline: now + window,
            timeout: policy.timeout,
            reply_window: window,
        };
        // A first attempt finds the recorder's context clear: a request that retried clears
        // it when it ends (`Drop`), so the common path takes no lock on the recorder.
        if let (Some(r), true) = (self.health.recorder(), self.made > 0) {
            r.set_attempt(self.made, self.last.as_ref().map(AttemptError::as_cause));
        }
        self.sent.push(now);
        self.last_window = window;
        self.made += 1;
        Some(attempt)
    }

    /// The request was answered during the current attempt by a reply that cannot be
    /// attributed to one transmission (no transaction id): by Karn's rule it gives a round
    /// trip only when there was no earlier attempt.
    pub fn succeeded(self) {
        let clean = self.made == 1;
        if clean {
            self.sample(0);
        }
        self.health.finished(!clean);
    }

    /// The request was answered by a reply matched by id to attempt `number`: an
    /// unambiguous round trip from that attempt's transmission, retried or not.
    pub fn succeeded_by(self, number: u32) {
        self.sample(number);
        self.health.finished(self.made > 1);
    }

    fn sample(&self, number: u32) {
        if let Some(sent) = self.sent.get(number as usize) {
            // Only the first attempt is ever held before a sample is taken from it (ids are
            // matched on links that never hold), so the held time is its own.
            let held = if number == 0 { self.health.held() } else { Duration::ZERO };
            self.health.sample(sent.elapsed().saturating_sub(held));
        }
    }

    /// Records a failed attempt: a retryable failure is kept for the final report, a final
    /// one (the device's own code, an answer: it gives a round trip as
    /// [`Retry::succeeded`] does) is returned as the request's error at once.
    pub fn failed(&mut self, e: AttemptError) -> Result<(), PlcError> {
        if !e.is_retryable() {
            let clean = self.made == 1;
            if clean {
                self.sample(0);
            }
            self.health.finished(!clean);
            return Err(e.into_plc_error(self.made, self.last_window, None));
        }
        match &e {
            AttemptError::Timeout => self.health.timed_out(),
            AttemptError::Malformed(_) => self.health.malformed(),
            AttemptError::Io(_) | AttemptError::Device(_) => {}
        }
        tracing::debug!(protocol = self.protocol, attempt = self.made, error = ?e, "attempt failed");
        self.last = Some(e);
        Ok(())
    }

    /// The request's error once every attempt failed: the last failure, with the replies
    /// dropped meanwhile when it is a timeout.
    pub fn spent(mut self) -> PlcError {
        self.health.finished(true);
        let dropped = self.health.dropped_this_request();
        self.last.take().unwrap_or(AttemptError::Timeout).into_plc_error(self.made, self.last_window, dropped)
    }
}

impl Drop for Retry<'_> {
    /// The request is over (answered, failed, or given up by a cancelled caller): frames
    /// sent after it (a broadcast) are no attempt's.
    fn drop(&mut self) {
        if let (Some(r), true) = (self.health.recorder(), self.made > 1) {
            r.set_attempt(0, None);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocols::DropReason;

    fn health(retries: u32) -> LinkHealth {
        LinkHealth::new(RetryPolicy::new(Duration::from_millis(100), retries))
    }

    #[test]
    fn retryable_failures_use_every_attempt_and_report_the_last() {
        let h = health(2);
        let mut retry = Retry::start(&h, "test");
        let mut numbers = Vec::new();
        while let Some(attempt) = retry.next_attempt() {
            numbers.push((attempt.number, attempt.is_first()));
            retry.failed(AttemptError::Timeout).unwrap();
        }
        assert_eq!(numbers, [(0, true), (1, false), (2, false)]);
        assert!(
            matches!(retry.spent(), PlcError::Timeout { attempts: 3, timeout, dropped: None } if timeout.as_millis() == 100)
        );
        let stats = h.stats();
        assert_eq!((stats.requests, stats.retries, stats.timeouts), (1, 2, 3));

        let h = health(1);
        let mut retry = Retry::start(&h, "test");
        retry.next_attempt().unwrap();
        retry.failed(AttemptError::Timeout).unwrap();
        retry.next_attempt().unwrap();
        retry.failed(AttemptError::Malformed("bad")).unwrap();
        assert!(retry.next_attempt().is_none());
        assert!(matches!(retry.spent(), PlcError::Malformed("bad")));
    }

    #[tokio::test(start_paused = true)]
    async fn karns_rule_no_round_trip_from_a_retried_request_unless_matched_by_id() {
        let h = health(2);
        let mut retry = Retry::start(&h, "test");
        retry.next_attempt().unwrap();
        retry.failed(AttemptError::Timeout).unwrap();
        retry.next_attempt().unwrap();
        tokio::time::advance(Duration::from_millis(5)).await;
        retry.succeeded();
        assert_eq!(h.stats().srtt_ms, None, "ambiguous: which attempt was answered?");
        let mut retry = Retry::start(&h, "test");
        retry.next_attempt().unwrap();
        retry.failed(AttemptError::Timeout).unwrap();
        retry.next_attempt().unwrap();
        tokio::time::advance(Duration::from_millis(5)).await;
        retry.succeeded_by(1);
        assert_eq!(h.stats().srtt_ms, Some(5.0), "the retry's own id: a clean sample");
        let mut retry = Retry::start(&h, "test");
        retry.next_attempt().unwrap();
        h.dropped(DropReason::Unit);
        h.dropped(DropReason::TransactionId);
        h.dropped(DropReason::TransactionId);
        retry.failed(AttemptError::Timeout).unwrap();
        let err = retry.spent();
        let dropped = Some(Dropped { count: 2, reason: DropReason::TransactionId });
        assert!(
            matches!(err, PlcError::Timeout { dropped: d, .. } if d == dropped),
            "the commonest: {err:?}"
        );
        let stats = h.stats();
        assert_eq!((stats.requests, stats.retries, stats.foreign), (3, 2, 3));
    }

    #[test]
    fn a_device_code_ends_the_request_at_once() {
        let h = health(5);
        let mut retry = Retry::start(&h, "test");
        retry.next_attempt().unwrap();
        let code = DeviceCode::Modbus(crate::protocols::modbus::Exception(2));
        assert!(matches!(retry.failed(AttemptError::Device(code)), Err(PlcError::Device(c)) if c == code));
        assert_eq!(RetryPolicy::new(Duration::ZERO, u32::MAX).attempts(), u32::MAX, "no overflow");
    }
}
