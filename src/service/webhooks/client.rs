//! The HTTP client a subscription delivers with, one per subscription for the process's
//! life (its connection to the receiver is kept alive between deliveries).
//!
//! Outbound calls from a plant network, so:
//! - **no proxy** from the environment (`HTTP_PROXY` and the like are ignored); one only
//!   when the subscription names it (`proxy`);
//! - **https** trusting the subscription's `ca_file` alone when set (its certificates as
//!   read when the configuration was loaded: [`Material`]), otherwise the system's store
//!   (`/etc/ssl/certs`, read when the client is built), where a site installs its own CA; unlike
//!   the standby's forwarder, which trusts the compiled-in public roots, a WMS is often
//!   behind a company CA the system already trusts;
//! - **no redirect** followed: a 3xx is a failed delivery (the events and their signature
//!   go only where the configuration says);
//! - **timeouts**: `timeout_ms` for the whole try, the answer's body included; the
//!   connection within the same time, at most 2 s;
//! - **the answer's body** is read up to [`BODY_LIMIT`] bytes (an excerpt of it goes into
//!   the delivery's error), and the connection dropped beyond.

use std::time::Duration;

use crate::config::WebhookConfig;
use crate::config::webhooks::Material;

/// The most of an answer's body read.
pub const BODY_LIMIT: usize = 64 * 1024;

/// The client for subscription `config`, trusting `material`'s roots; an error says what
/// in its configuration is wrong.
pub fn client(config: &WebhookConfig, material: &Material) -> anyhow::Result<reqwest::Client> {
    let timeout = Duration::from_millis(config.timeout_ms.max(1));
    let mut builder = reqwest::Client::builder()
        .no_proxy()
        .redirect(reqwest::redirect::Policy::none())
        .timeout(timeout)
        .connect_timeout(timeout.min(Duration::from_secs(2)))
        .pool_max_idle_per_host(1)
        .user_agent(concat!("rackd/", env!("CARGO_PKG_VERSION")))
        .tls_built_in_webpki_certs(false);
    match &material.roots {
        Some(roots) => {
            builder = builder.tls_built_in_root_certs(false);
            for cert in roots {
                builder = builder.add_root_certificate(reqwest::Certificate::from_der(cert)?);
            }
        }
        None => builder = builder.tls_built_in_native_certs(true),
    }
    if let Some(proxy) = &config.proxy {
        builder = builder.proxy(reqwest::Proxy::all(proxy)?);
    }
    Ok(builder.build()?)
}
