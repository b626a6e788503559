//! The client a standby forwards with ([`Forwarder`]), and what is said about a link
//! between nodes that is not encrypted. Why it is built as it is:
//! [`super::forward`]'s module documentation.

use std::sync::atomic::AtomicBool;
use std::time::Duration;

/// How a standby reaches the active node: one client for the process's life.
pub struct Forwarder {
    pub(super) client: reqwest::Client,
    /// The largest body forwarded: `server.body_limit_bytes`.
    pub(super) limit: usize,
    /// Whether keys are configured (then plain http to another machine is warned about).
    pub(super) keyed: bool,
    /// Whether that warning was logged.
    pub(super) warned: AtomicBool,
}

impl Forwarder {
    /// A forwarder trusting the CA in `ca_file` (PEM), or the compiled-in public roots
    /// when there is none; bodies up to `limit` bytes.
    pub fn new(ca_file: Option<&std::path::Path>, limit: usize, keyed: bool) -> anyhow::Result<Forwarder> {
        let mut builder = reqwest::Client::builder()
            .no_proxy()
            .redirect(reqwest::redirect::Policy::none())
            .tls_built_in_native_certs(false)
            .timeout(Duration::from_secs(30))
            .connect_timeout(Duration::from_secs(2));
        if let Some(path) = ca_file {
            builder = builder.tls_built_in_root_certs(false);
            for cert in crate::config::ca::read_ca(path)? {
                builder = builder.add_root_certificate(reqwest::Certificate::from_der(&cert)?);
            }
        }
        Ok(Forwarder { client: builder.build()?, limit, keyed, warned: AtomicBool::new(false) })
    }
}

/// Logs a warning when `url` is plain http to another machine while keys are configured:
/// the callers' keys would cross the network in clear. `what` names the URL.
pub fn warn_if_clear(url: &str, keyed: bool, what: &str) {
    if keyed && in_clear(url) {
        tracing::warn!(
            url = crate::redact::url(url),
            "{what} is plain http to another machine: forwarded requests carry API keys there in clear \
             (serve https with [server.tls] and say https:// in cluster.url)"
        );
    }
}

/// Whether `url` is `http://` to a host that is not this machine (the configuration's
/// own test, which `check-config` warns of for webhooks).
pub(super) use crate::config::in_clear;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_client_trusts_the_cluster_ca_file_and_refuses_one_that_is_not() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("ca.pem");
        std::fs::write(&file, "not pem").unwrap();
        let err = Forwarder::new(Some(&file), 1024, true).err().unwrap().to_string();
        assert!(err.contains("holds no certificate"), "{err}");
        assert!(Forwarder::new(None, 1024, true).is_ok());
    }
}
