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
//!   (`secret = "..."`, shown as `***` by `--explain`) or from `secret_file` (one line),
//!   never both.
//! - **`secret_file` and `ca_file` are read once, when the configuration is loaded** (at
//!   start, and again by each reload), into [`WebhookConfig::material`]: what a node signs
//!   and trusts with when it starts delivering, at start or when it takes over hours later,
//!   is what they held then. A file rotated or removed since cannot stop a takeover (a
//!   standby that read them again would exit with "won the lease but cannot drive", and
//!   with every node alike none would drive the machines); a reload reads them again, and
//!   a file that does not read then refuses the reload, as `check-config` would. A
//!   configuration built in code (tests, the demo) has no material: its deliverer reads the
//!   files when it starts, and one that cannot is an alarm, never a failed start
//!   (`service::webhooks`).
//! - **Outbound calls**: `ca_file` (PEM) replaces the trusted roots when set (a site's own
//!   CA); otherwise the system's store. No proxy unless `proxy` names one (the environment's
//!   `HTTP_PROXY` is ignored: a proxy meant for other traffic must not see the events).
//! - **Checked whole when loaded** ([`WebhookConfig::check`], so by `rackd check-config` as
//!   by the start): the secret is decoded and `secret_file` and `ca_file` are read, and each
//!   problem names its key. `url` and `proxy` need a host as written: the URL standard reads
//!   `http:///x` as `http://x/`, which here would be a typo delivered to a wrong host.

use std::path::PathBuf;

use rustls::pki_types::CertificateDer;
use serde::{Deserialize, Serialize};

use super::ca::CaError;

/// The event types a subscription may name (a `*` family is a prefix before the dot).
pub const EVENT_TYPES: [&str; 10] = [
    "job.updated",
    "device.updated",
    "alarm.raised",
    "alarm.updated",
    "alarm.cleared",
    "location.updated",
    "audit.recorded",
    "config.reloaded",
    "job.late",
    "sequence.updated",
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
    /// What the secret and `ca_file` held when the configuration was loaded; None for an
    /// entry built in code, or one whose files did not read (the check says why). Not a
    /// key of the file.
    #[serde(skip)]
    pub material: Option<Material>,
}

/// What a subscription signs and trusts with: its secret decoded and `ca_file`'s
/// certificates, as read when the configuration was loaded. Its `Debug` shows no key.
#[derive(Clone, PartialEq, Eq)]
pub struct Material {
    /// The signing key.
    pub key: Vec<u8>,
    /// `ca_file`'s certificates, None without one (the system's store is trusted then).
    pub roots: Option<Vec<CertificateDer<'static>>>,
}

impl std::fmt::Debug for Material {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let roots = self.roots.as_ref().map(Vec::len);
        f.debug_struct("Material").field("key", &"***").field("roots", &roots).finish()
    }
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
            material: None,
        }
    }

    /// Whether an event of type `kind` goes to this subscription.
    pub fn wants(&self, kind: &str) -> bool {
        self.events.iter().any(|pattern| matches(pattern, kind))
    }

    /// The signing key: as loaded ([`WebhookConfig::material`]), or else the secret (or
    /// `secret_file`'s first line) decoded now. The error says what is wrong, without the
    /// secret.
    pub fn key(&self) -> Result<Vec<u8>, SecretError> {
        if let Some(material) = &self.material {
            return Ok(material.key.clone());
        }
        let text = match (&self.secret, &self.secret_file) {
            (Some(_), Some(_)) => return Err(SecretError::Both),
            (None, None) => return Err(SecretError::Neither),
            (Some(secret), None) => secret.clone(),
            (None, Some(file)) => std::fs::read_to_string(file)
                .map_err(|source| SecretError::Read { path: file.clone(), source })?,
        };
        decode_secret(text.trim())
    }

    /// `ca_file`'s certificates (None without one): as loaded, or else read now.
    pub fn roots(&self) -> Result<Option<Vec<CertificateDer<'static>>>, CaError> {
        if let Some(material) = &self.material {
            return Ok(material.roots.clone());
        }
        self.ca_file.as_deref().map(super::ca::read_ca).transpose()
    }

    /// The key and the CA's certificates, as loaded or else read now.
    pub fn material(&self) -> Result<Material, WebhookProblem> {
        if let Some(material) = &self.material {
            return Ok(material.clone());
        }
        let key = self.key().map_err(WebhookProblem::Secret)?;
        Ok(Material { key, roots: self.roots()? })
    }

    /// Reads `secret_file` and `ca_file` (or decodes `secret`) into
    /// [`WebhookConfig::material`], once, as the configuration is loaded; files that do not
    /// read leave it None, and the check that follows names the key and why.
    pub fn resolve(&mut self) {
        self.material = None;
        self.material = self.material().ok();
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
pub fn decode_secret(text: &str) -> Result<Vec<u8>, SecretError> {
    use base64::Engine;
    let b64 = text.strip_prefix("whsec_").unwrap_or(text);
    let key = base64::engine::general_purpose::STANDARD.decode(b64).map_err(|_| SecretError::NotBase64)?;
    if !(16..=64).contains(&key.len()) {
        return Err(SecretError::Length(key.len()));
    }
    Ok(key)
}

/// Why a subscription has no signing key. No variant holds the secret.
#[derive(Debug, thiserror::Error)]
pub enum SecretError {
    /// Both `secret` and `secret_file`.
    #[error("set secret or secret_file, not both")]
    Both,
    /// Neither.
    #[error("a subscription needs secret or secret_file")]
    Neither,
    /// `secret_file` cannot be read.
    #[error("{} cannot be read: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Not base64.
    #[error("the secret is not base64 (as `whsec_` followed by base64)")]
    NotBase64,
    /// Too short or too long once decoded.
    #[error("the secret decodes to {0} bytes: 16 to 64 are needed")]
    Length(usize),
}

/// Why a `url` or `proxy` is not one a subscription takes.
#[derive(Debug, thiserror::Error)]
pub enum UrlProblem {
    /// Not a URL at all, in the URL parser's words.
    #[error(transparent)]
    Parse(<reqwest::Url as std::str::FromStr>::Err),
    /// Another scheme than `http` or `https`.
    #[error("the scheme is {0}")]
    Scheme(String),
    /// No host written after `//`.
    #[error("no host")]
    NoHost,
}

/// A `[[webhooks]]` entry that cannot be used: which one, and why.
#[derive(Debug, thiserror::Error)]
#[error("webhooks {name:?}: {problem}")]
pub struct WebhookConfigError {
    /// The entry's `name`.
    pub name: String,
    /// What is wrong with it.
    pub problem: WebhookProblem,
}

/// What is wrong with a `[[webhooks]]` entry. No variant carries the secret.
#[derive(Debug, thiserror::Error)]
pub enum WebhookProblem {
    /// A name that cannot be a path segment, a label and a header value as it is.
    #[error("a name is 1 to 64 characters of A-Z, a-z, 0-9, '_' and '-'")]
    Name,
    /// `url` or `proxy` is not an `http://` or `https://` URL with a host; the URL is
    /// shown without its password.
    #[error("{key} {url:?} is not an http:// or https:// URL with a host: {why}")]
    Url {
        /// `url` or `proxy`.
        key: &'static str,
        /// The URL, redacted.
        url: String,
        /// What is wrong.
        why: UrlProblem,
    },
    /// No event type at all: the subscription would deliver nothing.
    #[error("events is empty: name event types (job.updated), families (job.*) or \"*\"")]
    NoEvents,
    /// A pattern that covers no event type rackd writes (a typo would deliver nothing).
    #[error("{0:?} is not an event type: {types}", types = known_patterns())]
    UnknownEvent(String),
    /// The secret cannot be read or decoded (`secret_file`'s path is named, the secret never).
    #[error(transparent)]
    Secret(SecretError),
    /// A time that must be above 0.
    #[error("{0} must be at least 1")]
    Zero(&'static str),
    /// A longest wait shorter than the first.
    #[error("max_backoff_ms ({max}) is less than backoff_ms ({first})")]
    Backoff {
        /// `backoff_ms`.
        first: u64,
        /// `max_backoff_ms`.
        max: u64,
    },
    /// `ca_file` is not a usable CA file.
    #[error(transparent)]
    Ca(#[from] super::ca::CaError),
}

impl WebhookProblem {
    /// The entry's key the problem is about, for pointing at its line.
    pub fn key(&self, entry: &WebhookConfig) -> &'static str {
        match self {
            WebhookProblem::Name => "name",
            WebhookProblem::Url { key, .. } | WebhookProblem::Zero(key) => key,
            WebhookProblem::NoEvents | WebhookProblem::UnknownEvent(_) => "events",
            // Both set, or only the file: the file's line; neither: the entry's.
            WebhookProblem::Secret(_) if entry.secret_file.is_some() => "secret_file",
            WebhookProblem::Secret(_) => "secret",
            WebhookProblem::Backoff { .. } => "max_backoff_ms",
            WebhookProblem::Ca(_) => "ca_file",
        }
    }
}

/// What `events` may name, in words: every type, every family, `*`.
fn known_patterns() -> String {
    let mut families: Vec<String> = Vec::new();
    for family in EVENT_TYPES.iter().filter_map(|t| t.split('.').next()).map(|f| format!("{f}.*")) {
        if !families.contains(&family) {
            families.push(family);
        }
    }
    format!(
        "the types are {}; the families {}; and \"*\" for all",
        EVENT_TYPES.join(", "),
        families.join(", ")
    )
}

impl WebhookConfig {
    /// Checks the entry alone: its material as loaded, or else `secret_file` and `ca_file`
    /// read now.
    pub fn check(&self) -> Result<(), WebhookConfigError> {
        self.problem().map_or(Ok(()), |problem| Err(WebhookConfigError { name: self.name.clone(), problem }))
    }

    fn problem(&self) -> Option<WebhookProblem> {
        let name_ok = (1..=64).contains(&self.name.len())
            && self.name.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-');
        if !name_ok {
            return Some(WebhookProblem::Name);
        }
        if let Err(why) = http_url(&self.url) {
            return Some(WebhookProblem::Url { key: "url", url: crate::redact::url(&self.url), why });
        }
        if self.events.is_empty() {
            return Some(WebhookProblem::NoEvents);
        }
        if let Some(pattern) = self.events.iter().find(|p| !known(p)) {
            return Some(WebhookProblem::UnknownEvent(pattern.clone()));
        }
        if let Err(why) = self.key() {
            return Some(WebhookProblem::Secret(why));
        }
        let zero = [
            ("timeout_ms", self.timeout_ms),
            ("backoff_ms", self.backoff_ms),
            ("max_backoff_ms", self.max_backoff_ms),
            ("alarm_after_secs", self.alarm_after_secs),
        ];
        if let Some((key, _)) = zero.into_iter().find(|&(_, n)| n == 0) {
            return Some(WebhookProblem::Zero(key));
        }
        if self.max_backoff_ms < self.backoff_ms {
            return Some(WebhookProblem::Backoff { first: self.backoff_ms, max: self.max_backoff_ms });
        }
        if let Err(e) = self.roots() {
            return Some(e.into());
        }
        if let Some(proxy) = &self.proxy
            && let Err(why) = http_url(proxy)
        {
            return Some(WebhookProblem::Url { key: "proxy", url: crate::redact::url(proxy), why });
        }
        None
    }
}

/// Whether `text` is an `http://` or `https://` URL with a host. The URL standard reads
/// `http:///x` and `http:x` as `http://x/`; a missing host is a mistake here, so the text
/// itself must have one after `//`.
fn http_url(text: &str) -> Result<(), UrlProblem> {
    let url = reqwest::Url::parse(text).map_err(UrlProblem::Parse)?;
    if !matches!(url.scheme(), "http" | "https") {
        return Err(UrlProblem::Scheme(url.scheme().to_owned()));
    }
    let authority = text.split_once("://").map(|(_, rest)| rest);
    let written = authority.is_some_and(|a| !a.starts_with('/'));
    if !written || url.host_str().is_none_or(str::is_empty) {
        return Err(UrlProblem::NoHost);
    }
    Ok(())
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
        assert!(matches!(decode_secret("whsec_not base64!"), Err(SecretError::NotBase64)));
        assert!(matches!(decode_secret("whsec_c2hvcnQ="), Err(SecretError::Length(5))));
        assert!(decode_secret("whsec_c2hvcnQ=").unwrap_err().to_string().contains("5 bytes"));
    }
}
