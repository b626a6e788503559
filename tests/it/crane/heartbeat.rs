//! Heartbeat loss and return, and cancels through the API.

use std::time::Duration;

use rackd::protocols::mc3e::TransportKind;
use rackd::sim::crane::{CraneSim, CraneSimOptions};
use rackd::store::Engine;
use rackd::wire::task_id_for;
use serde_json::json;

use super::*;
use crate::support;
use crate::support::{eventually, eventually_every};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stalled_heartbeat_takes_the_crane_offline_until_it_moves_again() {
    let (app, sim) = crane_app(TransportKind::Udp, 10, |_| {}).await;
    wait_device(&app, "online", 5, |s| s["online"] == true && s["crane"]["heartbeat_ok"] == true).await;
    // The 4-step scheme runs: both words keep flipping.
    let (mut flips, mut last) = ([0, 0], [sim.word(0), sim.word(200)]);
    eventually_every(
        Duration::from_millis(2),
        "both heartbeat words to flip 3 times",
        Duration::from_secs(5),
        async || {
            for (k, n) in [0, 200].into_iter().enumerate() {
                let w = sim.word(n);
                if w != last[k] {
                    flips[k] += 1;
                    last[k] = w;
                }
            }
            if flips[0] >= 3 && flips[1] >= 3 { Ok(()) } else { Err(format!("{last:?}, {flips:?} flips")) }
        },
    )
    .await;
    sim.set_heartbeat(false);
    let lost = std::time::Instant::now();
    let status = wait_device(&app, "lost", 5, |s| s["crane"]["heartbeat_ok"] == false).await;
    assert_eq!(status["online"], false, "{status}");
    assert!(status["last_error"].as_str().is_some_and(|e| e.contains("heartbeat")), "{status}");
    // Configured loss time 500 ms: not before it, and well within the bounded wait.
    assert!(lost.elapsed() >= Duration::from_millis(300), "declared lost too early: {:?}", lost.elapsed());
    let id = submit(&app, json!({"kind": "travel", "to": cloc(2, 3, 1, 1)}), "hb").await;
    // The job is with the dispatcher once the POST is answered; rackd keeps polling the lost
    // crane and tries to dispatch after every poll: let it do so a few times.
    support::wait_for_more("polls of the lost crane", POLLS, 5, || sim.requests_seen()).await;
    let (_, job) = app.get(&format!("/api/v1/jobs/{id}")).await;
    assert_eq!(job["state"], "queued", "no work for a lost crane: {job}");
    assert_eq!(sim.received(task_id_for(id)), 0);
    sim.set_heartbeat(true);
    wait_device(&app, "back", 5, |s| s["online"] == true && s["crane"]["heartbeat_ok"] == true).await;
    let job = wait_job(&app, id, &["completed", "failed", "cancelled"], 5).await;
    assert_eq!(job["state"], "completed", "{job}");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cancelling_a_running_job_sends_mode_3_and_a_queued_one_cancels_at_once() {
    let (app, sim) = crane_app(TransportKind::Tcp, 40, |_| {}).await;
    let a = submit(&app, json!({"kind": "retrieve", "from": cloc(1, 6, 3, 2)}), "run").await;
    let b = submit(&app, json!({"kind": "retrieve", "from": cloc(1, 7, 3, 2)}), "wait").await;
    wait_job(&app, a, &["running"], 5).await;
    let (status, job) = app.post(&format!("/api/v1/jobs/{b}/cancel"), &json!({})).await;
    assert_eq!((status, job["state"].as_str()), (200, Some("cancelled")), "{job}");
    let (status, job) = app.post(&format!("/api/v1/jobs/{a}/cancel"), &json!({})).await;
    // The job as it stands after the cancel: `cancelling` while the crane carries it out,
    // or already `cancelled` when the crane was quicker than the answer.
    assert_eq!(status, 200, "{job}");
    assert!(["cancelling", "cancelled"].contains(&job["state"].as_str().unwrap_or("")), "{job}");
    let job = wait_job(&app, a, &["completed", "failed", "cancelled"], 5).await;
    assert_eq!(job["state"], "cancelled", "{job}");
    assert_eq!(sim.cancels(), 1);
    assert_eq!(sim.received(task_id_for(b)), 0, "the queued job never reached the crane");
    // The crane homes after the cancel and then takes new work.
    let c = submit(&app, json!({"kind": "travel", "to": cloc(1, 2, 2, 1)}), "next").await;
    let job = wait_job(&app, c, &["completed", "failed", "cancelled"], 5).await;
    assert_eq!(job["state"], "completed", "{job}");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_heartbeat_lost_mid_task_fails_nothing_and_the_task_is_followed_again() {
    let (app, sim) = crane_app(TransportKind::Tcp, 30, |_| {}).await;
    let id = submit(&app, json!({"kind": "retrieve", "from": cloc(2, 11, 7, 1)}), "hb-task").await;
    wait_job(&app, id, &["running"], 5).await;
    sim.set_heartbeat(false);
    wait_device(&app, "lost", 5, |s| s["crane"]["heartbeat_ok"] == false).await;
    let (_, job) = app.get(&format!("/api/v1/jobs/{id}")).await;
    assert!(["running", "completed"].contains(&job["state"].as_str().unwrap()), "{job}");
    sim.set_heartbeat(true);
    let job = wait_job(&app, id, &["completed", "failed", "cancelled"], 5).await;
    assert_eq!(job["state"], "completed", "{job}");
    assert_eq!(sim.received(task_id_for(id)), 1);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_crane_sees_rackds_heartbeat_and_raises_7020_only_while_rackd_is_away() {
    let options = CraneSimOptions {
        transport: TransportKind::Tcp,
        step: Duration::from_millis(10),
        wcs_timeout: Some(Duration::from_millis(400)),
        ..Default::default()
    };
    let sim = CraneSim::start("127.0.0.1:0", options).await.unwrap();
    let device = device_for(&sim, TransportKind::Tcp, |_| {});
    let app = support::spawn_with(Engine::Sqlite, |c| with_crane(c, device.clone())).await;
    wait_device(&app, "clean", 5, |s| s["online"] == true && s["crane"]["alarm_code"].is_null()).await;
    // rackd writes D0 at most every heartbeat_ms (20 ms), so 30 changes of D0 span more than
    // the crane's 400 ms watchdog; the watchdog stays quiet all along.
    let (mut moves, mut last) = (0, sim.word(0));
    eventually_every(
        Duration::from_millis(2),
        "30 moves of rackd's heartbeat",
        Duration::from_secs(10),
        async || {
            assert_eq!(sim.word(205), 0, "rackd's heartbeat keeps the crane's watchdog quiet");
            if sim.word(0) != last {
                (moves, last) = (moves + 1, sim.word(0));
            }
            if moves >= 30 { Ok(()) } else { Err(format!("{moves} moves")) }
        },
    )
    .await;
    assert_eq!(sim.word(205), 0);
    let (db, _dir) = app.stop().await;
    eventually("the crane to notice rackd is gone", Duration::from_secs(5), async || sim.word(205) == 7020)
        .await;
    let app = support::spawn_on(db, |c| with_crane(c, device)).await;
    let id = submit(&app, json!({"kind": "travel", "to": cloc(1, 9, 1, 1)}), "back").await;
    let job = wait_job(&app, id, &["completed", "failed", "cancelled"], 5).await;
    assert_eq!(job["state"], "completed", "{job}");
    assert_eq!(sim.word(205), 0);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stalled_heartbeat_shows_since_when_and_the_crane_block_stays_shown() {
    let (app, sim) = crane_app(TransportKind::Tcp, 10, |_| {}).await;
    let healthy =
        wait_device(&app, "online", 5, |s| s["online"] == true && s["crane"]["heartbeat_ok"] == true).await;
    assert!(healthy["crane"]["heartbeat_stalled_since"].is_null(), "{healthy}");
    let before = time::OffsetDateTime::now_utc();
    sim.set_heartbeat(false);
    // The crane's own watchdog would raise 7020 too; the link still answers.
    sim.raise_alarm(7020);
    let lost = wait_device(&app, "lost with the alarm shown", 5, |s| {
        s["crane"]["heartbeat_ok"] == false && s["crane"]["alarm_code"] == 7020
    })
    .await;
    let after = time::OffsetDateTime::now_utc();
    assert_eq!(lost["online"], false, "{lost}");
    assert_eq!(lost["crane"]["known"], true, "{lost}");
    assert_eq!(lost["crane"]["alarm_class"], "hardware", "{lost}");
    let since = lost["crane"]["heartbeat_stalled_since"].clone();
    let at = time::OffsetDateTime::parse(
        since.as_str().unwrap_or(""),
        &time::format_description::well_known::Rfc3339,
    )
    .unwrap_or_else(|e| panic!("{since}: {e}"));
    // D200 last moved shortly before it was stopped (rackd polls every 20 ms).
    assert!(at <= after && at >= before - Duration::from_secs(1), "{at} not near {before}");
    // The stall time stays put, poll after poll.
    support::wait_for_more("polls of the stalled crane", POLLS, 5, || sim.requests_seen()).await;
    let (_, still) = app.get("/api/v1/devices/crane1").await;
    assert_eq!(still["crane"]["heartbeat_stalled_since"], since, "{still}");
    assert_eq!(still["crane"]["alarm_code"], 7020, "{still}");
    // Both reach the alarm list: the heartbeat alarm of rackd's, and the crane's own 7020
    // though the device is offline.
    let active = wait_alarms(&app, |kinds| kinds.len() == 2).await;
    assert_eq!(
        active.iter().map(|a| (a["kind"].as_str().unwrap(), a["code"].as_u64().unwrap())).collect::<Vec<_>>(),
        vec![("heartbeat", 0), ("device", 7020)],
        "newest first: {active:?}"
    );
    let text = active[0]["text"].as_str().unwrap();
    let secs: f64 = text
        .trim_start_matches("the crane's heartbeat (D200) has not changed for ")
        .trim_end_matches(" s")
        .parse()
        .unwrap_or_else(|_| panic!("{text}"));
    assert!(secs >= 0.5, "at least the 500 ms timeout: {text}");
    sim.clear_alarm();
    sim.set_heartbeat(true);
    // The heartbeat may be seen moving again before the poll that reads the cleared alarm
    // (the alarm was read just before it cleared): wait for both.
    let back = wait_device(&app, "back", 5, |s| {
        s["online"] == true && s["crane"]["heartbeat_ok"] == true && s["crane"]["alarm_code"].is_null()
    })
    .await;
    assert!(back["crane"]["heartbeat_stalled_since"].is_null(), "{back}");
    assert!(back["crane"]["alarm_code"].is_null(), "{back}");
    assert!(back["last_error"].is_null(), "the heartbeat's error is over: {back}");
    assert!(back["last_error_at"].is_string(), "its time stays: {back}");
    wait_alarms(&app, |kinds| kinds.is_empty()).await;
    app.stop().await;
}

/// Waits (bounded) until the active alarms' kinds satisfy `pred`; returns them.
async fn wait_alarms(app: &support::TestApp, pred: impl Fn(&[String]) -> bool) -> Vec<serde_json::Value> {
    eventually("the active alarms to come right", Duration::from_secs(5), async || {
        let (_, page) = app.get("/api/v1/alarms?active=true").await;
        let alarms = page["alarms"].as_array().unwrap().clone();
        let kinds: Vec<String> = alarms.iter().map(|a| a["kind"].as_str().unwrap().to_owned()).collect();
        if pred(&kinds) { Ok(alarms) } else { Err(alarms) }
    })
    .await
}
