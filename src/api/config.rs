//! `GET /api/v1/config` (which configuration runs) and `POST /api/v1/config/reload`
//! (admins): read the configuration again from the file and environment rackd started
//! with, check it as `rackd check-config` does, and apply what changed, or with
//! `?dry_run=true` (or a body `{"dry_run": true}`, as the bulk actions take it:
//! [`super::dry_run`]) only answer it (`service::reload` has the decisions).
//!
//! Refusals, each with nothing applied: 422 `invalid_config` for a file that
//! `check-config` refuses (the same `WHERE: KEY: MESSAGE`), or a device that cannot be
//! built; 409 `fixed_key` for a key that cannot change while rackd runs (any outside
//! `[[devices]]`, `[site]` and `[auth]`, and `auth.keys` emptied or given its first key),
//! `aisle_in_use` for an aisle removed or shrunk while a box
//! or a job uses a location it would lose, `device_busy` for a device removed while it
//! holds jobs on the machine (each naming them), `no_config_file` when rackd did not start
//! from a file.

use axum::extract::State;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::dry_run::{DryRunParams, dry_run};
use super::error::{ApiError, ErrorBody};
use super::extract::{Caller, Json, OptionalJson, Query};
use super::state::AppState;
use crate::config::Difference;
use crate::service::reload::{ReloadError, RunningConfig};

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(loaded)).routes(routes!(reload))
}

/// A reload's body, which may be left out.
#[derive(Debug, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"dry_run": true}))]
pub struct ReloadRequest {
    /// Answer what would change, applying nothing (as `?dry_run=`; they may not disagree).
    #[schema(nullable = false)]
    pub dry_run: Option<bool>,
}

/// What a reload changes, or changed.
#[derive(Debug, Serialize, ToSchema)]
#[schema(example = json!({"dry_run": false, "kept_for_takeover": false,
    "hash": "9f2c4e0d3b8a7f61e5d2c9b0a4f7e3d1c8b6a5f4e3d2c1b0a9f8e7d6c5b4a3f2",
    "loaded_at": "2026-11-27T08:00:00Z",
    "devices": [{"id": "shelf-1", "change": "changed", "keys": ["address", "timeout_ms"]},
        {"id": "crane-3", "change": "added"}],
    "aisles": {"added": [3], "removed": [], "changed": []},
    "auth": {"keys": [{"name": "wms", "change": "removed"}, {"name": "wms-2", "change": "added"}], "settings": []},
    "fixed": []}))]
pub struct ReloadView {
    /// Whether nothing was applied (`?dry_run=true`).
    pub dry_run: bool,
    /// On a standby of a cluster: the configuration is kept for when it takes over (it
    /// runs no device to change).
    pub kept_for_takeover: bool,
    /// The configuration running now: after the reload, or for a dry run the one that
    /// still runs.
    #[serde(flatten)]
    pub loaded: RunningConfig,
    /// The difference between the configuration that ran and the file's.
    #[serde(flatten)]
    pub difference: Difference,
}

impl From<ReloadError> for ApiError {
    fn from(e: ReloadError) -> Self {
        match e {
            ReloadError::NoSources => ApiError::conflict("no_config_file", e.to_string()),
            ReloadError::Invalid(_) | ReloadError::Device(..) => {
                ApiError::invalid("invalid_config", e.to_string())
            }
            ReloadError::Fixed(_) | ReloadError::Keyless(_) => ApiError::conflict("fixed_key", e.to_string()),
            ReloadError::InUse(_) => ApiError::conflict("aisle_in_use", e.to_string()),
            ReloadError::Busy(_) => ApiError::conflict("device_busy", e.to_string()),
            ReloadError::Task(_) | ReloadError::Store(_) => ApiError::unavailable(e),
        }
    }
}

/// Which configuration runs: the hash of its `[site]` and `[[devices]]`, and when it was
/// loaded (the start, or the last reload). Each node of a cluster answers for itself.
#[utoipa::path(get, path = "/config", tag = "operations",
    responses(
        (status = 200, description = "The running configuration's hash and load time", body = RunningConfig),
        (status = 401, description = "No key, or an unknown key", body = ErrorBody),
    ))]
async fn loaded(State(app): State<AppState>) -> Json<RunningConfig> {
    Json(app.reload.loaded())
}

/// Reads the configuration again and applies what changed, or answers it.
///
/// The file and environment are those rackd started with; the configuration is checked
/// exactly as `rackd check-config` checks it. Devices are matched by id, aisles by number,
/// API keys by name; only names are reported, never values. Devices added, removed or
/// changed are started, stopped or restarted, each at a safe point (never inside a
/// hand-over); the others run on untouched. Queued jobs of a removed device wait
/// (`no_device`). `[auth]` applies last: a removed key gets 401 from the next request on,
/// and its WebSockets are closed. Audited, and told as a `config.reloaded` event. All or
/// nothing: a refusal applies nothing.
#[utoipa::path(post, path = "/config/reload", tag = "operations", params(DryRunParams),
    request_body(content = Option<ReloadRequest>),
    responses(
        (status = 200, description = "What changed (or, for a dry run, would change)", body = ReloadView),
        (status = 401, description = "No key, or an unknown key", body = ErrorBody),
        (status = 403, description = "Not an administrator's key", body = ErrorBody),
        (status = 409, description = "A key that cannot change while rackd runs (`fixed_key`, naming it and \
where it is set; `auth.keys` may not become empty nor get its first key), an aisle removed or shrunk while a box or a job uses a location it would lose (`aisle_in_use`), a \
device removed while it holds jobs on the machine (`device_busy`), each naming them, or rackd did not start from a \
file (`no_config_file`); nothing was applied", body = ErrorBody),
        (status = 422, description = "The configuration does not check (`invalid_config`: WHERE: KEY: MESSAGE, \
as `rackd check-config` says); nothing was applied", body = ErrorBody),
    ))]
async fn reload(
    State(app): State<AppState>,
    caller: Caller,
    Query(query): Query<DryRunParams>,
    OptionalJson(body): OptionalJson<ReloadRequest>,
) -> Result<Json<ReloadView>, ApiError> {
    if dry_run(&query, body.dry_run)? {
        let plan = app.reload.check().await?;
        let kept_for_takeover = app.reload.fleet().is_none();
        let loaded = app.reload.loaded();
        return Ok(Json(ReloadView {
            dry_run: true,
            kept_for_takeover,
            loaded,
            difference: plan.difference,
        }));
    }
    // Applied on a task of its own: a client that gives up (or the request's timeout) must
    // not cut a reload between stopping a device and starting it again.
    let reload = app.reload.clone();
    let applied = tokio::spawn(async move { reload.apply(caller.who(), None).await })
        .await
        .map_err(|e| ReloadError::Task(e.to_string()))??;
    Ok(Json(ReloadView {
        dry_run: false,
        kept_for_takeover: applied.kept_for_takeover,
        loaded: applied.loaded,
        difference: applied.difference,
    }))
}
