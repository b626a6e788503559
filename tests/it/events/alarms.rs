//! Alarms and device events: a crane's alarm raised and cleared, a link alarm while a
//! device does not answer, `GET /api/v1/alarms`.

use std::time::Duration;

use rackd::config::devices::CraneConfig;
use rackd::sim::crane::{CraneSim, CraneSimOptions};
use rackd::store::Engine;
use rstest::rstest;
use serde_json::{Value, json};

use crate::support::eventually;
use crate::support::ws::Ws;
use crate::support::{TestApp, spawn_with};

async fn crane_app(engine: Engine) -> (TestApp, CraneSim) {
    let sim = CraneSim::start("127.0.0.1:0", CraneSimOptions::default()).await.unwrap();
    let mut device = CraneConfig::new("crane1", &sim.local_addr().to_string(), vec![2]);
    device.poll_ms = 20;
    device.link.timeout = Duration::from_millis(100);
    // A fixed timeout: no retries here, so the adaptive timer's floor (a few ms) would count a
    // loaded machine's late replies as a degraded link, an alarm these tests do not expect.
    device.link.tuning.min_timeout = device.link.timeout;
    device.link.retries = 0;
    device.offline_after = 2;
    device.heartbeat_ms = 20;
    device.heartbeat_timeout_ms = 300;
    let app = spawn_with(engine, |c| {
        c.devices = vec![device.into()];
    })
    .await;
    (app, sim)
}

/// The next message of type `kind`, skipping others.
async fn next_of(ws: &mut Ws, kind: &str) -> Value {
    eventually(format!("a {kind}"), Duration::from_secs(10), async || {
        let v = ws.json().await;
        if v["type"] == kind { Ok(v) } else { Err(v) }
    })
    .await
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn a_crane_alarm_is_raised_and_cleared_live_and_listed(#[case] engine: Engine) {
    let (app, sim) = crane_app(engine).await;
    let mut ws = Ws::connect(&app.base, "?topics=alarms,devices").await;
    let snapshot = ws.json().await;
    assert_eq!(snapshot["data"]["devices"][0]["id"], "crane1", "{snapshot}");
    let online = loop {
        let v = next_of(&mut ws, "device.updated").await;
        if v["data"]["online"] == true {
            break v;
        }
    };
    assert_eq!(online["data"]["kind"], "crane");

    sim.raise_alarm(41);
    let raised = next_of(&mut ws, "alarm.raised").await;
    assert_eq!(raised["data"]["device"], "crane1");
    assert_eq!(raised["data"]["code"], 41);
    assert!(raised["data"]["text"].as_str().is_some_and(|t| !t.is_empty()), "{raised}");
    assert!(raised["data"]["cleared_at"].is_null());
    let (status, page) = app.get("/api/v1/alarms?active=true").await;
    assert_eq!(status, 200);
    assert_eq!(page["alarms"].as_array().unwrap().len(), 1, "{page}");
    assert_eq!(page["alarms"][0]["id"], raised["data"]["id"]);

    sim.clear_alarm();
    let cleared = next_of(&mut ws, "alarm.cleared").await;
    assert_eq!(cleared["data"]["id"], raised["data"]["id"]);
    assert!(cleared["data"]["cleared_at"].is_string(), "{cleared}");
    let (_, page) = app.get("/api/v1/alarms?active=true").await;
    assert_eq!(page["alarms"], serde_json::json!([]));
    let (_, page) = app.get("/api/v1/alarms?device=crane1").await;
    assert_eq!(page["alarms"].as_array().unwrap().len(), 1);
    assert!(page["alarms"][0]["raised_at"].is_string());
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn a_silent_device_raises_a_link_alarm_until_it_answers_again(#[case] engine: Engine) {
    let (app, sim) = crane_app(engine).await;
    let mut ws = Ws::connect(&app.base, "?topics=alarms").await;
    ws.json().await;
    sim.set_link(false);
    let raised = next_of(&mut ws, "alarm.raised").await;
    assert_eq!(
        (raised["data"]["class"].clone(), raised["data"]["kind"].clone()),
        (json!("link"), json!("link"))
    );
    assert_eq!(raised["data"]["code"], 0);
    let text = raised["data"]["text"].as_str().unwrap();
    let address = sim.local_addr().to_string();
    assert!(
        text.starts_with(&format!("no answer from {address} for ")) && text.contains(" poll"),
        "plain words: {text}"
    );
    assert!(
        raised["data"]["detail"].as_str().is_some_and(|d| !d.is_empty()),
        "the protocol's words apart: {raised}"
    );
    let (_, device) = app.get("/api/v1/devices/crane1").await;
    assert_eq!(device["online"], false, "{device}");
    // Down for longer than the heartbeat timeout.
    tokio::time::sleep(Duration::from_millis(500)).await;
    sim.set_link(true);
    let cleared = next_of(&mut ws, "alarm.cleared").await;
    assert_eq!(cleared["data"]["id"], raised["data"]["id"]);
    // The heartbeat was unseen while the link was down, not stalled: once the crane
    // answers, no heartbeat alarm follows the outage.
    crate::support::wait_for_more("requests of the crane", 30, 10, || sim.requests_seen()).await;
    let (_, page) = app.get("/api/v1/alarms?device=crane1").await;
    // A `degraded` warning may come and go on a loaded test machine (late replies are the
    // link's quality, which it reports); the outage itself is one link alarm, and nothing else.
    let kinds: Vec<&str> = page["alarms"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a["kind"].as_str().unwrap())
        .filter(|kind| *kind != "degraded")
        .collect();
    assert_eq!(kinds, vec!["link"], "{page}");
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn the_alarm_list_pages_and_refuses_bad_queries(#[case] engine: Engine) {
    let (app, sim) = crane_app(engine).await;
    let mut ws = Ws::connect(&app.base, "?topics=alarms").await;
    ws.json().await;
    for code in [41, 42, 43] {
        sim.raise_alarm(code);
        next_of(&mut ws, "alarm.raised").await;
        sim.clear_alarm();
        next_of(&mut ws, "alarm.cleared").await;
    }
    let (_, first) = app.get("/api/v1/alarms?limit=2").await;
    let codes: Vec<i64> =
        first["alarms"].as_array().unwrap().iter().map(|a| a["code"].as_i64().unwrap()).collect();
    assert_eq!(codes, vec![43, 42], "newest first: {first}");
    let cursor = first["next_cursor"].as_str().unwrap();
    let (_, second) = app.get(&format!("/api/v1/alarms?limit=2&cursor={cursor}")).await;
    assert_eq!(second["alarms"][0]["code"], 41);
    assert!(second["next_cursor"].is_null());
    crate::support::assert_error(&app.get("/api/v1/alarms?limit=0").await, 400, "bad_query");
    crate::support::assert_error(&app.get("/api/v1/alarms?cursor=x").await, 400, "bad_cursor");
    crate::support::assert_error(&app.get("/api/v1/alarms?active=maybe").await, 400, "bad_query");
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn an_alarm_active_at_a_restart_is_carried_over_not_raised_twice(#[case] engine: Engine) {
    let (app, sim) = crane_app(engine).await;
    let mut ws = Ws::connect(&app.base, "?topics=alarms").await;
    ws.json().await;
    sim.raise_alarm(41);
    let raised = next_of(&mut ws, "alarm.raised").await;
    ws.close().await;
    let (db, dir) = app.stop().await;

    let mut device = CraneConfig::new("crane1", &sim.local_addr().to_string(), vec![2]);
    device.poll_ms = 20;
    let app = crate::support::spawn_on(db, |c| {
        c.devices = vec![device.into()];
    })
    .await;
    let seq = raised["seq"].as_i64().unwrap();
    let mut ws = Ws::connect(&app.base, &format!("?topics=alarms&since={seq}")).await;
    // The restarted rackd reads the crane (its status shows the alarm), then polls it on:
    // every poll is judged by the monitor, and none may raise the alarm a second time.
    eventually("the restarted rackd to show alarm 41", Duration::from_secs(5), async || {
        app.get("/api/v1/devices/crane1").await.1["crane"]["alarm_code"] == 41
    })
    .await;
    crate::support::wait_for_more("polls of the crane", 10, 5, || sim.requests_seen()).await;
    sim.clear_alarm();
    // Events come in order: had the alarm been raised again, that event would come first.
    let cleared = ws.json().await;
    assert_eq!(cleared["type"], "alarm.cleared", "{cleared}");
    assert_eq!(cleared["data"]["id"], raised["data"]["id"]);
    let (_, page) = app.get("/api/v1/alarms").await;
    assert_eq!(page["alarms"].as_array().unwrap().len(), 1, "{page}");
    drop(dir);
}
