//! Operators' actions on many jobs or locations at once: `POST /api/v1/locations/unlock`,
//! `POST /api/v1/jobs/retry`, `POST /api/v1/jobs/cancel`.
//!
//! Each takes its items from a filter (the failed jobs of a device or of a failure kind,
//! since a time; the queued jobs of a device or an aisle) or as a list (`jobs`,
//! `locations`: what a dry run answered), with `dry_run` (in the body or the query:
//! [`super::dry_run`]) and an optional `reason`. Each is
//! all or nothing in one commit, audited item by item, and answers with what it did (or,
//! as a dry run, would do): a [`BulkAnswer`]. The rules, and why unlock and retry is one
//! action, are in [`crate::service::dispatch::bulk`].
//!
//! Errors: a body that names no items, both a filter and a list, a device that is not
//! configured, an aisle or location outside the layout, a list with an item twice: 422
//! `invalid_bulk`; more than [`MAX_BULK`] items, selected or listed: 422 `bulk_too_large`;
//! an item that cannot be done as asked: 409 `bulk_refused`, naming each, and nothing is
//! done. An empty selection is not an error: nothing to do, an empty answer.

use std::collections::HashSet;

use axum::extract::State;
use serde::{Deserialize, Serialize};
use time::OffsetDateTime;
use utoipa::ToSchema;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::control::actor;
use super::dry_run::{DryRunParams, dry_run};
use super::error::{ApiError, ErrorBody};
use super::extract::{Caller, Json, Query};
use super::state::AppState;
use crate::domain::{FailureKind, Location, LocationLock};
use crate::service::dispatch::{FailedJobs, MAX_BULK, QueuedJobs};
use crate::store::jobs::Job;
use crate::store::writer::Bulked;

/// The routes of the bulk actions.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(unlock_locations))
        .routes(routes!(retry_jobs))
        .routes(routes!(cancel_jobs))
}

/// Unlock the locations one cause locked: those locked by the failed jobs of a device
/// and/or of a failure kind, failed since a time; or the locations listed.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"failure": "lost", "since": "2026-11-21T08:00:00Z", "dry_run": true,
    "reason": "aisle 1 checked after the power cut"}))]
pub struct UnlockRequest {
    /// Locations locked by failed jobs of this device.
    pub device: Option<String>,
    /// Locations locked by jobs that failed this way.
    pub failure: Option<FailureKind>,
    /// Locations locked by jobs that failed at or after this time (RFC 3339).
    #[serde(default, with = "time::serde::rfc3339::option")]
    #[schema(value_type = Option<String>, format = DateTime)]
    pub since: Option<OffsetDateTime>,
    /// These locations instead of a cause (1..=10000, each once), each of which must be
    /// locked.
    pub locations: Option<Vec<Location>>,
    /// Only tell what would be done (as `?dry_run=`; the two may not disagree).
    #[schema(nullable = false)]
    pub dry_run: Option<bool>,
    /// Why (up to 500 characters), audited with each location.
    pub reason: Option<String>,
}

/// Retry failed jobs: those of a device and/or of a failure kind, failed since a time; or
/// the jobs listed.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"failure": "lost", "since": "2026-11-21T08:00:00Z", "unlock": true,
    "dry_run": true, "reason": "aisle 1 checked after the power cut"}))]
pub struct RetryRequest {
    /// Failed jobs of this device.
    pub device: Option<String>,
    /// Jobs that failed this way.
    pub failure: Option<FailureKind>,
    /// Jobs that failed at or after this time (RFC 3339).
    #[serde(default, with = "time::serde::rfc3339::option")]
    #[schema(value_type = Option<String>, format = DateTime)]
    pub since: Option<OffsetDateTime>,
    /// These jobs instead of a filter (1..=10000 ids, each once), each of which must have
    /// failed.
    pub jobs: Option<Vec<i64>>,
    /// Also lift, in the same commit, the locks these jobs' failures set, so that they run
    /// before the later jobs on their locations (the order they were accepted in).
    #[serde(default)]
    pub unlock: bool,
    /// Only tell what would be done (as `?dry_run=`; the two may not disagree).
    #[schema(nullable = false)]
    pub dry_run: Option<bool>,
    /// Why (up to 500 characters), audited with each job.
    pub reason: Option<String>,
}

/// Cancel queued jobs: those of a device and/or touching an aisle; or the jobs listed.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"aisle": 1, "dry_run": true, "reason": "aisle 1 closed for repairs"}))]
pub struct CancelRequest {
    /// Queued jobs of this device.
    pub device: Option<String>,
    /// Queued jobs with a location in this aisle.
    pub aisle: Option<u16>,
    /// These jobs instead of a filter (1..=10000 ids, each once), each of which must be
    /// queued.
    pub jobs: Option<Vec<i64>>,
    /// Only tell what would be done (as `?dry_run=`; the two may not disagree).
    #[schema(nullable = false)]
    pub dry_run: Option<bool>,
    /// Why (up to 500 characters), audited with each job.
    pub reason: Option<String>,
}

/// What a bulk action did, or (a dry run) would do.
#[derive(Debug, Serialize, ToSchema)]
pub struct BulkAnswer {
    /// True for a dry run: nothing was done.
    pub dry_run: bool,
    /// The jobs retried or cancelled, in id order: as they now stand (or, for a dry run,
    /// as they stand before).
    pub jobs: Vec<Job>,
    /// The locations unlocked, each with the lock it had.
    pub unlocked: Vec<Unlocked>,
}

/// A location unlocked (or to be), with the lock it had.
#[derive(Debug, Serialize, ToSchema)]
pub struct Unlocked {
    /// The location.
    pub location: Location,
    /// Its lock.
    pub lock: LocationLock,
}

impl BulkAnswer {
    fn new(app: &AppState, done: Bulked, dry_run: bool) -> BulkAnswer {
        let jobs = done
            .jobs
            .into_iter()
            .map(|mut job| {
                app.dispatcher.queues().show(&mut job);
                job
            })
            .collect();
        let unlocked =
            done.unlocked.into_iter().map(|(location, lock)| Unlocked { location, lock }).collect();
        BulkAnswer { dry_run, jobs, unlocked }
    }
}

fn invalid(message: impl Into<String>) -> ApiError {
    ApiError::invalid("invalid_bulk", message)
}

/// `device`, checked to be configured.
fn device(app: &AppState, device: Option<String>) -> Result<Option<String>, ApiError> {
    match device {
        Some(d) if !app.dispatcher.queues().has(&d) => {
            Err(invalid(format!("device {d:?} is not configured (or runs no jobs)")))
        }
        other => Ok(other),
    }
}

/// A list of 1..=[`MAX_BULK`] items, each once.
fn listed<T: Eq + std::hash::Hash + std::fmt::Display + Copy>(
    name: &str,
    items: &[T],
) -> Result<(), ApiError> {
    if items.len() > MAX_BULK {
        let message = format!("`{name}` lists {} items; one action takes at most {MAX_BULK}", items.len());
        return Err(ApiError::invalid("bulk_too_large", message));
    }
    if items.is_empty() {
        return Err(invalid(format!("`{name}` is empty: list 1..={MAX_BULK} items")));
    }
    let mut seen = HashSet::with_capacity(items.len());
    match items.iter().enumerate().find(|(_, item)| !seen.insert(**item)) {
        Some((i, item)) => Err(invalid(format!("{name}[{i}]: {item} is listed twice"))),
        None => Ok(()),
    }
}

/// The items an action lists (`Some`, checked by [`listed`]), or None when its filter
/// chooses them: refused when it names both (`given`: a filter key is set) or neither
/// (`enough`: not the keys a filter needs); `filter` says what a filter is.
fn named<T: Eq + std::hash::Hash + std::fmt::Display + Copy>(
    name: &str,
    list: Option<Vec<T>>,
    given: bool,
    enough: bool,
    filter: &str,
) -> Result<Option<Vec<T>>, ApiError> {
    match list {
        Some(_) if given => Err(invalid(format!("name either {filter}, or `{name}`"))),
        Some(list) => listed(name, &list).map(|()| Some(list)),
        None if !enough => Err(invalid(format!("name {filter}, or `{name}`"))),
        None => Ok(None),
    }
}

/// Unlock many locations at once: those locked by the failures of the jobs a cause names,
/// or those listed. All or nothing in one commit; each location audited (`unlock`).
#[utoipa::path(post, path = "/locations/unlock", tag = "locations", request_body = UnlockRequest, params(DryRunParams),
    responses(
        (status = 200, description = "Unlocked (or, with `dry_run`, to be unlocked), in location order", body = BulkAnswer),
        (status = 409, description = "`bulk_refused`: a location is not locked (any more), or is locked by another cause than the job named; each is named, and nothing is unlocked", body = ErrorBody),
        (status = 422, description = "`invalid_bulk`: no cause and no list, or both; a device that is not configured; a location outside the layout or listed twice; `bulk_too_large`: more than 10,000 locations; `invalid_reason`, `invalid_body`", body = ErrorBody),
    ))]
async fn unlock_locations(
    State(app): State<AppState>,
    by: Caller,
    Query(query): Query<DryRunParams>,
    Json(body): Json<UnlockRequest>,
) -> Result<Json<BulkAnswer>, ApiError> {
    let dry = dry_run(&query, body.dry_run)?;
    let actor = actor(by, body.reason)?;
    let given = body.device.is_some() || body.failure.is_some() || body.since.is_some();
    let enough = body.device.is_some() || body.failure.is_some();
    let cause = "a cause: `device` and/or `failure` (optionally `since`)";
    let locations: Vec<(Location, Option<i64>)> =
        match named("locations", body.locations, given, enough, cause)? {
            Some(list) => {
                for (i, l) in list.iter().enumerate() {
                    app.rules().layout.check(l).map_err(|e| invalid(format!("locations[{i}]: {}", e.0)))?;
                }
                list.into_iter().map(|l| (l, None)).collect()
            }
            None => {
                let filter =
                    FailedJobs { device: device(&app, body.device)?, kind: body.failure, since: body.since };
                app.dispatcher.locked_by(&filter).await?.into_iter().map(|(l, job)| (l, Some(job))).collect()
            }
        };
    tracing::info!(locations = locations.len(), dry_run = dry, by = %actor.by, "bulk unlock through the API");
    let done = app.dispatcher.bulk_unlock(locations, dry, &actor).await?;
    Ok(Json(BulkAnswer::new(&app, done, dry)))
}

/// Retry many failed jobs at once, in the order they were accepted: those of a device
/// and/or of a failure kind, failed since a time, or those listed; with `unlock`, lifting
/// the locks their failures set in the same commit (after a PLC lost its memory: unlock
/// and retry once the aisle is checked). All or nothing in one commit; each job audited
/// (`retry`), each location too (`unlock`).
#[utoipa::path(post, path = "/jobs/retry", tag = "jobs", request_body = RetryRequest, params(DryRunParams),
    responses(
        (status = 200, description = "Queued again (or, with `dry_run`, to be), in id order, with the locations unlocked", body = BulkAnswer),
        (status = 409, description = "`bulk_refused`: a job does not exist or has not failed (any more); each is named, and nothing is done", body = ErrorBody),
        (status = 422, description = "`invalid_bulk`: no filter and no list, or both; a device that is not configured; an id listed twice; `bulk_too_large`: more than 10,000 jobs; `invalid_reason`, `invalid_body`", body = ErrorBody),
    ))]
async fn retry_jobs(
    State(app): State<AppState>,
    by: Caller,
    Query(query): Query<DryRunParams>,
    Json(body): Json<RetryRequest>,
) -> Result<Json<BulkAnswer>, ApiError> {
    let dry = dry_run(&query, body.dry_run)?;
    let actor = actor(by, body.reason)?;
    let given = body.device.is_some() || body.failure.is_some() || body.since.is_some();
    let enough = body.device.is_some() || body.failure.is_some();
    let filter = "a filter: `device` and/or `failure` (optionally `since`)";
    let jobs = match named("jobs", body.jobs, given, enough, filter)? {
        Some(list) => list,
        None => {
            let filter =
                FailedJobs { device: device(&app, body.device)?, kind: body.failure, since: body.since };
            app.dispatcher.failed_jobs(&filter).await?
        }
    };
    tracing::info!(jobs = jobs.len(), unlock = body.unlock, dry_run = dry, by = %actor.by, "bulk retry through the API");
    let done = app.dispatcher.bulk_retry(jobs, body.unlock, dry, &actor).await?;
    Ok(Json(BulkAnswer::new(&app, done, dry)))
}

/// Cancel many queued jobs at once: those of a device and/or touching an aisle, or those
/// listed. Only queued jobs: one a device holds (written into a slot, being handed over)
/// refuses the action, and is cancelled on its own. All or nothing in one commit; each job
/// audited (`cancel`).
#[utoipa::path(post, path = "/jobs/cancel", tag = "jobs", request_body = CancelRequest, params(DryRunParams),
    responses(
        (status = 200, description = "Cancelled (or, with `dry_run`, to be), in id order", body = BulkAnswer),
        (status = 409, description = "`bulk_refused`: a job does not exist, is no longer queued, or a device holds it; each is named, and nothing is cancelled", body = ErrorBody),
        (status = 422, description = "`invalid_bulk`: no filter and no list, or both; a device that is not configured; an aisle outside the layout; an id listed twice; `bulk_too_large`: more than 10,000 jobs; `invalid_reason`, `invalid_body`", body = ErrorBody),
        (status = 503, description = "A device that may hold some of the jobs does not answer; nothing is cancelled; retry", body = ErrorBody),
    ))]
async fn cancel_jobs(
    State(app): State<AppState>,
    by: Caller,
    Query(query): Query<DryRunParams>,
    Json(body): Json<CancelRequest>,
) -> Result<Json<BulkAnswer>, ApiError> {
    let dry = dry_run(&query, body.dry_run)?;
    let actor = actor(by, body.reason)?;
    let given = body.device.is_some() || body.aisle.is_some();
    let jobs = match named("jobs", body.jobs, given, given, "a filter: `device` and/or `aisle`")? {
        Some(list) => list,
        None => {
            if let Some(a) = body.aisle
                && !app.rules().layout.aisles().contains_key(&a)
            {
                return Err(invalid(format!("aisle {a} is not in the layout")));
            }
            let filter = QueuedJobs { device: device(&app, body.device)?, aisle: body.aisle };
            app.dispatcher.queued_jobs(&filter).await?
        }
    };
    tracing::info!(jobs = jobs.len(), dry_run = dry, by = %actor.by, "bulk cancel through the API");
    let done = app.dispatcher.bulk_cancel(jobs, &app.devices(), dry, &actor).await?;
    Ok(Json(BulkAnswer::new(&app, done, dry)))
}
