//! `[[webhooks]]`: subscriptions that push the event log to a WMS over HTTP, one entry per
//! receiver (delivery itself: `service::webhooks`).
//!
//! Decisions:
//! - **A name is the subscription's identity** (1 to 64 of `A-Za-z0-9_-`): the cursor in
//!   the store, the API's paths, the metrics' label and the `webhook-id` header all use it.
//!   Renaming a subscription starts a new one (from the log's newest event); the old name's
//!   cursor stays in the store unused.
//! - **Events by type**, exactly (`alarm.raised`) or by family (`job.*`), or `*` for all;
//!   an unknown type is refused, so a typo never silently delivers nothing.
//! - **The secret** as the Standard Webhooks specification writes it: base64, with or
//!   without the `whsec_` prefix, 16 to 64 bytes once decoded. From the file
//!   (`secret = "..."`, shown as `***` by `--explain`) or from `secret_file` (one line,
//!   read at start), never both.
//! - **Outbound calls**: `ca_file` (PEM) replaces the trusted roots when set (a site's own
//!   CA); otherwise the system's store. No proxy unless `proxy` names one (the environment's
//!   `HTTP_PROXY` is ignored: a proxy meant for other traffic must not see the events).

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

/// The event types a subscription may name (a `*` family is a prefix before the dot).
pub const EVENT_TYPES: [&str; 7] = [
    "job.updated",
    "device.updated",
    "alarm.raised",
    "alarm.updated",
    "alarm.cleared",
    "location.updated",
    "audit.recorded",
];

/// One `[[webhooks]]` entry.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct WebhookConfig {
    /// The subscription's name.
    pub name: String,
    /// Where events are POSTed: `http://` or `https://`.
    pub url: String,
    /// Event types (`job.updated`), families (`job.*`), or `*`.
    pub events: Vec<String>,
    /// The signing secret, base64 (with or without `whsec_`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub secret: Option<String>,
    /// A file holding the secret (one line).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub secret_file: Option<PathBuf>,
    /// Milliseconds one delivery may take, connection included.
    #[serde(default = "timeout_ms")]
    pub timeout_ms: u64,
    /// PEM file of the CA(s) to trust instead of the system's store.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ca_file: Option<PathBuf>,
    /// A proxy to go through (`http://host:port`); none by default.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub proxy: Option<String>,
    /// Milliseconds before the first retry of a failed delivery; each next one waits twice
    /// as long, with jitter, up to `max_backoff_ms`.
    #[serde(default = "backoff_ms")]
    pub backoff_ms: u64,
    /// The longest wait between two tries.
    #[serde(default = "max_backoff_ms")]
    pub max_backoff_ms: u64,
    /// Seconds of failures in a row before the `webhook` alarm is raised.
    #[serde(default = "alarm_after_secs")]
    pub alarm_after_secs: u64,
}

fn timeout_ms() -> u64 {
    5000
}

fn backoff_ms() -> u64 {
    1000
}

fn max_backoff_ms() -> u64 {
    300_000
}

fn alarm_after_secs() -> u64 {
    900
}

impl WebhookConfig {
    /// A subscription with every default, to `url` for `events`, signed with `secret`.
    pub fn new(name: &str, url: &str, events: &[&str], secret: &str) -> WebhookConfig {
        WebhookConfig {
            name: name.into(),
            url: url.into(),
            events: events.iter().map(|e| (*e).to_owned()).collect(),
            secret: Some(secret.into()),
            secret_file: None,
            timeout_ms: timeout_ms(),
            ca_file: None,
            proxy: None,
            backoff_ms: backoff_ms(),
            max_backoff_ms: max_backoff_ms(),
            alarm_after_secs: alarm_after_secs(),
        }
    }

    /// Whether an event of type `kind` goes to this subscription.
    pub fn wants(&self, kind: &str) -> bool {
        self.events.iter().any(|pattern| matches(pattern, kind))
    }

    /// The signing key: the secret (or `secret_file`'s first line) decoded. The error says
    /// what is wrong, without the secret.
    pub fn key(&self) -> Result<Vec<u8>, String> {
        let text = match (&self.secret, &self.secret_file) {
            (Some(_), Some(_)) => return Err("set secret or secret_file, not both".into()),
            (None, None) => return Err("a subscription needs secret or secret_file".into()),
            (Some(secret), None) => secret.clone(),
            (None, Some(file)) => std::fs::read_to_string(file)
                .map_err(|e| format!("{} cannot be read: {e}", file.display()))?,
        };
        decode_secret(text.trim())
    }
}

/// Whether `pattern` (`job.updated`, `job.*`, `*`) covers `kind`.
pub fn matches(pattern: &str, kind: &str) -> bool {
    match pattern.strip_suffix('*') {
        Some("") => true,
        Some(prefix) => kind.starts_with(prefix),
        None => pattern == kind,
    }
}

/// Whether `pattern` covers at least one event type rackd writes.
pub fn known(pattern: &str) -> bool {
    let family = pattern.strip_suffix(".*").filter(|f| !f.contains('*'));
    match family {
        Some(family) => EVENT_TYPES.iter().any(|t| t.split('.').next() == Some(family)),
        None => pattern == "*" || EVENT_TYPES.contains(&pattern),
    }
}

/// A Standard Webhooks secret, `whsec_` prefix optional, decoded: 16 to 64 bytes.
pub fn decode_secret(text: &str) -> Result<Vec<u8>, String> {
    use base64::Engine;
    let b64 = text.strip_prefix("whsec_").unwrap_or(text);
    let key = base64::engine::general_purpose::STANDARD
        .decode(b64)
        .map_err(|_| "the secret is not base64 (as `whsec_` followed by base64)".to_owned())?;
    if !(16..=64).contains(&key.len()) {
        return Err(format!("the secret decodes to {} bytes: 16 to 64 are needed", key.len()));
    }
    Ok(key)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patterns_cover_types_and_families() {
        assert!(matches("job.*", "job.updated") && matches("*", "alarm.raised"));
        assert!(matches("alarm.raised", "alarm.raised") && !matches("alarm.raised", "alarm.cleared"));
        assert!(!matches("job.*", "jobs.updated"));
        assert!(known("job.*") && known("*") && known("alarm.cleared") && known("audit.*"));
        assert!(!known("job.created") && !known("robot.*") && !known("job*") && !known("*.*"));
    }

    #[test]
    fn secrets_are_base64_of_16_to_64_bytes() {
        let key = decode_secret("whsec_MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw").unwrap();
        assert_eq!(key.len(), 24);
        assert_eq!(decode_secret("MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw").unwrap(), key);
        assert!(decode_secret("whsec_not base64!").unwrap_err().contains("not base64"));
        assert!(decode_secret("whsec_c2hvcnQ=").unwrap_err().contains("5 bytes"));
    }
}
