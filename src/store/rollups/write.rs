//! Rollup rows to and from the database: a group's transitions added in its own
//! transaction ([`save`]), and rows merged into a table ([`merge`]), which a rebuild uses
//! too. Every statement carries its rows in one JSON parameter, as the writer's others
//! (see [`crate::store::engine`]).

use std::collections::BTreeMap;

use serde::Serialize;

use super::{Busy, Fold, Key, LOCK, Move, Tally};
use crate::store::on;
use crate::store::{Engine, Tx};

/// A connection inside a write transaction, on either engine.
pub enum Db<'a> {
    /// SQLite.
    Sqlite(&'a mut sqlx::SqliteConnection),
    /// PostgreSQL.
    Postgres(&'a mut sqlx::PgConnection),
}

impl<'a> From<&'a mut Tx> for Db<'a> {
    fn from(tx: &'a mut Tx) -> Db<'a> {
        match tx {
            Tx::Sqlite(t) => Db::Sqlite(&mut *t),
            Tx::Postgres(t) => Db::Postgres(&mut *t),
        }
    }
}

impl Db<'_> {
    fn engine(&self) -> Engine {
        match self {
            Db::Sqlite(_) => Engine::Sqlite,
            Db::Postgres(_) => Engine::Postgres,
        }
    }
}

/// The mark of the time from which the store holds every job's whole history, and the
/// minute rows (moved up by each archive; absent: from the beginning).
pub const HISTORY_FROM: &str = "history_from";

/// The mark that the rollups were filled from the history (by the first start after the
/// upgrade, or a rebuild).
pub const BUILT: &str = "built";

/// Adds `moves` (a group's transitions) to the rollups, inside the caller's transaction:
/// the busy state of their scopes read, the rows they touch read, added to and written
/// back. Returns the statements it ran.
pub async fn save(db: &mut Db<'_>, moves: &[Move]) -> Result<usize, sqlx::Error> {
    if moves.is_empty() {
        return Ok(0);
    }
    let mut statements = lock(db).await?;
    let mut fold = Fold { busy: load_busy(db).await?, ..Fold::default() };
    fold.minutes_from = mark(db, HISTORY_FROM).await?.unwrap_or(i64::MIN);
    statements += 2;
    let before = fold.busy.clone();
    for m in moves {
        fold.add(m);
    }
    if fold.strays > 0 {
        tracing::warn!(
            strays = fold.strays,
            "jobs left a device or aisle no job was on, by the rollups' count"
        );
    }
    statements += merge(db, "rollups", &fold.rows).await?;
    let changed: BTreeMap<String, Busy> =
        fold.busy.into_iter().filter(|(scope, b)| before.get(scope) != Some(b)).collect();
    statements += write_busy(db, &changed).await?;
    Ok(statements)
}

/// Takes the rollups' lock for the rest of the transaction: on PostgreSQL the advisory
/// lock [`LOCK`] (taken last in any transaction, see the module doc); on SQLite the write
/// transaction holds the lock already. Returns the statements it ran.
pub async fn lock(db: &mut Db<'_>) -> Result<usize, sqlx::Error> {
    match db {
        Db::Postgres(c) => {
            sqlx::query("SELECT pg_advisory_xact_lock($1)").bind(LOCK).execute(&mut **c).await?;
            Ok(1)
        }
        Db::Sqlite(_) => Ok(0),
    }
}

/// Every scope's busy state.
pub async fn load_busy(db: &mut Db<'_>) -> Result<BTreeMap<String, Busy>, sqlx::Error> {
    let sql = "SELECT scope, active, since FROM rollup_busy";
    let rows: Vec<(String, i64, i64)> = on!(Db, db, c => sqlx::query_as(sql).fetch_all(&mut **c).await)?;
    Ok(rows.into_iter().map(|(scope, active, since)| (scope, Busy { active, since })).collect())
}

/// A mark's time, if set.
pub async fn mark(db: &mut Db<'_>, name: &str) -> Result<Option<i64>, sqlx::Error> {
    let sql = "SELECT at FROM rollup_marks WHERE name = $1";
    on!(Db, db, c => sqlx::query_scalar(sql).bind(name).fetch_optional(&mut **c).await)
}

/// Sets a mark's time.
pub async fn set_mark(db: &mut Db<'_>, name: &str, at: i64) -> Result<(), sqlx::Error> {
    let sql = "INSERT INTO rollup_marks (name, at) VALUES ($1, $2) ON CONFLICT (name) DO UPDATE SET at = excluded.at";
    on!(Db, db, c => sqlx::query(sql).bind(name).bind(at).execute(&mut **c).await.map(drop))
}

#[derive(Serialize)]
struct BusyOut<'a> {
    scope: &'a str,
    active: i64,
    since: i64,
}

/// Writes the busy state of the scopes in `busy`.
pub async fn write_busy(db: &mut Db<'_>, busy: &BTreeMap<String, Busy>) -> Result<usize, sqlx::Error> {
    if busy.is_empty() {
        return Ok(0);
    }
    let rows: Vec<BusyOut> =
        busy.iter().map(|(scope, b)| BusyOut { scope, active: b.active, since: b.since }).collect();
    let sql = format!(
        "INSERT INTO rollup_busy (scope, active, since) {} WHERE TRUE \
         ON CONFLICT (scope) DO UPDATE SET active = excluded.active, since = excluded.since",
        db.engine().json_rows("rollup_busy", &["scope", "active", "since"])
    );
    run(db, sql, &rows).await?;
    Ok(1)
}

#[derive(Serialize)]
struct RowOut<'a> {
    grain: i64,
    bucket: i64,
    scope: &'a str,
    figures: String,
}

/// Adds `rows` to the rows of `table` (`rollups`, or a rebuild's `rollups_rebuild`):
/// those there read, added to, and all written back. Returns the statements it ran.
pub async fn merge(db: &mut Db<'_>, table: &str, rows: &BTreeMap<Key, Tally>) -> Result<usize, sqlx::Error> {
    if rows.is_empty() {
        return Ok(0);
    }
    let engine = db.engine();
    let keys: Vec<RowOut> = rows
        .keys()
        .map(|(grain, bucket, scope)| RowOut {
            grain: *grain,
            bucket: *bucket,
            scope,
            figures: String::new(),
        })
        .collect();
    let keys = serde_json::to_string(&keys).unwrap_or_default();
    let sql = sqlx::AssertSqlSafe(format!(
        "SELECT grain, bucket, scope, figures FROM {table} WHERE (grain, bucket, scope) IN \
         (SELECT grain, bucket, scope FROM ({}) AS k)",
        engine.json_rows(table, &["grain", "bucket", "scope"])
    ));
    let stored: Vec<(i64, i64, String, String)> =
        on!(Db, db, c => sqlx::query_as(sql).bind(keys).fetch_all(&mut **c).await)?;
    let mut stored: BTreeMap<Key, String> = stored.into_iter().map(|(g, b, s, f)| ((g, b, s), f)).collect();
    let out: Vec<RowOut> = rows
        .iter()
        .map(|((grain, bucket, scope), add)| {
            let mut tally: Tally = stored
                .remove(&(*grain, *bucket, scope.clone()))
                .and_then(|text| serde_json::from_str(&text).ok())
                .unwrap_or_default();
            tally.merge(add);
            RowOut {
                grain: *grain,
                bucket: *bucket,
                scope,
                figures: serde_json::to_string(&tally).unwrap_or_default(),
            }
        })
        .collect();
    let sql = format!(
        "INSERT INTO {table} (grain, bucket, scope, figures) {} WHERE TRUE \
         ON CONFLICT (grain, bucket, scope) DO UPDATE SET figures = excluded.figures",
        engine.json_rows(table, &["grain", "bucket", "scope", "figures"])
    );
    run(db, sql, &out).await?;
    Ok(2)
}

/// Runs `sql` with `rows` as its JSON parameter.
async fn run<T: Serialize>(db: &mut Db<'_>, sql: String, rows: &[T]) -> Result<(), sqlx::Error> {
    // Serializing our own rows cannot fail (no maps with non-string keys).
    let json = serde_json::to_string(rows).unwrap_or_default();
    let sql = sqlx::AssertSqlSafe(sql);
    on!(Db, db, c => sqlx::query(sql).bind(json).execute(&mut **c).await.map(drop))
}
