//! Ended jobs loaded in bulk, with their history, straight into the store: what
//! `bench history` seeds a store of millions of jobs with (a year of a site, in minutes
//! rather than the weeks of replaying it through the API), and the way in for the history
//! of another system.
//!
//! Decisions:
//! - **Ended jobs only** (`completed`, `failed`, `cancelled`): they hold no location, slot
//!   or device, so loading them cannot disturb what the writer and the devices keep in
//!   memory. Anything else is refused before a row is written.
//! - **Ids are the caller's**, above every id the store holds (a clash is the database's
//!   unique-key error, and nothing of the call is written); the writer numbers the next
//!   new job after the highest at its next start. History rows take the table's own ids.
//! - **No events**: the event log is for live subscribers and is kept for days; a loaded
//!   year of jobs has nothing to tell them. Audit entries are not written either. The
//!   counts of jobs (`job_counts`, what `/metrics` shows) are, in the same commit; a rackd
//!   running meanwhile shows them from its next start.
//! - **One transaction per call**, written with the writer's own set-based statements (one
//!   statement per table, the rows as one JSON parameter): a call of a few thousand jobs
//!   is a fast unit; a failed call leaves nothing behind.
//! - rackd may run meanwhile: the transaction takes the database's write lock like one of
//!   the writer's groups (SQLite waits up to `busy_timeout` for it).

use serde::Serialize;

use super::columns::{JOBS, JobOut};
use super::counts::{self, Counts};
use super::{Pool, Tx, on};
use crate::domain::{Job, JobState};

/// A job to load and its history: each state it entered, why, and when (Unix ms), in order.
#[derive(Clone, Debug)]
pub struct Ended {
    /// The job, in its final state.
    pub job: Job,
    /// The request as the WMS would have posted it (`NewJob::canonical`): a re-POST of the
    /// job's reference is compared with it, as for any stored job.
    pub request: String,
    /// `(state, cause, at)`: its history, the first entry `queued`, the last its final state.
    pub history: Vec<(JobState, String, i64)>,
}

/// Why a load was refused; nothing of it was written.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// A job that has not ended.
    #[error("job {id} is {state}: only ended jobs (completed, failed, cancelled) are loaded")]
    NotEnded {
        /// The job.
        id: i64,
        /// Its state.
        state: &'static str,
    },
    /// A job whose history does not end in its state.
    #[error("job {0}: its history must end in its state")]
    History(i64),
    /// The database refused the rows (an id the store holds already, a lost connection).
    #[error("the database refused the rows: {0}")]
    Database(#[from] sqlx::Error),
}

#[derive(Serialize)]
struct HistoryOut<'a> {
    job_id: i64,
    state: &'static str,
    cause: &'a str,
    at: i64,
}

/// The history's columns written (its `id` is the table's own, `detail` null).
const HISTORY: [&str; 4] = ["job_id", "state", "cause", "at"];

/// Writes `jobs` and their history in one transaction.
pub async fn ended_jobs(pool: &Pool, jobs: &[Ended]) -> Result<(), ImportError> {
    for e in jobs {
        let (id, state) = (e.job.id, e.job.state);
        if !state.is_terminal() {
            return Err(ImportError::NotEnded { id, state: state.as_str() });
        }
        if e.history.last().map(|h| h.0) != Some(state) {
            return Err(ImportError::History(id));
        }
    }
    let rows: Vec<JobOut> = jobs.iter().map(|e| JobOut::new(&e.job, Some(&e.request))).collect();
    let history: Vec<HistoryOut> = jobs
        .iter()
        .flat_map(|e| {
            e.history.iter().map(|(state, cause, at)| HistoryOut {
                job_id: e.job.id,
                state: state.as_str(),
                cause,
                at: *at,
            })
        })
        .collect();
    // The counts `/metrics` reads (`store::counts`), in the same commit as the jobs.
    let mut counts = Counts::default();
    for e in jobs {
        counts.job(e.job.device.as_deref(), e.job.state, 1);
    }
    let engine = pool.engine();
    let statements = [
        (engine.insert_json("jobs", &JOBS), serde_json::to_string(&rows)),
        (engine.insert_json("job_history", &HISTORY), serde_json::to_string(&history)),
        (counts::add_json(engine), serde_json::to_string(&counts.job_rows())),
    ];
    let mut tx = pool.write_tx().await?;
    for (sql, json) in statements {
        // Serializing our own rows cannot fail (no maps with non-string keys).
        let json = json.unwrap_or_default();
        let sql = sqlx::AssertSqlSafe(sql);
        on!(Tx, &mut tx, t => sqlx::query(sql).bind(json).execute(&mut **t).await.map(drop))?;
    }
    on!(Tx, tx, t => t.commit().await)?;
    Ok(())
}
