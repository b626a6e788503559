//! Datagram loss, PLC failures of both kinds, and a PLC that stops answering.

use std::time::Duration;

use rackd::protocols::faults::Faults;
use rackd::sim::shelf::ShelfSimOptions;
use serde_json::json;

use super::workload::{Model, mixed_jobs, rackd_store, submit};
use super::{shelf_app, sim};
use crate::support::*;

async fn online(app: &TestApp) -> bool {
    app.get("/api/v1/devices/shelf1").await.1["online"].as_bool().unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_twenty_percent_loss_every_job_completes_exactly_once() {
    let mut options = sim(0);
    options.faults = Faults { drop_rate: 0.2, ..Faults::default() };
    let (app, sim) = shelf_app(options, |d| {
        d.link.timeout = Duration::from_millis(40);
        d.link.retries = 8;
        d.offline_after = 20;
    })
    .await;
    let mut model = Model::default();
    let jobs = mixed_jobs(200, 11, &mut model);
    submit(&app, &jobs).await;
    let done = wait_ended(&app, 200, 180).await;
    super::assert_each_completed_once(&app, &sim, &done).await;
    assert_eq!(rackd_store(&app).await.0, sim.inventory());
    assert_eq!(sim.violations(), 0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn plc_faults_and_rejections_fail_jobs_with_the_reason() {
    let options = ShelfSimOptions { fail_rate: 1.0, ..sim(0) };
    let (app, _sim) = shelf_app(options, |_| {}).await;
    let (_, job) = app.post("/api/v1/jobs", &store("FAULT")).await;
    let done = wait_ended(&app, 1, 30).await;
    assert_eq!(done[0]["id"], job["id"]);
    assert_eq!(done[0]["state"], "failed");
    assert_eq!(done[0]["failure"]["kind"], "device_fault");
    assert_eq!(done[0]["failure"]["code"], 1);

    let (app, sim) = shelf_app(sim(0), |_| {}).await;
    let empty = loc(2, 9, 6, 4);
    let (_, job) = app.post("/api/v1/jobs", &json!({"kind": "retrieve", "from": empty})).await;
    let done = wait_ended(&app, 1, 30).await;
    assert_eq!(done[0]["id"], job["id"]);
    assert_eq!(done[0]["state"], "failed");
    assert_eq!(done[0]["failure"]["kind"], "rejected");
    assert_eq!(done[0]["failure"]["code"], 2);
    assert!(done[0]["failure"]["text"].as_str().unwrap().contains("check the location"));
    // Store into a place the PLC knows is full (a box put there by hand).
    let full = rackd::domain::Location { aisle: 1, row: 1, bay: 1, level: 1, position: 1 };
    sim.place(full, "BY-HAND");
    app.post("/api/v1/jobs", &json!({"kind": "store", "to": loc(1, 1, 1, 1)})).await;
    let done = wait_ended(&app, 2, 30).await;
    assert_eq!(done[1]["failure"]["code"], 2, "{}", done[1]);
    assert_eq!(sim.violations(), 0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_silent_plc_goes_offline_and_comes_back_by_itself() {
    let (app, sim) = shelf_app(sim(0), |d| {
        d.link.timeout = Duration::from_millis(20);
        d.link.retries = 0;
        d.offline_after = 3;
    })
    .await;
    eventually("the shelf to come online", Duration::from_secs(10), async || online(&app).await).await;
    sim.set_faults(Faults { drop_rate: 1.0, ..Faults::default() });
    eventually("the shelf to go offline", Duration::from_secs(10), async || !online(&app).await).await;
    let (_, device) = app.get("/api/v1/devices/shelf1").await;
    assert!(device["consecutive_failures"].as_u64().unwrap() >= 3);
    assert!(device["last_error"].as_str().unwrap().contains("no reply"), "{device}");
    // No new work while offline.
    let (_, job) = app.post("/api/v1/jobs", &store("WAITS")).await;
    // One unanswered request per poll (no retries), each poll followed by a dispatch attempt.
    let faults = sim.faults();
    wait_for_more("polls of the silent shelf", 5, 5, || faults.requests_seen()).await;
    assert_eq!(app.get(&format!("/api/v1/jobs/{}", job["id"])).await.1["state"], "queued");
    sim.set_faults(Faults::default());
    let done = wait_ended(&app, 1, 30).await;
    assert_eq!(done[0]["state"], "completed");
    assert!(online(&app).await);
}
