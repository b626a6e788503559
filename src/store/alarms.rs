//! Device alarms as recorded: raised and cleared by the writer thread (with their events),
//! read through the pool by the API and the WebSocket snapshot.

use rusqlite::{OptionalExtension, Transaction, params};
use serde::Serialize;
use sqlx::SqliteExecutor;
use time::OffsetDateTime;
use utoipa::ToSchema;

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

#[derive(sqlx::FromRow)]
struct Row {
    id: i64,
    device: String,
    kind: String,
    code: i64,
    class: String,
    text: String,
    detail: Option<String>,
    action: Option<String>,
    acknowledged_by: Option<String>,
    acknowledged_at: Option<i64>,
    raised_at: i64,
    cleared_at: Option<i64>,
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

const COLUMNS: &str = "id, device, kind, code, class, text, detail, action, acknowledged_by, acknowledged_at, raised_at, cleared_at";

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

/// Alarms matching `filter`, newest first.
pub async fn list(db: impl SqliteExecutor<'_>, filter: &AlarmFilter) -> Result<Vec<Alarm>, sqlx::Error> {
    let rows: Vec<Row> = sqlx::query_as(sqlx::AssertSqlSafe(format!(
        "SELECT {COLUMNS} FROM alarms WHERE (?1 IS NULL OR (cleared_at IS NULL) = ?1) \
         AND (?2 IS NULL OR device = ?2) AND (?3 IS NULL OR id < ?3) ORDER BY id DESC LIMIT ?4"
    )))
    .bind(filter.active)
    .bind(&filter.device)
    .bind(filter.before_id)
    .bind(filter.limit)
    .fetch_all(db)
    .await?;
    Ok(rows.into_iter().map(Alarm::from).collect())
}

/// Every active alarm, oldest first.
pub async fn active(db: impl SqliteExecutor<'_>) -> Result<Vec<Alarm>, sqlx::Error> {
    let rows: Vec<Row> = sqlx::query_as(sqlx::AssertSqlSafe(format!(
        "SELECT {COLUMNS} FROM alarms WHERE cleared_at IS NULL ORDER BY id"
    )))
    .fetch_all(db)
    .await?;
    Ok(rows.into_iter().map(Alarm::from).collect())
}

/// Active alarms counted by device and class, in one grouped query.
pub async fn count_active(db: impl SqliteExecutor<'_>) -> Result<Vec<(String, String, i64)>, sqlx::Error> {
    sqlx::query_as(
        "SELECT device, class, COUNT(*) FROM alarms WHERE cleared_at IS NULL GROUP BY device, class",
    )
    .fetch_all(db)
    .await
}

/// Records a raised alarm (writer thread); None when the same alarm is already active.
pub(crate) fn raise(tx: &Transaction<'_>, new: &NewAlarm, now: i64) -> rusqlite::Result<Option<Alarm>> {
    let active: Option<i64> = tx
        .prepare_cached(
            "SELECT id FROM alarms WHERE device = ?1 AND kind = ?2 AND code = ?3 AND cleared_at IS NULL",
        )?
        .query_row(params![new.device, new.kind.as_str(), new.code], |r| r.get(0))
        .optional()?;
    if active.is_some() {
        return Ok(None);
    }
    tx.prepare_cached(
        "INSERT INTO alarms (device, kind, code, class, text, detail, action, raised_at) \
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8)",
    )?
    .execute(params![
        new.device,
        new.kind.as_str(),
        new.code,
        new.class.as_str(),
        new.text,
        new.detail,
        new.action,
        now
    ])?;
    Ok(Some(Alarm {
        id: tx.last_insert_rowid(),
        device: new.device.clone(),
        kind: new.kind,
        code: new.code,
        class: new.class,
        text: new.text.clone(),
        detail: new.detail.clone(),
        action: new.action.clone(),
        acknowledged_by: None,
        acknowledged_at: None,
        raised_at: from_ms(now),
        cleared_at: None,
    }))
}

/// Clears the device's active alarm of this kind and code (writer thread); None when none
/// is active.
pub(crate) fn clear(
    tx: &Transaction<'_>,
    device: &str,
    (kind, code): (AlarmKind, u16),
    now: i64,
) -> rusqlite::Result<Option<Alarm>> {
    let row = tx
        .prepare_cached(&format!(
            "SELECT {COLUMNS} FROM alarms WHERE device = ?1 AND kind = ?2 AND code = ?3 AND cleared_at IS NULL"
        ))?
        .query_row(params![device, kind.as_str(), code], read_row)
        .optional()?;
    let Some(mut row) = row else { return Ok(None) };
    tx.prepare_cached("UPDATE alarms SET cleared_at = ?1 WHERE id = ?2")?.execute(params![now, row.id])?;
    row.cleared_at = Some(now);
    Ok(Some(row.into()))
}

/// A row as the writer thread reads it (columns in [`COLUMNS`] order).
fn read_row(r: &rusqlite::Row<'_>) -> rusqlite::Result<Row> {
    Ok(Row {
        id: r.get(0)?,
        device: r.get(1)?,
        kind: r.get(2)?,
        code: r.get(3)?,
        class: r.get(4)?,
        text: r.get(5)?,
        detail: r.get(6)?,
        action: r.get(7)?,
        acknowledged_by: r.get(8)?,
        acknowledged_at: r.get(9)?,
        raised_at: r.get(10)?,
        cleared_at: r.get(11)?,
    })
}

/// What became of an acknowledgement.
pub(crate) enum Acknowledged {
    /// Recorded: the alarm as it now is.
    Done(Alarm),
    /// No alarm has the id.
    NotFound,
    /// Someone (named) acknowledged it before; the first acknowledgement stands.
    Before(String),
}

/// Records that `by` acknowledged alarm `id` (writer thread), unless there is no such
/// alarm or it was acknowledged before.
pub(crate) fn acknowledge(
    tx: &Transaction<'_>,
    id: i64,
    by: &str,
    now: i64,
) -> rusqlite::Result<Acknowledged> {
    let row = tx
        .prepare_cached(&format!("SELECT {COLUMNS} FROM alarms WHERE id = ?1"))?
        .query_row([id], read_row)
        .optional()?;
    let Some(mut row) = row else { return Ok(Acknowledged::NotFound) };
    if let Some(by) = row.acknowledged_by {
        return Ok(Acknowledged::Before(by));
    }
    tx.prepare_cached("UPDATE alarms SET acknowledged_by = ?1, acknowledged_at = ?2 WHERE id = ?3")?
        .execute(params![by, now, id])?;
    row.acknowledged_by = Some(by.to_owned());
    row.acknowledged_at = Some(now);
    Ok(Acknowledged::Done(row.into()))
}

/// Alarms raised in `[from, to)` (Unix ms), oldest first, at most `limit`.
pub async fn raised_between(
    db: impl SqliteExecutor<'_>,
    from: i64,
    to: i64,
    limit: u32,
) -> Result<Vec<Alarm>, sqlx::Error> {
    let rows: Vec<Row> = sqlx::query_as(sqlx::AssertSqlSafe(format!(
        "SELECT {COLUMNS} FROM alarms WHERE raised_at >= $1 AND raised_at < $2 ORDER BY id LIMIT $3"
    )))
    .bind(from)
    .bind(to)
    .bind(limit)
    .fetch_all(db)
    .await?;
    Ok(rows.into_iter().map(Alarm::from).collect())
}

/// One alarm.
pub async fn get(db: impl SqliteExecutor<'_>, id: i64) -> Result<Option<Alarm>, sqlx::Error> {
    let row: Option<Row> =
        sqlx::query_as(sqlx::AssertSqlSafe(format!("SELECT {COLUMNS} FROM alarms WHERE id = $1")))
            .bind(id)
            .fetch_optional(db)
            .await?;
    Ok(row.map(Alarm::from))
}
