//! `/api/v1/locations`: what rackd knows of every location.

use axum::extract::State;
use serde::Deserialize;
use utoipa::IntoParams;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::error::{ApiError, ErrorBody};
use super::extract::{Json, Query};
use super::state::AppState;
use crate::store::locations::{self, LocationState};

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(list_locations))
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
