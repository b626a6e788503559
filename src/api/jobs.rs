//! `/api/v1/jobs`: submit, list, read, cancel, re-prioritise and retry jobs.

use axum::extract::State;
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use time::OffsetDateTime;
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::error::{ApiError, ErrorBody};
use super::extract::{Caller, Json, Path, Query, page};
use super::state::AppState;
use crate::domain::time::to_ms;
use crate::domain::{JobKind, JobState, Priority, Waiting, WaitingReason};
use crate::service::dispatch::Actor;
use crate::service::intake::{JobRequest, MAX_BATCH};
use crate::service::planner::refusal::{NearOccupied, near_occupied};
use crate::store::jobs::{self, Job, JobEvent, JobFilter, NewJob};
use crate::store::writer::{Change, Outcome};

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(create_job, list_jobs))
        .routes(routes!(create_batch))
        .routes(routes!(get_job, patch_job))
        .routes(routes!(job_history))
        .routes(routes!(cancel_job))
        .routes(routes!(retry_job))
}

/// Submit one job. Answers once the job is on disk.
#[utoipa::path(post, path = "/jobs", tag = "jobs", request_body = JobRequest,
    responses(
        (status = 201, description = "Stored, queued", body = Job, headers(("Location" = String, description = "The job's URL"))),
        (status = 200, description = "A job with this reference and the same request already exists", body = Job),
        (status = 400, description = "Malformed JSON", body = ErrorBody),
        (status = 409, description = "`reference_conflict`: the reference is used by a different request; `near_occupied`: a store into a far location of a double-deep aisle whose near location holds a box no job takes away", body = ErrorBody),
        (status = 413, description = "Body too large", body = ErrorBody),
        (status = 415, description = "Not `application/json`", body = ErrorBody),
        (status = 422, description = "Unknown or missing field, wrong type, location outside the layout", body = ErrorBody),
        (status = 503, description = "`overloaded`: more jobs arrive than rackd can store now; `store_full` or `store_unavailable`: the store cannot commit now (its disk is full, it fails or does not answer); retry after `Retry-After` seconds", body = ErrorBody,
            headers(("Retry-After" = String, description = "Seconds to wait"))),
    ))]
async fn create_job(
    State(app): State<AppState>,
    by: Caller,
    Json(req): Json<JobRequest>,
) -> Result<Response, ApiError> {
    let job = app.rules().check(req).map_err(|e| ApiError::invalid("invalid_job", e.0))?;
    let jobs = vec![job];
    if let Some(refused) = refused(&app, &jobs).await? {
        return Err(ApiError::conflict("near_occupied", refused.to_string()));
    }
    let started = std::time::Instant::now();
    let outcome = app.writer.submit_as(jobs, by.who()).await?;
    app.metrics.intake_seconds.observe(started.elapsed().as_secs_f64());
    Ok(match outcome.into_iter().next() {
        Some(Outcome::Created { job, json }) => {
            let location = HeaderValue::from_str(&format!("/api/v1/jobs/{}", job.id)).ok();
            let mut headers = HeaderMap::new();
            headers.insert(header::CONTENT_TYPE, HeaderValue::from_static(JSON));
            headers.extend(location.map(|l| (header::LOCATION, l)));
            (StatusCode::CREATED, headers, json).into_response()
        }
        Some(Outcome::Existing(mut job)) => {
            app.dispatcher.queues().show(&mut job);
            (StatusCode::OK, Json(job)).into_response()
        }
        None => return Err(ApiError::unavailable("writer returned no outcome")),
    })
}

/// A batch of jobs to submit together.
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"jobs": [
    {"kind": "store", "reference": "WMS-2001", "barcode": "BOX-0002", "to": {"aisle": 1, "row": 2, "bay": 4, "level": 1, "position": 2}},
    {"kind": "light", "reference": "WMS-2002", "location": {"aisle": 1, "row": 2, "bay": 4, "level": 1, "position": 2}, "color": "green", "on": true}
]}))]
pub struct BatchRequest {
    /// 1..=1000 jobs, stored all or nothing.
    pub jobs: Vec<JobRequest>,
}

// The answer's schema: the body itself is built by `batch_body` from the jobs as the writer
// serialized them, and a test holds it to this type's serialization.
/// The jobs of a batch, in request order.
#[derive(Serialize, ToSchema)]
#[allow(dead_code)]
pub struct BatchResponse {
    /// One job per requested job, in order (existing ones for repeated references).
    pub jobs: Vec<Job>,
}

/// Submit up to 1000 jobs at once, all or nothing.
#[utoipa::path(post, path = "/jobs/batch", tag = "jobs", request_body = BatchRequest,
    responses(
        (status = 201, description = "All stored (or already there)", body = BatchResponse),
        (status = 200, description = "Every job already existed with the same request", body = BatchResponse),
        (status = 400, description = "Malformed JSON", body = ErrorBody),
        (status = 409, description = "`reference_conflict`: a reference is used by a different request; `near_occupied`: a store into a far location behind a box (the index is named); nothing stored", body = ErrorBody),
        (status = 413, description = "Body too large", body = ErrorBody),
        (status = 415, description = "Not `application/json`", body = ErrorBody),
        (status = 422, description = "A job is invalid (its index is named); nothing stored", body = ErrorBody),
        (status = 503, description = "`overloaded`: more jobs arrive than rackd can store now; `store_full` or `store_unavailable`: the store cannot commit now (its disk is full, it fails or does not answer); retry after `Retry-After` seconds", body = ErrorBody,
            headers(("Retry-After" = String, description = "Seconds to wait"))),
    ))]
async fn create_batch(
    State(app): State<AppState>,
    by: Caller,
    Json(req): Json<BatchRequest>,
) -> Result<Response, ApiError> {
    if req.jobs.is_empty() || req.jobs.len() > MAX_BATCH {
        return Err(ApiError::invalid(
            "invalid_batch",
            format!("a batch holds 1..={MAX_BATCH} jobs, got {}", req.jobs.len()),
        ));
    }
    let jobs = req
        .jobs
        .into_iter()
        .enumerate()
        .map(|(i, r)| {
            app.rules().check(r).map_err(|e| ApiError::invalid("invalid_job", format!("jobs[{i}]: {}", e.0)))
        })
        .collect::<Result<Vec<_>, _>>()?;
    if let Some(refused) = refused(&app, &jobs).await? {
        return Err(ApiError::conflict("near_occupied", format!("jobs[{}]: {refused}", refused.index)));
    }
    let started = std::time::Instant::now();
    let outcomes = app.writer.submit_as(jobs, by.who()).await?;
    app.metrics.intake_seconds.observe(started.elapsed().as_secs_f64());
    let created = outcomes.iter().any(|o| matches!(o, Outcome::Created { .. }));
    let jobs = outcomes
        .into_iter()
        .map(|o| match o {
            Outcome::Created { json, .. } => json,
            Outcome::Existing(mut j) => {
                app.dispatcher.queues().show(&mut j);
                serde_json::to_string(&j).unwrap_or_else(|_| "null".into())
            }
        })
        .collect::<Vec<_>>();
    let status = if created { StatusCode::CREATED } else { StatusCode::OK };
    Ok((status, [(header::CONTENT_TYPE, HeaderValue::from_static(JSON))], batch_body(&jobs)).into_response())
}

/// The body's media type.
const JSON: &str = "application/json";

/// A [`BatchResponse`] from its jobs as JSON, written as `serde_json` writes the type: the
/// writer serializes each new job once, for its event, and the answer reuses that text
/// (serializing the jobs again for the answer was 8% of the CPU in the batch phase of
/// `bench intake`).
fn batch_body(jobs: &[String]) -> String {
    let mut body = String::with_capacity(12 + jobs.iter().map(|j| j.len() + 1).sum::<usize>());
    body.push_str(r#"{"jobs":["#);
    for (i, job) in jobs.iter().enumerate() {
        if i > 0 {
            body.push(',');
        }
        body.push_str(job);
    }
    body.push_str("]}");
    body
}

/// Filters and paging for the job list.
#[derive(Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct ListParams {
    /// Only jobs in this state.
    state: Option<JobState>,
    /// Only jobs of this kind.
    kind: Option<JobKind>,
    /// Only jobs on this device.
    device: Option<String>,
    /// Only the job with this WMS reference.
    reference: Option<String>,
    /// Only jobs accepted at or after this time (RFC 3339).
    #[serde(default, with = "time::serde::rfc3339::option")]
    #[param(value_type = Option<String>, format = DateTime)]
    created_from: Option<OffsetDateTime>,
    /// Only jobs accepted before this time (RFC 3339).
    #[serde(default, with = "time::serde::rfc3339::option")]
    #[param(value_type = Option<String>, format = DateTime)]
    created_to: Option<OffsetDateTime>,
    /// Only queued jobs waiting for this reason (`any`: every waiting job). Reasons are
    /// computed now, so a job may have moved on by the time the page is read.
    waiting: Option<WaitingFilter>,
    /// Continue after this cursor (the `next_cursor` of the previous page).
    cursor: Option<String>,
    /// Jobs per page, 1..=1000 (default 100).
    #[param(minimum = 1, maximum = 1000)]
    limit: Option<u32>,
}

/// A waiting reason to filter on, or `any`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum WaitingFilter {
    /// Every waiting job.
    Any,
    /// See [`WaitingReason::DeviceOffline`].
    DeviceOffline,
    /// See [`WaitingReason::DevicePaused`].
    DevicePaused,
    /// See [`WaitingReason::AislePaused`].
    AislePaused,
    /// See [`WaitingReason::DeviceAlarm`].
    DeviceAlarm,
    /// See [`WaitingReason::LocationLocked`].
    LocationLocked,
    /// See [`WaitingReason::BehindJob`].
    BehindJob,
    /// See [`WaitingReason::SlotsBusy`].
    SlotsBusy,
    /// See [`WaitingReason::NoDevice`].
    NoDevice,
    /// See [`WaitingReason::NoPlace`].
    NoPlace,
    /// See [`WaitingReason::Dependency`].
    Dependency,
    /// See [`WaitingReason::Sequence`].
    Sequence,
}

impl WaitingFilter {
    /// Whether a job waiting for `waiting` passes.
    fn passes(self, waiting: Option<&Waiting>) -> bool {
        let Some(w) = waiting else { return false };
        self == WaitingFilter::Any || Some(w.reason) == WaitingReason::parse(self.as_str())
    }

    fn as_str(self) -> &'static str {
        match self {
            WaitingFilter::Any => "any",
            WaitingFilter::DeviceOffline => WaitingReason::DeviceOffline.as_str(),
            WaitingFilter::DevicePaused => WaitingReason::DevicePaused.as_str(),
            WaitingFilter::AislePaused => WaitingReason::AislePaused.as_str(),
            WaitingFilter::DeviceAlarm => WaitingReason::DeviceAlarm.as_str(),
            WaitingFilter::LocationLocked => WaitingReason::LocationLocked.as_str(),
            WaitingFilter::BehindJob => WaitingReason::BehindJob.as_str(),
            WaitingFilter::SlotsBusy => WaitingReason::SlotsBusy.as_str(),
            WaitingFilter::NoDevice => WaitingReason::NoDevice.as_str(),
            WaitingFilter::NoPlace => WaitingReason::NoPlace.as_str(),
            WaitingFilter::Dependency => WaitingReason::Dependency.as_str(),
            WaitingFilter::Sequence => WaitingReason::Sequence.as_str(),
        }
    }
}

/// How many queued jobs a `waiting` filter reads at a time.
const WAITING_SCAN: u32 = 1000;

/// A page of jobs.
#[derive(Serialize, ToSchema)]
pub struct JobPage {
    /// Jobs in acceptance order.
    pub jobs: Vec<Job>,
    /// Pass as `cursor` for the next page; absent when this page was the last one so far.
    /// Jobs accepted later always come after it, so paging never skips or repeats a job.
    pub next_cursor: Option<String>,
}

/// List jobs, oldest first, with filters and cursor paging.
#[utoipa::path(get, path = "/jobs", tag = "jobs", params(ListParams),
    responses(
        (status = 200, description = "A page of jobs", body = JobPage),
        (status = 400, description = "Bad filter or cursor", body = ErrorBody),
    ))]
async fn list_jobs(
    State(app): State<AppState>,
    Query(p): Query<ListParams>,
) -> Result<Json<JobPage>, ApiError> {
    let (limit, after_id) = page(p.limit, p.cursor, 0)?;
    let filter = JobFilter {
        state: p.state,
        kind: p.kind,
        device: p.device,
        reference: p.reference,
        created_from: p.created_from.map(to_ms),
        created_to: p.created_to.map(to_ms),
        after_id,
        limit,
    };
    if let Some(waiting) = p.waiting {
        return Ok(Json(waiting_page(&app, filter, waiting).await?));
    }
    let mut jobs = jobs::list(&app.pool, &filter).await?;
    for job in &mut jobs {
        app.dispatcher.queues().show(job);
    }
    let next_cursor = (jobs.len() == limit as usize).then(|| jobs.last().map(|j| j.id.to_string())).flatten();
    Ok(Json(JobPage { jobs, next_cursor }))
}

/// A page of waiting jobs: only queued jobs wait, so queued ones are read a batch at a time
/// and kept while their reason passes, until the page is full (its cursor is then the last
/// job kept) or none are left.
async fn waiting_page(
    app: &AppState,
    mut filter: JobFilter,
    waiting: WaitingFilter,
) -> Result<JobPage, ApiError> {
    let limit = filter.limit as usize;
    if filter.state.is_some_and(|s| s != JobState::Queued) {
        return Ok(JobPage { jobs: Vec::new(), next_cursor: None });
    }
    filter.state = Some(JobState::Queued);
    filter.limit = WAITING_SCAN;
    let mut kept = Vec::new();
    loop {
        let batch = jobs::list(&app.pool, &filter).await?;
        let read = batch.len();
        for mut job in batch {
            filter.after_id = Some(job.id);
            app.dispatcher.queues().show(&mut job);
            if waiting.passes(job.waiting.as_ref()) {
                kept.push(job);
                if kept.len() == limit {
                    let next_cursor = kept.last().map(|j| j.id.to_string());
                    return Ok(JobPage { jobs: kept, next_cursor });
                }
            }
        }
        if read < WAITING_SCAN as usize {
            return Ok(JobPage { jobs: kept, next_cursor: None });
        }
    }
}

/// Read one job.
#[utoipa::path(get, path = "/jobs/{id}", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    responses(
        (status = 200, description = "The job", body = Job),
        (status = 400, description = "The id is not a number", body = ErrorBody),
        (status = 404, description = "No such job", body = ErrorBody),
    ))]
async fn get_job(State(app): State<AppState>, Path(id): Path<i64>) -> Result<Json<Job>, ApiError> {
    let mut job = jobs::get(&app.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found(format!("job {id} does not exist")))?;
    app.dispatcher.queues().show(&mut job);
    Ok(Json(job))
}

/// A change of priority.
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"priority": 2}))]
pub struct PatchJob {
    /// The new priority, 0..=20 (lower first).
    #[schema(value_type = u8, minimum = 0, maximum = 20)]
    pub priority: Priority,
}

/// Change a queued job's priority.
#[utoipa::path(patch, path = "/jobs/{id}", tag = "jobs", request_body = PatchJob,
    params(("id" = i64, Path, description = "Job id")),
    responses(
        (status = 200, description = "The job with its new priority", body = Job),
        (status = 404, description = "No such job", body = ErrorBody),
        (status = 409, description = "The job is no longer queued", body = ErrorBody),
        (status = 422, description = "Priority outside 0..=20 or unknown field", body = ErrorBody),
    ))]
async fn patch_job(
    State(app): State<AppState>,
    Path(id): Path<i64>,
    by: Caller,
    Json(p): Json<PatchJob>,
) -> Result<Json<Job>, ApiError> {
    Ok(Json(app.writer.change_as(id, Change::Priority(p.priority), by.who()).await?))
}

/// A job's history, oldest first.
#[utoipa::path(get, path = "/jobs/{id}/history", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    responses(
        (status = 200, description = "Every state change with its time and cause", body = Vec<JobEvent>),
        (status = 404, description = "No such job", body = ErrorBody),
    ))]
async fn job_history(
    State(app): State<AppState>,
    Path(id): Path<i64>,
) -> Result<Json<Vec<JobEvent>>, ApiError> {
    let history = jobs::history(&app.pool, id).await?;
    if history.is_empty() {
        return Err(ApiError::not_found(format!("job {id} does not exist")));
    }
    Ok(Json(history))
}

/// Cancel a job. A queued job is cancelled at once.
#[utoipa::path(post, path = "/jobs/{id}/cancel", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    responses(
        (status = 200, description = "Cancelled", body = Job),
        (status = 404, description = "No such job", body = ErrorBody),
        (status = 409, description = "The job has ended, or is on a device and cannot be withdrawn", body = ErrorBody),
        (status = 503, description = "The job's device does not answer now; retry", body = ErrorBody),
    ))]
async fn cancel_job(
    State(app): State<AppState>,
    Path(id): Path<i64>,
    by: Caller,
) -> Result<Json<Job>, ApiError> {
    Ok(Json(app.dispatcher.cancel(id, &app.devices(), &by.who()).await?))
}

/// Retry a failed job once its locations are checked: the same job, with the same
/// reference, goes back in the queue as its next `attempt`, its history kept. A location
/// still locked keeps it waiting (see the job's `waiting`).
#[utoipa::path(post, path = "/jobs/{id}/retry", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    responses(
        (status = 200, description = "Queued again as its next attempt", body = Job),
        (status = 404, description = "No such job", body = ErrorBody),
        (status = 409, description = "The job has not failed", body = ErrorBody),
    ))]
async fn retry_job(
    State(app): State<AppState>,
    Path(id): Path<i64>,
    by: Caller,
) -> Result<Json<Job>, ApiError> {
    tracing::info!(job = id, by = %by.name, "retried through the API");
    let actor = Actor { by: by.name, client: by.client, reason: None };
    let mut job = app.dispatcher.retry(id, &actor).await?;
    app.dispatcher.queues().show(&mut job);
    Ok(Json(job))
}

/// The first new store of `jobs` the rack refuses (see `service::planner::refusal`); a
/// repeated request whose reference is stored already is answered as before.
async fn refused(app: &AppState, jobs: &[NewJob]) -> Result<Option<NearOccupied>, ApiError> {
    if app.rules().deep.is_empty() {
        return Ok(None);
    }
    let Some(refused) = near_occupied(
        &app.pool,
        |l| app.dispatcher.queues().taking_from(l).is_some(),
        &app.rules().deep,
        jobs,
    )
    .await?
    else {
        return Ok(None);
    };
    if let Some(reference) = &jobs[refused.index].reference {
        let filter = JobFilter { reference: Some(reference.clone()), limit: 1, ..JobFilter::default() };
        if !jobs::list(&app.pool, &filter).await?.is_empty() {
            return Ok(None);
        }
    }
    Ok(Some(refused))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::domain::{JobSpec, Location};

    #[test]
    fn a_batch_body_is_its_response_as_serde_writes_it() {
        let at = |bay| Location { aisle: 1, row: 1, bay, level: 1, position: 1 };
        let new = NewJob {
            spec: JobSpec::Move { from: at(1), to: at(2) },
            reference: Some("WMS-1".into()),
            priority: Priority::DEFAULT,
            barcode: None,
            device: None,
            serves: None,
            terms: Default::default(),
        };
        let jobs: Vec<Job> = (1..=3).map(|id| new.accepted(id, 1_700_000_000_123)).collect();
        let json: Vec<String> = jobs.iter().map(|j| serde_json::to_string(j).unwrap()).collect();
        for n in 1..=3 {
            let expected = serde_json::to_string(&BatchResponse { jobs: jobs[..n].to_vec() }).unwrap();
            assert_eq!(batch_body(&json[..n]), expected);
        }
    }
}
