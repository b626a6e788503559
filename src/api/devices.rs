//! `/api/v1/devices`: device status, pause and resume; tags devices' values ([`tags`]); the
//! flight recorder's capture ([`capture`]).

pub mod capture;
mod tags;

use axum::extract::State;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::control::{ControlRequest, actor};
use super::error::{ApiError, ErrorBody};
use super::extract::{Caller, Json, OptionalJson, Path};
use super::state::AppState;
use crate::devices::{DeviceHandle, DeviceStatus};
use crate::domain::Target;
use crate::service::monitor::{all_shown, shown};

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(list_devices))
        .routes(routes!(get_device))
        .routes(routes!(pause_device))
        .routes(routes!(resume_device))
        .routes(routes!(capture::device_capture))
        .routes(routes!(capture::alarm_capture))
        .merge(tags::router())
}

fn device(app: &AppState, id: &str) -> Result<DeviceHandle, ApiError> {
    app.devices()
        .get(id)
        .cloned()
        .ok_or_else(|| ApiError::not_found(format!("device {id:?} is not configured")))
}

/// Pauses or resumes a device (stored and audited first) and shows it.
async fn set_paused(
    app: &AppState,
    id: &str,
    paused: bool,
    by: Caller,
    reason: Option<String>,
) -> Result<DeviceStatus, ApiError> {
    let handle = device(app, id)?;
    let actor = actor(by, reason)?;
    tracing::info!(device = %id, paused, by = %actor.by, reason = ?actor.reason, "device pause through the API");
    app.dispatcher.set_paused(Target::Device(id.to_owned()), paused, &actor).await?;
    Ok(shown(id, &handle, app.dispatcher.queues()))
}

/// Every device with its status.
#[utoipa::path(get, path = "/devices", tag = "devices",
    responses((status = 200, description = "Every configured device", body = Vec<DeviceStatus>)))]
async fn list_devices(State(app): State<AppState>) -> Json<Vec<DeviceStatus>> {
    Json(all_shown(&app.devices(), app.dispatcher.queues()))
}

/// One device's status: online, last contact, slots in use, last error.
#[utoipa::path(get, path = "/devices/{id}", tag = "devices", params(("id" = String, Path, description = "Device id")),
    responses(
        (status = 200, description = "The device", body = DeviceStatus),
        (status = 404, description = "No such device", body = ErrorBody),
    ))]
async fn get_device(
    State(app): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<DeviceStatus>, ApiError> {
    Ok(Json(shown(&id, &device(&app, &id)?, app.dispatcher.queues())))
}

/// Pause a device: it gets no new work; what it runs goes on and is followed. Kept across
/// restarts and audited (who, when, the optional reason).
#[utoipa::path(post, path = "/devices/{id}/pause", tag = "devices", request_body(content = Option<ControlRequest>),
    params(("id" = String, Path, description = "Device id")),
    responses(
        (status = 200, description = "Paused", body = DeviceStatus),
        (status = 404, description = "No such device", body = ErrorBody),
        (status = 422, description = "Reason too long or unknown field", body = ErrorBody),
    ))]
async fn pause_device(
    State(app): State<AppState>,
    Path(id): Path<String>,
    by: Caller,
    OptionalJson(body): OptionalJson<ControlRequest>,
) -> Result<Json<DeviceStatus>, ApiError> {
    Ok(Json(set_paused(&app, &id, true, by, body.reason).await?))
}

/// Resume a paused device: queued work is handed over at once.
#[utoipa::path(post, path = "/devices/{id}/resume", tag = "devices", request_body(content = Option<ControlRequest>),
    params(("id" = String, Path, description = "Device id")),
    responses(
        (status = 200, description = "Resumed", body = DeviceStatus),
        (status = 404, description = "No such device", body = ErrorBody),
        (status = 422, description = "Reason too long or unknown field", body = ErrorBody),
    ))]
async fn resume_device(
    State(app): State<AppState>,
    Path(id): Path<String>,
    by: Caller,
    OptionalJson(body): OptionalJson<ControlRequest>,
) -> Result<Json<DeviceStatus>, ApiError> {
    Ok(Json(set_paused(&app, &id, false, by, body.reason).await?))
}
