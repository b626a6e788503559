//! Webhooks to a WMS (`service::webhooks`), against the test receiver of
//! [`crate::support::receiver`]: the API and the rules of delivery in one process
//! ([`api`]); verified by a receiver built on the Standard Webhooks library for Python,
//! with nothing of rackd's ([`python`]); and delivery through SIGKILLs of a `rackd serve`
//! process driving the shelf and crane simulators ([`kills`]; the two-node failover is
//! `standby::failover`); a 410 Gone's pause, alarmed and holding its events ([`gone`]); a
//! subscription that cannot start, alarmed while the machines are driven ([`unstarted`]).

pub mod api;
mod gone;
mod kills;
mod python;
mod retention;
mod unstarted;

use crate::support::receiver::Receiver;

/// The stored `cursor` passes no event of `passed` (the `job.*` events up to it) that the
/// receiver has not acknowledged; `receiver` is read after the cursor, so what it
/// acknowledged meanwhile counts too.
pub fn assert_cursor_acknowledged(cursor: i64, passed: &[i64], receiver: &Receiver) {
    let acked = receiver.acked();
    let unacked: Vec<_> = passed.iter().filter(|s| !acked.contains(s)).collect();
    assert!(unacked.is_empty(), "the cursor {cursor} passed events never acknowledged: {unacked:?}");
}

/// Waits (at most a minute) until the receiver has acknowledged every event of `wanted`.
pub async fn every_event_acked(receiver: &Receiver, wanted: &[i64]) {
    crate::support::eventually("every job event delivered", std::time::Duration::from_secs(60), async || {
        let acked = receiver.acked();
        let missing: Vec<_> = wanted.iter().filter(|s| !acked.contains(s)).collect();
        match missing.first() {
            None => Ok(()),
            Some(first) => Err(format!("{} missing, the first {first}", missing.len())),
        }
    })
    .await
}
