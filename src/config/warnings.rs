//! What `rackd check-config` warns of, and `rackd serve` logs at its start: settings that
//! run, but that a site most likely does not mean. A warning names where the value was set
//! and its key, as an error does (`WHERE: KEY: warning: MESSAGE`), and never stops rackd.
//!
//! Decisions:
//! - **A webhook to another machine over plain `http://`**: every event (jobs, locations,
//!   alarms, the audit log) and its signature cross the network in clear; the signature
//!   proves who sent an event, it hides nothing. A warning, not an error: a receiver on a
//!   segment the site trusts may be meant. Loopback (`127.0.0.0/8`, `::1`, `localhost`) is
//!   this machine, and not warned of.
//! - The URL is shown as every URL is ([`crate::redact`]).

use std::fmt;

use super::{Loaded, Origin};

/// A setting rackd runs with, but warns of.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Warning {
    /// Where the value was set.
    pub origin: Origin,
    /// The key (`webhooks[0].url`).
    pub key: String,
    /// Why, and what to do.
    pub message: String,
}

impl fmt::Display for Warning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}: warning: {}", self.origin, self.key, self.message)
    }
}

impl Loaded {
    /// What this configuration is warned of, in the order of its keys.
    pub fn warnings(&self) -> Vec<Warning> {
        let mut out = Vec::new();
        for (i, webhook) in self.config.webhooks.iter().enumerate() {
            if in_clear(&webhook.url) {
                let key = format!("webhooks[{i}].url");
                out.push(Warning {
                    origin: self.origin(&key),
                    message: format!(
                        "{:?} is plain http to another machine: every event and its signature cross the network \
                         in clear; say https:// (with ca_file for a site's own CA)",
                        crate::redact::url(&webhook.url)
                    ),
                    key,
                });
            }
        }
        out
    }
}

/// Whether `url` is `http://` to a host that is not this machine.
pub fn in_clear(url: &str) -> bool {
    let Ok(url) = reqwest::Url::parse(url) else { return false };
    let host = url.host_str().unwrap_or_default().trim_start_matches('[').trim_end_matches(']');
    let local = host.is_empty()
        || host.eq_ignore_ascii_case("localhost")
        || host.parse::<std::net::IpAddr>().is_ok_and(|ip| ip.is_loopback());
    url.scheme() == "http" && !local
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::config::Sources;

    #[test]
    fn plain_http_is_in_clear_only_to_another_machine() {
        assert!(in_clear("http://10.0.0.11:8080"));
        assert!(in_clear("http://rackd-2.plant:8080"));
        assert!(!in_clear("https://10.0.0.11:8080"));
        assert!(!in_clear("http://127.0.0.1:8080") && !in_clear("http://localhost:8080"));
        assert!(!in_clear("http://[::1]:8080") && !in_clear("http://127.9.9.9/x"));
    }

    #[test]
    fn a_webhook_in_clear_is_warned_of_where_it_is_set() {
        let text = "[[webhooks]]\nname = \"wms\"\nurl = \"http://wms.plant/e?token=T\"\nevents = [\"*\"]\n\
                    secret = \"whsec_MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw\"\n";
        let loaded = Sources::file(Path::new("x.toml")).load_text(Some(text.into())).unwrap();
        let warnings = loaded.warnings();
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        let line = warnings[0].to_string();
        assert!(
            line.starts_with("x.toml:3:1: webhooks[0].url: warning: \"http://wms.plant/e?token=***\""),
            "{line}"
        );
        let quiet = text.replace("http://wms.plant", "https://wms.plant");
        let loaded = Sources::file(Path::new("x.toml")).load_text(Some(quiet)).unwrap();
        assert!(loaded.warnings().is_empty());
    }
}
