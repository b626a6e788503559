//! `POST /api/v1/config/reload` (admins): read the configuration again from the file and
//! environment rackd started with, check it as `rackd check-config` does, and answer what
//! would change (`service::reload` has the decisions).
//!
//! Only `?dry_run=true` is answered for now; a reload that would apply answers 501 once
//! the configuration checks, so a caller learns first what is wrong with its file. Refusals:
//! 422 `invalid_config` for a file that `check-config` refuses (the same
//! `WHERE: KEY: MESSAGE`), 409 `fixed_key` for a key that cannot change while rackd runs
//! (the listen address, the database, the cluster node), 409 `aisle_in_use` for an aisle
//! removed or shrunk while a box or a job uses a location it would lose (naming them), 409
//! `no_config_file` when rackd did not start from a file.

use axum::extract::State;
use axum::http::StatusCode;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::error::{ApiError, ErrorBody};
use super::extract::{Json, Query};
use super::state::AppState;
use crate::config::Difference;
use crate::service::reload::ReloadError;

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(reload))
}

/// `?dry_run=`.
#[derive(Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct ReloadParams {
    /// Answer what would change without applying it (only dry runs are answered for now).
    dry_run: Option<bool>,
}

/// What a reload changes.
#[derive(Debug, Serialize, ToSchema)]
#[schema(example = json!({"dry_run": true,
    "devices": [{"id": "shelf-1", "change": "changed", "keys": ["address", "timeout_ms"]},
        {"id": "crane-3", "change": "added"}],
    "aisles": {"added": [3], "removed": [], "changed": []},
    "settings": ["events.buffer"], "fixed": []}))]
pub struct ReloadView {
    /// Whether nothing was applied (always, for now).
    pub dry_run: bool,
    /// The difference between the running configuration and the file's.
    #[serde(flatten)]
    pub difference: Difference,
}

impl From<ReloadError> for ApiError {
    fn from(e: ReloadError) -> Self {
        match e {
            ReloadError::NoSources => ApiError::conflict("no_config_file", e.to_string()),
            ReloadError::Invalid(_) => ApiError::invalid("invalid_config", e.to_string()),
            ReloadError::Fixed(_) => ApiError::conflict("fixed_key", e.to_string()),
            ReloadError::InUse(_) => ApiError::conflict("aisle_in_use", e.to_string()),
            ReloadError::Task(_) | ReloadError::Store(_) => ApiError::unavailable(e),
        }
    }
}

/// Reads the configuration again and answers what would change.
///
/// The file and environment are those rackd started with; the configuration is checked
/// exactly as `rackd check-config` checks it. Devices are matched by id, aisles by number;
/// only key names are reported, never values.
#[utoipa::path(post, path = "/config/reload", tag = "operations", params(ReloadParams),
    responses(
        (status = 200, description = "What the file changes (dry run)", body = ReloadView),
        (status = 401, description = "No key, or an unknown key", body = ErrorBody),
        (status = 403, description = "Not an administrator's key", body = ErrorBody),
        (status = 409, description = "A key that cannot change while rackd runs (`fixed_key`, naming it and \
where it is set), an aisle removed or shrunk while a box or a job uses a location it would lose (`aisle_in_use`, naming them), or rackd did not start from a file (`no_config_file`); nothing was applied", body = ErrorBody),
        (status = 422, description = "The configuration does not check (`invalid_config`: WHERE: KEY: MESSAGE, \
as `rackd check-config` says)", body = ErrorBody),
        (status = 501, description = "Applying is not done yet: ask with `?dry_run=true`", body = ErrorBody),
    ))]
async fn reload(
    State(app): State<AppState>,
    Query(p): Query<ReloadParams>,
) -> Result<Json<ReloadView>, ApiError> {
    let plan = app.reload.check().await?;
    if p.dry_run != Some(true) {
        return Err(ApiError::new(
            StatusCode::NOT_IMPLEMENTED,
            "not_implemented",
            "the configuration checks, but it is not yet applied: dry run only (?dry_run=true)",
        ));
    }
    Ok(Json(ReloadView { dry_run: true, difference: plan.difference }))
}
