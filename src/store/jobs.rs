//! Job rows: the API's view of a job, and the queries that read them.

use serde::Serialize;
use sqlx::{QueryBuilder, Sqlite, SqliteExecutor};
use time::OffsetDateTime;
use utoipa::ToSchema;

use super::time::from_ms;
use crate::domain::{Barcode, Failure, JobKind, JobSpec, JobState, LightColor, Location, Priority};

/// A job as the API shows it.
#[derive(Clone, Debug, PartialEq, Serialize, ToSchema)]
#[schema(example = json!({
    "id": 1, "reference": "WMS-1001", "kind": "store", "priority": 10, "barcode": "BOX-0001",
    "to": {"aisle": 1, "row": 1, "bay": 2, "level": 3, "position": 1}, "device": null,
    "state": "queued", "forced": false, "failure": null,
    "created_at": "2026-11-21T08:00:00.000Z", "updated_at": "2026-11-21T08:00:00.000Z"}))]
pub struct Job {
    /// rackd's id for the job.
    pub id: i64,
    /// The WMS's reference, unique; the idempotency key.
    pub reference: Option<String>,
    /// What the job does.
    pub kind: JobKind,
    /// 0..=20, lower first.
    pub priority: u8,
    /// The box's barcode, if given.
    pub barcode: Option<String>,
    /// Source location (`retrieve`, `move`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub from: Option<Location>,
    /// Target location (`store`, `move`, `travel`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub to: Option<Location>,
    /// The location (`clear`, `light`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub location: Option<Location>,
    /// The light (`light`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub color: Option<LightColor>,
    /// On or off (`light`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub on: Option<bool>,
    /// The device that runs the job, once known.
    pub device: Option<String>,
    /// Where the job is in its life.
    pub state: JobState,
    /// Completed by force on the device (crane forced completion).
    pub forced: bool,
    /// Why the job failed, when it did.
    pub failure: Option<Failure>,
    /// When rackd accepted the job.
    #[serde(with = "time::serde::rfc3339")]
    #[schema(value_type = String, format = DateTime)]
    pub created_at: OffsetDateTime,
    /// When the job last changed.
    #[serde(with = "time::serde::rfc3339")]
    #[schema(value_type = String, format = DateTime)]
    pub updated_at: OffsetDateTime,
}

impl Job {
    /// The job's kind-specific fields.
    pub fn spec(&self) -> Option<JobSpec> {
        Some(match self.kind {
            JobKind::Store => JobSpec::Store { to: self.to? },
            JobKind::Retrieve => JobSpec::Retrieve { from: self.from? },
            JobKind::Move => JobSpec::Move { from: self.from?, to: self.to? },
            JobKind::Clear => JobSpec::Clear { location: self.location? },
            JobKind::Light => JobSpec::Light { location: self.location?, color: self.color?, on: self.on? },
            JobKind::Travel => JobSpec::Travel { to: self.to? },
        })
    }
}

/// A job to be stored, already validated.
#[derive(Clone, Debug, PartialEq)]
pub struct NewJob {
    /// What it does.
    pub spec: JobSpec,
    /// The WMS's reference, if any.
    pub reference: Option<String>,
    /// Its priority.
    pub priority: Priority,
    /// The box's barcode, if any.
    pub barcode: Option<Barcode>,
    /// The device named in the request, if any.
    pub device: Option<String>,
}

impl NewJob {
    /// The canonical form of the request, compared on a repeated POST with the same reference.
    pub fn canonical(&self) -> String {
        #[derive(Serialize)]
        struct Canonical<'a> {
            spec: &'a JobSpec,
            reference: &'a Option<String>,
            priority: Priority,
            barcode: &'a Option<Barcode>,
            device: &'a Option<String>,
        }
        let c = Canonical {
            spec: &self.spec,
            reference: &self.reference,
            priority: self.priority,
            barcode: &self.barcode,
            device: &self.device,
        };
        serde_json::to_string(&c).unwrap_or_default()
    }

    /// The job as it is stored on acceptance.
    pub fn accepted(&self, id: i64, now_ms: i64) -> Job {
        let at = from_ms(now_ms);
        let mut job = Job {
            id,
            reference: self.reference.clone(),
            kind: self.spec.kind(),
            priority: self.priority.get(),
            barcode: self.barcode.as_ref().map(|b| b.as_str().to_owned()),
            from: None,
            to: None,
            location: None,
            color: None,
            on: None,
            device: self.device.clone(),
            state: JobState::Queued,
            forced: false,
            failure: None,
            created_at: at,
            updated_at: at,
        };
        match self.spec {
            JobSpec::Store { to } | JobSpec::Travel { to } => job.to = Some(to),
            JobSpec::Retrieve { from } => job.from = Some(from),
            JobSpec::Move { from, to } => (job.from, job.to) = (Some(from), Some(to)),
            JobSpec::Clear { location } => job.location = Some(location),
            JobSpec::Light { location, color, on } => {
                (job.location, job.color, job.on) = (Some(location), Some(color), Some(on))
            }
        }
        job
    }
}

/// One entry of a job's history.
#[derive(Clone, Debug, PartialEq, Serialize, ToSchema)]
pub struct JobEvent {
    /// The state the job entered.
    pub state: JobState,
    /// What caused it: `accepted`, `api cancel`, `device reported finished`, ...
    pub cause: String,
    /// When.
    #[serde(with = "time::serde::rfc3339")]
    #[schema(value_type = String, format = DateTime)]
    pub at: OffsetDateTime,
}

/// Filters and paging for listing jobs. Jobs come in acceptance (id) order.
#[derive(Clone, Debug, Default)]
pub struct JobFilter {
    /// Only jobs in this state.
    pub state: Option<JobState>,
    /// Only jobs of this kind.
    pub kind: Option<JobKind>,
    /// Only jobs on this device.
    pub device: Option<String>,
    /// Only the job with this reference.
    pub reference: Option<String>,
    /// Only jobs accepted at or after this time (Unix ms).
    pub created_from: Option<i64>,
    /// Only jobs accepted before this time (Unix ms).
    pub created_to: Option<i64>,
    /// Only jobs after this id (the cursor).
    pub after_id: Option<i64>,
    /// At most this many.
    pub limit: u32,
}

/// A job as stored, column by column (read through sqlx or, by the writer, rusqlite).
#[derive(sqlx::FromRow)]
pub(crate) struct JobRow {
    id: i64,
    reference: Option<String>,
    priority: i64,
    barcode: Option<String>,
    spec: String,
    device: Option<String>,
    state: String,
    forced: bool,
    failure_kind: Option<String>,
    failure_code: Option<i64>,
    failure_text: Option<String>,
    created_at: i64,
    updated_at: i64,
}

impl JobRow {
    /// Reads the row from a rusqlite row whose columns start with [`COLUMNS`] at `first`.
    pub(crate) fn from_rusqlite(row: &rusqlite::Row<'_>, first: usize) -> rusqlite::Result<JobRow> {
        Ok(JobRow {
            id: row.get(first)?,
            reference: row.get(first + 1)?,
            priority: row.get(first + 2)?,
            barcode: row.get(first + 3)?,
            spec: row.get(first + 4)?,
            device: row.get(first + 5)?,
            state: row.get(first + 6)?,
            forced: row.get(first + 7)?,
            failure_kind: row.get(first + 8)?,
            failure_code: row.get(first + 9)?,
            failure_text: row.get(first + 10)?,
            created_at: row.get(first + 11)?,
            updated_at: row.get(first + 12)?,
        })
    }
}

/// The columns [`JobRow`] reads, in a SELECT list.
pub(crate) const COLUMNS: &str = "id, reference, priority, barcode, spec, device, state, forced, \
    failure_kind, failure_code, failure_text, created_at, updated_at";

/// A stored row that does not make a valid job (a damaged or hand-edited database).
#[derive(Debug, thiserror::Error)]
#[error("job {id}: bad {what} in the database")]
pub struct CorruptRow {
    /// The job.
    pub id: i64,
    /// The column.
    pub what: &'static str,
}

impl TryFrom<JobRow> for Job {
    type Error = CorruptRow;
    fn try_from(row: JobRow) -> Result<Job, CorruptRow> {
        let id = row.id;
        let corrupt = |what: &'static str| CorruptRow { id, what };
        let spec: JobSpec = serde_json::from_str(&row.spec).map_err(|_| corrupt("spec"))?;
        let priority = Priority::try_from(row.priority).map_err(|_| corrupt("priority"))?;
        let state = JobState::parse(&row.state).ok_or_else(|| corrupt("state"))?;
        let new = NewJob { spec, reference: row.reference, priority, barcode: None, device: row.device };
        let mut job = new.accepted(row.id, row.created_at);
        job.barcode = row.barcode;
        job.state = state;
        job.forced = row.forced;
        job.updated_at = from_ms(row.updated_at);
        job.failure = row.failure_kind.map(|kind| Failure {
            kind,
            code: row.failure_code,
            text: row.failure_text.unwrap_or_default(),
        });
        Ok(job)
    }
}

/// One job by id.
pub async fn get(db: impl SqliteExecutor<'_>, id: i64) -> Result<Option<Job>, sqlx::Error> {
    let sql = format!("SELECT {COLUMNS} FROM jobs WHERE id = ?");
    let row: Option<JobRow> = sqlx::query_as(sqlx::AssertSqlSafe(sql)).bind(id).fetch_optional(db).await?;
    row.map(Job::try_from).transpose().map_err(decode)
}

/// A corrupt row as the sqlx error the read functions return.
fn decode(e: CorruptRow) -> sqlx::Error {
    sqlx::Error::Decode(e.into())
}

/// Jobs matching `filter`, in id order.
pub async fn list(db: impl SqliteExecutor<'_>, filter: &JobFilter) -> Result<Vec<Job>, sqlx::Error> {
    let mut q = QueryBuilder::<Sqlite>::new(format!("SELECT {COLUMNS} FROM jobs WHERE 1 = 1"));
    if let Some(s) = filter.state {
        q.push(" AND state = ").push_bind(s.as_str());
    }
    if let Some(k) = filter.kind {
        q.push(" AND kind = ").push_bind(k.as_str());
    }
    if let Some(d) = &filter.device {
        q.push(" AND device = ").push_bind(d.clone());
    }
    if let Some(r) = &filter.reference {
        q.push(" AND reference = ").push_bind(r.clone());
    }
    if let Some(t) = filter.created_from {
        q.push(" AND created_at >= ").push_bind(t);
    }
    if let Some(t) = filter.created_to {
        q.push(" AND created_at < ").push_bind(t);
    }
    if let Some(id) = filter.after_id {
        q.push(" AND id > ").push_bind(id);
    }
    q.push(" ORDER BY id LIMIT ").push_bind(filter.limit as i64);
    let rows: Vec<JobRow> = q.build_query_as().fetch_all(db).await?;
    rows.into_iter().map(|r| Job::try_from(r).map_err(decode)).collect()
}

/// Up to `limit` jobs not yet ended (queued, dispatched, running, cancelling), newest first.
pub async fn active(db: impl SqliteExecutor<'_>, limit: u32) -> Result<Vec<Job>, sqlx::Error> {
    let sql = format!(
        "SELECT {COLUMNS} FROM jobs WHERE state NOT IN ('completed', 'failed', 'cancelled') \
         ORDER BY id DESC LIMIT ?"
    );
    let rows: Vec<JobRow> = sqlx::query_as(sqlx::AssertSqlSafe(sql)).bind(limit).fetch_all(db).await?;
    rows.into_iter().map(|r| Job::try_from(r).map_err(decode)).collect()
}

/// A job's history, oldest first.
pub async fn history(db: impl SqliteExecutor<'_>, id: i64) -> Result<Vec<JobEvent>, sqlx::Error> {
    let rows: Vec<(String, String, i64)> =
        sqlx::query_as("SELECT state, cause, at FROM job_history WHERE job_id = ? ORDER BY id")
            .bind(id)
            .fetch_all(db)
            .await?;
    rows.into_iter()
        .map(|(state, cause, at)| {
            let state = JobState::parse(&state)
                .ok_or_else(|| sqlx::Error::Decode(format!("job {id}: bad history state").into()))?;
            Ok(JobEvent { state, cause, at: from_ms(at) })
        })
        .collect()
}

/// How many jobs are in each state.
pub async fn count_by_state(db: impl SqliteExecutor<'_>) -> Result<Vec<(String, i64)>, sqlx::Error> {
    sqlx::query_as("SELECT state, COUNT(*) FROM jobs GROUP BY state").fetch_all(db).await
}

/// The jobs with these ids that exist, in id order.
pub async fn many(db: impl SqliteExecutor<'_>, ids: &[i64]) -> Result<Vec<Job>, sqlx::Error> {
    if ids.is_empty() {
        return Ok(Vec::new());
    }
    let mut q = QueryBuilder::<Sqlite>::new(format!("SELECT {COLUMNS} FROM jobs WHERE id IN ("));
    let mut list = q.separated(", ");
    for id in ids {
        list.push_bind(*id);
    }
    q.push(") ORDER BY id");
    let rows: Vec<JobRow> = q.build_query_as().fetch_all(db).await?;
    rows.into_iter().map(|r| Job::try_from(r).map_err(decode)).collect()
}

/// The unfinished jobs of `device` a dispatcher considers: every one on the device, and the
/// oldest `window` queued ones, oldest first. Since the queued ones are a prefix by age,
/// every older job that could block one of them (same location) is among them too.
pub async fn dispatch_window(
    db: impl SqliteExecutor<'_> + Copy,
    device: &str,
    window: u32,
) -> Result<Vec<Job>, sqlx::Error> {
    let on_device = format!(
        "SELECT {COLUMNS} FROM jobs WHERE device = ? AND state IN ('dispatched', 'running', 'cancelling') ORDER BY id"
    );
    let queued =
        format!("SELECT {COLUMNS} FROM jobs WHERE device = ? AND state = 'queued' ORDER BY id LIMIT ?");
    let mut rows: Vec<JobRow> =
        sqlx::query_as(sqlx::AssertSqlSafe(on_device)).bind(device).fetch_all(db).await?;
    rows.extend(
        sqlx::query_as::<_, JobRow>(sqlx::AssertSqlSafe(queued))
            .bind(device)
            .bind(window as i64)
            .fetch_all(db)
            .await?,
    );
    rows.into_iter().map(|r| Job::try_from(r).map_err(decode)).collect()
}

/// Every job of `device` that has not ended, oldest first.
pub async fn unfinished(db: impl SqliteExecutor<'_>, device: &str) -> Result<Vec<Job>, sqlx::Error> {
    let sql = format!(
        "SELECT {COLUMNS} FROM jobs WHERE device = ? \
         AND state IN ('queued', 'dispatched', 'running', 'cancelling') ORDER BY id"
    );
    let rows: Vec<JobRow> = sqlx::query_as(sqlx::AssertSqlSafe(sql)).bind(device).fetch_all(db).await?;
    rows.into_iter().map(|r| Job::try_from(r).map_err(decode)).collect()
}
