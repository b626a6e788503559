//! `/api/v1/alarms`: device alarms, active and past.

use axum::extract::State;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::error::{ApiError, ErrorBody};
use super::extract::{Json, Query, page};
use super::state::AppState;
use crate::store::alarms::{self, Alarm, AlarmFilter};

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(list_alarms))
}

/// Filters and paging for the alarm list.
#[derive(Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct AlarmParams {
    /// Only active (true) or only cleared (false) alarms.
    active: Option<bool>,
    /// Only this device's alarms.
    device: Option<String>,
    /// Continue after this cursor (the `next_cursor` of the previous page).
    cursor: Option<String>,
    /// Alarms per page, 1..=1000 (default 100).
    #[param(minimum = 1, maximum = 1000)]
    limit: Option<u32>,
}

/// A page of alarms.
#[derive(Serialize, ToSchema)]
pub struct AlarmPage {
    /// Alarms, newest first.
    pub alarms: Vec<Alarm>,
    /// Pass as `cursor` for the next (older) page; absent on the last page.
    pub next_cursor: Option<String>,
}

/// Device alarms, newest first: device, code, class, text, raised and cleared times.
///
/// A crane's alarm (its D205 code, with the catalogue's text and class) is raised when the
/// crane reports it and cleared when the crane no longer does; a `link` alarm (code 0) is
/// raised while a device does not answer.
#[utoipa::path(get, path = "/alarms", tag = "alarms", params(AlarmParams),
    responses(
        (status = 200, description = "A page of alarms", body = AlarmPage),
        (status = 400, description = "Bad filter or cursor", body = ErrorBody),
    ))]
async fn list_alarms(
    State(app): State<AppState>,
    Query(p): Query<AlarmParams>,
) -> Result<Json<AlarmPage>, ApiError> {
    let (limit, before_id) = page(p.limit, p.cursor, 1)?;
    let filter = AlarmFilter { active: p.active, device: p.device, before_id, limit };
    let alarms = alarms::list(&app.pool, &filter).await?;
    let next_cursor =
        (alarms.len() == limit as usize).then(|| alarms.last().map(|a| a.id.to_string())).flatten();
    Ok(Json(AlarmPage { alarms, next_cursor }))
}
