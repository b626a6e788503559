//! The location model: what rackd knows of each location (occupancy, barcode, lights,
//! reservation), updated when jobs complete.

use serde::Serialize;
use sqlx::{QueryBuilder, Sqlite, SqliteConnection, SqliteExecutor};
use time::OffsetDateTime;
use utoipa::ToSchema;

use crate::domain::time::from_ms;
use crate::domain::{JobSpec, Layout, LightColor, Location, LocationLock};

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

/// A location row as stored, read by sqlx (the API) or rusqlite (the writer).
#[derive(sqlx::FromRow)]
struct Row {
    aisle: i64,
    row: i64,
    bay: i64,
    level: i64,
    position: i64,
    occupied: bool,
    barcode: Option<String>,
    red: bool,
    green: bool,
    reserved_by: Option<i64>,
    updated_at: i64,
    locked_at: Option<i64>,
    locked_by: Option<String>,
    lock_reason: Option<String>,
    lock_job: Option<i64>,
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
pub async fn seed(db: &mut SqliteConnection, layout: &Layout, now: i64) -> Result<(), sqlx::Error> {
    let all: Vec<Location> = layout.locations().collect();
    for chunk in all.chunks(1000) {
        let mut q = QueryBuilder::<Sqlite>::new(
            "INSERT OR IGNORE INTO locations (aisle, row, bay, level, position, updated_at) ",
        );
        q.push_values(chunk, |mut b, l| {
            b.push_bind(l.aisle as i64)
                .push_bind(l.row as i64)
                .push_bind(l.bay as i64)
                .push_bind(l.level as i64)
                .push_bind(l.position as i64)
                .push_bind(now);
        });
        q.build().execute(&mut *db).await?;
    }
    Ok(())
}

/// Every location, optionally of one aisle, in order.
pub async fn list(
    db: impl SqliteExecutor<'_>,
    aisle: Option<u16>,
) -> Result<Vec<LocationState>, sqlx::Error> {
    let rows: Vec<Row> = sqlx::query_as(
        "SELECT * FROM locations WHERE (?1 IS NULL OR aisle = ?1) ORDER BY aisle, row, bay, level, position",
    )
    .bind(aisle.map(|a| a as i64))
    .fetch_all(db)
    .await?;
    Ok(rows.into_iter().map(LocationState::from).collect())
}

// What follows runs in the job writer's thread on its own rusqlite connection, inside the
// writer's transaction (see `writer`).

const KEY: &str = "aisle = ?1 AND row = ?2 AND bay = ?3 AND level = ?4 AND position = ?5";

fn key(l: Location) -> [i64; 5] {
    [l.aisle as i64, l.row as i64, l.bay as i64, l.level as i64, l.position as i64]
}

/// One location, if the layout has it.
pub(crate) fn state(db: &rusqlite::Connection, l: Location) -> rusqlite::Result<Option<LocationState>> {
    use rusqlite::OptionalExtension;
    let sql = format!(
        "SELECT aisle, row, bay, level, position, occupied, barcode, red, green, reserved_by, updated_at, \
         locked_at, locked_by, lock_reason, lock_job FROM locations WHERE {KEY}"
    );
    db.prepare_cached(&sql)?
        .query_row(rusqlite::params_from_iter(key(l)), |r| {
            Ok(Row {
                aisle: r.get(0)?,
                row: r.get(1)?,
                bay: r.get(2)?,
                level: r.get(3)?,
                position: r.get(4)?,
                occupied: r.get(5)?,
                barcode: r.get(6)?,
                red: r.get(7)?,
                green: r.get(8)?,
                reserved_by: r.get(9)?,
                updated_at: r.get(10)?,
                locked_at: r.get(11)?,
                locked_by: r.get(12)?,
                lock_reason: r.get(13)?,
                lock_job: r.get(14)?,
            })
        })
        .optional()
        .map(|row| row.map(LocationState::from))
}

/// Every locked location with its lock (at start, for the dispatcher).
pub async fn locked(db: impl SqliteExecutor<'_>) -> Result<Vec<(Location, LocationLock)>, sqlx::Error> {
    let rows: Vec<Row> =
        sqlx::query_as("SELECT * FROM locations WHERE locked_at IS NOT NULL").fetch_all(db).await?;
    Ok(rows
        .into_iter()
        .map(LocationState::from)
        .filter_map(|s| s.lock.clone().map(|lock| (s.location(), lock)))
        .collect())
}

/// One location as it stands, if the layout has it.
pub async fn get(db: impl SqliteExecutor<'_>, l: Location) -> Result<Option<LocationState>, sqlx::Error> {
    let row: Option<Row> =
        sqlx::query_as(sqlx::AssertSqlSafe(format!("SELECT * FROM locations WHERE {KEY}")))
            .bind(l.aisle as i64)
            .bind(l.row as i64)
            .bind(l.bay as i64)
            .bind(l.level as i64)
            .bind(l.position as i64)
            .fetch_optional(db)
            .await?;
    Ok(row.map(LocationState::from))
}

/// Locks `l` unless it is locked already (the first reason stands); whether it did.
pub(crate) fn lock(
    db: &rusqlite::Connection,
    l: Location,
    lock: &LocationLock,
    now: i64,
) -> rusqlite::Result<bool> {
    let sql = format!(
        "UPDATE locations SET locked_at = ?6, locked_by = ?7, lock_reason = ?8, lock_job = ?9, updated_at = ?10 \
         WHERE {KEY} AND locked_at IS NULL"
    );
    let [a, r, b, v, p] = key(l);
    let at = crate::domain::time::to_ms(lock.at);
    let n = db.prepare_cached(&sql)?.execute(rusqlite::params![
        a,
        r,
        b,
        v,
        p,
        at,
        lock.by,
        lock.reason,
        lock.job,
        now
    ])?;
    Ok(n > 0)
}

/// Unlocks `l`; whether it was locked.
pub(crate) fn unlock(db: &rusqlite::Connection, l: Location, now: i64) -> rusqlite::Result<bool> {
    let sql = format!(
        "UPDATE locations SET locked_at = NULL, locked_by = NULL, lock_reason = NULL, lock_job = NULL, \
         updated_at = ?6 WHERE {KEY} AND locked_at IS NOT NULL"
    );
    let [a, r, b, v, p] = key(l);
    Ok(db.prepare_cached(&sql)?.execute(rusqlite::params![a, r, b, v, p, now])? > 0)
}

/// Marks `locations` reserved by `job`.
pub(crate) fn reserve(db: &rusqlite::Connection, job: i64, locations: &[Location]) -> rusqlite::Result<()> {
    let mut q = db.prepare_cached(&format!("UPDATE locations SET reserved_by = ?6 WHERE {KEY}"))?;
    for &l in locations {
        let [a, r, b, v, p] = key(l);
        q.execute(rusqlite::params![a, r, b, v, p, job])?;
    }
    Ok(())
}

/// Releases every location `job` holds; returns how many it held.
pub(crate) fn release(db: &rusqlite::Connection, job: i64) -> rusqlite::Result<usize> {
    db.prepare_cached("UPDATE locations SET reserved_by = NULL WHERE reserved_by = ?1")?.execute([job])
}

/// Sets whether a box is at `l` and its barcode.
fn set_box(
    db: &rusqlite::Connection,
    l: Location,
    occupied: bool,
    barcode: Option<String>,
    now: i64,
) -> rusqlite::Result<()> {
    let sql = format!("UPDATE locations SET occupied = ?6, barcode = ?7, updated_at = ?8 WHERE {KEY}");
    let [a, r, b, v, p] = key(l);
    db.prepare_cached(&sql)?.execute(rusqlite::params![a, r, b, v, p, occupied, barcode, now])?;
    Ok(())
}

/// Applies what a completed job did to the locations it touched; returns them.
///
/// store: the target is occupied with the job's barcode; retrieve and clear: the location
/// is empty; move: the box (and its barcode) goes from source to target; light: the light's
/// state; travel: nothing.
pub(crate) fn complete(
    db: &rusqlite::Connection,
    spec: &JobSpec,
    barcode: Option<&str>,
    now: i64,
) -> rusqlite::Result<Vec<Location>> {
    Ok(match *spec {
        JobSpec::Store { to } => {
            set_box(db, to, true, barcode.map(str::to_owned), now)?;
            vec![to]
        }
        JobSpec::Retrieve { from: l } | JobSpec::Clear { location: l } => {
            set_box(db, l, false, None, now)?;
            vec![l]
        }
        JobSpec::Move { from, to } => {
            let moved = match barcode {
                Some(b) => Some(b.to_owned()),
                None => state(db, from)?.and_then(|s| s.barcode),
            };
            set_box(db, from, false, None, now)?;
            set_box(db, to, true, moved, now)?;
            vec![from, to]
        }
        JobSpec::Light { location, color, on } => {
            let column = match color {
                LightColor::Red => "red",
                LightColor::Green => "green",
            };
            let sql = format!("UPDATE locations SET {column} = ?6, updated_at = ?7 WHERE {KEY}");
            let [a, r, b, v, p] = key(location);
            db.prepare_cached(&sql)?.execute(rusqlite::params![a, r, b, v, p, on, now])?;
            vec![location]
        }
        JobSpec::Travel { .. } => Vec::new(),
    })
}
