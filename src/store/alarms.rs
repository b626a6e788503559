//! Device alarms as recorded: raised and cleared by the writer (with their events),
//! read through the pool by the API and the WebSocket snapshot.

use serde::Serialize;
use time::OffsetDateTime;
use utoipa::ToSchema;

use super::paging::Query;
use super::{Reader, read};
use crate::domain::time::from_ms;
use crate::domain::{AlarmClass, AlarmKind};

/// One alarm, active (no `cleared_at`) or past.
#[derive(Clone, Debug, PartialEq, Serialize, ToSchema)]
#[schema(example = json!({"id": 3, "device": "crane1", "kind": "device", "code": 41, "class": "hardware",
    "text": "crane1 stopped: travel inverter fault (alarm 7011)", "detail": "D205 = 7011 (hardware alarm)",
    "action": "A person must go to the crane: check the travel drive and its inverter, then reset the fault on the crane's panel.",
    "acknowledged_by": null, "acknowledged_at": null, "raised_at": "2026-11-21T08:00:00.000Z", "cleared_at": null}))]
pub struct Alarm {
    /// The alarm's number.
    pub id: i64,
    /// The device that raised it.
    pub device: String,
    /// What raised it: the device's own code (`device`) or rackd about the device.
    pub kind: AlarmKind,
    /// The device's own alarm code (kind `device`); 0 for the other kinds.
    pub code: u16,
    /// `business` (rackd resolves it), `hardware` (needs a person) or `link` (the link).
    pub class: AlarmClass,
    /// The alarm in words, for people.
    pub text: String,
    /// The protocol's or device's own words, when the text leaves them out.
    pub detail: Option<String>,
    /// What to do, in plain words; null when nothing is to be done by hand.
    pub action: Option<String>,
    /// Who acknowledged it; null until someone does.
    pub acknowledged_by: Option<String>,
    /// When it was acknowledged.
    #[serde(with = "time::serde::rfc3339::option")]
    #[schema(value_type = Option<String>, format = DateTime)]
    pub acknowledged_at: Option<OffsetDateTime>,
    /// When it was raised.
    #[serde(with = "time::serde::rfc3339")]
    #[schema(value_type = String, format = DateTime)]
    pub raised_at: OffsetDateTime,
    /// When it was cleared; null while active.
    #[serde(with = "time::serde::rfc3339::option")]
    #[schema(value_type = Option<String>, format = DateTime)]
    pub cleared_at: Option<OffsetDateTime>,
}

/// An alarm to raise.
#[derive(Clone, Debug, PartialEq)]
pub struct NewAlarm {
    /// The device.
    pub device: String,
    /// What raised it.
    pub kind: AlarmKind,
    /// The device's own code (kind `device`); 0 otherwise.
    pub code: u16,
    /// Who resolves it.
    pub class: AlarmClass,
    /// In words.
    pub text: String,
    /// The protocol's words, if any.
    pub detail: Option<String>,
    /// What to do, if anything.
    pub action: Option<String>,
}

impl NewAlarm {
    /// The alarm's identity on its device: one active alarm per kind and code.
    pub fn key(&self) -> (AlarmKind, u16) {
        (self.kind, self.code)
    }
}

/// An alarm as stored (the same on both engines).
#[derive(Clone, Serialize, sqlx::FromRow)]
pub(crate) struct Row {
    pub(crate) id: i64,
    pub(crate) device: String,
    pub(crate) kind: String,
    pub(crate) code: i64,
    pub(crate) class: String,
    pub(crate) text: String,
    pub(crate) detail: Option<String>,
    pub(crate) action: Option<String>,
    pub(crate) acknowledged_by: Option<String>,
    pub(crate) acknowledged_at: Option<i64>,
    pub(crate) raised_at: i64,
    pub(crate) cleared_at: Option<i64>,
}

impl From<Row> for Alarm {
    fn from(r: Row) -> Alarm {
        Alarm {
            id: r.id,
            device: r.device,
            // A kind this version does not know is the device's own.
            kind: AlarmKind::parse(&r.kind).unwrap_or(AlarmKind::Device),
            code: r.code.clamp(0, u16::MAX as i64) as u16,
            // A class this version does not know (a hand-edited row) needs a person.
            class: AlarmClass::parse(&r.class).unwrap_or(AlarmClass::Hardware),
            text: r.text,
            detail: r.detail,
            action: r.action,
            acknowledged_by: r.acknowledged_by,
            acknowledged_at: r.acknowledged_at.map(from_ms),
            raised_at: from_ms(r.raised_at),
            cleared_at: r.cleared_at.map(from_ms),
        }
    }
}

/// The columns [`Row`] reads.
pub(crate) const COLUMNS: &str = "id, device, kind, code, class, text, detail, action, acknowledged_by, acknowledged_at, raised_at, cleared_at";

/// Which alarms to list. Alarms come newest first.
#[derive(Clone, Debug, Default)]
pub struct AlarmFilter {
    /// Only active (true) or only cleared (false) alarms.
    pub active: Option<bool>,
    /// Only this device's.
    pub device: Option<String>,
    /// Only alarms older than this id (the cursor).
    pub before_id: Option<i64>,
    /// At most this many.
    pub limit: u32,
}

/// Alarms matching `filter`, newest first, a page read on the index of its filter (see
/// [`super::paging`]).
pub async fn list(db: impl Into<Reader<'_>>, filter: &AlarmFilter) -> Result<Vec<Alarm>, sqlx::Error> {
    let rows: Vec<Row> = list_query(filter).fetch_all(db.into()).await?;
    Ok(rows.into_iter().map(Alarm::from).collect())
}

/// The statement [`list`] runs for `filter`: only the conditions it sets, so that each
/// engine matches them to an index (a condition such as `($1 IS NULL OR id < $1)` can use
/// none).
pub fn list_query(filter: &AlarmFilter) -> Query {
    let mut q = Query::new(format!("SELECT {COLUMNS} FROM alarms WHERE TRUE"));
    match filter.active {
        Some(true) => q.push(" AND cleared_at IS NULL"),
        Some(false) => q.push(" AND cleared_at IS NOT NULL"),
        None => &mut q,
    };
    if let Some(d) = &filter.device {
        q.push(" AND device = ").text(d);
    }
    if let Some(id) = filter.before_id {
        q.push(" AND id < ").int(id);
    }
    q.push(" ORDER BY id DESC LIMIT ").int(filter.limit as i64);
    q
}

/// Every active alarm, oldest first.
pub async fn active(db: impl Into<Reader<'_>>) -> Result<Vec<Alarm>, sqlx::Error> {
    let sql =
        sqlx::AssertSqlSafe(format!("SELECT {COLUMNS} FROM alarms WHERE cleared_at IS NULL ORDER BY id"));
    let rows: Vec<Row> = read!(db.into(), p => sqlx::query_as(sql).fetch_all(p).await)?;
    Ok(rows.into_iter().map(Alarm::from).collect())
}

/// Alarms raised in `[from, to)` (Unix ms), oldest first, after the alarm `after` (0: from
/// the first), at most `limit`: a page of the period, read as [`raised_query`] says.
pub async fn raised_between(
    db: impl Into<Reader<'_>>,
    from: i64,
    to: i64,
    after: i64,
    limit: u32,
) -> Result<Vec<Alarm>, sqlx::Error> {
    let rows: Vec<Row> = raised_query(from, to, after, limit).fetch_all(db.into()).await?;
    Ok(rows.into_iter().map(Alarm::from).collect())
}

/// The statement [`raised_between`] runs: the period as a range of ids, each bound sought on
/// `alarms_raised` (ids are given in the order alarms are raised), as the jobs' period is
/// (see [`super::paging`]); the page read on the key.
pub fn raised_query(from: i64, to: i64, after: i64, limit: u32) -> Query {
    const FIRST_FROM: &str = "(SELECT id FROM alarms WHERE raised_at >= ";
    const IN_ORDER: &str = " ORDER BY raised_at, id LIMIT 1)";
    let mut q = Query::new(format!("SELECT {COLUMNS} FROM alarms WHERE id >= "));
    q.push(FIRST_FROM).int(from).push(IN_ORDER);
    q.push(" AND id < COALESCE(").push(FIRST_FROM).int(to).push(IN_ORDER).push(", ").int(i64::MAX).push(")");
    q.push(" AND +raised_at >= ").int(from).push(" AND +raised_at < ").int(to);
    q.push(" AND id > ").int(after).push(" ORDER BY id LIMIT ").int(limit as i64);
    q
}

/// One alarm.
pub async fn get(db: impl Into<Reader<'_>>, id: i64) -> Result<Option<Alarm>, sqlx::Error> {
    let sql = sqlx::AssertSqlSafe(format!("SELECT {COLUMNS} FROM alarms WHERE id = $1"));
    let row: Option<Row> = read!(db.into(), p => sqlx::query_as(sql).bind(id).fetch_optional(p).await)?;
    Ok(row.map(Alarm::from))
}
