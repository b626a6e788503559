//! `rackd db archive` (src/store/archive.rs) on both engines: ended jobs leave the store for
//! a gzip'd JSON Lines file per day, written before anything is deleted; a job a lock or an
//! unfinished relocation names stays until nothing does; every job is in the store or in
//! the archive, exactly once.

use std::collections::BTreeSet;
use std::io::Read;

use rackd::domain::time::from_ms;
use rackd::domain::{JobState, NewJob};
use rackd::store::archive::{self, ArchiveError, Delete::Direct};
use rackd::store::import::{self, Ended};
use rackd::store::writer::{Hooks, Outcome, Writer};
use rackd::store::{Engine, Pool, locations};
use rstest::rstest;
use time::macros::date;

use super::{light, open, rows};

/// 2026-01-01, midnight UTC, in Unix ms.
const DAY0: i64 = 1_767_225_600_000;
const DAY: i64 = 86_400_000;

/// Job `id`, ended at noon of day `day` after DAY0.
fn ended(id: i64, day: i64) -> Ended {
    let new = light(&format!("A-{id}"), 1);
    let end = DAY0 + day * DAY + DAY / 2;
    let mut job = new.accepted(id, end - 60_000);
    job.state = JobState::Completed;
    job.updated_at = from_ms(end);
    let history =
        vec![(JobState::Queued, "accepted".into(), end - 60_000), (JobState::Completed, "done".into(), end)];
    Ended { request: new.canonical(), job, history }
}

/// The job ids of the archive's files, each file's in order.
fn archived(files: &[std::path::PathBuf]) -> Vec<Vec<i64>> {
    files
        .iter()
        .map(|f| {
            let mut text = String::new();
            flate2::read::GzDecoder::new(std::fs::File::open(f).unwrap()).read_to_string(&mut text).unwrap();
            text.lines()
                .map(|line| {
                    let v: serde_json::Value = serde_json::from_str(line).unwrap();
                    let states: Vec<&str> = v["history"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .map(|h| h["state"].as_str().unwrap())
                        .collect();
                    assert_eq!(states, ["queued", "completed"], "{line}");
                    assert_eq!(v["job"]["state"], "completed", "{line}");
                    v["job"]["id"].as_i64().unwrap()
                })
                .collect()
        })
        .collect()
}

async fn ids(pool: &Pool) -> BTreeSet<i64> {
    rows::<(i64,)>(pool, "SELECT id FROM jobs").await.into_iter().map(|(id,)| id).collect()
}

async fn execute(pool: &Pool, sql: &'static str) {
    match pool {
        Pool::Sqlite(p) => drop(sqlx::query(sql).execute(p).await.unwrap()),
        Pool::Postgres(p) => drop(sqlx::query(sql).execute(p).await.unwrap()),
    }
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ended_jobs_move_to_a_file_per_day_and_named_ones_stay(#[case] engine: Engine) {
    let (pool, _db, _dir) = open(engine).await;
    locations::seed(&pool, &rackd::config::Config::demo().layout(), 1).await.unwrap();
    // Three jobs ended on each of three days.
    let jobs: Vec<Ended> = (1..=9).map(|id| ended(id, (id - 1) / 3)).collect();
    import::ended_jobs(&pool, &jobs).await.unwrap();
    // Job 2 is named by a lock; job 5 by a relocation not yet done.
    execute(
        &pool,
        "UPDATE locations SET lock_job = 2, locked_at = 1, locked_by = 'rackd', lock_reason = 'lost' \
                    WHERE aisle = 1 AND row = 1 AND bay = 2 AND level = 1 AND position = 1",
    )
    .await;
    let (writer, task) = Writer::start(&pool, 64, 64, Hooks::default()).await.unwrap();
    let relocation = NewJob { serves: Some(5), ..light("R-1", 3) };
    let Outcome::Created { job, .. } = &writer.submit(vec![relocation]).await.unwrap()[0] else { panic!() };
    assert_eq!(job.id, 10);
    drop(writer);
    task.await.unwrap();

    // A folder that cannot take files: nothing moves.
    let dir = tempfile::tempdir().unwrap();
    let not_a_folder = dir.path().join("file");
    std::fs::write(&not_a_folder, "").unwrap();
    let refused = archive::archive(&pool, date!(2026 - 01 - 03), &not_a_folder, Direct).await.unwrap_err();
    assert!(matches!(refused, ArchiveError::Folder { .. }), "{refused}");
    assert_eq!(ids(&pool).await.len(), 10, "nothing deleted");

    // Before the third day: the first two days go, but for jobs 2 and 5.
    let to = dir.path().join("archive");
    let done = archive::archive(&pool, date!(2026 - 01 - 03), &to, Direct).await.unwrap();
    let names: Vec<String> =
        done.files.iter().map(|f| f.file_name().unwrap().to_string_lossy().into()).collect();
    assert_eq!(names, ["jobs-2026-01-01.jsonl.gz", "jobs-2026-01-02.jsonl.gz"]);
    assert_eq!((done.jobs, done.kept), (4, 2));
    assert_eq!(archived(&done.files), [vec![1, 3], vec![4, 6]]);
    assert_eq!(ids(&pool).await, BTreeSet::from([2, 5, 7, 8, 9, 10]));
    // The counts `/metrics` starts from moved in the same transaction (9 loaded, 4 gone).
    let sql = "SELECT n FROM job_counts WHERE device = '' AND state = 'completed'";
    assert_eq!(rows::<(i64,)>(&pool, sql).await, [(5,)]);
    let leftovers: Vec<_> = std::fs::read_dir(&to).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(leftovers.len(), 2, "no temporary file left: {leftovers:?}");

    // Again: nothing new. Then the lock is cleared: job 2 goes, to a file of its own.
    let again = archive::archive(&pool, date!(2026 - 01 - 03), &to, Direct).await.unwrap();
    assert_eq!((again.files.len(), again.jobs, again.kept), (0, 0, 2));
    execute(
        &pool,
        "UPDATE locations SET lock_job = NULL, locked_at = NULL, locked_by = NULL, lock_reason = NULL",
    )
    .await;
    let later = archive::archive(&pool, date!(2026 - 01 - 03), &to, Direct).await.unwrap();
    assert_eq!(later.files, [to.join("jobs-2026-01-01.2.jsonl.gz")]);
    assert_eq!(archived(&later.files), [vec![2]]);

    // Every job exactly once, in the store or in the archive.
    let mut files: Vec<_> = std::fs::read_dir(&to).unwrap().map(|e| e.unwrap().path()).collect();
    files.sort();
    let mut all: Vec<i64> = archived(&files).concat();
    all.extend(ids(&pool).await);
    all.sort();
    assert_eq!(all, (1..=10).collect::<Vec<_>>());
}
