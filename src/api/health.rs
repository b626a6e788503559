//! `GET /api/v1/health`: the whole site at a glance, for people and for load balancers
//! that want more than `/readyz`: the store, and each device's link, pause, warnings and
//! active alarms.
//!
//! `status` is `ok` when the store works and every device is online with no active alarm
//! and no degraded link; `degraded` when the store works but a device does not (rackd still
//! takes and keeps jobs); `down` when the store does not (it does not answer, its writer
//! stopped, or its last commit failed for the store's own cause: `store::fault`), answered
//! with 503.

use axum::extract::State;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use time::OffsetDateTime;
use utoipa::ToSchema;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::extract::Json;
use super::state::AppState;
use crate::service::monitor::all_shown;
use crate::store::alarms;
use crate::store::fault::Fault;

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(health))
}

/// The site at a glance.
#[derive(Debug, Serialize, ToSchema)]
#[schema(example = json!({"status": "degraded", "store": "ok", "devices": [{"id": "shelf1", "online": false,
    "paused": false, "degraded": false, "active_alarms": 1, "last_contact": "2026-11-21T08:00:00.000Z",
    "seconds_since_contact": 42.5}]}))]
pub struct SiteHealth {
    /// `ok`, `degraded` (a device is offline, degraded or in alarm) or `down` (the store).
    pub status: &'static str,
    /// `ok`, or what is wrong with the store (in plain words, no driver text).
    pub store: String,
    /// Each device.
    pub devices: Vec<DeviceHealth>,
}

/// One device at a glance.
#[derive(Debug, Serialize, ToSchema)]
pub struct DeviceHealth {
    /// The device's id.
    pub id: String,
    /// It answers (a crane: and its heartbeat moves).
    pub online: bool,
    /// Paused by an operator.
    pub paused: bool,
    /// Its link retries more than it should (a warning).
    pub degraded: bool,
    /// Its active alarms.
    pub active_alarms: u32,
    /// When it last answered.
    #[serde(with = "time::serde::rfc3339::option")]
    #[schema(value_type = Option<String>, format = DateTime)]
    pub last_contact: Option<OffsetDateTime>,
    /// Seconds since it last answered (null: never).
    pub seconds_since_contact: Option<f64>,
}

/// How long `/readyz` and the health wait for the database before they say it does not
/// answer: a server that went away would hold them for the pool's whole wait (5 s and
/// more). Two seconds, not less: a healthy store under load (a busy pool on a loaded
/// machine) must not be reported down. What must be told faster is: the writer tells a
/// failed commit at once and a commit that waits a second (`store::writer`'s stall), these
/// answer from that memory without waiting, and the dashboard hears it over the
/// WebSocket (`{"type": "store"}`).
pub const READ_WAIT: std::time::Duration = std::time::Duration::from_secs(2);

/// The store's readiness now: the writer's fault from memory if it has one (also when it
/// meets one while this waits), else [`crate::store::ready`] within [`READ_WAIT`]. `Ok`
/// with a fault: the database reads but the store cannot commit.
pub async fn store_now(app: &AppState) -> (Result<(), crate::store::NotReady>, Option<Fault>) {
    if let Some(fault) = app.store_fault.current() {
        return (Ok(()), Some(fault));
    }
    let mut told = app.store_fault.subscribe();
    let met = async move { told.wait_for(Option::is_some).await.map(|f| *f) };
    tokio::select! {
        read = tokio::time::timeout(READ_WAIT, crate::store::ready(&app.pool)) => {
            let read = read.unwrap_or(Err(crate::store::NotReady::Unreachable(sqlx::Error::PoolTimedOut)));
            (read, app.store_fault.current())
        }
        Ok(Some(fault)) = met => (Ok(()), Some(fault)),
    }
}

/// The site at a glance: the store and each device; 503 when the store is down.
#[utoipa::path(get, path = "/health", tag = "operations",
    responses(
        (status = 200, description = "The store works; `status` says whether every device does", body = SiteHealth),
        (status = 503, description = "The store is down (`status`: `down`)", body = SiteHealth),
    ))]
async fn health(State(app): State<AppState>) -> Response {
    // While the store cannot commit, the answer comes from memory at once (the devices'
    // active alarms uncounted): a database that does not answer would otherwise hold it
    // for the pool's connection wait, twice, and the dashboard would learn why seconds
    // late. Otherwise each read waits at most `READ_WAIT`.
    let (ready, fault) = store_now(&app).await;
    let store = match ready {
        Ok(()) if let Some(fault) = fault => format!("the store cannot commit: {}", fault.cause.words()),
        Ok(()) if app.writer.is_running() => "ok".to_owned(),
        Ok(()) => "the job writer has stopped".to_owned(),
        Err(e) => {
            tracing::error!(error = %e, "health: the store is not ready");
            match e {
                crate::store::NotReady::Unreachable(_) => "the database does not answer".to_owned(),
                crate::store::NotReady::Migration { .. } => {
                    "the database schema is not up to date".to_owned()
                }
            }
        }
    };
    // Not waited for again when the store is down already.
    let active = match fault {
        Some(_) => Vec::new(),
        None if store != "ok" => Vec::new(),
        None => tokio::time::timeout(READ_WAIT, alarms::active(&app.pool))
            .await
            .ok()
            .and_then(Result::ok)
            .unwrap_or_default(),
    };
    let now = crate::domain::time::now();
    let devices: Vec<DeviceHealth> = all_shown(&app.devices(), app.dispatcher.queues())
        .into_iter()
        .map(|d| DeviceHealth {
            active_alarms: active.iter().filter(|a| a.device == d.id).count() as u32,
            online: d.online,
            paused: d.paused,
            degraded: d.link.degraded,
            last_contact: d.last_contact,
            seconds_since_contact: d.last_contact.map(|t| (now - t).as_seconds_f64().max(0.0)),
            id: d.id,
        })
        .collect();
    let troubled = devices.iter().any(|d| !d.online || d.degraded || d.active_alarms > 0);
    let (status, code) = match (store.as_str(), troubled) {
        ("ok", false) => ("ok", StatusCode::OK),
        ("ok", true) => ("degraded", StatusCode::OK),
        _ => ("down", StatusCode::SERVICE_UNAVAILABLE),
    };
    (code, Json(SiteHealth { status, store, devices })).into_response()
}
