//! Webhooks to a WMS (`service::webhooks`), against the test receiver of
//! [`crate::support::receiver`]: the API and the rules of delivery in one process
//! ([`api`]); verified by a receiver built on the Standard Webhooks library for Python,
//! with nothing of rackd's ([`python`]); and delivery through SIGKILLs of a `rackd serve`
//! process driving the shelf and crane simulators ([`kills`]; the two-node failover is
//! `standby::failover`).

mod api;
mod kills;
mod python;
