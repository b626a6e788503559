//! `/api/v1/sequences/{name}`: a sequence as the WMS sees it (its members, the position due,
//! what holds it), and what it does to one as a whole: complete it, cancel it, give its
//! queued members a new priority. Members join a sequence as jobs do, through
//! `POST /api/v1/jobs` with `sequence`; what a sequence means for dispatch is written in
//! `service::dispatch::gate`.

use axum::extract::State;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::error::{ApiError, ErrorBody};
use super::extract::{Caller, Json, Path};
use super::state::AppState;
use crate::domain::{JobState, Priority, Waiting, WaitingReason};
use crate::service::dispatch::gate::next_due;
use crate::store::writer::{Change, Record, WriteError};
use crate::store::{jobs, sequences};

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(get_sequence, patch_sequence))
        .routes(routes!(complete_sequence))
        .routes(routes!(cancel_sequence))
}

/// Where a sequence is in its life.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum SequenceState {
    /// Members may still join, at any position.
    Open,
    /// Its last position is known (a member posted as the last), or the WMS completed it
    /// (no member may join any more); some position is still due.
    Complete,
    /// Complete, and every position delivered or passed.
    Done,
    /// Cancelled as a whole.
    Cancelled,
}

/// A member of a sequence.
#[derive(Debug, Serialize, ToSchema)]
pub struct SequenceMember {
    /// Its position.
    pub position: u32,
    /// Its job.
    pub job: i64,
    /// The job's reference.
    pub reference: Option<String>,
    /// The job's state (null: the job went to the archive).
    pub state: Option<JobState>,
    /// Whole seconds past its deadline (see the job's `late_by_s`).
    pub late_by_s: Option<i64>,
}

/// A sequence: the jobs that reach their destination in `position` order.
#[derive(Debug, Serialize, ToSchema)]
#[schema(example = json!({"name": "ORD-77", "station": 3, "state": "open", "complete": false, "last": null,
    "next_position": 2, "members": [
        {"position": 1, "job": 41, "reference": "ORD-77-01", "state": "completed", "late_by_s": null},
        {"position": 2, "job": 42, "reference": "ORD-77-02", "state": "queued", "late_by_s": null}],
    "holding": {"reason": "device_offline", "text": "crane1 does not answer", "device": "crane1",
        "code": null, "job": null, "by": null}}))]
pub struct Sequence {
    /// Its name.
    pub name: String,
    /// The station its members go to, if its first member named one.
    pub station: Option<u16>,
    /// Where it is in its life.
    pub state: SequenceState,
    /// Its last position is known, or the WMS completed it.
    pub complete: bool,
    /// Its last position, once known.
    pub last: Option<u32>,
    /// The lowest position neither delivered (completed) nor passed (cancelled, or never
    /// posted in a complete sequence); null when every one is.
    pub next_position: Option<u32>,
    /// Its members, by position.
    pub members: Vec<SequenceMember>,
    /// Why the position due is not moving, if it is not: its job's `waiting`, or that it
    /// is not posted yet, or failed.
    pub holding: Option<Waiting>,
}

/// A new priority for a sequence's queued members.
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"priority": 2}))]
pub struct PatchSequence {
    /// The new priority, 0..=20 (lower first).
    #[schema(value_type = u8, minimum = 0, maximum = 20)]
    pub priority: Priority,
}

/// The sequence `name` as stored now.
async fn read(app: &AppState, name: &str) -> Result<Sequence, ApiError> {
    let stored = sequences::get(&app.pool, name)
        .await?
        .ok_or_else(|| ApiError::not_found(format!("sequence {name:?} does not exist")))?;
    let ids: Vec<i64> = stored.members.values().map(|m| m.job).collect();
    let mut found = jobs::many(&app.pool, &ids).await?;
    for job in &mut found {
        app.dispatcher.queues().show(job);
    }
    let last = stored.row.last.and_then(|l| u32::try_from(l).ok());
    let closed = stored.row.completed_at.is_some();
    let next = next_due(stored.members.values().filter_map(|m| Some((m.position, m.state?))), last, closed);
    let job_of = |id: i64| found.iter().find(|j| j.id == id);
    let holding = next.and_then(|p| match stored.members.get(&p) {
        None => Some(Waiting::new(WaitingReason::Sequence, format!("position {p} is not posted yet"))),
        Some(m) => {
            let job = job_of(m.job)?;
            match job.state {
                JobState::Failed => {
                    let mut w = Waiting::new(
                        WaitingReason::Sequence,
                        format!("position {p} (job {}) failed: retry it, or cancel the sequence", job.id),
                    );
                    w.job = Some(job.id);
                    Some(w)
                }
                _ => job.waiting.clone(),
            }
        }
    });
    let members: Vec<SequenceMember> = stored
        .members
        .values()
        .map(|m| SequenceMember {
            position: m.position,
            job: m.job,
            reference: m.reference.clone(),
            state: m.state,
            late_by_s: job_of(m.job).and_then(|j| j.late_by_s),
        })
        .collect();
    let complete = closed || last.is_some();
    let state = match (stored.row.cancelled_at, complete) {
        (Some(_), _) => SequenceState::Cancelled,
        (None, true) if next.is_none() => SequenceState::Done,
        (None, true) => SequenceState::Complete,
        (None, false) => SequenceState::Open,
    };
    Ok(Sequence {
        name: stored.row.name,
        station: stored.row.station.and_then(|s| u16::try_from(s).ok()),
        state,
        complete,
        last,
        next_position: next,
        members,
        holding: holding.filter(|_| state != SequenceState::Cancelled),
    })
}

/// Read a sequence: its members, the position due and what holds it.
#[utoipa::path(get, path = "/sequences/{name}", tag = "sequences",
    params(("name" = String, Path, description = "The sequence's name")),
    responses(
        (status = 200, description = "The sequence", body = Sequence),
        (status = 404, description = "No such sequence", body = ErrorBody),
    ))]
async fn get_sequence(
    State(app): State<AppState>,
    Path(name): Path<String>,
) -> Result<Json<Sequence>, ApiError> {
    Ok(Json(read(&app, &name).await?))
}

/// Complete a sequence: no member may join it any more; positions never posted are passed.
/// Idempotent.
#[utoipa::path(post, path = "/sequences/{name}/complete", tag = "sequences",
    params(("name" = String, Path, description = "The sequence's name")),
    responses(
        (status = 200, description = "The sequence, complete", body = Sequence),
        (status = 404, description = "No such sequence", body = ErrorBody),
    ))]
async fn complete_sequence(
    State(app): State<AppState>,
    Path(name): Path<String>,
    by: Caller,
) -> Result<Json<Sequence>, ApiError> {
    record(&app, &name, false, &by).await?;
    Ok(Json(read(&app, &name).await?))
}

/// Cancel a sequence as a whole: it is complete, its queued members are cancelled, and no
/// member is handed out any more. A member already on its machine runs to its end.
#[utoipa::path(post, path = "/sequences/{name}/cancel", tag = "sequences",
    params(("name" = String, Path, description = "The sequence's name")),
    responses(
        (status = 200, description = "The sequence, cancelled", body = Sequence),
        (status = 404, description = "No such sequence", body = ErrorBody),
    ))]
async fn cancel_sequence(
    State(app): State<AppState>,
    Path(name): Path<String>,
    by: Caller,
) -> Result<Json<Sequence>, ApiError> {
    // First the sequence: from its commit on, no member is handed out.
    record(&app, &name, true, &by).await?;
    let stored = read(&app, &name).await?;
    let devices = app.devices();
    for m in stored.members.iter().filter(|m| m.state == Some(JobState::Queued)) {
        match app.dispatcher.cancel(m.job, &devices, &by.who()).await {
            Ok(_) | Err(crate::service::dispatch::CancelError::Ended { .. }) => {}
            Err(e) => return Err(e.into()),
        }
    }
    Ok(Json(read(&app, &name).await?))
}

/// Give every queued member of a sequence a new priority (members on their machine or
/// ended keep theirs).
#[utoipa::path(patch, path = "/sequences/{name}", tag = "sequences", request_body = PatchSequence,
    params(("name" = String, Path, description = "The sequence's name")),
    responses(
        (status = 200, description = "The sequence", body = Sequence),
        (status = 404, description = "No such sequence", body = ErrorBody),
        (status = 422, description = "Priority outside 0..=20 or unknown field", body = ErrorBody),
    ))]
async fn patch_sequence(
    State(app): State<AppState>,
    Path(name): Path<String>,
    by: Caller,
    Json(p): Json<PatchSequence>,
) -> Result<Json<Sequence>, ApiError> {
    let stored = read(&app, &name).await?;
    for m in stored.members.iter().filter(|m| m.state == Some(JobState::Queued)) {
        match app.writer.change_as(m.job, Change::Priority(p.priority), by.who()).await {
            // Handed out meanwhile: it keeps its priority, as a running job does.
            Ok(_) | Err(WriteError::Unexpected { .. }) => {}
            Err(e) => return Err(e.into()),
        }
    }
    Ok(Json(read(&app, &name).await?))
}

/// Completes (or cancels) the sequence, 404 if it does not exist.
async fn record(app: &AppState, name: &str, cancel: bool, by: &Caller) -> Result<(), ApiError> {
    let record = Record::Sequence { name: name.to_owned(), cancel };
    match app.writer.record_as(record, by.who()).await {
        Ok(()) => Ok(()),
        Err(WriteError::Sequence(message)) => Err(ApiError::not_found(message)),
        Err(e) => Err(e.into()),
    }
}
