//! A paused crane stays paused across a graceful restart: its queued job waits until an
//! operator resumes it.

use rackd::protocols::mc3e::TransportKind;
use rackd::wire::task_id_for;
use serde_json::json;

use super::*;
use crate::support::{spawn_on, wait_for_more};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_paused_crane_runs_nothing_after_a_restart_until_resumed() {
    let (app, sim) = crane_app(TransportKind::Tcp, 10, |_| {}).await;
    let device = device_for(&sim, TransportKind::Tcp, |_| {});
    let (status, shown) = app.post("/api/v1/devices/crane1/pause", &json!({"reason": "aisle walk"})).await;
    assert_eq!((status, shown["paused"].clone()), (200, json!(true)), "{shown}");
    let id = submit(&app, json!({"kind": "travel", "to": cloc(1, 7, 2, 1)}), "paused-travel").await;
    let (db, _dir) = app.stop().await;

    let app = spawn_on(db, |c| with_crane(c, device)).await;
    let shown = wait_device(&app, "online", 5, |s| s["online"] == true).await;
    assert_eq!(
        (shown["paused"].clone(), shown["pause"]["reason"].clone()),
        (json!(true), json!("aisle walk"))
    );
    wait_for_more("polls of the paused crane", POLLS, 10, || sim.requests_seen()).await;
    let job = wait_job(&app, id, &["queued", "dispatched", "running", "completed"], 5).await;
    assert_eq!(job["state"], "queued", "{job}");
    assert_eq!(sim.received(task_id_for(id)), 0, "nothing handed over while paused");

    let (status, _) = app.post("/api/v1/devices/crane1/resume", &json!({})).await;
    assert_eq!(status, 200);
    let job = wait_job(&app, id, &["completed", "failed", "cancelled"], 10).await;
    assert_eq!(job["state"], "completed", "{job}");
    assert_eq!(sim.received(task_id_for(id)), 1);
    assert_eq!(sim.refused(), 0);
    app.stop().await;
}
