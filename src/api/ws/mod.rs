//! `GET /api/v1/ws`: live events over WebSocket.
//!
//! The conversation, server to client, every message a JSON text frame:
//! 1. the start: either a **snapshot** `{"type": "snapshot", "seq", "reason", "data": {"jobs",
//!    "jobs_truncated", "devices", "alarms", "locations"}}` (the state as of event `seq`; only
//!    the requested topics' parts), or, with `?since=SEQ` still in the log, the **replay** of
//!    every event after `SEQ`;
//! 2. then every new **event** `{"seq", "time", "type", "data"}` in sequence order, with no
//!    gap and no duplicate (the snapshot or replay and the live stream are joined on `seq`);
//! 3. a client that falls `events.buffer` commits behind gets `{"type": "resync", "seq",
//!    "reason"}` (seq = the last event it was sent) and the connection is closed with code
//!    4000; it reconnects with `?since=SEQ`. Nobody else waits for it.
//! 4. **the store's state** `{"type": "store", "ok", "cause", "message", "since"}` whenever
//!    the store stops or starts committing again (`store::fault`), and right after the start
//!    while it cannot. It is not an event of the log (the log cannot record anything then)
//!    and has no `seq`; it comes within a moment of the first failed commit, so a dashboard
//!    says why nothing moves while the machines are held.
//!
//! The server pings every `events.ping_secs` and drops a client silent for two pings;
//! clients may ping too. A socket opened with a key that a reload removes is closed with
//! code 1008 (`session::CLOSE_REVOKED`): a revoked key reads nothing more, on a socket
//! opened before as on a request. A `since` that is no longer in the log (retention) or beyond its
//! end (another database) starts with a snapshot whose `reason` says so.

mod session;
mod snapshot;

use axum::extract::State;
use axum::extract::ws::{WebSocketUpgrade, rejection::WebSocketUpgradeRejection};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::error::{ApiError, ErrorBody};
use super::extract::Query;
use super::state::AppState;
use crate::service::events::Topic;

pub use snapshot::{Snapshot, SnapshotData};

/// Sent to a subscriber that fell too far behind, just before the connection is closed
/// with code 4000.
#[derive(Debug, serde::Serialize, ToSchema)]
#[schema(example = json!({"type": "resync", "seq": 1200, "reason": "fell 1025 commits behind; reconnect with since=1200"}))]
pub struct Resync {
    /// Always `resync`.
    #[serde(rename = "type")]
    #[schema(rename = "type")]
    pub kind: &'static str,
    /// The last event this subscriber was sent: reconnect with `?since=` this.
    pub seq: i64,
    /// Why, in words.
    pub reason: String,
}

/// Whether the store commits: sent when that changes, and after the start while it cannot.
#[derive(Debug, serde::Serialize, ToSchema)]
#[schema(example = json!({"type": "store", "ok": false, "cause": "full",
    "message": "the disk that holds the database is full", "since": "2026-11-29T12:00:00Z"}))]
pub struct StoreState {
    /// Always `store`.
    #[serde(rename = "type")]
    #[schema(rename = "type")]
    pub kind: &'static str,
    /// Whether the store commits.
    pub ok: bool,
    /// Why not: `full`, `read_only`, `io_error` or `unreachable` (null when ok).
    pub cause: Option<&'static str>,
    /// Why not, in words (null when ok).
    pub message: Option<&'static str>,
    /// Since when it cannot (null when ok).
    #[serde(with = "time::serde::rfc3339::option")]
    #[schema(value_type = Option<String>, format = DateTime)]
    pub since: Option<time::OffsetDateTime>,
}

impl StoreState {
    /// The message for `fault` (None: the store commits).
    pub fn of(fault: Option<crate::store::fault::Fault>) -> StoreState {
        StoreState {
            kind: "store",
            ok: fault.is_none(),
            cause: fault.map(|f| f.cause.as_str()),
            message: fault.map(|f| f.cause.words()),
            since: fault.map(|f| crate::domain::time::from_ms(f.since_ms)),
        }
    }
}

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(subscribe))
}

/// `?topics=` and `?since=`.
#[derive(Debug, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct WsParams {
    /// Comma-separated topics: `jobs`, `devices`, `alarms`, `locations` (default: all).
    pub topics: Option<String>,
    /// Replay every event after this sequence number, then continue live.
    pub since: Option<i64>,
    /// The API key, for browsers (which cannot set headers on a WebSocket).
    pub token: Option<String>,
}

/// One event as subscribers receive it.
#[derive(ToSchema)]
#[schema(example = json!({"seq": 42, "time": "2026-11-21T08:00:00.000Z", "type": "job.updated",
    "data": {"id": 7, "kind": "store", "state": "running"}}))]
#[allow(dead_code)]
pub struct Event {
    /// Position in the event log, from 1, without gaps.
    seq: i64,
    /// When the change was committed (RFC 3339).
    time: String,
    /// `job.updated` (data: a Job), `device.updated` (a DeviceStatus), `alarm.raised` and
    /// `alarm.cleared` (an Alarm), `location.updated` (a LocationState).
    #[schema(rename = "type")]
    kind: String,
    /// The changed object, whole.
    data: serde_json::Value,
}

/// Which topics a subscriber asked for.
fn topics(text: Option<&str>) -> Result<Vec<Topic>, ApiError> {
    let Some(text) = text.filter(|t| !t.trim().is_empty()) else { return Ok(Topic::ALL.to_vec()) };
    text.split(',')
        .map(|name| {
            Topic::parse(name.trim()).ok_or_else(|| {
                ApiError::bad_request(
                    "bad_query",
                    format!("unknown topic {:?}: topics are jobs, devices, alarms, locations", name.trim()),
                )
            })
        })
        .collect()
}

/// Live events: a snapshot (or a replay from `since`), then every change as it is committed.
///
/// Messages are JSON text frames: `snapshot` `{"type": "snapshot", "seq", "reason", "data":
/// {"jobs", "jobs_truncated", "devices", "alarms", "locations"}}`, then events `{"seq",
/// "time", "type", "data"}` (schema `Event`) in sequence order without gap or duplicate, and
/// `{"type": "resync", "seq", "reason"}` when the client fell too far behind (the connection
/// then closes with code 4000; reconnect with `?since=SEQ`), and `{"type": "store", "ok",
/// "cause", "message", "since"}` (schema `StoreState`) when the store stops or starts
/// committing again, and after the start while it cannot. Viewer role; browsers pass the
/// key as `?token=`. A reload that removes the key closes the socket with code 1008.
#[utoipa::path(get, path = "/ws", tag = "events", params(WsParams),
    responses(
        (status = 101, description = "Switching to the WebSocket protocol; then messages as described", body = Event),
        (status = 400, description = "Unknown topic or not a WebSocket request", body = ErrorBody),
        (status = 401, description = "No or unknown key", body = ErrorBody),
    ))]
async fn subscribe(
    State(app): State<AppState>,
    who: Option<axum::Extension<crate::auth::Principal>>,
    Query(params): Query<WsParams>,
    upgrade: Result<WebSocketUpgrade, WebSocketUpgradeRejection>,
) -> Result<Response, ApiError> {
    let topics = topics(params.topics.as_deref())?;
    if params.since.is_some_and(|s| s < 0) {
        return Err(ApiError::bad_request("bad_query", "since must be 0 or more"));
    }
    let upgrade = upgrade.map_err(|e| {
        ApiError::bad_request(
            "websocket_required",
            format!("this route speaks WebSocket only ({})", e.body_text().trim()),
        )
    })?;
    // Subscribe before the snapshot or replay is read, so that nothing committed in
    // between can be missed; duplicates are dropped by sequence number.
    let key = who.map(|axum::Extension(p)| p.hash);
    let session = session::Session::new(&app, topics, params.since, key);
    // Clients send little (pongs, a close), and the read buffer is zero-filled to its size
    // each time the socket is polled for input, which is once per event sent: a small one
    // keeps that from costing more than the send (it cut the CPU per delivery by half).
    let upgrade = upgrade.max_message_size(64 * 1024).read_buffer_size(4 * 1024);
    Ok(upgrade.on_upgrade(move |socket| session.run(socket)).into_response())
}
