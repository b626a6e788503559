//! How hard a client tries ([`RetryPolicy`]: attempts and the timeout of each) and how its
//! link adapts ([`LinkTuning`]: the adaptive timeout's floor and the degraded judgement):
//! plain settings, read from a device's configuration, under both the retry loop
//! ([`super::retry`]) and the link's health ([`super::health`]).

use std::time::Duration;

use crate::protocols::Replies;

/// How hard a client tries: `retries + 1` attempts, each waiting for its reply up to
/// `timeout` (less once round trips are known: [`LinkTuning`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RetryPolicy {
    /// Time allowed for one attempt (connect, send and the whole reply); the ceiling of
    /// the adaptive reply timeout.
    pub timeout: Duration,
    /// Further attempts after a retryable failure (0 = send once).
    pub retries: u32,
    /// The adaptive timeout's floor and the degraded judgement.
    pub tuning: LinkTuning,
}

impl RetryPolicy {
    /// A policy with the default [`LinkTuning`].
    pub fn new(timeout: Duration, retries: u32) -> Self {
        RetryPolicy { timeout, retries, tuning: LinkTuning::default() }
    }

    /// Every attempt a request gets.
    pub fn attempts(&self) -> u32 {
        self.retries.saturating_add(1)
    }
}

/// How a link adapts its timeout and when it counts as degraded.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkTuning {
    /// The shortest reply timeout the adaptive timer may choose (`min_timeout_ms`).
    pub min_timeout: Duration,
    /// Recent requests the degraded judgement looks at (`degraded_window`).
    pub degraded_window: u32,
    /// Degraded once more than this share of them needed a retry or failed
    /// (`degraded_above`).
    pub degraded_above: f64,
    /// Healthy again once this share or less did (`degraded_below`).
    pub degraded_below: f64,
}

impl LinkTuning {
    /// The tuning a link gets by default: the floor is 2 ms where replies name their
    /// request ([`Replies::Named`]), since a resend there costs one request and a late
    /// reply is dropped by its id; 20 ms where they do not, since there every attempt that
    /// times out leaves a reply owed, which costs a new carrier or a `timeout_ms` of
    /// silence before the next request (the transport's module documentation).
    pub fn for_replies(replies: Replies) -> LinkTuning {
        let floor = match replies {
            Replies::Named => 2,
            Replies::Unnamed => 20,
        };
        LinkTuning { min_timeout: Duration::from_millis(floor), ..LinkTuning::default() }
    }
}

impl Default for LinkTuning {
    /// 20 ms floor; degraded above 10% troubled requests of the last 50, healthy again at
    /// 2% (one in 50) or less.
    fn default() -> Self {
        LinkTuning {
            min_timeout: Duration::from_millis(20),
            degraded_window: 50,
            degraded_above: 0.10,
            degraded_below: 0.02,
        }
    }
}
