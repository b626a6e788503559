//! The one retry policy of every client: how many attempts, how long each may take, which
//! failures are worth another attempt, and the error once they are spent.
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
//! let mut retry = self.policy.start("modbus");
//! while let Some(attempt) = retry.next_attempt() {
//!     match link.attempt(&exchange, &attempt).await {
//!         Ok(reply) => return Ok(reply),
//!         Err(e) => retry.failed(e)?,
//!     }
//! }
//! Err(retry.spent())
//! ```

use std::io;
use std::time::Duration;

use tokio::time::Instant;

use crate::protocols::{DeviceCode, PlcError};

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

    /// The error a request reports when this was its last failure after `attempts` tries.
    fn into_plc_error(self, attempts: u32, timeout: Duration) -> PlcError {
        match self {
            AttemptError::Timeout => PlcError::Timeout { attempts, timeout },
            AttemptError::Io(e) => PlcError::Connection(e),
            AttemptError::Malformed(what) => PlcError::Malformed(what),
            AttemptError::Device(code) => PlcError::Device(code),
        }
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

/// How hard a client tries: `retries + 1` attempts of `timeout` each.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RetryPolicy {
    /// Time allowed for one attempt (connect, send and the whole reply).
    pub timeout: Duration,
    /// Further attempts after a retryable failure (0 = send once).
    pub retries: u32,
}

impl RetryPolicy {
    /// Every attempt a request gets.
    pub fn attempts(&self) -> u32 {
        self.retries.saturating_add(1)
    }

    /// Starts the attempts of one request; `protocol` names it in debug logs.
    pub(crate) fn start(&self, protocol: &'static str) -> Retry {
        Retry { policy: *self, protocol, made: 0, last: None }
    }

    /// One attempt outside any retry loop: a broadcast, sent once and never answered.
    pub(crate) fn single(&self) -> Attempt {
        Attempt { number: 0, deadline: Instant::now() + self.timeout, timeout: self.timeout }
    }

    /// The error of a request whose single, unretried attempt failed (a broadcast).
    pub(crate) fn once(&self, e: AttemptError) -> PlcError {
        e.into_plc_error(1, self.timeout)
    }
}

/// One attempt of a request.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Attempt {
    /// 0 for the first attempt, 1 for the first retry, ...
    pub number: u32,
    /// When this attempt gives up.
    pub deadline: Instant,
    /// The policy's timeout (for steps that take a duration rather than a deadline).
    pub timeout: Duration,
}

impl Attempt {
    /// True for the first attempt of a request (later ones are retries of it).
    pub fn is_first(&self) -> bool {
        self.number == 0
    }
}

/// The attempts of one request under way.
#[derive(Debug)]
pub(crate) struct Retry {
    policy: RetryPolicy,
    protocol: &'static str,
    made: u32,
    last: Option<AttemptError>,
}

impl Retry {
    /// The next attempt, with its deadline from now; `None` once every attempt was made.
    pub fn next_attempt(&mut self) -> Option<Attempt> {
        if self.made >= self.policy.attempts() {
            return None;
        }
        let attempt = Attempt {
            number: self.made,
            deadline: Instant::now() + self.policy.timeout,
            timeout: self.policy.timeout,
        };
        self.made += 1;
        Some(attempt)
    }

    /// Records a failed attempt: a retryable failure is kept for the final report, a final
    /// one (the device's own code) is returned as the request's error at once.
    pub fn failed(&mut self, e: AttemptError) -> Result<(), PlcError> {
        if !e.is_retryable() {
            return Err(e.into_plc_error(self.made, self.policy.timeout));
        }
        tracing::debug!(protocol = self.protocol, attempt = self.made, error = ?e, "attempt failed");
        self.last = Some(e);
        Ok(())
    }

    /// The request's error once every attempt failed: the last failure.
    pub fn spent(self) -> PlcError {
        self.last.unwrap_or(AttemptError::Timeout).into_plc_error(self.made, self.policy.timeout)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn policy(retries: u32) -> RetryPolicy {
        RetryPolicy { timeout: Duration::from_millis(100), retries }
    }

    #[test]
    fn retryable_failures_use_every_attempt_and_report_the_last() {
        let mut retry = policy(2).start("test");
        let mut numbers = Vec::new();
        while let Some(attempt) = retry.next_attempt() {
            numbers.push((attempt.number, attempt.is_first()));
            retry.failed(AttemptError::Timeout).unwrap();
        }
        assert_eq!(numbers, [(0, true), (1, false), (2, false)]);
        assert!(
            matches!(retry.spent(), PlcError::Timeout { attempts: 3, timeout } if timeout.as_millis() == 100)
        );

        let mut retry = policy(1).start("test");
        retry.next_attempt().unwrap();
        retry.failed(AttemptError::Timeout).unwrap();
        retry.next_attempt().unwrap();
        retry.failed(AttemptError::Malformed("bad")).unwrap();
        assert!(retry.next_attempt().is_none());
        assert!(matches!(retry.spent(), PlcError::Malformed("bad")));
    }

    #[test]
    fn a_device_code_ends_the_request_at_once() {
        let mut retry = policy(5).start("test");
        retry.next_attempt().unwrap();
        let code = DeviceCode::Modbus(crate::protocols::modbus::Exception(2));
        assert!(matches!(retry.failed(AttemptError::Device(code)), Err(PlcError::Device(c)) if c == code));
        assert_eq!(policy(u32::MAX).attempts(), u32::MAX, "no overflow");
    }
}
