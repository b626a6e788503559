//! The state every handler shares.

use std::sync::Arc;

use sqlx::SqlitePool;

use super::metrics::Metrics;
use crate::auth::KeyRing;
use crate::service::intake::Rules;
use crate::store::writer::Writer;

/// Everything a handler may need, cloned cheaply into each request.
#[derive(Clone)]
pub struct AppState {
    /// The database, for reads.
    pub pool: SqlitePool,
    /// The one writer of jobs.
    pub writer: Writer,
    /// What job requests are checked against.
    pub rules: Arc<Rules>,
    /// The API keys.
    pub keys: Arc<KeyRing>,
    /// Prometheus metrics.
    pub metrics: Arc<Metrics>,
    /// The running devices.
    pub devices: crate::devices::Devices,
    /// Live events, for WebSocket subscribers.
    pub hub: crate::service::events::Hub,
    /// Settings of the event stream.
    pub events: Arc<crate::config::EventsConfig>,
}
