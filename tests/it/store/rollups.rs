//! The KPIs' rollups (src/store/rollups) on both engines: filled at the first start after
//! the upgrade, or rebuilt, from a history loaded by another tool, they give the figures
//! the history gives by hand; a year's figures read
//! them; archiving the history keeps them (hour and day rows) and a rebuild after the
//! archive changes nothing.

use std::time::Duration;

use rackd::domain::time::from_ms;
use rackd::domain::{Failure, FailureKind, JobState};
use rackd::store::import::{self, Ended};
use rackd::store::rollups::rebuild::{self, RebuildError};
use rackd::store::rollups::{DAY, HOUR, MINUTE};
use rackd::store::stats::{self, Period};
use rackd::store::{Engine, Pool, archive, locations};
use rstest::rstest;
use time::macros::date;

use super::{light, open, rows};

/// 2026-01-01, midnight UTC, in Unix ms.
const DAY0: i64 = 1_767_225_600_000;

/// Job `id` on the shelf, dispatched at `at` and ended `took` ms later, completed or failed.
fn job(id: i64, at: i64, took: i64, failed: bool) -> Ended {
    let mut new = light(&format!("R-{id}"), 1 + (id % 5) as u16);
    new.device = Some("shelf1".into());
    let mut job = new.accepted(id, at - 1000);
    let end = if failed { JobState::Failed } else { JobState::Completed };
    job.state = end;
    job.updated_at = from_ms(at + took);
    if failed {
        job.failure = Some(Failure { kind: FailureKind::DeviceFault, code: Some(3), text: "drive".into() });
    }
    let history = vec![
        (JobState::Queued, "accepted".into(), at - 1000),
        (JobState::Dispatched, "sent".into(), at),
        (end, "done".into(), at + took),
    ];
    Ended { request: new.canonical(), job, history }
}

/// Four days of jobs: every 7 minutes from DAY0, 40 s to 3 min 20 s each, one in ten failed,
/// and two that overlap each hour's first (the union counts their overlap once).
fn history() -> Vec<Ended> {
    let mut jobs = Vec::new();
    let mut at = DAY0 + 90_000;
    let mut id = 1;
    while at < DAY0 + 4 * DAY {
        jobs.push(job(id, at, 40_000 + (id % 17) * 10_000, id % 10 == 0));
        if (at - DAY0) % HOUR < 7 * MINUTE {
            id += 1;
            jobs.push(job(id, at + 20_000, 30_000, false));
        }
        id += 1;
        at += 7 * MINUTE;
    }
    jobs
}

/// The figures of `[from, to)` worked out by hand from `jobs`: completed, failed, summed
/// duration of the completed, and busy time (the union of the spans clipped).
fn by_hand(jobs: &[Ended], from: i64, to: i64) -> (u64, u64, i64, i64) {
    let (mut completed, mut failed, mut took) = (0, 0, 0);
    let mut spans = Vec::new();
    for e in jobs {
        let (start, end) = (e.history[1].2, e.history[2].2);
        if (from..to).contains(&end) {
            if e.job.state == JobState::Completed {
                completed += 1;
                took += end - start;
            } else {
                failed += 1;
            }
        }
        spans.push((start.max(from), end.min(to)));
    }
    spans.sort_unstable();
    let (mut busy, mut reach) = (0, from);
    for (a, b) in spans {
        let (a, b) = (a.max(reach), b);
        if b > a {
            busy += b - a;
            reach = b;
        }
    }
    (completed, failed, took, busy)
}

/// Checks the figures of a period read up to `to - 1` (its last minute the one before
/// `to`) against those worked out by hand for `[p.from, to)`.
fn check(p: &Period, jobs: &[Ended], to: i64) {
    let (completed, failed, took, busy) = by_hand(jobs, p.from, to);
    let shelf = &p.devices["shelf1"];
    assert_eq!((shelf.completed, shelf.failed), (completed, failed));
    assert_eq!(shelf.failures.get("device_fault").copied().unwrap_or(0), failed);
    let d = &shelf.durations[0];
    assert_eq!((d.kind.as_str(), d.count), ("light", completed));
    assert!((d.mean_s - took as f64 / completed as f64 / 1000.0).abs() < 1e-9, "{d:?}");
    let span = (to - 1 - p.from) as f64;
    assert!(
        (shelf.utilisation * span - busy as f64).abs() < 1.0,
        "{} against {busy}",
        shelf.utilisation * span
    );
    assert_eq!(&p.aisles[&1], shelf, "one shelf, one aisle");
}

async fn rebuilt(pool: &Pool) -> rebuild::Rebuilt {
    rebuild::rebuild(pool, |_, _| {}).await.unwrap()
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn figures_come_from_the_rollups_and_outlive_the_archived_history(#[case] engine: Engine) {
    let (pool, db, _dir) = open(engine).await;
    locations::seed(&pool, &rackd::config::Config::demo().layout(), 1).await.unwrap();
    let jobs = history();
    import::ended_jobs(&pool, &jobs).await.unwrap();
    // Loaded by another tool: nothing in the rollups until they are rebuilt.
    let (from, to) = (DAY0, DAY0 + 4 * DAY);
    assert!(stats::period(&pool, from, to - 1).await.unwrap().devices.is_empty());
    // A store from before the rollups (no mark `built`): the first start fills them.
    let sql = "DELETE FROM rollup_marks WHERE name = 'built'";
    match &pool {
        Pool::Sqlite(p) => drop(sqlx::query(sql).execute(p).await.unwrap()),
        Pool::Postgres(p) => drop(sqlx::query(sql).execute(p).await.unwrap()),
    }
    pool.close().await;
    let pool = rackd::store::open(&db, Duration::from_secs(5)).await.unwrap();
    let whole = stats::period(&pool, from, to - 1).await.unwrap();
    assert_eq!(whole.from, from);
    check(&whole, &jobs, to);
    // Rebuilt on demand: the same.
    let done = rebuilt(&pool).await;
    assert_eq!(done.entries, 3 * jobs.len() as u64);
    assert_eq!(stats::period(&pool, from, to - 1).await.unwrap(), whole);
    // A shift that starts and ends inside hours, and one inside a minute's rows.
    let (a, b) = (DAY0 + DAY + 5 * HOUR + 17 * MINUTE, DAY0 + 2 * DAY + 3 * HOUR + 11 * MINUTE);
    let part = stats::period(&pool, a, b - 1).await.unwrap();
    assert_eq!(part.from, a);
    check(&part, &jobs, b);
    let shelf = &part.devices["shelf1"];
    let exact = {
        let mut t: Vec<i64> = jobs
            .iter()
            .filter(|e| e.job.state == JobState::Completed && (a..b).contains(&e.history[2].2))
            .map(|e| e.history[2].2 - e.history[1].2)
            .collect();
        t.sort_unstable();
        t[((t.len() as f64) * 0.95).ceil() as usize - 1] as f64 / 1000.0
    };
    assert!((shelf.durations[0].p95_s - exact).abs() <= 0.01 * exact + 0.0005, "{shelf:?} against {exact}");

    // Eight days: a whole week's row (DAY0 is a Thursday, as weeks start), then a day's.
    let eight = stats::period(&pool, from, from + 8 * DAY - 1).await.unwrap();
    check(&eight, &jobs, from + 8 * DAY);

    // Archiving the first two days keeps the day and week rows; the finer ones go.
    let dir = tempfile::tempdir().unwrap();
    let cut = DAY0 + 2 * DAY;
    archive::archive(&pool, date!(2026 - 01 - 03), dir.path(), archive::Delete::Direct).await.unwrap();
    let sql = "SELECT COUNT(*) FROM rollups WHERE grain < 86400000 AND bucket < 1767398400000";
    assert_eq!(rows::<(i64,)>(&pool, sql).await, vec![(0,)], "no rows finer than a day before the cut");
    let sql = "SELECT COUNT(*) FROM rollups WHERE grain = 3600000 AND bucket >= 1767398400000";
    assert!(rows::<(i64,)>(&pool, sql).await[0].0 > 0, "hour rows after it");
    assert_eq!(
        stats::period(&pool, from, to - 1).await.unwrap(),
        whole,
        "the same figures without the history"
    );
    // A period starting before the cut starts on its whole day.
    let early = stats::period(&pool, a - DAY, b - 1).await.unwrap();
    assert_eq!(early.from, DAY0);
    check(&early, &jobs, b);
    // A rebuild replays what is left and keeps what is not.
    let again = rebuilt(&pool).await;
    assert!(again.entries < done.entries);
    assert_eq!(stats::period(&pool, from, to - 1).await.unwrap(), whole);
    assert_eq!(
        stats::period(&pool, from, from + 8 * DAY - 1).await.unwrap(),
        eight,
        "the week the cut is in"
    );
    // Jobs loaded after the cut (a restore): a rebuild counts them, in the cut's week too.
    let mut jobs = jobs;
    let late: Vec<Ended> = (0..3).map(|n| job(900_000 + n, cut + DAY + n * HOUR, 50_000, false)).collect();
    import::ended_jobs(&pool, &late).await.unwrap();
    jobs.extend(late);
    rebuilt(&pool).await;
    check(&stats::period(&pool, from, to - 1).await.unwrap(), &jobs, to);
    check(&stats::period(&pool, from, from + 8 * DAY - 1).await.unwrap(), &jobs, from + 8 * DAY);
    assert_eq!(stats::period(&pool, cut + 17 * MINUTE, to).await.unwrap().from, cut + 17 * MINUTE);

    // Opened again (a start): filled once, never again.
    let now = stats::period(&pool, from, to - 1).await.unwrap();
    pool.close().await;
    let pool = rackd::store::open(&db, Duration::from_secs(5)).await.unwrap();
    assert_eq!(stats::period(&pool, from, to - 1).await.unwrap(), now);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn one_rebuild_at_a_time() {
    let (pool, _db, _dir) = open(Engine::Sqlite).await;
    let Pool::Sqlite(p) = &pool else { unreachable!("a SQLite store") };
    let now = rackd::domain::time::now_ms();
    let mark = |at: i64| {
        sqlx::query("INSERT INTO rollup_marks (name, at) VALUES ('rebuilding', $1) ON CONFLICT (name) DO UPDATE SET at = excluded.at")
            .bind(at)
            .execute(p)
    };
    mark(now).await.unwrap();
    let err = rebuild::rebuild(&pool, |_, _| {}).await.unwrap_err();
    assert!(matches!(err, RebuildError::Running(_)), "{err}");
    assert!(err.to_string().contains("another rebuild"), "{err}");
    // A mark left by a rebuild killed midway goes stale: the next may start.
    mark(now - rebuild::STALE_MS - 1).await.unwrap();
    rebuilt(&pool).await;
}
