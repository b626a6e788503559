//! Every crane job kind through the handshake, over TCP and over UDP.

use std::time::Duration;

use rackd::protocols::mc3e::TransportKind;
use rackd::wire::task_id_for;
use serde_json::json;

use super::*;
use crate::support::eventually_every;

async fn every_kind(transport: TransportKind) {
    // 20 ms a step: a transfer (16 steps) outlasts a poll (20 ms) many times over, so it is
    // seen running even when the tests around it load the machine.
    let (app, sim) = crane_app(transport, 20, |_| {}).await;
    let jobs = [
        (json!({"kind": "store", "barcode": "PAL-1", "to": cloc(1, 5, 3, 2)}), [1, 5, 3, 2], 2),
        (json!({"kind": "retrieve", "from": cloc(2, 20, 8, 1)}), [1, 0, 1, 1], 2),
        (json!({"kind": "move", "from": cloc(1, 1, 1, 1), "to": cloc(2, 2, 2, 2)}), [2, 2, 2, 2], 2),
        (json!({"kind": "travel", "to": cloc(1, 7, 4, 1)}), [1, 7, 4, 1], 1),
    ];
    for (k, (body, to, mode)) in jobs.into_iter().enumerate() {
        let id = submit(&app, body.clone(), &format!("{transport:?}-{k}")).await;
        let done = wait_job(&app, id, &["completed", "failed", "cancelled"], 10).await;
        assert_eq!(done["state"], "completed", "{body} -> {done}");
        assert_eq!(done["forced"], false, "{done}");
        assert_eq!(sim.received(task_id_for(id)), 1, "job {id} handed over once");
        let h = history(&app, id).await;
        let states: Vec<&str> = h.iter().map(|(s, _)| s.as_str()).collect();
        // A 2-step travel may finish between two polls; a transfer is always seen running.
        assert!(states.contains(&"dispatched") && (mode == 1 || states.contains(&"running")), "{h:?}");
        let handed = h.iter().find(|(s, _)| s == "dispatched").unwrap();
        assert!(handed.1.contains(&format!("mode {mode}")), "{h:?}");
        // The crane ends at the destination, so its axes show the target bay and level.
        assert_eq!(sim.word(220), to[1] * 1000, "travel axis after {body}");
        assert_eq!(sim.word(221), to[2] * 500, "lift axis after {body}");
    }
    let status = wait_device(&app, "idle", 5, |s| s["crane"]["action_state"] == 0).await;
    assert_eq!(status["online"], true, "{status}");
    assert_eq!(status["crane"]["heartbeat_ok"], true, "{status}");
    assert_eq!(sim.refused(), 0);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_job_kind_completes_over_tcp() {
    every_kind(TransportKind::Tcp).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_job_kind_completes_over_udp() {
    every_kind(TransportKind::Udp).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tasks_carry_the_mapped_coordinates_and_run_one_at_a_time() {
    // Stations come from the configuration.
    let (app, sim) = crane_app(TransportKind::Tcp, 40, |d| d.outbound_station = [1, 0, 2, 2].into()).await;
    // The second job is posted once the first is the crane's: posted together, the
    // planner would order them for travel (the link's first request waits a timeout, so a
    // job posted at start is not taken at once).
    let a = submit(&app, json!({"kind": "retrieve", "from": cloc(2, 9, 6, 2)}), "one").await;
    wait_job(&app, a, &["dispatched", "running"], 5).await;
    let b = submit(&app, json!({"kind": "store", "barcode": "P", "to": cloc(1, 3, 2, 1)}), "two").await;
    wait_job(&app, a, &["running"], 5).await;
    // The crane shows the retrieve's words: from the rack to the outbound station.
    let words: Vec<u16> = (208..218).map(|n| sim.word(n)).collect();
    assert_eq!(words, vec![task_id_for(a), 2, 2, 9, 6, 2, 1, 0, 2, 2]);
    let (_, second) = app.get(&format!("/api/v1/jobs/{b}")).await;
    assert_eq!(second["state"], "queued", "one task at a time: {second}");
    let status = wait_device(&app, "running", 5, |s| s["crane"]["task"] == task_id_for(a)).await;
    assert!(status["crane"]["action"].as_str().is_some(), "{status}");
    wait_job(&app, b, &["completed"], 10).await;
    wait_job(&app, a, &["completed"], 1).await;
    assert_eq!(sim.refused(), 0);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dropped_link_mid_task_is_survived_and_nothing_is_sent_twice() {
    let (app, sim) = crane_app(TransportKind::Tcp, 30, |d| d.ack = rackd::config::devices::Ack::Echo).await;
    let id =
        submit(&app, json!({"kind": "move", "from": cloc(1, 3, 3, 1), "to": cloc(1, 4, 4, 2)}), "drop").await;
    wait_job(&app, id, &["running"], 5).await;
    sim.drop_link();
    sim.set_link(false);
    let status = wait_device(&app, "offline", 5, |s| s["online"] == false).await;
    assert!(status["last_error"].as_str().is_some(), "{status}");
    sim.set_link(true);
    let job = wait_job(&app, id, &["completed", "failed", "cancelled"], 10).await;
    assert_eq!(job["state"], "completed", "{job}");
    assert_eq!(sim.received(task_id_for(id)), 1);
    // The echo reading acknowledged it: the crane dropped the task.
    wait_device(&app, "idle", 5, |s| s["crane"]["task"] == 0 && s["online"] == true).await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_hand_over_the_crane_never_acknowledges_times_out_and_the_job_waits() {
    let (app, sim) = crane_app(TransportKind::Udp, 10, |d| d.handshake_timeout_ms = 200).await;
    sim.set_handshake(false);
    let id = submit(&app, json!({"kind": "travel", "to": cloc(2, 5, 5, 1)}), "deaf").await;
    let status = wait_device(&app, "reporting the timeout", 5, |s| {
        s["last_error"].as_str().is_some_and(|e| e.contains("step 2"))
    })
    .await;
    assert_eq!(status["online"], true, "{status}");
    let (_, job) = app.get(&format!("/api/v1/jobs/{id}")).await;
    assert_eq!(job["state"], "queued", "{job}");
    // Paused, rackd stops retrying. The hand-over under way when the pause lands may still
    // raise the strobe once (it read its job before the pause); it is withdrawn within the
    // 200 ms hand-over timeout, and no further hand-over starts over 40 requests (at least
    // 20 polls of 20 ms, two hand-over timeouts and more).
    let (status, _) = app.post("/api/v1/devices/crane1/pause", &json!({})).await;
    assert_eq!(status, 200);
    let (from, mut rises, mut last) = (sim.requests_seen(), 0, sim.word(21));
    let what = "the strobe withdrawn and rackd polling on";
    eventually_every(Duration::from_millis(1), what, Duration::from_secs(5), async || {
        let strobe = sim.word(21);
        rises += u32::from(last == 0 && strobe == 1);
        last = strobe;
        assert!(rises <= 1, "a new hand-over started while paused");
        let polled = sim.requests_seen() - from;
        if polled >= 4 * POLLS && strobe == 0 {
            Ok(())
        } else {
            Err(format!("strobe {strobe}, {polled} requests"))
        }
    })
    .await;
    assert_eq!(sim.word(21), 0, "the strobe was withdrawn");
    sim.set_handshake(true);
    let (status, _) = app.post("/api/v1/devices/crane1/resume", &json!({})).await;
    assert_eq!(status, 200);
    let job = wait_job(&app, id, &["completed", "failed", "cancelled"], 5).await;
    assert_eq!(job["state"], "completed", "{job}");
    assert_eq!(sim.received(task_id_for(id)), 1);
    app.stop().await;
}
