//! Jobs by device and state, and active alarms by device and class: what `/metrics` shows
//! as `rackd_jobs` and `rackd_alarms_active`, kept so that a scrape reads no table and costs
//! the same whatever the history holds (issue 39).
//!
//! Decisions:
//! - **Counted where the changes happen.** The writer knows every job it creates or moves
//!   and every alarm it raises or clears: each group works out its net change ([`Counts`],
//!   signed) while it is applied, and hands it to `/metrics` with its other figures once
//!   the group is on disk (`GroupStats::counts`), never before. A group that rolls back
//!   changed nothing and tells nothing.
//! - **Jobs: a small table, `job_counts`, kept in the writer's own commit.** Counting the
//!   jobs at start-up (a `COUNT` over ten million ended jobs) would take seconds, and a
//!   counter of ended jobs since the process started would change what `rackd_jobs` means.
//!   The table has one row per device and state (`''` for a job with no device), and each
//!   group adds its net change to it in the same transaction as the jobs, so it is exactly
//!   as durable as they are and start-up reads a few dozen rows. Whatever deletes jobs (an
//!   archive) must take them off the table in the same commit. Migration 0008 fills it
//!   once from the jobs stored before (one pass over `jobs`, at the upgrade).
//! - **Alarms: counted from the table at start.** Active alarms are few, and
//!   `alarms_device_open` (a partial index) holds only them, so counting them is cheap
//!   whatever the past holds; no second table.
//! - **A node of a cluster reads them again after each commit it follows.** Its writer
//!   sees only its own commits, while every node commits (a standby takes submissions);
//!   every node follows the event log, so each batch it follows (its own commits among
//!   them) asks for a fresh [`load`]: one read transaction of a few dozen rows, coalesced
//!   while one runs (`app::cluster`). Its writer's changes are then not added as well, so
//!   nothing counts twice.

use std::collections::BTreeMap;

use super::{Pool, read};
use crate::domain::JobState;

/// Counts by (device, state) of jobs and by (device, class) of active alarms: the totals,
/// or a group's signed change to them.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    /// Jobs by device (`""`: none) and state.
    pub jobs: BTreeMap<(String, String), i64>,
    /// Active alarms by device and class.
    pub alarms: BTreeMap<(String, String), i64>,
}

impl Counts {
    /// Whether nothing is counted (or nothing changed).
    pub fn is_empty(&self) -> bool {
        self.jobs.values().all(|n| *n == 0) && self.alarms.values().all(|n| *n == 0)
    }

    /// Adds `n` jobs of `device` in `state`.
    pub fn job(&mut self, device: Option<&str>, state: JobState, n: i64) {
        *self.jobs.entry((device.unwrap_or("").to_owned(), state.as_str().to_owned())).or_insert(0) += n;
    }

    /// Adds `n` active alarms of `device` in `class`.
    pub fn alarm(&mut self, device: &str, class: &str, n: i64) {
        *self.alarms.entry((device.to_owned(), class.to_owned())).or_insert(0) += n;
    }

    /// Adds every count of `other`.
    pub fn add(&mut self, other: &Counts) {
        for (key, n) in &other.jobs {
            *self.jobs.entry(key.clone()).or_insert(0) += n;
        }
        for (key, n) in &other.alarms {
            *self.alarms.entry(key.clone()).or_insert(0) += n;
        }
    }

    /// The jobs' rows that change something, as `job_counts` rows.
    pub(crate) fn job_rows(&self) -> Vec<Row<'_>> {
        self.jobs
            .iter()
            .filter(|(_, n)| **n != 0)
            .map(|((device, state), n)| Row { device, state, n: *n })
            .collect()
    }
}

/// A row of `job_counts`, or a change to one.
#[derive(Debug, serde::Serialize)]
pub(crate) struct Row<'a> {
    pub(crate) device: &'a str,
    pub(crate) state: &'a str,
    pub(crate) n: i64,
}

/// The writer's statement adding a group's change to `job_counts`, its rows in one JSON
/// parameter (as the writer's other statements, see [`super::engine`]).
pub(crate) fn add_json(engine: super::Engine) -> String {
    let columns = ["device", "state", "n"];
    format!(
        "INSERT INTO job_counts (device, state, n) {} WHERE TRUE {UPSERT}",
        engine.json_rows("job_counts", &columns)
    )
}

/// What a row already there becomes (`WHERE TRUE` before it lets SQLite tell the upsert's
/// `ON CONFLICT` from a join's `ON`).
pub(crate) const UPSERT: &str = "ON CONFLICT (device, state) DO UPDATE SET n = job_counts.n + excluded.n";

/// Every count as committed: `job_counts`, and the active alarms counted, in one read
/// transaction (so both are as of one moment).
pub async fn load(pool: &Pool) -> Result<Counts, sqlx::Error> {
    let mut tx = pool.read_tx().await?;
    let jobs: Vec<(String, String, i64)> = read!(tx.reader(), p => {
        sqlx::query_as("SELECT device, state, n FROM job_counts").fetch_all(p).await
    })?;
    let sql = "SELECT device, class, COUNT(*) FROM alarms WHERE cleared_at IS NULL GROUP BY device, class";
    let alarms: Vec<(String, String, i64)> = read!(tx.reader(), p => sqlx::query_as(sql).fetch_all(p).await)?;
    tx.finish().await?;
    Ok(Counts {
        jobs: jobs.into_iter().map(|(d, s, n)| ((d, s), n)).collect(),
        alarms: alarms.into_iter().map(|(d, c, n)| ((d, c), n)).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn changes_add_up_and_only_nonzero_rows_are_written() {
        let mut total = Counts::default();
        total.job(Some("shelf1"), JobState::Queued, 3);
        let mut change = Counts::default();
        change.job(Some("shelf1"), JobState::Queued, -1);
        change.job(Some("shelf1"), JobState::Dispatched, 1);
        change.job(None, JobState::Queued, 0);
        change.alarm("shelf1", "link", 1);
        total.add(&change);
        assert_eq!(total.jobs[&("shelf1".into(), "queued".into())], 2);
        assert_eq!(total.jobs[&("shelf1".into(), "dispatched".into())], 1);
        assert_eq!(total.alarms[&("shelf1".into(), "link".into())], 1);
        let rows = change.job_rows();
        assert_eq!(rows.len(), 2, "{rows:?}");
        assert!(!change.is_empty());
        assert!(Counts::default().is_empty());
    }

    #[test]
    fn the_upsert_adds_to_a_row_already_there() {
        let sql = add_json(super::super::Engine::Postgres);
        assert_eq!(
            sql,
            "INSERT INTO job_counts (device, state, n) SELECT device, state, n FROM \
             json_populate_recordset(NULL::job_counts, $1::json) WHERE TRUE \
             ON CONFLICT (device, state) DO UPDATE SET n = job_counts.n + excluded.n"
        );
    }
}
