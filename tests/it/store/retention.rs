//! `[retention]` on a running rackd, both engines: the node that drives the machines moves
//! jobs that ended more than `jobs_days` ago to the archive and keeps the rest; a folder
//! that stops taking files raises the `archive` alarm and deletes nothing, and the alarm
//! clears once it works again; a folder that cannot take files stops the start.

use std::time::Duration;

use rackd::app::Application;
use rackd::domain::JobState;
use rackd::domain::time::{from_ms, now_ms};
use rackd::store::import::{self, Ended};
use rackd::store::{self, Engine};
use rstest::rstest;

use super::light;
use crate::support::{eventually, fresh_database, spawn_on, use_database};

const DAY: i64 = 86_400_000;

/// Job `id`, ended `days` days ago.
fn ended(id: i64, days: i64) -> Ended {
    let new = light(&format!("K-{id}"), 1);
    let end = now_ms() - days * DAY;
    let mut job = new.accepted(id, end - 1_000);
    job.device = Some("shelf1".into());
    job.state = JobState::Completed;
    job.updated_at = from_ms(end);
    let history =
        vec![(JobState::Queued, "accepted".into(), end - 1_000), (JobState::Completed, "done".into(), end)];
    Ended { request: new.canonical(), job, history }
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn jobs_past_the_retention_move_to_the_archive_and_a_broken_folder_raises_an_alarm(
    #[case] engine: Engine,
) {
    let (db, _keep) = fresh_database(engine).await;
    let pool = store::open(&db, Duration::from_secs(5)).await.unwrap();
    let jobs: Vec<Ended> =
        [(1, 100), (2, 100), (3, 95), (4, 10), (5, 1)].map(|(id, days)| ended(id, days)).into();
    import::ended_jobs(&pool, &jobs).await.unwrap();
    pool.close().await;

    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("archive");
    let app = spawn_on(db, |c| {
        c.retention.archive_dir = Some(folder.clone());
        c.retention.every = Duration::from_millis(100);
    })
    .await;
    eventually("the jobs past 90 days to leave the store", Duration::from_secs(10), async || {
        let (status, _) = app.get("/api/v1/jobs/3").await;
        status == 404
    })
    .await;
    for (id, status) in [(1, 404), (2, 404), (4, 200), (5, 200)] {
        assert_eq!(app.get(&format!("/api/v1/jobs/{id}")).await.0, status, "job {id}");
    }
    let mut files: Vec<String> = std::fs::read_dir(&folder)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    files.sort();
    assert_eq!(files.len(), 2, "a file for each day, 100 and 95 days ago: {files:?}");
    // `/metrics` counts what the store holds: the writer took the archived jobs off (told
    // once the commit is synced, which may come a moment after a reader sees it).
    let line = "rackd_jobs{device=\"shelf1\",state=\"completed\"} 2";
    eventually("the archived jobs off /metrics", Duration::from_secs(5), async || {
        let metrics = app.client.get(app.url("/metrics")).send().await.unwrap().text().await.unwrap();
        metrics.lines().any(|l| l == line)
    })
    .await;

    // The folder stops taking files: an alarm, nothing deleted; back, the alarm clears.
    std::fs::remove_dir_all(&folder).unwrap();
    std::fs::write(&folder, "not a folder").unwrap();
    let alarm = eventually("the archive alarm", Duration::from_secs(10), async || {
        let (_, page) = app.get("/api/v1/alarms?active=true").await;
        page["alarms"].as_array().unwrap().iter().find(|a| a["kind"] == "archive").cloned()
    })
    .await;
    assert_eq!(
        (alarm["device"].as_str(), alarm["class"].as_str()),
        (Some("store"), Some("hardware")),
        "{alarm}"
    );
    assert!(alarm["text"].as_str().unwrap().contains("could not be archived"), "{alarm}");
    assert_eq!(app.get("/api/v1/jobs/4").await.0, 200);
    std::fs::remove_file(&folder).unwrap();
    eventually("the archive alarm to clear", Duration::from_secs(10), async || {
        let (_, page) = app.get("/api/v1/alarms?active=true").await;
        !page["alarms"].as_array().unwrap().iter().any(|a| a["kind"] == "archive")
    })
    .await;
    app.stop().await;
}

#[tokio::test]
async fn a_folder_that_takes_no_files_stops_the_start_and_a_retention_under_a_day_is_refused() {
    let (db, _keep) = fresh_database(Engine::Sqlite).await;
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("file");
    std::fs::write(&file, "").unwrap();
    let mut config = rackd::config::Config::demo();
    config.server.listen = "127.0.0.1:0".parse().unwrap();
    use_database(&mut config, &db);
    config.retention.archive_dir = Some(file);
    let refused = Application::build(&config, false).await.err().expect("the start is refused");
    assert!(format!("{refused:#}").contains("retention.archive_dir"), "{refused:#}");

    let text = "[retention]\njobs_days = 0\n";
    let err = rackd::config::Config::parse(text, std::path::Path::new("r.toml")).unwrap_err().to_string();
    assert!(err.contains("retention.jobs_days") && err.contains("at least 1"), "{err}");
}
