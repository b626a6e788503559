//! `[events]`: the event log, live subscribers and the device monitor.

use serde::{Deserialize, Serialize};

/// `[events]`
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct EventsConfig {
    /// Events older than this many hours are deleted from the log (replay with `?since=`
    /// reaches back this far; the newest event is always kept).
    pub retention_hours: u64,
    /// How many commits (each one or more events) a WebSocket subscriber may fall behind
    /// before it is sent `resync` and disconnected.
    pub buffer: usize,
    /// Seconds between the server's pings; a subscriber silent for two pings is dropped.
    pub ping_secs: u64,
    /// Seconds one send to a subscriber may take before it is dropped as stalled.
    pub send_timeout_secs: u64,
    /// Most non-terminal jobs in a WebSocket snapshot (the newest; `jobs_truncated` tells).
    pub snapshot_jobs: u32,
    /// Longest time a device's new last contact goes unpublished, in milliseconds.
    pub contact_refresh_ms: u64,
    /// Hours beyond `retention_hours` the log keeps events an active `[[webhooks]]`
    /// subscription has not delivered yet; older ones are pruned all the same (and the
    /// subscription's `webhook` alarm says which were lost), so a receiver gone for good
    /// cannot fill the disk.
    pub webhook_hold_hours: u64,
}

impl Default for EventsConfig {
    fn default() -> Self {
        EventsConfig {
            retention_hours: 168,
            buffer: 1024,
            ping_secs: 20,
            send_timeout_secs: 10,
            snapshot_jobs: 5000,
            contact_refresh_ms: 5000,
            webhook_hold_hours: 168,
        }
    }
}

/// An `[events]` value that cannot work.
#[derive(Debug, thiserror::Error)]
pub enum EventsConfigError {
    /// A buffer or period of 0.
    #[error("events.buffer, ping_secs and send_timeout_secs must be at least 1")]
    Zero,
    /// A log that keeps nothing (replay with `?since=` would never work).
    #[error("events.retention_hours must be at least 1")]
    Retention,
    /// No hold for undelivered webhook events.
    #[error("events.webhook_hold_hours must be at least 1")]
    WebhookHold,
}

impl EventsConfig {
    /// Checks the values make sense together.
    pub fn check(&self) -> Result<(), EventsConfigError> {
        if self.buffer == 0 || self.ping_secs == 0 || self.send_timeout_secs == 0 {
            return Err(EventsConfigError::Zero);
        }
        if self.retention_hours == 0 {
            return Err(EventsConfigError::Retention);
        }
        if self.webhook_hold_hours == 0 {
            return Err(EventsConfigError::WebhookHold);
        }
        Ok(())
    }
}
