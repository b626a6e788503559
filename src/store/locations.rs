//! The location model: what rackd knows of each location (occupancy, barcode, lights,
//! reservation), updated when jobs complete.

use serde::Serialize;
use sqlx::{QueryBuilder, Sqlite, SqliteConnection, SqliteExecutor};
use time::OffsetDateTime;
use utoipa::ToSchema;

use super::time::from_ms;
use crate::domain::{JobSpec, Layout, LightColor, Location};

/// A location and what rackd knows of it.
#[derive(Clone, Debug, PartialEq, Serialize, ToSchema)]
pub struct LocationState {
    /// Where.
    #[serde(flatten)]
    pub location: Location,
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
    /// When this last changed.
    #[serde(with = "time::serde::rfc3339")]
    #[schema(value_type = String, format = DateTime)]
    pub updated_at: OffsetDateTime,
}

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
}

impl From<Row> for LocationState {
    fn from(r: Row) -> Self {
        let n = |v: i64| v.clamp(0, u16::MAX as i64) as u16;
        LocationState {
            location: Location {
                aisle: n(r.aisle),
                row: n(r.row),
                bay: n(r.bay),
                level: n(r.level),
                position: n(r.position),
            },
            occupied: r.occupied,
            barcode: r.barcode,
            red: r.red,
            green: r.green,
            reserved_by: r.reserved_by,
            updated_at: from_ms(r.updated_at),
        }
    }
}

const KEY: &str = "aisle = ? AND row = ? AND bay = ? AND level = ? AND position = ?";

fn bind_key<'q>(
    q: sqlx::query::Query<'q, Sqlite, sqlx::sqlite::SqliteArguments>,
    l: Location,
) -> sqlx::query::Query<'q, Sqlite, sqlx::sqlite::SqliteArguments> {
    q.bind(l.aisle as i64).bind(l.row as i64).bind(l.bay as i64).bind(l.level as i64).bind(l.position as i64)
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

/// One location, if the layout has it.
pub async fn get(db: impl SqliteExecutor<'_>, l: Location) -> Result<Option<LocationState>, sqlx::Error> {
    let q = sqlx::query_as::<_, Row>(sqlx::AssertSqlSafe(format!("SELECT * FROM locations WHERE {KEY}")));
    let q = q
        .bind(l.aisle as i64)
        .bind(l.row as i64)
        .bind(l.bay as i64)
        .bind(l.level as i64)
        .bind(l.position as i64);
    Ok(q.fetch_optional(db).await?.map(LocationState::from))
}

/// Marks `locations` reserved by `job` (`hold`), or releases everything `job` holds.
pub async fn reserve(
    db: &mut SqliteConnection,
    job: i64,
    locations: &[Location],
    hold: bool,
) -> Result<(), sqlx::Error> {
    if hold {
        for &l in locations {
            let sql = format!("UPDATE locations SET reserved_by = ? WHERE {KEY}");
            bind_key(sqlx::query(sqlx::AssertSqlSafe(sql)).bind(job), l).execute(&mut *db).await?;
        }
    } else {
        sqlx::query("UPDATE locations SET reserved_by = NULL WHERE reserved_by = ?")
            .bind(job)
            .execute(&mut *db)
            .await?;
    }
    Ok(())
}

/// Sets whether a box is at `l` and its barcode.
async fn set_box(
    db: &mut SqliteConnection,
    l: Location,
    occupied: bool,
    barcode: Option<String>,
    now: i64,
) -> Result<(), sqlx::Error> {
    let sql = format!("UPDATE locations SET occupied = ?, barcode = ?, updated_at = ? WHERE {KEY}");
    let q = sqlx::query(sqlx::AssertSqlSafe(sql)).bind(occupied).bind(barcode).bind(now);
    bind_key(q, l).execute(db).await?;
    Ok(())
}

/// Applies what a completed job did to the locations it touched; returns them.
///
/// store: the target is occupied with the job's barcode; retrieve and clear: the location
/// is empty; move: the box (and its barcode) goes from source to target; light: the light's
/// state; travel: nothing.
pub async fn complete(
    db: &mut SqliteConnection,
    spec: &JobSpec,
    barcode: Option<&str>,
    now: i64,
) -> Result<Vec<Location>, sqlx::Error> {
    Ok(match *spec {
        JobSpec::Store { to } => {
            set_box(db, to, true, barcode.map(str::to_owned), now).await?;
            vec![to]
        }
        JobSpec::Retrieve { from: l } | JobSpec::Clear { location: l } => {
            set_box(db, l, false, None, now).await?;
            vec![l]
        }
        JobSpec::Move { from, to } => {
            let moved = match barcode {
                Some(b) => Some(b.to_owned()),
                None => get(&mut *db, from).await?.and_then(|s| s.barcode),
            };
            set_box(db, from, false, None, now).await?;
            set_box(db, to, true, moved, now).await?;
            vec![from, to]
        }
        JobSpec::Light { location, color, on } => {
            let column = match color {
                LightColor::Red => "red",
                LightColor::Green => "green",
            };
            let sql = format!("UPDATE locations SET {column} = ?, updated_at = ? WHERE {KEY}");
            bind_key(sqlx::query(sqlx::AssertSqlSafe(sql)).bind(on).bind(now), location).execute(db).await?;
            vec![location]
        }
        JobSpec::Travel { .. } => Vec::new(),
    })
}
