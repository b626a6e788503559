//! Sequences: a sequence's row (its station, whether it is complete or cancelled) and its
//! members' positions, as the job writer keeps them (`migrations/*/0015_sequences.sql`).
//! What a sequence means for dispatch is `service::dispatch::gate`'s.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::LazyLock;

use serde::Serialize;

use super::engine::Engine;
use super::{Pool, Reader, on, read};
use crate::domain::JobState;

/// A sequence's row.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, sqlx::FromRow)]
pub struct Row {
    /// Its name.
    pub name: String,
    /// The station its members go to, if its first member named one.
    pub station: Option<i64>,
    /// The last position, once known (a member posted as the last, or the sequence
    /// completed).
    pub last: Option<i64>,
    /// When the WMS completed it: no member may join any more, positions never posted are
    /// passed (Unix ms).
    pub completed_at: Option<i64>,
    /// When the WMS cancelled it as a whole (Unix ms).
    pub cancelled_at: Option<i64>,
    /// When its first member was accepted (Unix ms).
    pub created_at: i64,
    /// When it last changed (Unix ms).
    pub updated_at: i64,
}

/// The columns of [`Row`], in a SELECT list.
pub const COLUMNS: &str = "name, station, last, completed_at, cancelled_at, created_at, updated_at";

/// One member as stored: its position, its job, the job's state and when the job last
/// changed (Unix ms; for an ended member, when it ended), and the aisle its job ran in.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StoredMember {
    /// Its position.
    pub position: u32,
    /// Its job.
    pub job: i64,
    /// The job's reference.
    pub reference: Option<String>,
    /// The job's state (None: the job was archived).
    pub state: Option<JobState>,
    /// When the job last changed.
    pub updated_at: Option<i64>,
    /// The aisle the job runs in (where it picks, or its first location).
    pub aisle: Option<u16>,
}

/// A sequence and its members by position.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Stored {
    /// The row.
    pub row: Row,
    /// Its members, by position.
    pub members: BTreeMap<u32, StoredMember>,
}

/// A member as the statement of [`statements`] reads it.
#[derive(sqlx::FromRow)]
pub(crate) struct MemberRow {
    name: String,
    position: i64,
    job: i64,
    reference: Option<String>,
    state: Option<String>,
    updated_at: Option<i64>,
    spec: Option<String>,
}

/// The statements, per engine.
struct Statements {
    rows: String,
    members: String,
}

impl Statements {
    fn new(e: Engine) -> Statements {
        let names = e.json_rows("sequences", &["name"]);
        Statements {
            rows: format!("SELECT {COLUMNS} FROM sequences WHERE name IN (SELECT name FROM ({names}) AS k)"),
            members: format!(
                "SELECT m.name, m.position, m.job, j.reference, j.state, j.updated_at, j.spec FROM sequence_members m \
                 LEFT JOIN jobs j ON j.id = m.job WHERE m.name IN (SELECT name FROM ({names}) AS k) \
                 ORDER BY m.name, m.position"
            ),
        }
    }
}

static SQLITE: LazyLock<Statements> = LazyLock::new(|| Statements::new(Engine::Sqlite));
static POSTGRES: LazyLock<Statements> = LazyLock::new(|| Statements::new(Engine::Postgres));

/// The statements that read the sequences named in a JSON array `[{"name": ...}]` bound as
/// `$1`: their rows, and their members.
pub(crate) fn statements(e: Engine) -> (&'static str, &'static str) {
    let sql = match e {
        Engine::Sqlite => &*SQLITE,
        Engine::Postgres => &*POSTGRES,
    };
    (sql.rows.as_str(), sql.members.as_str())
}

/// The JSON parameter of [`statements`] for `names`.
pub(crate) fn keys(names: &BTreeSet<String>) -> String {
    let keys: Vec<_> = names.iter().map(|n| serde_json::json!({ "name": n })).collect();
    serde_json::to_string(&keys).unwrap_or_default()
}

/// The sequences named, with their members; a name with no row is left out.
pub async fn many(db: &Pool, names: &BTreeSet<String>) -> Result<BTreeMap<String, Stored>, sqlx::Error> {
    if names.is_empty() {
        return Ok(BTreeMap::new());
    }
    let (rows, members) = statements(db.engine());
    let json = keys(names);
    let rows: Vec<Row> = on!(Pool, db, p => sqlx::query_as(rows).bind(&json).fetch_all(p).await)?;
    let members: Vec<MemberRow> = on!(Pool, db, p => sqlx::query_as(members).bind(&json).fetch_all(p).await)?;
    Ok(assemble(rows, members))
}

/// Rows and their members, by name.
pub(crate) fn assemble(rows: Vec<Row>, members: Vec<MemberRow>) -> BTreeMap<String, Stored> {
    let mut found: BTreeMap<String, Stored> =
        rows.into_iter().map(|row| (row.name.clone(), Stored { row, members: BTreeMap::new() })).collect();
    for m in members {
        let Some(s) = found.get_mut(&m.name) else { continue };
        let position = u32::try_from(m.position).unwrap_or(u32::MAX);
        let state = m.state.as_deref().and_then(JobState::parse);
        let aisle = m
            .spec
            .as_deref()
            .and_then(|t| crate::store::jobs::StoredSpec::parse(t).ok())
            .and_then(|s| s.spec.locations().first().map(|l| l.aisle));
        let member = StoredMember {
            position,
            job: m.job,
            reference: m.reference,
            state,
            updated_at: m.updated_at,
            aisle,
        };
        s.members.insert(position, member);
    }
    found
}

/// One sequence with its members.
pub async fn get(db: &Pool, name: &str) -> Result<Option<Stored>, sqlx::Error> {
    Ok(many(db, &BTreeSet::from([name.to_owned()])).await?.into_values().next())
}

/// The names of the sequences with a member not ended: those dispatch holds in memory.
pub async fn open(db: impl Into<Reader<'_>>) -> Result<BTreeSet<String>, sqlx::Error> {
    let sql = "SELECT DISTINCT m.name FROM sequence_members m JOIN jobs j ON j.id = m.job \
               WHERE j.state IN ('queued', 'dispatched', 'running', 'cancelling')";
    let names: Vec<(String,)> = read!(db.into(), p => sqlx::query_as(sql).fetch_all(p).await)?;
    Ok(names.into_iter().map(|(n,)| n).collect())
}
