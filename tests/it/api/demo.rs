//! The demo site with its simulators, for the API tests that need machines: the shelf PLC
//! `shelf1` on aisle 1, the crane `crane1` on aisle 2 and the light tower `tower1`.

use std::time::Duration;

use rackd::cli::demo::{self, Pace};
use rackd::config::Config;
use rackd::sim::crane::CraneSim;
use rackd::sim::shelf::ShelfSim;
use rackd::sim::tower::TowerSim;
use rackd::store::Engine;
use serde_json::{Value, json};

use crate::support::{self, TestApp, eventually};

/// Fast: a shelf task takes 200 ms, a crane transfer 16 x 40 ms.
pub const FAST: Pace = Pace { task_time: Duration::from_millis(200), crane_step: Duration::from_millis(40) };

/// A slow crane (16 x 500 ms a transfer): a job stays on it long enough to look at the
/// jobs behind it.
pub const SLOW_CRANE: Pace =
    Pace { task_time: Duration::from_millis(200), crane_step: Duration::from_millis(500) };

/// The demo site's simulators; kept as long as the server.
pub struct Sims {
    /// The crane (tests raise alarms on it).
    pub crane: CraneSim,
    _shelf: ShelfSim,
    _tower: TowerSim,
}

/// The demo site at `pace`, with the config changed by `edit`.
pub async fn demo_app(engine: Engine, pace: Pace, edit: impl FnOnce(&mut Config)) -> (TestApp, Sims) {
    let mut site = Config::demo();
    let (shelf, crane, tower) = demo::start_with(&mut site, pace).await.expect("demo simulators start");
    let app = support::spawn_with(engine, |c| {
        c.site = site.site.clone();
        c.devices = site.devices.clone();
        edit(c);
    })
    .await;
    (app, Sims { crane, _shelf: shelf, _tower: tower })
}

/// A location of aisle 2 (the crane's).
pub fn cloc(row: u16, bay: u16, level: u16, position: u16) -> Value {
    json!({"aisle": 2, "row": row, "bay": bay, "level": level, "position": position})
}

/// Submits a job, answering its id.
pub async fn submit(app: &TestApp, job: Value) -> i64 {
    let (status, body) = app.post("/api/v1/jobs", &job).await;
    assert_eq!(status, 201, "{body}");
    body["id"].as_i64().unwrap()
}

/// Waits (bounded) until job `id` passes `done`, answering it.
pub async fn wait_job(app: &TestApp, id: i64, secs: u64, done: impl Fn(&Value) -> bool) -> Value {
    eventually(format!("job {id} to get there"), Duration::from_secs(secs), async || {
        let (status, job) = app.get(&format!("/api/v1/jobs/{id}")).await;
        assert_eq!(status, 200, "{job}");
        if done(&job) { Ok(job) } else { Err(job) }
    })
    .await
}

/// Waits until job `id` waits for `reason`, answering it.
pub async fn wait_reason(app: &TestApp, id: i64, reason: &str) -> Value {
    wait_job(app, id, 10, |j| j["waiting"]["reason"] == reason).await
}

/// The ids of `GET /api/v1/jobs?waiting=...`.
pub async fn waiting_ids(app: &TestApp, filter: &str) -> Vec<i64> {
    let (status, page) = app.get(&format!("/api/v1/jobs?waiting={filter}")).await;
    assert_eq!(status, 200, "{page}");
    page["jobs"].as_array().unwrap().iter().map(|j| j["id"].as_i64().unwrap()).collect()
}
