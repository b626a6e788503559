//! The location model: what rackd knows of each location (occupancy, barcode, lights,
//! reservation), updated when jobs complete.

use serde::Serialize;
use sqlx::QueryBuilder;
use time::OffsetDateTime;
use utoipa::ToSchema;

use super::{Pool, Reader, read};
use crate::domain::time::from_ms;
use crate::domain::{Layout, Location, LocationLock};

/// A location and what rackd knows of it.
#[derive(Clone, Debug, PartialEq, Serialize, ToSchema)]
pub struct LocationState {
    // The place's five numbers are fields of their own rather than a flattened `Location`:
    // `Location` refuses unknown keys as a request body, and its schema says so, which a
    // flattened schema would impose on this answer's other fields too.
    /// Aisle, from 1.
    pub aisle: u16,
    /// Row: 1 = A (left), 2 = B (right).
    pub row: u16,
    /// Bay along the aisle, from 1; 0 is the aisle's station.
    pub bay: u16,
    /// Level, bottom-up from 1.
    pub level: u16,
    /// Box position along the level, or depth (1 near, 2 far), from 1.
    pub position: u16,
    /// A box is there.
    pub occupied: bool,
    /// The box's barcode, when known.
    pub barcode: Option<String>,
    /// The red light is on.
    pub red: bool,
    /// The green light is on.
    pub green: bool,
    /// The job that has reserved the location while it runs.
    pub reserved_by: Option<i64>,
    /// Locked: no job touching it is handed out until a person unlocks it; null when not.
    pub lock: Option<LocationLock>,
    /// When this last changed.
    #[serde(with = "time::serde::rfc3339")]
    #[schema(value_type = String, format = DateTime)]
    pub updated_at: OffsetDateTime,
}

/// A location row as stored (the same on both engines).
#[derive(Clone, Serialize, sqlx::FromRow)]
pub(crate) struct Row {
    pub(crate) aisle: i64,
    pub(crate) row: i64,
    pub(crate) bay: i64,
    pub(crate) level: i64,
    pub(crate) position: i64,
    pub(crate) occupied: bool,
    pub(crate) barcode: Option<String>,
    pub(crate) red: bool,
    pub(crate) green: bool,
    pub(crate) reserved_by: Option<i64>,
    pub(crate) updated_at: i64,
    pub(crate) locked_at: Option<i64>,
    pub(crate) locked_by: Option<String>,
    pub(crate) lock_reason: Option<String>,
    pub(crate) lock_job: Option<i64>,
}

impl LocationState {
    /// The place.
    pub fn location(&self) -> Location {
        Location {
            aisle: self.aisle,
            row: self.row,
            bay: self.bay,
            level: self.level,
            position: self.position,
        }
    }
}

/// The columns [`Row`] reads, in a SELECT list.
pub(crate) const COLUMNS: &str = "aisle, row, bay, level, position, occupied, barcode, red, green, reserved_by, \
    updated_at, locked_at, locked_by, lock_reason, lock_job";

impl From<Row> for LocationState {
    fn from(r: Row) -> Self {
        let n = |v: i64| v.clamp(0, u16::MAX as i64) as u16;
        LocationState {
            aisle: n(r.aisle),
            row: n(r.row),
            bay: n(r.bay),
            level: n(r.level),
            position: n(r.position),
            occupied: r.occupied,
            barcode: r.barcode,
            red: r.red,
            green: r.green,
            reserved_by: r.reserved_by,
            lock: r.locked_at.map(|at| LocationLock {
                by: r.locked_by.unwrap_or_default(),
                reason: r.lock_reason.unwrap_or_default(),
                job: r.lock_job,
                at: from_ms(at),
            }),
            updated_at: from_ms(r.updated_at),
        }
    }
}

/// Adds a row for every location of the layout that has none (existing rows are kept).
pub async fn seed(db: &Pool, layout: &Layout, now: i64) -> Result<(), sqlx::Error> {
    let all: Vec<Location> = layout.locations().collect();
    for chunk in all.chunks(1000) {
        read!(Reader::from(db), p => {
            let mut q = QueryBuilder::new("INSERT INTO locations (aisle, row, bay, level, position, updated_at) ");
            q.push_values(chunk, |mut b, l| {
                b.push_bind(l.aisle as i64)
                    .push_bind(l.row as i64)
                    .push_bind(l.bay as i64)
                    .push_bind(l.level as i64)
                    .push_bind(l.position as i64)
                    .push_bind(now);
            });
            q.push(" ON CONFLICT DO NOTHING");
            q.build().execute(p).await.map(drop)
        })?;
    }
    Ok(())
}

/// Deletes the rows of aisle `aisle` that `layout` no longer has (a reload removed or
/// shrank the aisle, after checking that nothing uses them). Answers how many went.
pub async fn drop_outside(db: &Pool, layout: &Layout, aisle: u16) -> Result<u64, sqlx::Error> {
    let gone: Vec<Location> = list(db, Some(aisle))
        .await?
        .iter()
        .map(|l| l.location())
        .filter(|l| layout.check(l).is_err())
        .collect();
    let mut dropped = 0;
    for l in gone {
        let sql = "DELETE FROM locations WHERE aisle = $1 AND row = $2 AND bay = $3 AND level = $4 AND position = $5";
        dropped += read!(Reader::from(db), p => sqlx::query(sql)
            .bind(l.aisle as i64)
            .bind(l.row as i64)
            .bind(l.bay as i64)
            .bind(l.level as i64)
            .bind(l.position as i64)
            .execute(p)
            .await
            .map(|r| r.rows_affected()))?;
    }
    Ok(dropped)
}

/// Every location, optionally of one aisle, in order.
pub async fn list(db: impl Into<Reader<'_>>, aisle: Option<u16>) -> Result<Vec<LocationState>, sqlx::Error> {
    let sql = sqlx::AssertSqlSafe(format!(
        "SELECT {COLUMNS} FROM locations WHERE ($1 IS NULL OR aisle = $1) ORDER BY aisle, row, bay, level, position"
    ));
    let aisle = aisle.map(|a| a as i64);
    let rows: Vec<Row> = read!(db.into(), p => sqlx::query_as(sql).bind(aisle).fetch_all(p).await)?;
    Ok(rows.into_iter().map(LocationState::from).collect())
}

/// Every locked location with its lock (at start, for the dispatcher).
pub async fn locked(db: impl Into<Reader<'_>>) -> Result<Vec<(Location, LocationLock)>, sqlx::Error> {
    let sql = sqlx::AssertSqlSafe(format!("SELECT {COLUMNS} FROM locations WHERE locked_at IS NOT NULL"));
    let rows: Vec<Row> = read!(db.into(), p => sqlx::query_as(sql).fetch_all(p).await)?;
    Ok(rows
        .into_iter()
        .map(LocationState::from)
        .filter_map(|s| s.lock.clone().map(|lock| (s.location(), lock)))
        .collect())
}

/// One location as it stands, if the layout has it.
pub async fn get(db: impl Into<Reader<'_>>, l: Location) -> Result<Option<LocationState>, sqlx::Error> {
    let sql = sqlx::AssertSqlSafe(format!(
        "SELECT {COLUMNS} FROM locations WHERE aisle = $1 AND row = $2 AND bay = $3 AND level = $4 AND position = $5"
    ));
    let row: Option<Row> = read!(db.into(), p => {
        sqlx::query_as(sql)
            .bind(l.aisle as i64)
            .bind(l.row as i64)
            .bind(l.bay as i64)
            .bind(l.level as i64)
            .bind(l.position as i64)
            .fetch_optional(p)
            .await
    })?;
    Ok(row.map(LocationState::from))
}
