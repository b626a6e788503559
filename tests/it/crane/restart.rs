//! rackd stopped mid-task and started again on the same database: it reads the crane's
//! registers and carries on without sending the task again.

use std::time::Duration;

use rackd::protocols::mc3e::TransportKind;
use rackd::wire::task_id_for;
use serde_json::json;

use super::*;
use crate::support::eventually;
use crate::support::spawn_on;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_restart_mid_task_follows_the_task_without_sending_it_again() {
    let (app, sim) = crane_app(TransportKind::Tcp, 60, |_| {}).await;
    let device = device_for(&sim, TransportKind::Tcp, |_| {});
    let id =
        submit(&app, json!({"kind": "move", "from": cloc(1, 2, 3, 1), "to": cloc(2, 8, 5, 2)}), "m").await;
    wait_job(&app, id, &["running"], 5).await;
    let (db, _dir) = app.stop().await;
    assert!((1..=18).contains(&sim.action()), "the crane is mid-task: {}", sim.action());
    let app = spawn_on(db, |c| with_crane(c, device)).await;
    let job = wait_job(&app, id, &["completed", "failed", "cancelled"], 10).await;
    assert_eq!(job["state"], "completed", "{job}");
    assert_eq!(sim.received(task_id_for(id)), 1, "the task was sent once");
    let h = history(&app, id).await;
    assert_eq!(h.iter().filter(|(s, _)| s == "completed").count(), 1, "{h:?}");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_completion_while_rackd_is_down_is_recorded_and_acknowledged() {
    let (app, sim) = crane_app(TransportKind::Udp, 15, |_| {}).await;
    let device = device_for(&sim, TransportKind::Udp, |_| {});
    let id = submit(&app, json!({"kind": "store", "barcode": "X", "to": cloc(1, 1, 1, 1)}), "s").await;
    wait_job(&app, id, &["running"], 5).await;
    let (db, _dir) = app.stop().await;
    eventually("the crane to complete", Duration::from_secs(5), async || sim.action() == 20).await;
    assert_eq!(sim.word(223), 20, "waiting for acknowledgement");
    let app = spawn_on(db, |c| with_crane(c, device)).await;
    let job = wait_job(&app, id, &["completed", "failed", "cancelled"], 5).await;
    assert_eq!((job["state"].as_str(), job["forced"].as_bool()), (Some("completed"), Some(false)), "{job}");
    wait_device(&app, "idle after the acknowledgement", 5, |s| s["crane"]["task"] == 0).await;
    assert_eq!(sim.word(223), 0);
    assert_eq!(sim.received(task_id_for(id)), 1);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_hand_over_cut_by_a_crash_is_finished_on_restart_and_followed() {
    let (app, sim) = crane_app(TransportKind::Tcp, 10, |_| {}).await;
    let device = device_for(&sim, TransportKind::Tcp, |_| {});
    let (status, _) = app.post("/api/v1/devices/crane1/pause", &json!({})).await;
    assert_eq!(status, 200);
    let id = submit(&app, json!({"kind": "travel", "to": cloc(2, 6, 2, 1)}), "cut").await;
    let (db, _dir) = app.stop().await;
    // rackd died right after STB := 1 (step 1): the task words and the strobe are up.
    let task = task_id_for(id);
    for (k, w) in [task, 1, 0, 0, 0, 0, 2, 6, 2, 1].into_iter().enumerate() {
        sim.set_word(8 + k as u32, w);
    }
    sim.set_word(21, 1);
    eventually("the crane to take the data", Duration::from_secs(5), async || sim.word(225) == 1).await;
    let app = spawn_on(db, |c| with_crane(c, device)).await;
    let job = wait_job(&app, id, &["completed", "failed", "cancelled"], 5).await;
    assert_eq!(job["state"], "completed", "{job}");
    assert_eq!(sim.received(task), 1, "finished the cut hand-over instead of sending again");
    assert_eq!(sim.word(21), 0);
    let h = history(&app, id).await;
    assert!(h.iter().any(|(_, cause)| cause.contains("the crane holds it")), "{h:?}");
    app.stop().await;
}
