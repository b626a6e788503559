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
//!   transaction on the target: a failed copy leaves it empty. A page starts after the last
//!   key of the one before (not at an offset, which would read every row before it again:
//!   a copy of a year's history would take hours instead of minutes).
//! - rackd must not run on either database meanwhile (the command says so; it cannot
//!   check a server it does not run on).

use std::time::Duration;

use super::columns::{ALARMS, AUDIT, CONTROLS, EVENTS, JOB_COUNTS, JOB_HISTORY, JOBS, LOCATIONS};
use super::engine::{Database, Engine, OpenError};
use super::{Pool, Tx, on};

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
    ("rollups", "grain, bucket, scope", &ROLLUPS),
    ("rollup_busy", "scope", &ROLLUP_BUSY),
    ("rollup_marks", "name", &ROLLUP_MARKS),
    ("webhooks", "name", &WEBHOOKS),
    ("webhook_deliveries", "id", &WEBHOOK_DELIVERIES),
];

/// The webhooks' tables' columns (see [`super::webhooks`]): the cursors come along, so a
/// subscription goes on from where it was rather than from the copy's newest event.
const WEBHOOKS: [&str; 9] = [
    "name",
    "cursor",
    "paused",
    "paused_reason",
    "last_ok_at",
    "last_error",
    "last_error_at",
    "failing_since",
    "updated_at",
];
const WEBHOOK_DELIVERIES: [&str; 9] =
    ["id", "name", "seq", "attempt", "status", "outcome", "latency_ms", "error", "at"];

/// The rollups' tables' columns (see [`super::rollups`]).
const ROLLUPS: [&str; 4] = ["grain", "bucket", "scope", "figures"];
const ROLLUP_BUSY: [&str; 3] = ["scope", "active", "since"];
const ROLLUP_MARKS: [&str; 2] = ["name", "at"];

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
    let mut tx = target.write_tx().await.map_err(|error| CopyError::Table { table: "jobs", error })?;
    // Opening the empty target filled its rollups from its empty history: the source's
    // take their place.
    for table in ["rollups", "rollup_busy", "rollup_marks"] {
        let sql = sqlx::AssertSqlSafe(format!("DELETE FROM {table}"));
        on!(Tx, &mut tx, t => sqlx::query(sql).execute(&mut **t).await.map(drop))
            .map_err(|error| CopyError::Table { table: "rollups", error })?;
    }
    let mut copied = Vec::new();
    for &(table, key, columns) in TABLES {
        let insert = target.engine().insert_json(table, columns);
        let mut after = Page::First;
        let mut count = 0;
        loop {
            let (rows, next) = page(&source, table, key, columns, after)
                .await
                .map_err(|error| CopyError::Table { table, error })?;
            if rows.is_empty() {
                break;
            }
            (after, count) = (next, count + rows.len() as u64);
            let json = format!("[{}]", rows.join(","));
            let sql = sqlx::AssertSqlSafe(insert.clone());
            on!(Tx, &mut tx, t => sqlx::query(sql).bind(json).execute(&mut **t).await.map(drop))
                .map_err(|error| CopyError::Table { table, error })?;
        }
        copied.push((table, count));
    }
    if let Tx::Postgres(t) = &mut tx {
        // Ids given explicitly leave the identities behind: move them on.
        for table in ["job_history", "webhook_deliveries"] {
            let sql = sqlx::AssertSqlSafe(format!(
                "SELECT setval(pg_get_serial_sequence('{table}', 'id'), (SELECT COALESCE(MAX(id), 0) + 1 FROM {table}), false)"
            ));
            sqlx::query(sql).execute(&mut **t).await.map_err(|error| CopyError::Table { table, error })?;
        }
    }
    on!(Tx, tx, t => t.commit().await).map_err(|error| CopyError::Table { table: "audit", error })?;
    source.close().await;
    target.close().await;
    Ok(copied)
}

/// Where the next page starts.
#[derive(Clone, Copy)]
enum Page {
    /// At the table's first row.
    First,
    /// After this key (a table keyed by one integer column: read by its index, so a page
    /// costs the same at the end of a table of millions as at its start).
    After(i64),
    /// After this many rows (`locations`, keyed by five columns, a few thousand rows at
    /// most; `controls`, a row per pause).
    Skip(i64),
}

/// Up to [`PAGE`] rows of `table` after `after`, in key order, each as a JSON object; and
/// where the next page starts.
async fn page(
    source: &Pool,
    table: &str,
    key: &str,
    columns: &[&str],
    after: Page,
) -> Result<(Vec<String>, Page), sqlx::Error> {
    // Tables keyed by one integer column; `locations` and `controls` (a text key) are small.
    let single = key == "id" || key == "seq";
    let (filter, skip, from) = match after {
        Page::First => ("", 0, 0),
        Page::After(k) => (" WHERE {key} > $3", 0, k),
        Page::Skip(n) => ("", n, 0),
    };
    let filter = filter.replace("{key}", key);
    let read = match source.engine() {
        Engine::Sqlite => {
            let fields: Vec<String> = columns.iter().map(|c| format!("'{c}', {c}")).collect();
            format!(
                "SELECT json_object({}), {} FROM {table}{filter} ORDER BY {key} LIMIT $1 OFFSET $2",
                fields.join(", "),
                if single { key } else { "0" },
            )
        }
        Engine::Postgres => format!(
            "SELECT row_to_json(t)::text, {} FROM (SELECT {} FROM {table}{filter} ORDER BY {key} LIMIT $1 OFFSET $2) AS t",
            if single { format!("t.{key}::bigint") } else { "0::bigint".to_owned() },
            columns.join(", ")
        ),
    };
    let sql = sqlx::AssertSqlSafe(read);
    let rows: Vec<(String, i64)> = on!(Pool, source, p => {
        let q = sqlx::query_as(sql).bind(PAGE).bind(skip);
        let q = if matches!(after, Page::After(_)) { q.bind(from) } else { q };
        q.fetch_all(p).await
    })?;
    let next = match (single, rows.last()) {
        (true, Some((_, k))) => Page::After(*k),
        (false, _) => Page::Skip(skip + rows.len() as i64),
        (true, None) => after,
    };
    Ok((rows.into_iter().map(|(json, _)| json).collect(), next))
}
