//! Alarms: business alarms cancel and fail the job with their code, hardware alarms block
//! the crane until cleared, and forced completion ends the job `forced`.

use rackd::protocols::mc3e::TransportKind;
use rackd::store::Engine;
use rackd::wire::alarms::{self, business_codes};
use rackd::wire::task_id_for;
use serde_json::json;

use super::*;
use crate::support;

fn store_job() -> serde_json::Value {
    json!({"kind": "store", "barcode": "PAL", "to": cloc(1, 4, 2, 1)})
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_business_alarm_cancels_the_task_and_fails_the_job_with_its_code() {
    let (app, sim) = crane_app(TransportKind::Udp, 25, |_| {}).await;
    for code in business_codes() {
        let id = submit(&app, store_job(), &format!("alarm-{code}")).await;
        wait_job(&app, id, &["running"], 5).await;
        let cancels = sim.cancels();
        sim.raise_alarm(code);
        let job = wait_job(&app, id, &["failed", "completed", "cancelled"], 5).await;
        assert_eq!(job["state"], "failed", "{job}");
        assert_eq!(job["failure"]["kind"], "alarm", "{job}");
        assert_eq!(job["failure"]["code"], code, "{job}");
        assert_eq!(job["failure"]["text"], alarms::lookup(code).text, "{job}");
        assert_eq!(sim.cancels(), cancels + 1, "one cancel for alarm {code}");
        assert_eq!(sim.word(205), 0, "the crane cleared alarm {code}");
        let states: Vec<String> = history(&app, id).await.into_iter().map(|(s, _)| s).collect();
        assert!(states.contains(&"cancelling".to_owned()), "{states:?}");
        // The store cannot be trusted there: the location locked itself until a person
        // checks it.
        let (_, all) = app.get("/api/v1/locations?aisle=2").await;
        let lock = all
            .as_array()
            .unwrap()
            .iter()
            .find(|l| l["row"] == 1 && l["bay"] == 4 && l["level"] == 2 && l["position"] == 1)
            .unwrap()["lock"]
            .clone();
        assert_eq!((lock["by"].clone(), lock["job"].clone()), (json!("rackd"), json!(id)), "{lock}");
        let (status, place) =
            app.post("/api/v1/locations/2/1/4/2/1/unlock", &json!({"reason": "checked"})).await;
        assert_eq!(status, 200, "{place}");
        let audit = app.get("/api/v1/audit?limit=1").await.1;
        assert_eq!(audit["entries"][0]["target"], "location:2/1/4/2/1", "{audit}");
    }
    // The crane is clean again: the next job completes.
    let id = submit(&app, store_job(), "after-alarms").await;
    let job = wait_job(&app, id, &["completed", "failed", "cancelled"], 5).await;
    assert_eq!(job["state"], "completed", "{job}");
    assert_eq!(sim.refused(), 0);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_hardware_alarm_blocks_the_crane_until_it_clears() {
    let (app, sim) = crane_app(TransportKind::Tcp, 20, |_| {}).await;
    wait_device(&app, "online", 5, |s| s["online"] == true).await;
    sim.raise_alarm(7002);
    let status = wait_device(&app, "showing the alarm", 5, |s| s["crane"]["alarm_code"] == 7002).await;
    assert_eq!(status["crane"]["alarm_class"], "hardware", "{status}");
    assert_eq!(status["crane"]["alarm_text"], alarms::lookup(7002).text, "{status}");
    let id = submit(&app, store_job(), "blocked").await;
    support::wait_for_more("polls under the alarm", POLLS, 5, || sim.requests_seen()).await;
    let (_, job) = app.get(&format!("/api/v1/jobs/{id}")).await;
    assert_eq!(job["state"], "queued", "no new work under a hardware alarm: {job}");
    assert_eq!(sim.received(task_id_for(id)), 0);
    sim.clear_alarm();
    let job = wait_job(&app, id, &["completed", "failed", "cancelled"], 5).await;
    assert_eq!(job["state"], "completed", "{job}");

    // Mid-task: the task halts, the job waits (not failed), then finishes after the reset.
    let id = submit(&app, store_job(), "halted").await;
    wait_job(&app, id, &["running"], 5).await;
    sim.raise_alarm(7011);
    let halted = sim.action();
    wait_device(&app, "showing the alarm", 5, |s| s["crane"]["alarm_code"] == 7011).await;
    // rackd sees the alarm and keeps polling; 10 more requests (>= 5 polls of 20 ms) span
    // several 20 ms steps in which the crane would have moved on.
    support::wait_for_more("polls under the alarm", POLLS, 5, || sim.requests_seen()).await;
    let (_, job) = app.get(&format!("/api/v1/jobs/{id}")).await;
    assert_eq!(job["state"], "running", "a hardware alarm fails nothing by itself: {job}");
    assert_eq!(sim.action(), halted, "the crane stands still");
    assert_eq!(sim.cancels(), 0, "no cancel for a hardware alarm");
    sim.clear_alarm();
    let job = wait_job(&app, id, &["completed", "failed", "cancelled"], 5).await;
    assert_eq!(job["state"], "completed", "{job}");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn forced_completion_completes_the_job_as_forced() {
    let (app, sim) = crane_app(TransportKind::Tcp, 30, |_| {}).await;
    let id = submit(&app, store_job(), "forced").await;
    wait_job(&app, id, &["running"], 5).await;
    sim.raise_alarm(7013);
    wait_device(&app, "showing the alarm", 5, |s| s["crane"]["alarm_code"] == 7013).await;
    assert!(sim.force_complete(), "a task was under way");
    let job = wait_job(&app, id, &["completed", "failed", "cancelled"], 5).await;
    assert_eq!(job["state"], "completed", "{job}");
    assert_eq!(job["forced"], true, "{job}");
    // Acknowledged: the crane drops its task and takes the next one.
    let next = submit(&app, store_job(), "after-forced").await;
    let job = wait_job(&app, next, &["completed", "failed", "cancelled"], 5).await;
    assert_eq!((job["state"].as_str(), job["forced"].as_bool()), (Some("completed"), Some(false)), "{job}");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn without_auto_cancel_a_business_alarm_waits_for_an_operator() {
    let (app, sim) = crane_app(TransportKind::Tcp, 30, |d| d.auto_cancel = false).await;
    let id = submit(&app, store_job(), "manual").await;
    wait_job(&app, id, &["running"], 5).await;
    sim.raise_alarm(7094);
    wait_device(&app, "showing the alarm", 5, |s| s["crane"]["alarm_class"] == "business").await;
    support::wait_for_more("polls under the alarm", POLLS, 5, || sim.requests_seen()).await;
    assert_eq!(sim.cancels(), 0);
    let (status, job) = app.post(&format!("/api/v1/jobs/{id}/cancel"), &json!({})).await;
    assert_eq!(status, 200, "{job}");
    let job = wait_job(&app, id, &["completed", "failed", "cancelled"], 5).await;
    assert_eq!(job["state"], "cancelled", "{job}");
    assert_eq!(sim.word(205), 0);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_crane_refuses_a_store_behind_a_load_with_7092_and_rackd_fails_the_job() {
    // The motion model at 1000 simulated seconds per second, the crane's own inventory
    // holding a load near in row 1, bay 4, level 2, which rackd does not know about.
    let options = CraneSimOptions {
        transport: TransportKind::Tcp,
        motion: Some(rackd::wire::motion::Motion::default()),
        time_scale: 1000.0,
        inventory: Some(vec![[1, 4, 2, 1]]),
        ..Default::default()
    };
    let sim = CraneSim::start("127.0.0.1:0", options).await.unwrap();
    let device = device_for(&sim, TransportKind::Tcp, |_| {});
    let app = support::spawn_with(Engine::Sqlite, |c| with_crane(c, device)).await;
    let id = submit(&app, json!({"kind": "store", "barcode": "FAR", "to": cloc(1, 4, 2, 2)}), "far").await;
    let job = wait_job(&app, id, &["failed", "completed", "cancelled"], 5).await;
    assert_eq!(
        (job["state"].clone(), job["failure"]["code"].clone()),
        (json!("failed"), json!(7092)),
        "{job}"
    );
    assert_eq!(sim.inventory(), Some(vec![[1, 4, 2, 1]]), "nothing stored; the station's load went back");
    // A possible store completes, ends in the crane's inventory, and the crane stands there.
    let id = submit(&app, json!({"kind": "store", "barcode": "OK", "to": cloc(1, 6, 3, 2)}), "ok").await;
    let job = wait_job(&app, id, &["failed", "completed", "cancelled"], 5).await;
    assert_eq!(job["state"], "completed", "{job}");
    assert_eq!(sim.inventory(), Some(vec![[1, 4, 2, 1], [1, 6, 3, 2]]));
    assert_eq!((sim.word(220), sim.word(221)), (840, 450), "6 x 1.4 m, 3 x 1.5 m in cm");
    let stats = sim.stats();
    assert_eq!((stats.cycles, stats.cancelled, stats.alarms.clone()), (1, 1, [(7092, 1)].into()), "{stats}");
    assert_eq!(sim.violations(), 0, "{:?}", sim.violation_log());
    assert_eq!(sim.refused(), 0);
    app.stop().await;
}
