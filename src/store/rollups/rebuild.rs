//! `rackd db rollups --rebuild`, and the first start after the upgrade that brought
//! rollups: the rollups recomputed from the job history, on a stopped or a running rackd.
//!
//! Decisions:
//! - **Built aside, then put in place at once.** The history is replayed in order, a page
//!   of [`PAGE`] entries at a time, into `rollups_rebuild` (each page its own short
//!   transaction: a running writer waits a few milliseconds at most). The last page is read
//!   inside the transaction that puts the result in place (on PostgreSQL under the rollups'
//!   advisory lock, on SQLite under the write lock), so nothing the writer commits meanwhile
//!   is missed or counted twice; the writer waits for that one transaction (copying the
//!   rebuilt rows: about a second per 300,000 on this project's machine).
//! - **What the history no longer holds is kept.** Days archived (before the mark
//!   `history_from`) have no history left: their rows stay as they are, and the replay adds
//!   nothing before that time. Their day and week rows are the only record of them.
//!   The week the mark falls in is summed again from its days, kept and rebuilt.
//! - **One rebuild at a time**: the mark `rebuilding`, refreshed at every page; another
//!   rebuild refuses while it is younger than [`STALE_MS`] (a rebuild killed midway
//!   leaves it; the next may start once it is stale).

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

use super::fold::End;
use super::write::{self, BUILT, Db, HISTORY_FROM};
use super::{DAY, Fold, Move, Tally, WEEK, floor, scopes};
use crate::domain::time::now_ms;
use crate::domain::{JobSpec, JobState};
use crate::store::{Pool, Tx, on};

/// History entries replayed per page.
pub const PAGE: i64 = 20_000;

/// How old the mark of a rebuild under way must be before another may start.
pub const STALE_MS: i64 = 120_000;

const REBUILDING: &str = "rebuilding";

/// Why a rebuild failed.
#[derive(Debug, thiserror::Error)]
pub enum RebuildError {
    /// Another rebuild is under way.
    #[error("another rebuild of the rollups is under way (its mark is {0} s old); try again once it ends")]
    Running(i64),
    /// The database failed; the rollups in use are unchanged.
    #[error(transparent)]
    Database(#[from] sqlx::Error),
}

/// What a rebuild did.
#[derive(Clone, Copy, Debug, Default)]
pub struct Rebuilt {
    /// History entries replayed.
    pub entries: u64,
    /// Rollup rows it put in place.
    pub rows: u64,
    /// How long its last transaction took (the last page and the swap): what a running
    /// writer waited for.
    pub swap: std::time::Duration,
}

/// The entries after a position, with what the rollups need of their jobs.
const ENTRIES: &str = "SELECT h.id, h.job_id, h.state, h.at, j.kind, j.device, j.spec, j.failure_kind \
     FROM job_history h JOIN jobs j ON j.id = h.job_id \
     WHERE h.at >= $1 AND (h.at > $1 OR h.id > $2) ORDER BY h.at, h.id LIMIT $3";

type Entry = (i64, i64, String, i64, String, Option<String>, String, Option<String>);

/// The replay: where it is, each job's scopes and dispatch time while it matters.
struct Replay {
    fold: Fold,
    at: i64,
    id: i64,
    scopes: HashMap<i64, Arc<[String]>>,
    on: HashMap<i64, i64>,
    entries: u64,
}

impl Replay {
    /// Adds one entry.
    fn entry(&mut self, e: Entry) {
        let (id, job, state, at, kind, device, spec, failure_kind) = e;
        (self.at, self.id, self.entries) = (at, id, self.entries + 1);
        let Some(state) = JobState::parse(&state) else { return };
        let scopes = self
            .scopes
            .entry(job)
            .or_insert_with(|| {
                let spec: Option<JobSpec> = serde_json::from_str(&spec).ok().flatten();
                scopes(device.as_deref(), spec.as_ref()).into()
            })
            .clone();
        let was_on = self.on.contains_key(&job);
        let mut took = None;
        let on = match (was_on, state.on_device()) {
            (false, true) => {
                self.on.insert(job, at);
                1
            }
            (true, true) => {
                if state == JobState::Dispatched {
                    self.on.insert(job, at);
                }
                0
            }
            (true, false) => {
                // Never negative, as in the writer (a clock stepped back while it ran).
                took = self.on.remove(&job).map(|since| (at - since).max(0));
                -1
            }
            (false, false) => 0,
        };
        let end = match state {
            JobState::Completed => Some(End::Completed(took)),
            JobState::Failed => Some(End::Failed(failure_kind.unwrap_or_else(|| "unknown".into()))),
            _ => None,
        };
        if state.is_terminal() {
            self.scopes.remove(&job);
        }
        if on != 0 || end.is_some() {
            self.fold.add(&Move { at, kind, scopes: scopes.to_vec(), on, end });
        }
    }
}

/// Reads the next page into the replay; the entries read.
async fn page(tx: &mut Tx, replay: &mut Replay) -> Result<usize, sqlx::Error> {
    let rows: Vec<Entry> = on!(Tx, tx, t => sqlx::query_as(ENTRIES)
        .bind(replay.at)
        .bind(replay.id)
        .bind(PAGE)
        .fetch_all(&mut **t)
        .await)?;
    let n = rows.len();
    for e in rows {
        replay.entry(e);
    }
    Ok(n)
}

/// Rebuilds the rollups from the history (see the module doc), telling `progress` the
/// entries replayed so far and the time reached after each page.
pub async fn rebuild(pool: &Pool, progress: impl Fn(u64, i64)) -> Result<Rebuilt, RebuildError> {
    let mut tx = pool.write_tx().await?;
    let now = now_ms();
    if let Some(at) = write::mark(&mut Db::from(&mut tx), REBUILDING).await?
        && now - at < STALE_MS
    {
        return Err(RebuildError::Running((now - at) / 1000));
    }
    write::set_mark(&mut Db::from(&mut tx), REBUILDING, now).await?;
    on!(Tx, &mut tx, t => sqlx::query("DELETE FROM rollups_rebuild").execute(&mut **t).await.map(drop))?;
    let clip = write::mark(&mut Db::from(&mut tx), HISTORY_FROM).await?.unwrap_or(i64::MIN);
    on!(Tx, tx, t => t.commit().await)?;

    let fold = Fold { clip, minutes_from: clip, ..Fold::default() };
    let mut replay =
        Replay { fold, at: i64::MIN, id: i64::MIN, scopes: HashMap::new(), on: HashMap::new(), entries: 0 };
    loop {
        let mut tx = pool.write_tx().await?;
        let n = page(&mut tx, &mut replay).await?;
        write::merge(&mut Db::from(&mut tx), "rollups_rebuild", &std::mem::take(&mut replay.fold.rows))
            .await?;
        write::set_mark(&mut Db::from(&mut tx), REBUILDING, now_ms()).await?;
        on!(Tx, tx, t => t.commit().await)?;
        progress(replay.entries, replay.at);
        if (n as i64) < PAGE {
            break;
        }
    }

    // The rest, and the swap, in one transaction the writer waits for.
    let swap = std::time::Instant::now();
    let mut tx = pool.write_tx().await?;
    write::lock(&mut Db::from(&mut tx)).await?;
    while page(&mut tx, &mut replay).await? as i64 == PAGE {}
    write::merge(&mut Db::from(&mut tx), "rollups_rebuild", &std::mem::take(&mut replay.fold.rows)).await?;
    let rows: i64 = on!(Tx, &mut tx, t => sqlx::query_scalar("SELECT COUNT(*) FROM rollups_rebuild").fetch_one(&mut **t).await)?;
    for sql in [
        "DELETE FROM rollups WHERE bucket >= $1",
        // The part after the cut of the week the cut falls in: that week is summed below.
        "DELETE FROM rollups_rebuild WHERE bucket < $1",
        "INSERT INTO rollups (grain, bucket, scope, figures) SELECT grain, bucket, scope, figures FROM rollups_rebuild",
        "DELETE FROM rollups_rebuild",
        "DELETE FROM rollup_busy",
        "DELETE FROM rollup_marks WHERE name = 'rebuilding'",
    ] {
        on!(Tx, &mut tx, t => {
            let q = sqlx::query(sql);
            let q = if sql.contains("$1") { q.bind(clip) } else { q };
            q.execute(&mut **t).await.map(drop)
        })?;
    }
    if clip > i64::MIN && floor(clip, WEEK) < clip {
        week_of_days(&mut tx, floor(clip, WEEK)).await?;
    }
    let busy = replay.fold.busy.into_iter().filter(|(_, b)| b.active > 0).collect();
    write::write_busy(&mut Db::from(&mut tx), &busy).await?;
    write::set_mark(&mut Db::from(&mut tx), BUILT, now_ms()).await?;
    on!(Tx, tx, t => t.commit().await)?;
    if replay.fold.strays > 0 {
        tracing::warn!(strays = replay.fold.strays, "rollups rebuilt: jobs left a device no job was on");
    }
    Ok(Rebuilt { entries: replay.entries, rows: rows as u64, swap: swap.elapsed() })
}

/// Puts the rows of the week starting at `week` together again from its days' rows: the
/// week the mark `history_from` falls in, its days before the mark kept, those after
/// rebuilt.
async fn week_of_days(tx: &mut Tx, week: i64) -> Result<(), sqlx::Error> {
    let sql = "SELECT scope, figures FROM rollups WHERE grain = $1 AND bucket >= $2 AND bucket < $3";
    let days: Vec<(String, String)> = on!(Tx, tx, t => sqlx::query_as(sql)
        .bind(DAY)
        .bind(week)
        .bind(week + WEEK)
        .fetch_all(&mut **t)
        .await)?;
    let mut rows: BTreeMap<super::Key, Tally> = BTreeMap::new();
    for (scope, figures) in days {
        if let Ok(t) = serde_json::from_str::<Tally>(&figures) {
            rows.entry((WEEK, week, scope)).or_default().merge(&t);
        }
    }
    let sql = "DELETE FROM rollups WHERE grain = $1 AND bucket = $2";
    on!(Tx, tx, t => sqlx::query(sql).bind(WEEK).bind(week).execute(&mut **t).await.map(drop))?;
    write::merge(&mut Db::from(&mut *tx), "rollups", &rows).await?;
    Ok(())
}

/// Fills the rollups from the history once, at the first start after the upgrade that
/// brought them (the mark `built` absent); tells the logs how far it is on a large store.
pub async fn fill_once(pool: &Pool) -> Result<(), sqlx::Error> {
    let built: Option<i64> = on!(Pool, pool, p => sqlx::query_scalar("SELECT at FROM rollup_marks WHERE name = 'built'")
        .fetch_optional(p)
        .await)?;
    if built.is_some() {
        return Ok(());
    }
    let started = std::time::Instant::now();
    let done = match rebuild(pool, |entries, _| {
        if entries % (50 * PAGE as u64) == 0 {
            tracing::info!(entries, "filling the rollups from the job history");
        }
    })
    .await
    {
        // Another node of the cluster fills them.
        Err(RebuildError::Running(age)) => {
            tracing::warn!(
                age_s = age,
                "another node is filling the rollups; KPIs are partial until it is done"
            );
            return Ok(());
        }
        Err(RebuildError::Database(e)) => return Err(e),
        Ok(done) => done,
    };
    if done.entries > 0 {
        tracing::info!(
            entries = done.entries,
            rows = done.rows,
            took_ms = started.elapsed().as_millis() as u64,
            "rollups filled from the job history"
        );
    }
    Ok(())
}
