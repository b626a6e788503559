//! `store::import` (what `bench history` seeds with): ended jobs loaded in bulk read back as
//! jobs the writer had ended, on both engines; a rackd started on the store numbers its next
//! job after them and answers a re-POST of a loaded reference with the loaded job; anything
//! not ended is refused with nothing written.

use rackd::domain::time::to_ms;
use rackd::domain::{JobState, NewJob};
use rackd::store::import::{self, Ended, ImportError};
use rackd::store::{Engine, jobs};
use rstest::rstest;

use super::{light, open};
use crate::support::spawn_on;

/// Job `id`, ended a few seconds ago (within the retention: rackd keeps it).
fn ended(new: &NewJob, id: i64, state: JobState) -> Ended {
    let at = rackd::domain::time::now_ms() - 10_000 + 1_000 * id;
    let mut job = new.accepted(id, at);
    job.device = Some("shelf1".into());
    job.state = state;
    job.updated_at = rackd::domain::time::from_ms(at + 20);
    let history = vec![
        (JobState::Queued, "accepted".into(), at),
        (JobState::Dispatched, "handed to shelf1".into(), at + 10),
        (state, "loaded".into(), at + 20),
    ];
    Ended { request: new.canonical(), job, history }
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ended_jobs_load_in_bulk_and_read_back_as_the_writer_wrote_them(#[case] engine: Engine) {
    let (pool, db, dir) = open(engine).await;
    let news: Vec<NewJob> = (1..=3).map(|i| light(&format!("L-{i}"), i as u16)).collect();
    let batch: Vec<Ended> = news
        .iter()
        .zip([JobState::Completed, JobState::Failed, JobState::Cancelled])
        .enumerate()
        .map(|(i, (new, state))| ended(new, i as i64 + 1, state))
        .collect();

    // A job that has not ended, or whose history ends elsewhere, refuses the whole call.
    let mut queued = batch.clone();
    queued.push(ended(&light("L-9", 9), 9, JobState::Completed));
    queued[3].job.state = JobState::Queued;
    let refused = import::ended_jobs(&pool, &queued).await.unwrap_err();
    assert!(matches!(refused, ImportError::NotEnded { id: 9, state: "queued" }), "{refused}");
    let mut astray = batch.clone();
    astray[0].history.pop();
    assert!(matches!(import::ended_jobs(&pool, &astray).await, Err(ImportError::History(1))));
    assert!(jobs::get(&pool, 1).await.unwrap().is_none(), "nothing written");

    import::ended_jobs(&pool, &batch).await.unwrap();
    // The same ids again: the database's unique key, and nothing more of the call written.
    let again = import::ended_jobs(&pool, &batch).await.unwrap_err();
    assert!(matches!(again, ImportError::Database(_)), "{again}");
    for e in &batch {
        let stored = jobs::get(&pool, e.job.id).await.unwrap().unwrap();
        assert_eq!((stored.state, to_ms(stored.created_at)), (e.job.state, to_ms(e.job.created_at)));
        let history = jobs::history(&pool, e.job.id).await.unwrap();
        let states: Vec<JobState> = history.iter().map(|h| h.state).collect();
        assert_eq!(states, e.history.iter().map(|h| h.0).collect::<Vec<_>>());
    }
    pool.close().await;

    // rackd on the loaded store: the next job is number 4, a loaded reference is known.
    let app = spawn_on(db, |_| {}).await;
    let (status, job) = app.post("/api/v1/jobs", &crate::support::store("after-load")).await;
    assert_eq!((status, job["id"].as_i64()), (201, Some(4)), "{job}");
    let repost = serde_json::json!({"kind": "light", "reference": "L-2",
        "location": {"aisle": 1, "row": 1, "bay": 2, "level": 1, "position": 1}, "color": "green", "on": true});
    let (status, job) = app.post("/api/v1/jobs", &repost).await;
    assert_eq!((status, job["id"].as_i64(), job["state"].as_str()), (200, Some(2), Some("failed")), "{job}");
    app.stop().await;
    drop(dir);
}
