//! `/api/v1/aisles`: each aisle of the layout, the devices that serve it, and its pause.
//! A paused aisle gets no new work, whichever device serves it: jobs touching it wait.

use axum::extract::State;
use serde::Serialize;
use utoipa::ToSchema;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::control::{ControlRequest, actor};
use super::error::{ApiError, ErrorBody};
use super::extract::{Caller, Json, OptionalJson, Path};
use super::state::AppState;
use crate::domain::{Pause, Target};

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(list_aisles))
        .routes(routes!(pause_aisle))
        .routes(routes!(resume_aisle))
}

/// An aisle and its control state.
#[derive(Debug, Serialize, ToSchema)]
#[schema(example = json!({"aisle": 2, "devices": ["crane1"], "paused": true,
    "pause": {"by": "ops-desk", "reason": "maintenance", "at": "2026-11-21T08:00:00.000Z"}}))]
pub struct Aisle {
    /// The aisle's number.
    pub aisle: u16,
    /// The devices that serve it.
    pub devices: Vec<String>,
    /// Paused: jobs touching it wait.
    pub paused: bool,
    /// Who paused it, when and why.
    pub pause: Option<Pause>,
}

fn aisle(app: &AppState, n: u16) -> Result<Aisle, ApiError> {
    if !app.rules().layout.aisles().contains_key(&n) {
        return Err(ApiError::not_found(format!("aisle {n} is not in the layout")));
    }
    let pause = app.dispatcher.queues().paused_aisles().remove(&n);
    let devices = app
        .devices()
        .iter()
        .filter(|(_, h)| h.status.borrow().aisles.contains(&n))
        .map(|(id, _)| id.clone())
        .collect();
    Ok(Aisle { aisle: n, devices, paused: pause.is_some(), pause })
}

/// Every aisle of the layout with the devices that serve it and its pause.
#[utoipa::path(get, path = "/aisles", tag = "devices",
    responses((status = 200, description = "Every aisle", body = Vec<Aisle>)))]
async fn list_aisles(State(app): State<AppState>) -> Result<Json<Vec<Aisle>>, ApiError> {
    let numbers: Vec<u16> = app.rules().layout.aisles().keys().copied().collect();
    Ok(Json(numbers.into_iter().map(|n| aisle(&app, n)).collect::<Result<_, _>>()?))
}

async fn set_paused(
    app: AppState,
    n: u16,
    paused: bool,
    by: Caller,
    reason: Option<String>,
) -> Result<Json<Aisle>, ApiError> {
    aisle(&app, n)?;
    let actor = actor(by, reason)?;
    tracing::info!(aisle = n, paused, by = %actor.by, reason = ?actor.reason, "aisle pause through the API");
    app.dispatcher.set_paused(Target::Aisle(n), paused, &actor).await?;
    Ok(Json(aisle(&app, n)?))
}

/// Pause an aisle: no job touching it is handed out, whichever device serves it; what runs
/// goes on. Kept across restarts and audited.
#[utoipa::path(post, path = "/aisles/{aisle}/pause", tag = "devices", request_body(content = Option<ControlRequest>),
    params(("aisle" = u16, Path, description = "Aisle number")),
    responses(
        (status = 200, description = "Paused", body = Aisle),
        (status = 404, description = "No such aisle", body = ErrorBody),
        (status = 422, description = "Reason too long or unknown field", body = ErrorBody),
    ))]
async fn pause_aisle(
    State(app): State<AppState>,
    Path(n): Path<u16>,
    by: Caller,
    OptionalJson(body): OptionalJson<ControlRequest>,
) -> Result<Json<Aisle>, ApiError> {
    set_paused(app, n, true, by, body.reason).await
}

/// Resume a paused aisle: its waiting jobs are handed out at once.
#[utoipa::path(post, path = "/aisles/{aisle}/resume", tag = "devices", request_body(content = Option<ControlRequest>),
    params(("aisle" = u16, Path, description = "Aisle number")),
    responses(
        (status = 200, description = "Resumed", body = Aisle),
        (status = 404, description = "No such aisle", body = ErrorBody),
        (status = 422, description = "Reason too long or unknown field", body = ErrorBody),
    ))]
async fn resume_aisle(
    State(app): State<AppState>,
    Path(n): Path<u16>,
    by: Caller,
    OptionalJson(body): OptionalJson<ControlRequest>,
) -> Result<Json<Aisle>, ApiError> {
    set_paused(app, n, false, by, body.reason).await
}
