//! `/api/v1/webhooks`: the subscriptions that push events to the WMS
//! (`service::webhooks`), their state, their delivery log, and an administrator's pause,
//! resume and replay. Reads are answered by any node from the store; the actions by the
//! node that delivers (a standby forwards them), each audited on `webhook:NAME`.

use axum::extract::State;
use serde::{Deserialize, Serialize};
use time::OffsetDateTime;
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::control::{ControlRequest, actor};
use super::error::{ApiError, ErrorBody};
use super::extract::{Caller, Json, OptionalJson, Path, Query, page};
use super::state::AppState;
use crate::config::WebhookConfig;
use crate::domain::time::{from_ms, now_ms};
use crate::service::webhooks::{Action, ActionError};
use crate::store::events;
use crate::store::webhooks::{self, PausedBy, Row};

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(list_webhooks))
        .routes(routes!(list_deliveries))
        .routes(routes!(replay_webhook))
        .routes(routes!(pause_webhook))
        .routes(routes!(resume_webhook))
}

/// A subscription and how far it is.
#[derive(Debug, Serialize, ToSchema)]
pub struct Webhook {
    /// Its name.
    pub name: String,
    /// Where events go (a password and secret query parameters in it shown as `***`).
    pub url: String,
    /// The event types it takes (`job.*`, `alarm.raised`, `*`).
    pub events: Vec<String>,
    /// `delivering` (events are waiting), `caught_up`, `failing` (the last try failed, or
    /// the subscription could not start: `last_error` says why), `paused`.
    #[schema(example = "caught_up")]
    pub state: String,
    /// The last event seq it is done with.
    pub cursor: i64,
    /// Events in the log after the cursor (of any type).
    pub behind: i64,
    /// Seconds since the oldest event after the cursor was committed (0 when caught up).
    pub behind_secs: f64,
    /// Who paused it, while it is paused: `admin` (an administrator's pause: no alarm, its
    /// events not held) or `receiver` (its receiver, or a proxy in front of it, answered 410
    /// Gone: the `webhook` alarm with code 2, its events held up to
    /// `events.webhook_hold_hours`).
    pub paused_by: Option<PausedBy>,
    /// Why it is paused.
    pub paused_reason: Option<String>,
    /// When a delivery last succeeded.
    #[serde(with = "time::serde::rfc3339::option")]
    #[schema(value_type = Option<String>, format = DateTime)]
    pub last_ok_at: Option<OffsetDateTime>,
    /// The last failure.
    pub last_error: Option<String>,
    /// When it happened.
    #[serde(with = "time::serde::rfc3339::option")]
    #[schema(value_type = Option<String>, format = DateTime)]
    pub last_error_at: Option<OffsetDateTime>,
    /// Since when every try has failed.
    #[serde(with = "time::serde::rfc3339::option")]
    #[schema(value_type = Option<String>, format = DateTime)]
    pub failing_since: Option<OffsetDateTime>,
}

/// The subscriptions.
#[derive(Debug, Serialize, ToSchema)]
pub struct WebhookList {
    /// Each configured subscription, by name.
    pub webhooks: Vec<Webhook>,
}

/// Every configured subscription with its state, lag and last error.
#[utoipa::path(get, path = "/webhooks", tag = "webhooks",
    responses((status = 200, description = "The subscriptions", body = WebhookList)))]
async fn list_webhooks(State(app): State<AppState>) -> Result<Json<WebhookList>, ApiError> {
    let rows = webhooks::rows(&app.pool).await?;
    let mut list = Vec::new();
    for config in app.subscriptions.iter() {
        let row = rows.iter().find(|r| r.name == config.name).cloned();
        list.push(view(&app, config, row).await?);
    }
    Ok(Json(WebhookList { webhooks: list }))
}

/// A subscription as the API shows it: its row as the deliverer holds it on the node that
/// delivers (ahead of the store by the group being written), as stored elsewhere.
async fn view(app: &AppState, config: &WebhookConfig, stored: Option<Row>) -> Result<Webhook, ApiError> {
    let live = app.webhooks.get().and_then(|w| w.live().into_iter().find(|(c, _)| c.name == config.name));
    let row = match &live {
        Some((_, live)) if !live.row.name.is_empty() => live.row.clone(),
        _ => stored.unwrap_or_else(|| Row { name: config.name.clone(), ..Row::default() }),
    };
    let newest = app.hub.published().get();
    let behind = (newest - row.cursor).max(0);
    let behind_secs = match behind {
        0 => 0.0,
        _ => match events::after(&app.pool, row.cursor, 1).await?.first() {
            Some(next) => (now_ms() - next.at).max(0) as f64 / 1000.0,
            None => 0.0,
        },
    };
    // A subscription that could not start on this node delivers nothing: failing, with why
    // (its `webhook` alarm, code 3, says the same).
    let unstarted = app.webhooks.get().and_then(|w| w.unstarted(&config.name)).map(str::to_owned);
    let state = if row.paused != 0 {
        "paused"
    } else if row.failing_since.is_some() || unstarted.is_some() {
        "failing"
    } else if behind > 0 {
        "delivering"
    } else {
        "caught_up"
    };
    Ok(Webhook {
        name: config.name.clone(),
        url: crate::redact::url(&config.url),
        events: config.events.clone(),
        state: state.into(),
        cursor: row.cursor,
        behind,
        behind_secs,
        paused_by: row.paused_by(),
        paused_reason: row.paused_reason,
        last_ok_at: row.last_ok_at.map(from_ms),
        last_error: unstarted.map(|why| format!("cannot start: {why}")).or(row.last_error),
        last_error_at: row.last_error_at.map(from_ms),
        failing_since: row.failing_since.map(from_ms),
    })
}

/// One try to deliver one event.
#[derive(Debug, Serialize, ToSchema)]
pub struct DeliveryView {
    /// Its place in the log (a page's cursor).
    pub id: i64,
    /// The event.
    pub seq: i64,
    /// 1 for the first try of this event, then 2, 3...
    pub attempt: i64,
    /// The receiver's HTTP status, when it answered.
    pub status: Option<i64>,
    /// `delivered` (2xx), `failed` or `gone` (410: the subscription was paused).
    #[schema(example = "delivered")]
    pub outcome: String,
    /// From the request's start to its answer or failure.
    pub latency_ms: i64,
    /// What went wrong.
    pub error: Option<String>,
    /// When the try ended.
    #[serde(with = "time::serde::rfc3339")]
    #[schema(value_type = String, format = DateTime)]
    pub at: OffsetDateTime,
}

/// A page of the delivery log.
#[derive(Debug, Serialize, ToSchema)]
pub struct DeliveryPage {
    /// Tries, newest first.
    pub deliveries: Vec<DeliveryView>,
    /// Pass as `cursor` for the next (older) page; absent on the last page.
    pub next_cursor: Option<String>,
}

/// Paging for the delivery log.
#[derive(Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct DeliveryParams {
    /// Continue after this cursor (the `next_cursor` of the previous page).
    cursor: Option<String>,
    /// Tries per page, 1..=1000 (default 100).
    #[param(minimum = 1, maximum = 1000)]
    limit: Option<u32>,
}

/// The delivery log of one subscription, newest first: every try of every event (kept as
/// long as the events are: `events.retention_hours`).
#[utoipa::path(get, path = "/webhooks/{name}/deliveries", tag = "webhooks", params(
        ("name" = String, Path, description = "The subscription's name"),
        DeliveryParams,
    ),
    responses(
        (status = 200, description = "A page of the delivery log", body = DeliveryPage),
        (status = 400, description = "Bad cursor or limit", body = ErrorBody),
        (status = 404, description = "No such subscription", body = ErrorBody),
    ))]
async fn list_deliveries(
    State(app): State<AppState>,
    Path(name): Path<String>,
    Query(p): Query<DeliveryParams>,
) -> Result<Json<DeliveryPage>, ApiError> {
    configured(&app, &name)?;
    let (limit, before) = page(p.limit, p.cursor, 1)?;
    let rows = webhooks::deliveries(&app.pool, &name, before, limit).await?;
    let next_cursor = (rows.len() == limit as usize).then(|| rows.last().map(|d| d.id.to_string())).flatten();
    let deliveries = rows
        .into_iter()
        .map(|d| DeliveryView {
            id: d.id,
            seq: d.seq,
            attempt: d.attempt,
            status: d.status,
            outcome: d.outcome,
            latency_ms: d.latency_ms,
            error: d.error,
            at: from_ms(d.at),
        })
        .collect();
    Ok(Json(DeliveryPage { deliveries, next_cursor }))
}

/// Where a replay starts.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"from_seq": 1, "reason": "the WMS restored yesterday's backup"}))]
pub struct ReplayRequest {
    /// The first event to deliver again (one the log still holds).
    pub from_seq: i64,
    /// Why, for the audit log (at most 500 characters).
    pub reason: Option<String>,
}

/// Deliver again from an event on: the cursor goes back to the event before `from_seq`,
/// and every event of the subscription's types from there is sent again, in order, with
/// its same `webhook-id`. Audited.
#[utoipa::path(post, path = "/webhooks/{name}/replay", tag = "webhooks",
    request_body = ReplayRequest,
    params(("name" = String, Path, description = "The subscription's name")),
    responses(
        (status = 200, description = "The subscription, its cursor moved", body = Webhook),
        (status = 404, description = "No such subscription", body = ErrorBody),
        (status = 409, description = "The log no longer (or not yet) holds that event", body = ErrorBody),
        (status = 422, description = "Bad body", body = ErrorBody),
        (status = 503, description = "This node does not deliver (no node does at the moment)", body = ErrorBody),
    ))]
async fn replay_webhook(
    State(app): State<AppState>,
    Path(name): Path<String>,
    by: Caller,
    Json(body): Json<ReplayRequest>,
) -> Result<Json<Webhook>, ApiError> {
    act(&app, &name, Action::Replay(body.from_seq), by, body.reason).await
}

/// Stop delivering to this subscription (a try under way ends first); its events are kept
/// for it no longer than any others (see `events.retention_hours`). A subscription its
/// receiver paused (410 Gone) becomes paused by an administrator: its alarm clears. Audited.
#[utoipa::path(post, path = "/webhooks/{name}/pause", tag = "webhooks",
    request_body(content = Option<ControlRequest>),
    params(("name" = String, Path, description = "The subscription's name")),
    responses(
        (status = 200, description = "The subscription, paused", body = Webhook),
        (status = 404, description = "No such subscription", body = ErrorBody),
        (status = 422, description = "Bad body", body = ErrorBody),
        (status = 503, description = "This node does not deliver (no node does at the moment)", body = ErrorBody),
    ))]
async fn pause_webhook(
    State(app): State<AppState>,
    Path(name): Path<String>,
    by: Caller,
    OptionalJson(body): OptionalJson<ControlRequest>,
) -> Result<Json<Webhook>, ApiError> {
    act(&app, &name, Action::Pause, by, body.reason).await
}

/// Deliver again to a paused subscription (paused by hand or by a 410 Gone), from its
/// cursor; the alarm of a 410's pause clears. Audited.
#[utoipa::path(post, path = "/webhooks/{name}/resume", tag = "webhooks",
    request_body(content = Option<ControlRequest>),
    params(("name" = String, Path, description = "The subscription's name")),
    responses(
        (status = 200, description = "The subscription, delivering", body = Webhook),
        (status = 404, description = "No such subscription", body = ErrorBody),
        (status = 422, description = "Bad body", body = ErrorBody),
        (status = 503, description = "This node does not deliver (no node does at the moment)", body = ErrorBody),
    ))]
async fn resume_webhook(
    State(app): State<AppState>,
    Path(name): Path<String>,
    by: Caller,
    OptionalJson(body): OptionalJson<ControlRequest>,
) -> Result<Json<Webhook>, ApiError> {
    act(&app, &name, Action::Resume, by, body.reason).await
}

fn configured<'a>(app: &'a AppState, name: &str) -> Result<&'a WebhookConfig, ApiError> {
    app.subscriptions
        .iter()
        .find(|c| c.name == name)
        .ok_or_else(|| ApiError::not_found(format!("no webhook subscription is named {name:?}")))
}

async fn act(
    app: &AppState,
    name: &str,
    action: Action,
    by: Caller,
    reason: Option<String>,
) -> Result<Json<Webhook>, ApiError> {
    let config = configured(app, name)?;
    let actor = actor(by, reason)?;
    let Some(running) = app.webhooks.get() else {
        let why = "no node delivers webhooks at the moment (a takeover is under way); try again";
        return Err(ApiError::new(axum::http::StatusCode::SERVICE_UNAVAILABLE, "not_delivering", why));
    };
    tracing::info!(webhook = name, action = action.as_str(), by = %actor.by, "webhook action through the API");
    let who = actor.who();
    let row = running.act(name, action, who, actor.reason).await.map_err(|e| match e {
        ActionError::Unknown(_) => ApiError::not_found(e.to_string()),
        ActionError::OutOfLog { .. } => ApiError::conflict("not_in_log", e.to_string()),
        ActionError::Write(w) => w.into(),
        ActionError::Read(cause) => ApiError::unavailable(cause),
        ActionError::NotStarted(_) => {
            ApiError::new(axum::http::StatusCode::SERVICE_UNAVAILABLE, "not_delivering", e.to_string())
        }
        ActionError::Stopped => ApiError::new(
            axum::http::StatusCode::SERVICE_UNAVAILABLE,
            "not_delivering",
            "the subscription's deliverer stopped (this node is shutting down or lost its lease); try again",
        ),
    })?;
    Ok(Json(view(app, config, Some(row)).await?))
}
