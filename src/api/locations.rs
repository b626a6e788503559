//! `/api/v1/locations`: what rackd knows of every location, and location locks.
//!
//! A location locks by itself when a job on it fails as `lost`, `device_fault`,
//! `rejected` or `alarm` (the store cannot be trusted there), and by hand. Jobs touching a
//! locked location wait (they do not fail) until a person unlocks it.

use axum::extract::State;
use serde::Deserialize;
use utoipa::IntoParams;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::control::{ControlRequest, LockRequest, actor};
use super::error::{ApiError, ErrorBody};
use super::extract::{Caller, Json, OptionalJson, Path, Query};
use super::state::AppState;
use crate::domain::Location;
use crate::store::locations::{self, LocationState};

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(list_locations))
        .routes(routes!(lock_location))
        .routes(routes!(unlock_location))
}

/// Filters for the location list.
#[derive(Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct LocationParams {
    /// Only this aisle.
    aisle: Option<u16>,
    /// Only occupied (true) or empty (false) locations.
    occupied: Option<bool>,
}

/// Every location of the site: occupancy, barcode, lights, reservation.
#[utoipa::path(get, path = "/locations", tag = "locations", params(LocationParams),
    responses(
        (status = 200, description = "Locations in aisle, row, bay, level, position order", body = Vec<LocationState>),
        (status = 400, description = "Bad filter", body = ErrorBody),
    ))]
async fn list_locations(
    State(app): State<AppState>,
    Query(p): Query<LocationParams>,
) -> Result<Json<Vec<LocationState>>, ApiError> {
    let mut all = locations::list(&app.pool, p.aisle).await?;
    if let Some(occupied) = p.occupied {
        all.retain(|l| l.occupied == occupied);
    }
    Ok(Json(all))
}

/// The location a path names, if the layout has it.
fn location(
    app: &AppState,
    (aisle, row, bay, level, position): (u16, u16, u16, u16, u16),
) -> Result<Location, ApiError> {
    let l = Location { aisle, row, bay, level, position };
    app.rules().layout.check(&l).map_err(|e| ApiError::not_found(e.0))?;
    Ok(l)
}

/// The location as it now stands.
async fn state(app: &AppState, l: Location) -> Result<Json<LocationState>, ApiError> {
    let state = locations::get(&app.pool, l).await?;
    state.map(Json).ok_or_else(|| ApiError::not_found(format!("location {l} has no record")))
}

/// Lock a location: no job touching it is handed out until it is unlocked (jobs wait; they
/// do not fail). A location already locked keeps its first lock. Audited.
#[utoipa::path(post, path = "/locations/{aisle}/{row}/{bay}/{level}/{position}/lock", tag = "locations",
    request_body = LockRequest,
    params(("aisle" = u16, Path), ("row" = u16, Path), ("bay" = u16, Path), ("level" = u16, Path), ("position" = u16, Path)),
    responses(
        (status = 200, description = "Locked", body = LocationState),
        (status = 404, description = "No such location", body = ErrorBody),
        (status = 422, description = "No reason, a reason too long, or an unknown field", body = ErrorBody),
    ))]
async fn lock_location(
    State(app): State<AppState>,
    Path(at): Path<(u16, u16, u16, u16, u16)>,
    by: Caller,
    Json(body): Json<LockRequest>,
) -> Result<Json<LocationState>, ApiError> {
    let l = location(&app, at)?;
    let actor = actor(by, Some(body.reason))?;
    if actor.reason.is_none() {
        return Err(ApiError::invalid("invalid_reason", "a lock needs a reason"));
    }
    tracing::info!(location = %l, by = %actor.by, reason = ?actor.reason, "location locked through the API");
    app.dispatcher.lock(l, &actor).await?;
    state(&app, l).await
}

/// Unlock a location once a person checked it: jobs waiting on it may go. Audited.
#[utoipa::path(post, path = "/locations/{aisle}/{row}/{bay}/{level}/{position}/unlock", tag = "locations",
    request_body(content = Option<ControlRequest>),
    params(("aisle" = u16, Path), ("row" = u16, Path), ("bay" = u16, Path), ("level" = u16, Path), ("position" = u16, Path)),
    responses(
        (status = 200, description = "Unlocked", body = LocationState),
        (status = 404, description = "No such location", body = ErrorBody),
        (status = 422, description = "Reason too long or unknown field", body = ErrorBody),
    ))]
async fn unlock_location(
    State(app): State<AppState>,
    Path(at): Path<(u16, u16, u16, u16, u16)>,
    by: Caller,
    OptionalJson(body): OptionalJson<ControlRequest>,
) -> Result<Json<LocationState>, ApiError> {
    let l = location(&app, at)?;
    let actor = actor(by, body.reason)?;
    tracing::info!(location = %l, by = %actor.by, reason = ?actor.reason, "location unlocked through the API");
    app.dispatcher.unlock(l, &actor).await?;
    state(&app, l).await
}
