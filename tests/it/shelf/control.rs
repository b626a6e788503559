//! Pause and resume, the cancel rules, and more work than slots.

use std::time::Duration;

use serde_json::json;

use super::{shelf_app, sim};
use crate::support::*;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_paused_device_gets_no_new_work_until_resumed() {
    let (app, sim) = shelf_app(sim(0), |_| {}).await;
    let (status, device) = app.post("/api/v1/devices/shelf1/pause", &json!({})).await;
    assert_eq!((status, device["paused"].clone()), (200, json!(true)));
    let (_, job) = app.post("/api/v1/jobs", &store("PAUSED")).await;
    // The job is with the dispatcher once the POST is answered. Recovery at start reads each
    // slot once; after it an idle shelf is polled with one request, and every poll is
    // followed by a dispatch attempt: at least 5 of them found nothing to do.
    let slots = device["slots_total"].as_u64().unwrap();
    let faults = sim.faults();
    wait_for_more("polls of the paused shelf", slots + 5, 10, || faults.requests_seen()).await;
    assert_eq!(app.get(&format!("/api/v1/jobs/{}", job["id"])).await.1["state"], "queued");
    let (status, device) = app.post("/api/v1/devices/shelf1/resume", &json!({})).await;
    assert_eq!((status, device["paused"].clone()), (200, json!(false)));
    assert_eq!(wait_ended(&app, 1, 30).await[0]["state"], "completed");
    assert_error(&app.post("/api/v1/devices/nope/pause", &json!({})).await, 404, "not_found");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cancel_withdraws_waiting_tasks_and_refuses_running_ones() {
    // One machine, 3 s per task: the first task runs, the second waits in its slot.
    let (app, sim) = shelf_app(sim(3000), |_| {}).await;
    let (_, first) = app.post("/api/v1/jobs", &json!({"kind": "store", "to": loc(1, 1, 1, 1)})).await;
    let (_, second) = app.post("/api/v1/jobs", &json!({"kind": "store", "to": loc(1, 1, 1, 2)})).await;
    eventually("the first job running, the second in its slot", Duration::from_secs(10), async || {
        let (_, j1) = app.get(&format!("/api/v1/jobs/{}", first["id"])).await;
        let (_, j2) = app.get(&format!("/api/v1/jobs/{}", second["id"])).await;
        if j1["state"] == "running" && j2["state"] == "dispatched" {
            Ok(())
        } else {
            Err(format!("{j1} {j2}"))
        }
    })
    .await;
    let got = app.post(&format!("/api/v1/jobs/{}/cancel", first["id"]), &json!({})).await;
    assert_error(&got, 409, "job_on_device");
    assert!(got.1["error"]["message"].as_str().unwrap().contains("running"), "{got:?}");

    let (status, cancelled) = app.post(&format!("/api/v1/jobs/{}/cancel", second["id"]), &json!({})).await;
    assert_eq!((status, cancelled["state"].clone()), (200, json!("cancelled")), "{cancelled}");
    assert_eq!(sim.withdrawals(), 1);

    // A queued job (device paused) is cancelled at once.
    app.post("/api/v1/devices/shelf1/pause", &json!({})).await;
    let (_, third) = app.post("/api/v1/jobs", &json!({"kind": "store", "to": loc(1, 1, 1, 3)})).await;
    let (status, cancelled) = app.post(&format!("/api/v1/jobs/{}/cancel", third["id"]), &json!({})).await;
    assert_eq!((status, cancelled["state"].clone()), (200, json!("cancelled")));

    let done = wait_ended(&app, 3, 30).await;
    assert_eq!(done[0]["state"], "completed");
    assert_eq!(sim.violations(), 0, "a withdraw is not a violation");
    assert_eq!(sim.inventory().len(), 1, "only the first box was stored");
    assert_error(
        &app.post(&format!("/api/v1/jobs/{}/cancel", first["id"]), &json!({})).await,
        409,
        "job_ended",
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn more_jobs_than_slots_wait_in_rackd() {
    let (app, sim) = shelf_app(sim(2), |_| {}).await;
    let jobs: Vec<_> = (0..150)
        .map(|i| json!({"kind": "light", "location": loc(1 + i % 2, 1 + (i / 2) % 10, 1 + (i / 20) % 6, 1 + (i / 120) % 4), "color": "green", "on": true}))
        .collect();
    let (status, _) = app.post("/api/v1/jobs/batch", &json!({"jobs": jobs})).await;
    assert_eq!(status, 201);
    let mut most = 0;
    eventually("150 jobs completed", Duration::from_secs(60), async || {
        let (_, device) = app.get("/api/v1/devices/shelf1").await;
        let in_use = device["slots_in_use"].as_u64().unwrap();
        assert!(in_use <= 60, "{device}");
        most = most.max(in_use);
        let (_, page) = app.get("/api/v1/jobs?state=completed&limit=1000").await;
        let completed = page["jobs"].as_array().unwrap().len();
        if completed == 150 { Ok(()) } else { Err(completed) }
    })
    .await;
    assert_eq!(most, 60, "every slot was used");
    assert_eq!(sim.violations(), 0);
    assert_eq!(sim.lights_on().len(), 150);
}
