//! `rackd db archive --before DATE --to DIR`: ended jobs and their history leave the store
//! for an archive the site keeps and reads elsewhere, a file per day.
//!
//! Decisions:
//! - **What goes**: jobs that ended (`completed`, `failed`, `cancelled`) before `DATE`
//!   (midnight UTC), by the time they ended (`updated_at`, which an ended job never changes
//!   again), with their history. Never a job still referenced: one a location's lock names
//!   (`lock_job`: the lock a lost task or a failed job set, until a person clears it), or
//!   one an unfinished relocation serves. Alarms name devices, not jobs; a job an alarm is
//!   about is held by the lock its cause set.
//! - **The archive**: one file per day the jobs ended, `jobs-YYYY-MM-DD.jsonl.gz`, gzip'd
//!   JSON Lines, a line per job: `{"job": {...}, "history": [...]}` with every column as the
//!   store has it (times in Unix ms), so that the rows can be loaded back or read by any
//!   tool (`zcat | jq`). A day archived again (a job held by a lock then, free now) gets
//!   `jobs-YYYY-MM-DD.2.jsonl.gz`, and so on: a file, once written, is never changed.
//! - **Written before anything is deleted, and atomically**: each file is written to a
//!   temporary name of its own, synced, given the day's next free name without ever
//!   replacing a file ([`crate::files::Draft`]: the hourly retention and `rackd db archive`
//!   into one folder each take a name of their own) and its folder synced, readable by
//!   rackd's user alone (`0600`), a link planted in the folder never followed; only then
//!   are its jobs deleted, in batches of [`BATCH`] jobs, a transaction each (on a running
//!   rackd, a group of its writer each: [`Delete`]), so that new jobs wait for one batch at
//!   most. A crash between the naming and the last batch leaves jobs in the store that are
//!   in the archive too: the next run archives them again under the next name, and a
//!   reader de-duplicates by job id. Nothing is ever deleted that is not in a synced file.
//! - **rackd may run meanwhile**: by hand the jobs are deleted straight in the database
//!   (with `job_counts`, which `/metrics` shows from rackd's next start); the retention
//!   deletes through the writer, which takes them off its counts as it commits. A job
//!   retried while its day was being written stays in the store (its old state is in the
//!   file too). A re-POST of an archived job's reference makes a new job, as after any
//!   retention. Events are not touched: their own retention (`events.retention_hours`)
//!   keeps them.
//! - **The rollups stay.** The KPIs' day and week rows are kept forever; the minute,
//!   ten-minute and hour rows before `DATE` go with the jobs, and the mark `history_from` says from when the store
//!   holds every job's history (see [`super::rollups`]).
//! - **No partitions on PostgreSQL.** Partitioning `jobs` by month would let a month go
//!   with one `DROP`, but a partitioned table's unique indexes must hold its partition key,
//!   and a job's `reference` is unique across the whole store (the WMS's idempotence);
//!   and jobs leave by the day they ended, not the month they were created. The day's
//!   deletes by `jobs_ended`, 500 a transaction, cost the writer one batch at a time
//!   (`bench history`: single POSTs' p99 during a prune within 1.5x of without).
//! - gzip through `flate2` (its pure-Rust backend); written here rather than with an
//!   archive crate because the format is a line of JSON per job, nothing more.

use std::io::Write;
use std::path::{Path, PathBuf};

use flate2::Compression;
use flate2::write::GzEncoder;
use time::{Date, OffsetDateTime, Time};

use super::columns::JOBS;
use super::counts::{self, Counts};
use super::engine::Engine;
use super::writer::{Record, WriteError, Writer};
use super::{Pool, Tx, on};
use crate::domain::JobState;
use crate::domain::time::to_ms;
use crate::files;

/// Jobs deleted per transaction.
pub const BATCH: usize = 500;

const DAY_MS: i64 = 86_400_000;

/// Why an archive stopped. Every job deleted before it is in a synced file.
#[derive(Debug, thiserror::Error)]
pub enum ArchiveError {
    /// The folder cannot be written.
    #[error("the archive folder {path}: {source}")]
    Folder {
        /// The folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A file could not be written (a full disk, say); its jobs stay in the store.
    #[error("writing {path}: {source}")]
    File {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The database failed.
    #[error("the database: {0}")]
    Database(#[from] sqlx::Error),
    /// The writer refused the deletion (it stopped, or its database failed).
    #[error("the writer: {0}")]
    Writer(#[from] WriteError),
}

/// What one run archived.
#[derive(Debug, Default, PartialEq)]
pub struct Archived {
    /// The files written, in day order.
    pub files: Vec<PathBuf>,
    /// Jobs moved to them.
    pub jobs: u64,
    /// Ended jobs before the date kept because something still names them.
    pub kept: u64,
}

/// How the archived jobs leave the store.
#[derive(Clone, Copy)]
pub enum Delete<'a> {
    /// By rackd's running writer (the retention): in its own groups, so that its view of
    /// the jobs and the counts `/metrics` shows move with them.
    Writer(&'a Writer),
    /// By this process, straight in the database (`rackd db archive`): with the counts in
    /// the same transaction. A rackd running meanwhile shows the new counts from its next
    /// start.
    Direct,
}

/// Moves every ended job that ended before `before` (midnight UTC) and nothing names to
/// a file per day in `dir`.
pub async fn archive(
    pool: &Pool,
    before: Date,
    dir: &Path,
    how: Delete<'_>,
) -> Result<Archived, ArchiveError> {
    check_folder(dir)?;
    let cut = to_ms(OffsetDateTime::new_utc(before, Time::MIDNIGHT));
    let held = held(pool).await?;
    let mut done = Archived::default();
    let Some(mut day) = first_day(pool, cut).await? else {
        keep_rollups_from(pool, cut).await?;
        return Ok(done);
    };
    while day < cut {
        let rows = ended_on(pool, day, (day + DAY_MS).min(cut)).await?;
        let (keep, go): (Vec<_>, Vec<_>) = rows.into_iter().partition(|(id, _)| held.contains(id));
        done.kept += keep.len() as u64;
        if !go.is_empty() {
            let ids: Vec<i64> = go.iter().map(|(id, _)| *id).collect();
            let mut history = histories(pool, day, (day + DAY_MS).min(cut)).await?;
            let lines: Vec<String> = go
                .iter()
                .map(|(id, job)| {
                    let steps = history.remove(id).unwrap_or_default();
                    format!("{{\"job\":{job},\"history\":[{}]}}", steps.join(","))
                })
                .collect();
            let path = write_day(dir, day, &lines)?;
            for batch in ids.chunks(BATCH) {
                match how {
                    Delete::Writer(writer) => {
                        writer.record(Record::Archived { jobs: batch.to_vec() }).await?
                    }
                    Delete::Direct => delete(pool, batch).await?,
                }
            }
            done.jobs += ids.len() as u64;
            done.files.push(path);
        }
        day += DAY_MS;
    }
    keep_rollups_from(pool, cut).await?;
    Ok(done)
}

/// Once the jobs before `cut` are archived: the rollups' rows finer than a day before it go
/// too (day and week rows stay forever), and the mark `history_from` moves up to it, so
/// that a period starting earlier starts on its whole day and a rebuild keeps the rows
/// before it (see [`super::rollups`]).
async fn keep_rollups_from(pool: &Pool, cut: i64) -> Result<(), sqlx::Error> {
    use super::rollups::{DAY, write};
    let mut tx = pool.write_tx().await?;
    let mut db = write::Db::from(&mut tx);
    write::lock(&mut db).await?;
    if write::mark(&mut db, write::HISTORY_FROM).await?.is_some_and(|at| at >= cut) {
        return Ok(());
    }
    write::set_mark(&mut db, write::HISTORY_FROM, cut).await?;
    let sql = "DELETE FROM rollups WHERE grain < $1 AND bucket < $2";
    on!(Tx, &mut tx, t => sqlx::query(sql).bind(DAY).bind(cut).execute(&mut **t).await.map(drop))?;
    on!(Tx, tx, t => t.commit().await)
}

/// Creates `dir` if missing and writes and removes a file in it: proof that the folder
/// takes files, before anything is read (and at rackd's start, `retention.archive_dir`).
pub fn check_folder(dir: &Path) -> Result<(), ArchiveError> {
    let folder = |source| ArchiveError::Folder { path: dir.to_owned(), source };
    std::fs::create_dir_all(dir).map_err(folder)?;
    // A name of its own: nodes (and tests) sharing the folder probe it at the same time.
    let path = dir.join(format!(".rackd-archive-probe-{}-{:x}", std::process::id(), rand::random::<u64>()));
    files::create(&path).map_err(folder)?;
    std::fs::remove_file(&path).map_err(folder)
}

/// Ids of ended jobs something still names: a location's lock, an unfinished job's
/// `serves` (kept in its spec).
async fn held(pool: &Pool) -> Result<std::collections::HashSet<i64>, sqlx::Error> {
    let locks = "SELECT lock_job FROM locations WHERE lock_job IS NOT NULL";
    let mut ids: std::collections::HashSet<i64> =
        on!(Pool, pool, p => sqlx::query_scalar(locks).fetch_all(p).await)?.into_iter().collect();
    let unfinished = "SELECT spec FROM jobs WHERE state IN ('queued', 'dispatched', 'running', 'cancelling')";
    let specs: Vec<String> = on!(Pool, pool, p => sqlx::query_scalar(unfinished).fetch_all(p).await)?;
    for spec in specs {
        if let Ok(v) = serde_json::from_str::<serde_json::Value>(&spec)
            && let Some(id) = v["serves"].as_i64()
        {
            ids.insert(id);
        }
    }
    Ok(ids)
}

/// The start (Unix ms, midnight UTC) of the day the oldest ended job before `cut` ended.
async fn first_day(pool: &Pool, cut: i64) -> Result<Option<i64>, sqlx::Error> {
    let sql = format!("SELECT MIN(updated_at) FROM jobs WHERE {ENDED} AND updated_at < $1");
    let sql = sqlx::AssertSqlSafe(sql);
    let first: Option<i64> = on!(Pool, pool, p => sqlx::query_scalar(sql).bind(cut).fetch_one(p).await)?;
    Ok(first.map(|at| at.div_euclid(DAY_MS) * DAY_MS))
}

/// What makes a job ended, in SQL (the partial index `jobs_ended` has the same condition).
const ENDED: &str = "state IN ('completed', 'failed', 'cancelled')";

/// The jobs that ended in `[from, to)`, each as its row in JSON, by id.
async fn ended_on(pool: &Pool, from: i64, to: i64) -> Result<Vec<(i64, String)>, sqlx::Error> {
    let filter = format!("{ENDED} AND updated_at >= $1 AND updated_at < $2");
    let sql = match pool.engine() {
        Engine::Sqlite => {
            let fields: Vec<String> = JOBS.iter().map(|c| format!("'{c}', {c}")).collect();
            format!("SELECT id, json_object({}) FROM jobs WHERE {filter} ORDER BY id", fields.join(", "))
        }
        Engine::Postgres => format!(
            "SELECT t.id, row_to_json(t)::text FROM (SELECT {} FROM jobs WHERE {filter}) AS t ORDER BY t.id",
            JOBS.join(", ")
        ),
    };
    let sql = sqlx::AssertSqlSafe(sql);
    on!(Pool, pool, p => sqlx::query_as(sql).bind(from).bind(to).fetch_all(p).await)
}

/// The history rows (JSON, in order) of the jobs that ended in `[from, to)`, by job.
async fn histories(
    pool: &Pool,
    from: i64,
    to: i64,
) -> Result<std::collections::HashMap<i64, Vec<String>>, sqlx::Error> {
    let jobs = format!("SELECT id FROM jobs WHERE {ENDED} AND updated_at >= $1 AND updated_at < $2");
    let sql = match pool.engine() {
        Engine::Sqlite => format!(
            "SELECT job_id, json_object('id', id, 'state', state, 'cause', cause, 'detail', detail, 'at', at) \
             FROM job_history WHERE job_id IN ({jobs}) ORDER BY job_id, id"
        ),
        Engine::Postgres => format!(
            "SELECT t.job_id, row_to_json(t)::text FROM (SELECT job_id, id, state, cause, detail, at \
             FROM job_history WHERE job_id IN ({jobs})) AS t ORDER BY t.job_id, t.id"
        ),
    };
    let sql = sqlx::AssertSqlSafe(sql);
    let rows: Vec<(i64, String)> =
        on!(Pool, pool, p => sqlx::query_as(sql).bind(from).bind(to).fetch_all(p).await)?;
    let mut by_job: std::collections::HashMap<i64, Vec<String>> = std::collections::HashMap::new();
    for (job, row) in rows {
        by_job.entry(job).or_default().push(row);
    }
    Ok(by_job)
}

/// Writes `lines` to the day's next free file name: a draft synced and published under
/// the first name no file has (never over one: another archiver may have just taken it).
fn write_day(dir: &Path, day: i64, lines: &[String]) -> Result<PathBuf, ArchiveError> {
    let date = OffsetDateTime::from_unix_timestamp(day / 1000).map(|t| t.date()).unwrap_or(Date::MIN);
    let name = |n: u32| match n {
        1 => format!("jobs-{date}.jsonl.gz"),
        n => format!("jobs-{date}.{n}.jsonl.gz"),
    };
    let first = dir.join(name(1));
    let write = || -> std::io::Result<PathBuf> {
        let draft = files::Draft::beside(&first)?;
        let mut gz = GzEncoder::new(std::io::BufWriter::new(draft.file()), Compression::default());
        for line in lines {
            gz.write_all(line.as_bytes())?;
            gz.write_all(b"\n")?;
        }
        gz.finish()?.into_inner().map_err(|e| e.into_error())?;
        draft.publish((1..=u32::MAX).map(|n| dir.join(name(n))))
    };
    write().map_err(|source| ArchiveError::File { path: first, source })
}

/// Deletes `ids` (those still ended) and their history, and takes them off the counts, in
/// one transaction.
async fn delete(pool: &Pool, ids: &[i64]) -> Result<(), sqlx::Error> {
    let list = ids.iter().map(i64::to_string).collect::<Vec<_>>().join(",");
    let mut tx = pool.write_tx().await?;
    let jobs = format!("DELETE FROM jobs WHERE id IN ({list}) AND {ENDED} RETURNING id, device, state");
    let history = format!("DELETE FROM job_history WHERE job_id IN ({list})");
    let history = sqlx::AssertSqlSafe(history);
    on!(Tx, &mut tx, t => sqlx::query(history).execute(&mut **t).await.map(drop))?;
    let jobs = sqlx::AssertSqlSafe(jobs);
    let gone: Vec<(i64, Option<String>, String)> =
        on!(Tx, &mut tx, t => sqlx::query_as(jobs).fetch_all(&mut **t).await)?;
    let mut counts = Counts::default();
    for (_, device, state) in &gone {
        if let Some(state) = JobState::parse(state) {
            counts.job(device.as_deref(), state, -1);
        }
    }
    let rows = serde_json::to_string(&counts.job_rows()).unwrap_or_default();
    let sql = sqlx::AssertSqlSafe(counts::add_json(pool.engine()));
    on!(Tx, &mut tx, t => sqlx::query(sql).bind(rows).execute(&mut **t).await.map(drop))?;
    on!(Tx, tx, t => t.commit().await)
}
