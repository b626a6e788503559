//! The bodies of operators' actions (pause, resume, lock, unlock) and the audit log
//! (`/api/v1/audit`): who did what, when and why.

use axum::extract::State;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::error::{ApiError, ErrorBody};
use super::extract::{Caller, Json, Query, page};
use super::state::AppState;
use crate::service::dispatch::Actor;
use crate::store::controls::{self, AuditEntry};

/// The longest reason kept.
pub const MAX_REASON: usize = 500;

/// Why an operator pauses, resumes or unlocks; the body may be left out.
#[derive(Debug, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"reason": "fork inspection"}))]
pub struct ControlRequest {
    /// Why, for the audit log and the dashboard (at most 500 characters).
    pub reason: Option<String>,
}

/// Why an operator locks a location.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"reason": "box reported damaged; check before use"}))]
pub struct LockRequest {
    /// Why (1 to 500 characters).
    pub reason: String,
}

/// The actor of a request, its reason checked.
pub fn actor(caller: Caller, reason: Option<String>) -> Result<Actor, ApiError> {
    let reason = reason.map(|r| r.trim().to_owned()).filter(|r| !r.is_empty());
    if reason.as_ref().is_some_and(|r| r.chars().count() > MAX_REASON) {
        return Err(ApiError::invalid(
            "invalid_reason",
            format!("a reason is at most {MAX_REASON} characters"),
        ));
    }
    Ok(Actor { by: caller.name, client: caller.client, reason })
}

/// The routes of the audit log.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(list_audit))
}

/// Paging for the audit log.
#[derive(Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct AuditParams {
    /// Continue after this cursor (the `next_cursor` of the previous page).
    cursor: Option<String>,
    /// Entries per page, 1..=1000 (default 100).
    #[param(minimum = 1, maximum = 1000)]
    limit: Option<u32>,
}

/// A page of the audit log.
#[derive(Serialize, ToSchema)]
pub struct AuditPage {
    /// Entries, newest first.
    pub entries: Vec<AuditEntry>,
    /// Pass as `cursor` for the next (older) page; absent on the last page.
    pub next_cursor: Option<String>,
}

/// Every change made through the API, newest first: submissions (one entry per request, a
/// batch's naming its count), cancels, priorities, retries, pauses, resumes, locks, unlocks,
/// inventory corrections, alarm acknowledgements and tag writes, with who (the key's name),
/// from which address, when and why.
#[utoipa::path(get, path = "/audit", tag = "operations", params(AuditParams),
    responses(
        (status = 200, description = "A page of the audit log", body = AuditPage),
        (status = 400, description = "Bad cursor or limit", body = ErrorBody),
    ))]
async fn list_audit(
    State(app): State<AppState>,
    Query(p): Query<AuditParams>,
) -> Result<Json<AuditPage>, ApiError> {
    let (limit, before_id) = page(p.limit, p.cursor, 1)?;
    let entries = controls::audit(&app.pool, before_id, limit).await?;
    let next_cursor =
        (entries.len() == limit as usize).then(|| entries.last().map(|e| e.id.to_string())).flatten();
    Ok(Json(AuditPage { entries, next_cursor }))
}
