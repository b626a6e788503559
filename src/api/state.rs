//! The state every handler shares.

use std::sync::Arc;

use crate::store::Pool;

use super::metrics::Metrics;
use crate::auth::KeyRing;
use crate::service::intake::Rules;
use crate::store::writer::Writer;

/// Everything a handler may need, cloned into each request (and each middleware) as one
/// reference count: a struct of a dozen handles would pay a dozen atomic updates per clone
/// and drop, which showed in profiles of the intake path.
#[derive(Clone)]
pub struct AppState(Arc<Shared>);

impl AppState {
    /// The state for `shared`.
    pub fn new(shared: Shared) -> AppState {
        AppState(Arc::new(shared))
    }
}

impl Shared {
    /// The running devices (none on a standby node).
    pub fn devices(&self) -> crate::devices::Devices {
        self.reload.devices()
    }

    /// What job requests are checked against and routed by, as the running configuration
    /// sets them.
    pub fn rules(&self) -> Arc<Rules> {
        self.reload.rules()
    }

    /// The API keys and the failed-key limit, as the running configuration sets them.
    pub fn keys(&self) -> Arc<KeyRing> {
        self.reload.keys()
    }
}

impl std::ops::Deref for AppState {
    type Target = Shared;
    fn deref(&self) -> &Shared {
        &self.0
    }
}

/// What [`AppState`] holds.
pub struct Shared {
    /// The database, for reads.
    pub pool: Pool,
    /// The one writer of jobs.
    pub writer: Writer,
    /// Prometheus metrics.
    pub metrics: Arc<Metrics>,
    /// The webhook subscriptions' deliverers, once this node drives the machines.
    pub webhooks: Arc<std::sync::OnceLock<crate::service::webhooks::Webhooks>>,
    /// The webhook subscriptions as configured (every node lists them).
    pub subscriptions: Arc<Vec<crate::config::WebhookConfig>>,
    /// This node's part in a cluster, if it is in one.
    pub cluster: Option<crate::service::cluster::Node>,
    /// How a standby forwards to the active node (in a cluster).
    pub forwarder: Option<super::peer::Forwarder>,
    /// The dispatcher: cancels and devices' control state.
    pub dispatcher: crate::service::dispatch::Dispatcher,
    /// Live events, for WebSocket subscribers.
    pub hub: crate::service::events::Hub,
    /// Settings of the event stream.
    pub events: Arc<crate::config::EventsConfig>,
    /// The hosts keyless mode answers for.
    pub hosts: super::keyless::Hosts,
    /// The running configuration, where to read it again (`POST /config/reload`), the
    /// rules it sets and the devices it runs (once this node drives them: at start, or in a
    /// cluster when it becomes the active node).
    pub reload: crate::service::reload::Reload,
    /// Where alarm captures are (`retention.captures_dir`).
    pub captures: std::path::PathBuf,
    /// The places for device capture builds, `server.capture_downloads` of them
    /// (`api::devices::capture`).
    pub capture_builds: Arc<tokio::sync::Semaphore>,
    /// Failed authentications per client address (the limit is the key ring's).
    pub failures: super::failures::Failures,
    /// Whether the store commits (`store::fault`).
    pub store_fault: crate::store::fault::StoreFault,
}
