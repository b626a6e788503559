//! `PUT /api/v1/locations`: load or correct what the store holds, at commissioning or after a
//! stocktake (admin).
//!
//! Decisions:
//! - **All or nothing.** Every entry is checked (the layout, barcodes, no location twice)
//!   before anything is written; a location held by a job in flight (dispatched, so its
//!   box is that job's to move) refuses the whole inventory with 409 `location_reserved`.
//!   Queued jobs do not hold their locations: correcting under them is what an inventory is
//!   for, and they see the new state when they are dispatched.
//! - **History**: each location whose contents change gets an audit entry (`inventory`, by
//!   the key's name, with what it now holds and the reason) and a `location.updated`
//!   event; entries that change nothing write nothing.
//! - **Size**: at most [`MAX_ENTRIES`] entries a request (a large store loads in several).

use axum::extract::State;
use serde::Deserialize;
use utoipa::ToSchema;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::control::actor;
use super::error::{ApiError, ErrorBody};
use super::extract::{Caller, Json};
use super::state::AppState;
use crate::domain::{Barcode, Location};
use crate::store::locations::{self, LocationState};
use crate::store::writer::Stock;

/// Most entries in one inventory request.
pub const MAX_ENTRIES: usize = 10_000;

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(put_inventory))
}

/// What one location holds.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct StockEntry {
    /// Aisle.
    pub aisle: u16,
    /// Row.
    pub row: u16,
    /// Bay.
    pub bay: u16,
    /// Level.
    pub level: u16,
    /// Position (1 near, 2 far in a double-deep aisle).
    pub position: u16,
    /// A box is there.
    pub occupied: bool,
    /// Its barcode (1..=20 printable ASCII characters), only with `occupied`.
    pub barcode: Option<String>,
}

/// An inventory: what each listed location holds.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"locations": [
    {"aisle": 1, "row": 1, "bay": 2, "level": 3, "position": 1, "occupied": true, "barcode": "BOX-0001"},
    {"aisle": 1, "row": 1, "bay": 2, "level": 3, "position": 2, "occupied": false}
], "reason": "stocktake of aisle 1"}))]
pub struct InventoryRequest {
    /// 1..=10000 locations, each at most once.
    pub locations: Vec<StockEntry>,
    /// Why (up to 500 characters), kept in the audit log.
    pub reason: Option<String>,
}

/// Load or correct what locations hold (admin): all or nothing, audited, each change a
/// `location.updated` event.
#[utoipa::path(put, path = "/locations", tag = "locations", request_body = InventoryRequest,
    responses(
        (status = 200, description = "The listed locations as they now stand, in request order", body = Vec<LocationState>),
        (status = 400, description = "Malformed JSON", body = ErrorBody),
        (status = 409, description = "`location_reserved`: a job in flight holds one of the locations; nothing written", body = ErrorBody),
        (status = 413, description = "Body too large", body = ErrorBody),
        (status = 415, description = "Not `application/json`", body = ErrorBody),
        (status = 422, description = "A location outside the layout or listed twice, a bad barcode, a barcode on an empty location, an unknown field (the entry's index is named); nothing written", body = ErrorBody),
        (status = 503, description = "The store is unavailable", body = ErrorBody),
    ))]
async fn put_inventory(
    State(app): State<AppState>,
    by: Caller,
    Json(body): Json<InventoryRequest>,
) -> Result<Json<Vec<LocationState>>, ApiError> {
    if body.locations.is_empty() || body.locations.len() > MAX_ENTRIES {
        return Err(ApiError::invalid(
            "invalid_inventory",
            format!("an inventory lists 1..={MAX_ENTRIES} locations, got {}", body.locations.len()),
        ));
    }
    let actor = actor(by, body.reason)?;
    let mut entries = Vec::with_capacity(body.locations.len());
    let mut seen = std::collections::HashSet::new();
    for (i, e) in body.locations.into_iter().enumerate() {
        let bad = |m: String| ApiError::invalid("invalid_inventory", format!("locations[{i}]: {m}"));
        let location =
            Location { aisle: e.aisle, row: e.row, bay: e.bay, level: e.level, position: e.position };
        app.rules().layout.check(&location).map_err(|m| bad(m.0))?;
        if !seen.insert(location) {
            return Err(bad(format!("location {location} is listed twice")));
        }
        let barcode = match e.barcode {
            Some(_) if !e.occupied => return Err(bad("an empty location has no barcode".into())),
            Some(b) => Some(Barcode::try_from(b).map_err(|m| bad(m.0))?.into()),
            None => None,
        };
        entries.push(Stock { location, occupied: e.occupied, barcode });
    }
    let wanted: Vec<Location> = entries.iter().map(|e| e.location).collect();
    tracing::info!(locations = wanted.len(), by = %actor.by, "inventory loaded through the API");
    app.dispatcher.inventory(entries, &actor).await?;
    let mut now = Vec::with_capacity(wanted.len());
    for l in wanted {
        let state = locations::get(&app.pool, l).await?;
        now.push(state.ok_or_else(|| ApiError::not_found(format!("location {l} has no record")))?);
    }
    Ok(Json(now))
}
