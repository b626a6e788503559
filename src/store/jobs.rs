//! Job rows: the API's view of a job, and the queries that read them.

use serde::Serialize;
use sqlx::QueryBuilder;
use time::OffsetDateTime;
use utoipa::ToSchema;

use super::paging::Query;
use super::{Reader, read};
use crate::domain::time::from_ms;
use crate::domain::{Class, Failure, FailureKind, JobKind, JobSpec, JobState, Member, Priority, Terms, Zone};
pub use crate::domain::{Job, NewJob};

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

/// A job as stored, column by column (the same on both engines).
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
    attempt: i64,
}

/// The columns [`JobRow`] reads, in a SELECT list.
pub(crate) const COLUMNS: &str = "id, reference, priority, barcode, spec, device, state, forced, \
    failure_kind, failure_code, failure_text, created_at, updated_at, attempt";

/// The `spec` column: what the job does (a [`JobSpec`] as JSON), and beside its keys what
/// rackd's planner adds to it (`serves`: the job a relocation serves; `putaway`: where a
/// store left to rackd may go, kept once its location is chosen), so that jobs keep the
/// columns (and the bound values per row of a SQLite insert) they had.
///
/// Both directions are on the intake's path, measured: a plain job is written and read as
/// its `JobSpec` alone, and the planner's keys are added or looked for only when present
/// (serde's `flatten` cost intake about 15%).
pub(crate) struct StoredSpec {
    pub(crate) spec: JobSpec,
    pub(crate) serves: Option<i64>,
    pub(crate) putaway: Option<Putaway>,
    pub(crate) terms: Terms,
}

/// Where a store left to rackd may go, once its location is chosen.
#[derive(Serialize, serde::Deserialize)]
pub(crate) struct Putaway {
    zones: Vec<Zone>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    class: Option<Class>,
}

/// The keys of the column beside the spec's: the planner's, and the job's terms (its
/// sequence, deadline in Unix ms, and the references it waits for; a sequence's station and
/// completeness are the sequence's, in `sequences`).
#[derive(Serialize, serde::Deserialize)]
struct Planned {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    serves: Option<i64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    putaway: Option<Putaway>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    sequence: Option<Member>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    deadline: Option<i64>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    after: Vec<String>,
}

/// Keys only [`Planned`] writes: a column without any is a spec alone.
const PLANNED_KEYS: [&str; 5] = ["\"serves\"", "\"putaway\"", "\"sequence\"", "\"deadline\"", "\"after\""];

impl StoredSpec {
    /// The column's text for `job` (`null` for a job whose fields make no spec, which
    /// [`Job`]'s constructors never build).
    pub(crate) fn json(job: &Job) -> String {
        // Our own types, no maps with non-string keys: serializing cannot fail.
        let Some(spec) = job.spec() else { return "null".into() };
        let putaway = match (&spec, &job.zones) {
            (JobSpec::Store { .. }, Some(zones)) => Some(Putaway { zones: zones.clone(), class: job.class }),
            _ => None,
        };
        let plain = serde_json::to_string(&spec).unwrap_or_default();
        let plain_terms = job.sequence.is_none() && job.deadline.is_none() && job.after.is_empty();
        if job.serves.is_none() && putaway.is_none() && plain_terms {
            return plain;
        }
        let planned = Planned {
            serves: job.serves,
            putaway,
            sequence: job.sequence.clone(),
            deadline: job.deadline.map(crate::domain::time::to_ms),
            after: job.after.clone(),
        };
        let extra = serde_json::to_string(&planned).unwrap_or_default();
        // Two JSON objects, each with at least one key: one object with the keys of both.
        match (plain.strip_suffix('}'), extra.strip_prefix('{')) {
            (Some(head), Some(tail)) => format!("{head},{tail}"),
            _ => plain,
        }
    }

    /// Reads the column.
    pub(crate) fn parse(text: &str) -> Result<StoredSpec, serde_json::Error> {
        let spec: JobSpec = serde_json::from_str(text)?;
        let planned = if PLANNED_KEYS.iter().any(|k| text.contains(k)) {
            serde_json::from_str::<Planned>(text)?
        } else {
            Planned { serves: None, putaway: None, sequence: None, deadline: None, after: Vec::new() }
        };
        let terms = Terms {
            sequence: planned.sequence,
            deadline: planned.deadline,
            after: planned.after,
            ..Terms::default()
        };
        Ok(StoredSpec { spec, serves: planned.serves, putaway: planned.putaway, terms })
    }
}

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
        let stored = StoredSpec::parse(&row.spec).map_err(|_| corrupt("spec"))?;
        let spec = stored.spec;
        let priority = Priority::try_from(row.priority).map_err(|_| corrupt("priority"))?;
        let state = JobState::parse(&row.state).ok_or_else(|| corrupt("state"))?;
        let new = NewJob {
            spec,
            reference: row.reference,
            priority,
            barcode: None,
            device: row.device,
            serves: stored.serves,
            terms: stored.terms,
        };
        let mut job = new.accepted(row.id, row.created_at);
        job.barcode = row.barcode;
        if let Some(p) = stored.putaway {
            (job.zones, job.class) = (Some(p.zones), p.class);
        }
        job.state = state;
        job.forced = row.forced;
        job.updated_at = from_ms(row.updated_at);
        job.attempt =
            u32::try_from(row.attempt).ok().filter(|&a| a >= 1).ok_or_else(|| corrupt("attempt"))?;
        job.failure = match row.failure_kind {
            Some(kind) => Some(Failure {
                kind: FailureKind::parse(&kind).ok_or_else(|| corrupt("failure kind"))?,
                code: row.failure_code,
                text: row.failure_text.unwrap_or_default(),
            }),
            None => None,
        };
        Ok(job)
    }
}

/// One job by id.
pub async fn get(db: impl Into<Reader<'_>>, id: i64) -> Result<Option<Job>, sqlx::Error> {
    let sql = format!("SELECT {COLUMNS} FROM jobs WHERE id = $1");
    let row: Option<JobRow> =
        read!(db.into(), p => sqlx::query_as(sqlx::AssertSqlSafe(sql)).bind(id).fetch_optional(p).await)?;
    row.map(Job::try_from).transpose().map_err(decode)
}

/// A corrupt row as the sqlx error the read functions return.
pub(crate) fn decode(e: CorruptRow) -> sqlx::Error {
    sqlx::Error::Decode(e.into())
}

/// Jobs matching `filter`, in id order, a page read on the index of its filter (see
/// [`super::paging`]).
pub async fn list(db: impl Into<Reader<'_>>, filter: &JobFilter) -> Result<Vec<Job>, sqlx::Error> {
    let rows: Vec<JobRow> = list_query(filter).fetch_all(db.into()).await?;
    rows.into_iter().map(|r| Job::try_from(r).map_err(decode)).collect()
}

/// The statement [`list`] runs for `filter`.
pub fn list_query(filter: &JobFilter) -> Query {
    let mut q = Query::new(format!("SELECT {COLUMNS} FROM jobs WHERE TRUE"));
    if let Some(s) = filter.state {
        q.push(" AND state = ").text(s.as_str());
    }
    if let Some(k) = filter.kind {
        q.push(" AND kind = ").text(k.as_str());
    }
    if let Some(d) = &filter.device {
        q.push(" AND device = ").text(d);
    }
    if let Some(r) = &filter.reference {
        q.push(" AND reference = ").text(r);
    }
    // The period as a range of ids: from the first job accepted at or after each bound.
    const FIRST_FROM: &str = "(SELECT id FROM jobs WHERE created_at >= ";
    const IN_ORDER: &str = " ORDER BY created_at, id LIMIT 1)";
    if let Some(t) = filter.created_from {
        q.push(" AND id >= ").push(FIRST_FROM).int(t).push(IN_ORDER);
        q.push(" AND +created_at >= ").int(t);
    }
    if let Some(t) = filter.created_to {
        q.push(" AND id < COALESCE(")
            .push(FIRST_FROM)
            .int(t)
            .push(IN_ORDER)
            .push(", ")
            .int(i64::MAX)
            .push(")");
        q.push(" AND +created_at < ").int(t);
    }
    if let Some(id) = filter.after_id {
        q.push(" AND id > ").int(id);
    }
    q.push(" ORDER BY id LIMIT ").int(filter.limit as i64);
    q
}

/// Up to `limit` jobs not yet ended (queued, dispatched, running, cancelling), newest first:
/// read on the state index, never the ended ones (see [`super::paging`]).
pub async fn active(db: impl Into<Reader<'_>>, limit: u32) -> Result<Vec<Job>, sqlx::Error> {
    let rows: Vec<JobRow> = active_query(limit).fetch_all(db.into()).await?;
    rows.into_iter().map(|r| Job::try_from(r).map_err(decode)).collect()
}

/// The statement [`active`] runs.
pub fn active_query(limit: u32) -> Query {
    let mut q = Query::new(format!(
        "SELECT {COLUMNS} FROM jobs WHERE state IN ('queued', 'dispatched', 'running', 'cancelling') \
         ORDER BY id DESC LIMIT "
    ));
    q.int(limit as i64);
    q
}

/// A job's history, oldest first.
pub async fn history(db: impl Into<Reader<'_>>, id: i64) -> Result<Vec<JobEvent>, sqlx::Error> {
    let rows: Vec<(String, String, i64)> = history_query(id).fetch_all(db.into()).await?;
    rows.into_iter()
        .map(|(state, cause, at)| {
            let state = JobState::parse(&state)
                .ok_or_else(|| sqlx::Error::Decode(format!("job {id}: bad history state").into()))?;
            Ok(JobEvent { state, cause, at: from_ms(at) })
        })
        .collect()
}

/// The statement [`history`] runs: on `job_history_job` (job_id, id).
pub fn history_query(id: i64) -> Query {
    let mut q = Query::new("SELECT state, cause, at FROM job_history WHERE job_id = ");
    q.int(id).push(" ORDER BY id");
    q
}

/// The jobs with these ids that exist, in id order.
pub async fn many(db: impl Into<Reader<'_>>, ids: &[i64]) -> Result<Vec<Job>, sqlx::Error> {
    if ids.is_empty() {
        return Ok(Vec::new());
    }
    read!(db.into(), p => {
        let mut q = QueryBuilder::new(format!("SELECT {COLUMNS} FROM jobs WHERE id IN ("));
        let mut list = q.separated(", ");
        for id in ids {
            list.push_bind(*id);
        }
        q.push(") ORDER BY id");
        let rows: Vec<JobRow> = q.build_query_as().fetch_all(p).await?;
        rows.into_iter().map(|r| Job::try_from(r).map_err(decode)).collect()
    })
}

/// The ids of up to `limit` failed jobs, in id order: of `device`, of failure kind `kind`,
/// failed at or after `since` (Unix ms), each filter if given (an operator's bulk retry
/// or unlock, `service::dispatch::bulk`).
pub async fn failed(
    db: impl Into<Reader<'_>>,
    device: Option<&str>,
    kind: Option<FailureKind>,
    since: Option<i64>,
    limit: u32,
) -> Result<Vec<i64>, sqlx::Error> {
    let rows: Vec<(i64,)> = failed_query(device, kind, since, limit).fetch_all(db.into()).await?;
    Ok(rows.into_iter().map(|(id,)| id).collect())
}

/// The statement [`failed`] runs: the failed jobs in id order on `jobs_device_state` with a
/// device, else on `jobs_state`, the other filters checked on each (`+updated_at`, so that
/// neither engine reads them off `jobs_ended`, which is not in id order). It reads the
/// failed jobs the store keeps (ended jobs go with the retention), not the whole history.
pub fn failed_query(
    device: Option<&str>,
    kind: Option<FailureKind>,
    since: Option<i64>,
    limit: u32,
) -> Query {
    let mut q = Query::new("SELECT id FROM jobs WHERE state = ");
    q.text(JobState::Failed.as_str());
    if let Some(d) = device {
        q.push(" AND device = ").text(d);
    }
    if let Some(k) = kind {
        q.push(" AND failure_kind = ").text(k.as_str());
    }
    if let Some(t) = since {
        q.push(" AND +updated_at >= ").int(t);
    }
    q.push(" ORDER BY id LIMIT ").int(limit as i64);
    q
}

/// Every job of `device` that has not ended, oldest first.
pub async fn unfinished(db: impl Into<Reader<'_>>, device: &str) -> Result<Vec<Job>, sqlx::Error> {
    let mut rows: Vec<JobRow> = unfinished_query(device).fetch_all(db.into()).await?;
    rows.sort_unstable_by_key(|r| r.id);
    rows.into_iter().map(|r| Job::try_from(r).map_err(decode)).collect()
}

/// The statement [`unfinished`] runs: on `jobs_device_state`, sorted here rather than by an
/// `ORDER BY id`, which `jobs_device` (device, id) answers without a sort, and which SQLite,
/// without statistics, then prefers: it read every job the device ever had (measured: 0.6 s
/// at start on a store of 2 million jobs).
pub fn unfinished_query(device: &str) -> Query {
    let mut q = Query::new(format!("SELECT {COLUMNS} FROM jobs WHERE device = "));
    q.text(device).push(" AND state IN ('queued', 'dispatched', 'running', 'cancelling')");
    q
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::domain::Location;

    fn at(bay: u16, position: u16) -> Location {
        Location { aisle: 2, row: 1, bay, level: 3, position }
    }

    fn round_trip(new: NewJob, placed: Option<Location>) -> (String, Job) {
        let mut job = new.accepted(7, 0);
        job.to = placed.or(job.to);
        let text = StoredSpec::json(&job);
        let stored = StoredSpec::parse(&text).unwrap();
        let mut back = NewJob { spec: stored.spec, serves: stored.serves, ..new }.accepted(7, 0);
        if let Some(p) = stored.putaway {
            (back.zones, back.class) = (Some(p.zones), p.class);
        }
        (text, back)
    }

    #[test]
    fn the_spec_column_keeps_what_the_planner_adds() {
        let plain = NewJob {
            spec: JobSpec::Move { from: at(1, 1), to: at(2, 2) },
            reference: None,
            priority: Priority::DEFAULT,
            barcode: None,
            device: None,
            serves: None,
            terms: Default::default(),
        };
        let (text, back) = round_trip(plain.clone(), None);
        assert_eq!(text, serde_json::to_string(&plain.spec).unwrap(), "a plain job is its spec alone");
        assert_eq!(back.serves, None);
        let relocation = NewJob { serves: Some(41), ..plain };
        let (text, back) = round_trip(relocation.clone(), None);
        assert!(text.ends_with("\"position\":2},\"serves\":41}"), "{text}");
        assert_eq!((back.spec(), back.serves), (Some(relocation.spec), Some(41)));
        let zones = vec![Zone { row: Some(1), ..Zone::aisle(2) }];
        let putaway =
            NewJob { spec: JobSpec::Putaway { zones: zones.clone(), class: Some(Class::B) }, ..relocation };
        let (_, back) = round_trip(putaway.clone(), None);
        assert_eq!((back.to, back.zones.clone(), back.class), (None, Some(zones.clone()), Some(Class::B)));
        let (text, back) = round_trip(putaway, Some(at(4, 2)));
        assert!(text.contains("\"putaway\":{\"zones\":[{\"aisle\":2,\"row\":1}],\"class\":\"B\"}"), "{text}");
        assert_eq!((back.to, back.zones, back.class), (Some(at(4, 2)), Some(zones), Some(Class::B)));
    }
}
