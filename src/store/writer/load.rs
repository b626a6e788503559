//! What a group reads before it is applied, set-based: at most one statement per kind of
//! row (jobs by reference, jobs by id, locations, history starts, active alarms), each
//! taking all its keys in one JSON parameter, however many requests the group holds.
//!
//! The jobs a group's submissions name by reference are read only when [`References`] says
//! so. Otherwise the group is applied as if no reference it names were stored yet, which is
//! the rule: a WMS sends each job once and resends only what it had no answer for. The
//! unique index on `jobs.reference` is the check: it refuses the insert of a stored
//! reference, and the group is then rolled back and applied again, its references read (see
//! [`super::commit`]). The read did what the index does anyway, one probe a job, plus a
//! JSON parameter to build and parse: measured with `bench intake`, a tenth to a sixth of a
//! group's time on either path (figures in docs/development/benchmarks/intake.md).

use std::collections::{BTreeSet, HashMap};
use std::sync::LazyLock;

use super::apply::{Loaded, Next};
use super::{BulkAction, Change, Command, Conn, Record};
use crate::domain::{Job, Location};
use crate::store::engine::Engine;
use crate::store::jobs::{COLUMNS, JobRow, decode};
use crate::store::{alarms, locations, on};

/// The statements, per engine, built once.
struct Statements {
    by_reference: String,
    by_id: String,
    locations: String,
    starts: String,
    alarms: String,
    alarms_by_id: String,
}

impl Statements {
    fn new(e: Engine) -> Statements {
        let keys = ["aisle", "row", "bay", "level", "position"].join(", ");
        Statements {
            by_reference: format!(
                "SELECT request, {COLUMNS} FROM jobs WHERE reference IN (SELECT reference FROM ({}) AS k)",
                e.json_rows("jobs", &["reference"])
            ),
            by_id: format!(
                "SELECT {COLUMNS} FROM jobs WHERE id IN (SELECT id FROM ({}) AS k)",
                e.json_rows("jobs", &["id"])
            ),
            locations: format!(
                "SELECT {} FROM locations WHERE ({keys}) IN (SELECT {keys} FROM ({}) AS k)",
                locations::COLUMNS,
                e.json_rows("locations", &["aisle", "row", "bay", "level", "position"])
            ),
            starts: format!(
                "SELECT job_id, MAX(at) FROM job_history WHERE state IN ('queued', 'dispatched') \
                 AND job_id IN (SELECT job_id FROM ({}) AS k) GROUP BY job_id",
                e.json_rows("job_history", &["job_id"])
            ),
            alarms: format!("SELECT {} FROM alarms WHERE cleared_at IS NULL ORDER BY id", alarms::COLUMNS),
            alarms_by_id: format!(
                "SELECT {} FROM alarms WHERE id IN (SELECT id FROM ({}) AS k)",
                alarms::COLUMNS,
                e.json_rows("alarms", &["id"])
            ),
        }
    }
}

static SQLITE: LazyLock<Statements> = LazyLock::new(|| Statements::new(Engine::Sqlite));
static POSTGRES: LazyLock<Statements> = LazyLock::new(|| Statements::new(Engine::Postgres));

fn statements(e: Engine) -> &'static Statements {
    match e {
        Engine::Sqlite => &SQLITE,
        Engine::Postgres => &POSTGRES,
    }
}

/// Whether a group reads the stored jobs its submissions' references name (see the module
/// doc). After a group found one stored, the next [`References::AFTER_STORED`] groups read
/// them: a WMS resending a day's jobs after an outage then costs one attempt a group, not
/// two.
#[derive(Debug, Default)]
pub(super) struct References {
    /// Groups left that read them.
    read: u32,
}

impl References {
    /// Groups that read references after one found a reference stored.
    const AFTER_STORED: u32 = 64;

    /// Whether the next group reads them.
    pub(super) fn read(&self) -> bool {
        self.read > 0
    }

    /// A group found a stored reference (read, or refused by the unique index).
    pub(super) fn stored(&mut self) {
        self.read = Self::AFTER_STORED;
    }

    /// A group committed, having read a stored reference (`stored`) or not.
    pub(super) fn committed(&mut self, stored: bool) {
        self.read = match stored {
            true => Self::AFTER_STORED,
            false => self.read.saturating_sub(1),
        };
    }
}

/// The next free number of each numbered table, from what is committed.
pub(super) async fn next(db: &mut Conn) -> Result<Next, sqlx::Error> {
    let sql = "SELECT (SELECT COALESCE(MAX(id), 0) + 1 FROM jobs), (SELECT COALESCE(MAX(seq), 0) + 1 FROM events), \
               (SELECT COALESCE(MAX(id), 0) + 1 FROM audit), (SELECT COALESCE(MAX(id), 0) + 1 FROM alarms)";
    let (job, seq, audit, alarm): (i64, i64, i64, i64) =
        on!(Conn, db, c => sqlx::query_as(sql).fetch_one(&mut *c).await)?;
    Ok(Next { job, seq, audit, alarm })
}

/// The newest stamp the store holds (its newest event's time), if any: stamps of this
/// process go on from there (`domain::time::not_before`).
pub(super) async fn newest_stamp(db: &mut Conn) -> Result<Option<i64>, sqlx::Error> {
    let sql = "SELECT MAX(at) FROM events";
    on!(Conn, db, c => sqlx::query_scalar(sql).fetch_one(&mut *c).await)
}

/// Reads what `group` needs: the jobs its submissions' references (if `read_references`) and its
/// changes name, the locations those jobs and its locks touch, when each of those jobs last
/// started, and the active alarms if it raises or clears one.
pub(super) async fn load(
    db: &mut Conn,
    group: &[&Command],
    read_references: bool,
    count: &mut usize,
) -> Result<Loaded, sqlx::Error> {
    let sql = statements(db.engine());
    let mut loaded = Loaded::default();
    let mut references = BTreeSet::new();
    let mut ids = BTreeSet::new();
    let mut places = BTreeSet::new();
    let mut alarms = false;
    let mut acknowledged = BTreeSet::new();
    let mut sequences: BTreeSet<String> = BTreeSet::new();
    let mut after: BTreeSet<&str> = BTreeSet::new();
    for cmd in group {
        if let Command::Submit { jobs, .. } = cmd {
            for j in jobs.iter().filter(|j| !j.terms.is_plain()) {
                sequences.extend(j.terms.sequence.as_ref().map(|m| m.name.clone()));
                after.extend(j.terms.after.iter().map(String::as_str));
            }
        }
        match cmd {
            // Terms are checked against what a repeated request would find: read them.
            Command::Submit { jobs, .. } if read_references || jobs.iter().any(|j| !j.terms.is_plain()) => {
                references.extend(jobs.iter().filter_map(|j| j.reference.as_deref()))
            }
            Command::Submit { .. } => {}
            Command::Change { id, change, .. } => {
                ids.insert(*id);
                if let Change::Place(to) = change {
                    places.insert(*to);
                }
            }
            Command::Reports { reports, .. } => ids.extend(reports.iter().map(|r| r.job)),
            Command::Adopt { ids: adopt, .. } => ids.extend(adopt.iter().copied()),
            Command::Bulk { bulk, .. } => match &bulk.action {
                BulkAction::Unlock(locations) => places.extend(locations.iter().map(|(l, _)| *l)),
                BulkAction::Retry { jobs, .. } | BulkAction::Cancel(jobs) => ids.extend(jobs.iter().copied()),
            },
            Command::Record { record, .. } => match record {
                Record::Lock { location, .. } | Record::Unlock { location, .. } => {
                    places.insert(*location);
                }
                Record::Inventory { entries, .. } => places.extend(entries.iter().map(|e| e.location)),
                Record::AlarmRaised(_) | Record::AlarmCleared { .. } => alarms = true,
                Record::Acknowledge { alarm, .. } => {
                    acknowledged.insert(*alarm);
                }
                Record::Retell { jobs } | Record::Archived { jobs } | Record::Late { jobs } => {
                    ids.extend(jobs.iter().copied())
                }
                Record::Sequence { name, .. } => drop(sequences.insert(name.clone())),
                Record::Device { .. }
                | Record::Pause { .. }
                | Record::Audit { .. }
                | Record::Reloaded { .. }
                | Record::Prune { .. }
                | Record::Webhook { .. } => {}
            },
        }
    }
    if !references.is_empty() {
        let keys: Vec<_> = references.iter().map(|r| serde_json::json!({ "reference": r })).collect();
        let json = serde_json::to_string(&keys).unwrap_or_default();
        *count += 1;
        let rows: Vec<(String, JobRow)> = on!(Conn, db, c => {
            sqlx::query_as::<_, Stored>(sql.by_reference.as_str()).bind(json).fetch_all(&mut *c).await
        })?
        .into_iter()
        .map(|s| (s.request, s.row))
        .collect();
        for (request, row) in rows {
            let job = Job::try_from(row).map_err(decode)?;
            if let Some(r) = job.reference.clone() {
                loaded.by_reference.insert(r, (request, job));
            }
        }
    }
    if !after.is_empty() {
        // The jobs `after` names, read whatever `read_references` says: no index refuses
        // a reference that names nothing.
        let keys: Vec<_> = after.iter().map(|r| serde_json::json!({ "reference": r })).collect();
        let json = serde_json::to_string(&keys).unwrap_or_default();
        *count += 1;
        let rows: Vec<Stored> = on!(Conn, db, c => {
            sqlx::query_as::<_, Stored>(sql.by_reference.as_str()).bind(json).fetch_all(&mut *c).await
        })?;
        for s in rows {
            let job = Job::try_from(s.row).map_err(decode)?;
            if let Some(r) = job.reference.clone() {
                loaded.after.insert(r, job);
            }
        }
    }
    if !sequences.is_empty() {
        let (rows, members) = crate::store::sequences::statements(db.engine());
        let json = crate::store::sequences::keys(&sequences);
        *count += 2;
        let rows: Vec<crate::store::sequences::Row> =
            on!(Conn, db, c => sqlx::query_as(rows).bind(&json).fetch_all(&mut *c).await)?;
        let members: Vec<crate::store::sequences::MemberRow> =
            on!(Conn, db, c => sqlx::query_as(members).bind(&json).fetch_all(&mut *c).await)?;
        loaded.sequences = crate::store::sequences::assemble(rows, members);
    }
    if !ids.is_empty() {
        let keys: Vec<_> = ids.iter().map(|id| serde_json::json!({ "id": id })).collect();
        let json = serde_json::to_string(&keys).unwrap_or_default();
        *count += 1;
        let rows: Vec<JobRow> =
            on!(Conn, db, c => sqlx::query_as(sql.by_id.as_str()).bind(json).fetch_all(&mut *c).await)?;
        for row in rows {
            let job = Job::try_from(row).map_err(decode)?;
            places.extend(job.spec().map(|s| s.locations()).unwrap_or_default());
            loaded.jobs.insert(job.id, job);
        }
        // A change may name a job this same group creates: its locations are needed too.
        if ids.iter().any(|id| !loaded.jobs.contains_key(id)) {
            for cmd in group {
                if let Command::Submit { jobs, .. } = cmd {
                    places.extend(jobs.iter().flat_map(|j| j.spec.locations()));
                }
            }
        }
        let keys: Vec<_> = loaded.jobs.keys().map(|id| serde_json::json!({ "job_id": id })).collect();
        let json = serde_json::to_string(&keys).unwrap_or_default();
        *count += 1;
        let starts: Vec<(i64, i64)> =
            on!(Conn, db, c => sqlx::query_as(sql.starts.as_str()).bind(json).fetch_all(&mut *c).await)?;
        loaded.starts = starts.into_iter().collect::<HashMap<_, _>>();
    }
    if !places.is_empty() {
        let keys: Vec<_> = places.iter().map(location_json).collect();
        let json = serde_json::to_string(&keys).unwrap_or_default();
        *count += 1;
        let rows: Vec<locations::Row> =
            on!(Conn, db, c => sqlx::query_as(sql.locations.as_str()).bind(json).fetch_all(&mut *c).await)?;
        for row in rows {
            loaded.locations.insert(locations::LocationState::from(row.clone()).location(), row);
        }
    }
    if alarms {
        *count += 1;
        let rows: Vec<alarms::Row> =
            on!(Conn, db, c => sqlx::query_as(sql.alarms.as_str()).fetch_all(&mut *c).await)?;
        loaded.alarms.extend(rows.into_iter().map(|r| (r.id, r)));
    }
    if !acknowledged.is_empty() {
        *count += 1;
        let keys: Vec<_> = acknowledged.iter().map(|id| serde_json::json!({ "id": id })).collect();
        let json = serde_json::to_string(&keys).unwrap_or_default();
        let rows: Vec<alarms::Row> = on!(Conn, db, c => sqlx::query_as(sql.alarms_by_id.as_str()).bind(json).fetch_all(&mut *c).await)?;
        loaded.alarms.extend(rows.into_iter().map(|r| (r.id, r)));
    }
    Ok(loaded)
}

/// A location's key as a JSON object of its columns.
fn location_json(l: &Location) -> serde_json::Value {
    serde_json::json!({"aisle": l.aisle, "row": l.row, "bay": l.bay, "level": l.level, "position": l.position})
}

/// A stored job with its canonical request.
#[derive(sqlx::FromRow)]
struct Stored {
    request: String,
    #[sqlx(flatten)]
    row: JobRow,
}

impl Conn {
    /// Which engine the connection speaks to.
    pub(super) fn engine(&self) -> Engine {
        match self {
            Conn::Sqlite(_) => Engine::Sqlite,
            Conn::Postgres(_) => Engine::Postgres,
        }
    }
}
