//! `rackd db copy --from DB --to DB`: moves a site's store to another database (a SQLite
//! file to a PostgreSQL server, as a site outgrows one machine, or back), with every id and
//! event sequence number kept, so WebSocket clients' `since` and the WMS's job ids stay
//! valid.
//!
//! Decisions:
//! - Both sides are brought to this version's schema first (pending migrations run), and
//!   the target must be empty (no jobs, locations or events): a copy never merges.
//! - Rows travel as JSON: each table is read a page at a time as JSON objects (SQLite's
//!   `json_object`, PostgreSQL's `row_to_json`) and written with the writer's own set-based
//!   statements ([`super::engine::Engine::insert_json`]), one statement per page, all in one
//!   transaction on the target: a failed copy leaves it empty.
//! - rackd must not run on either database meanwhile (the command says so; it cannot
//!   check a server it does not run on).

use std::time::Duration;

use super::columns::{ALARMS, AUDIT, CONTROLS, EVENTS, JOB_COUNTS, JOB_HISTORY, JOBS, LOCATIONS};
use super::engine::{Database, Engine, OpenError};
use super::{Pool, on};

/// Each table, in an order that satisfies its foreign keys, with its key and columns.
const TABLES: &[(&str, &str, &[&str])] = &[
    ("jobs", "id", &JOBS),
    ("job_counts", "device, state", &JOB_COUNTS),
    ("job_history", "id", &JOB_HISTORY),
    ("locations", "aisle, row, bay, level, position", &LOCATIONS),
    ("events", "seq", &EVENTS),
    ("alarms", "id", &ALARMS),
    ("controls", "target", &CONTROLS),
    ("audit", "id", &AUDIT),
];

/// Rows per page.
const PAGE: i64 = 5000;

/// Why a copy failed.
#[derive(Debug, thiserror::Error)]
pub enum CopyError {
    /// A side could not be opened or migrated.
    #[error("{side}: {error}")]
    Open {
        /// `--from` or `--to`.
        side: &'static str,
        /// Why.
        error: OpenError,
    },
    /// The target already holds a store.
    #[error("--to already holds {0}: a copy goes to an empty database only")]
    NotEmpty(String),
    /// Reading or writing failed; nothing was written to the target.
    #[error("copying {table}: {error}")]
    Table {
        /// The table.
        table: &'static str,
        /// Why.
        error: sqlx::Error,
    },
}

/// Rows copied per table.
pub type Copied = Vec<(&'static str, u64)>;

/// Copies every table of `from` to the empty `to`.
pub async fn copy(from: &Database, to: &Database) -> Result<Copied, CopyError> {
    let timeout = Duration::from_secs(5);
    let source =
        super::open(from, timeout).await.map_err(|error| CopyError::Open { side: "--from", error })?;
    let target = super::open(to, timeout).await.map_err(|error| CopyError::Open { side: "--to", error })?;
    for table in ["jobs", "locations", "events"] {
        let sql = sqlx::AssertSqlSafe(format!("SELECT COUNT(*) FROM {table}"));
        let n: i64 = on!(Pool, &target, p => sqlx::query_scalar(sql).fetch_one(p).await)
            .map_err(|error| CopyError::Table { table: "jobs", error })?;
        if n > 0 {
            return Err(CopyError::NotEmpty(format!("{n} rows in {table}")));
        }
    }
    let mut tx = match &target {
        Pool::Sqlite(p) => p.begin().await.map(Tx::Sqlite),
        Pool::Postgres(p) => p.begin().await.map(Tx::Postgres),
    }
    .map_err(|error| CopyError::Table { table: "jobs", error })?;
    let mut copied = Vec::new();
    for &(table, key, columns) in TABLES {
        let insert = target.engine().insert_json(table, columns);
        let mut offset = 0;
        loop {
            let rows = page(&source, table, key, columns, offset)
                .await
                .map_err(|error| CopyError::Table { table, error })?;
            if rows.is_empty() {
                break;
            }
            offset += rows.len() as i64;
            let json = format!("[{}]", rows.join(","));
            let sql = sqlx::AssertSqlSafe(insert.clone());
            on!(Tx, &mut tx, t => sqlx::query(sql).bind(json).execute(&mut **t).await.map(drop))
                .map_err(|error| CopyError::Table { table, error })?;
        }
        copied.push((table, offset as u64));
    }
    if let Tx::Postgres(t) = &mut tx {
        // Ids given explicitly leave the history's identity behind: move it on.
        let sql = "SELECT setval(pg_get_serial_sequence('job_history', 'id'), \
                   (SELECT COALESCE(MAX(id), 0) + 1 FROM job_history), false)";
        sqlx::query(sql)
            .execute(&mut **t)
            .await
            .map_err(|error| CopyError::Table { table: "job_history", error })?;
    }
    on!(Tx, tx, t => t.commit().await).map_err(|error| CopyError::Table { table: "audit", error })?;
    source.close().await;
    target.close().await;
    Ok(copied)
}

/// The target's transaction.
enum Tx {
    Sqlite(sqlx::Transaction<'static, sqlx::Sqlite>),
    Postgres(sqlx::Transaction<'static, sqlx::Postgres>),
}

/// Up to [`PAGE`] rows of `table` from `offset` on, in key order, each as a JSON object.
async fn page(
    source: &Pool,
    table: &str,
    key: &str,
    columns: &[&str],
    offset: i64,
) -> Result<Vec<String>, sqlx::Error> {
    let read = match source.engine() {
        Engine::Sqlite => {
            let fields: Vec<String> = columns.iter().map(|c| format!("'{c}', {c}")).collect();
            format!(
                "SELECT json_object({}) FROM {table} ORDER BY {key} LIMIT $1 OFFSET $2",
                fields.join(", ")
            )
        }
        Engine::Postgres => format!(
            "SELECT row_to_json(t)::text FROM (SELECT {} FROM {table} ORDER BY {key} LIMIT $1 OFFSET $2) AS t",
            columns.join(", ")
        ),
    };
    let sql = sqlx::AssertSqlSafe(read);
    on!(Pool, source, p => sqlx::query_scalar(sql).bind(PAGE).bind(offset).fetch_all(p).await)
}
