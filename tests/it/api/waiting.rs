//! Why a job waits (`waiting`), for each reason, over the real server with the demo's
//! simulators; the `?waiting=` filter; and the `job.updated` event a change of reason
//! alone produces.

use std::time::Duration;

use rackd::store::Engine;
use rstest::rstest;
use serde_json::{Value, json};

use super::demo::{SLOW_CRANE, cloc, demo_app, submit, wait_job, wait_reason, waiting_ids};
use crate::support::eventually;
use crate::support::wait::EVERY;
use crate::support::ws::{Got, Ws};
use crate::support::{TestApp, assert_error, loc, spawn_app};

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn without_a_device_a_job_says_so_and_the_filter_finds_it(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    let id = submit(&app, json!({"kind": "store", "to": loc(1, 2, 3, 1)})).await;
    let job = wait_reason(&app, id, "no_device").await;
    assert_eq!(job["state"], "queued");
    assert_eq!(job["waiting"]["text"], "no configured device runs jobs on aisle 1", "{job}");
    assert_eq!(waiting_ids(&app, "no_device").await, vec![id]);
    assert_eq!(waiting_ids(&app, "any").await, vec![id]);
    assert!(waiting_ids(&app, "slots_busy").await.is_empty());
    let (_, page) = app.get("/api/v1/jobs?waiting=any&state=completed").await;
    assert_eq!(page["jobs"], json!([]), "only queued jobs wait");
    assert_error(&app.get("/api/v1/jobs?waiting=bored").await, 400, "bad_query");
    // Paging through waiting jobs: one a page, the cursor leads to the next.
    let second = submit(&app, json!({"kind": "store", "to": loc(1, 2, 3, 2)})).await;
    let (_, page) = app.get("/api/v1/jobs?waiting=any&limit=1").await;
    assert_eq!(page["jobs"][0]["id"], id);
    let cursor = page["next_cursor"].as_str().unwrap().to_owned();
    let (_, page) = app.get(&format!("/api/v1/jobs?waiting=any&limit=1&cursor={cursor}")).await;
    assert_eq!(page["jobs"][0]["id"], second, "{page}");
    app.stop().await;
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_shelf_that_does_not_answer_holds_its_jobs_offline(#[case] engine: Engine) {
    // A UDP port nothing answers on, held for the test (let go, another test's simulator
    // could take it and answer).
    let silent = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let dead = silent.local_addr().unwrap().to_string();
    let (app, _sims) = demo_app(engine, SLOW_CRANE, |c| {
        let shelf = c.devices.iter_mut().find(|d| d.id() == "shelf1").unwrap();
        shelf.link_mut().address = dead.clone();
    })
    .await;
    let id = submit(&app, json!({"kind": "store", "to": loc(1, 2, 3, 1)})).await;
    let job = wait_reason(&app, id, "device_offline").await;
    assert_eq!((job["state"].clone(), job["waiting"]["device"].clone()), (json!("queued"), json!("shelf1")));
    assert!(job["waiting"]["text"].as_str().unwrap().starts_with("shelf1 "), "{job}");
    assert_eq!(waiting_ids(&app, "device_offline").await, vec![id]);
    app.stop().await;
}

/// The next `job.updated` of job `id` on `ws` whose reason is `reason`.
async fn told(ws: &mut Ws, id: i64, reason: &str) -> Value {
    let what = format!("a job.updated of job {id} waiting for {reason}");
    eventually(&what, Duration::from_secs(10), async || match ws.next(EVERY).await {
        Got::Json(m) if m["type"] == "job.updated" && m["data"]["id"] == id => {
            if m["data"]["waiting"]["reason"] == reason { Ok(m["data"].clone()) } else { Err(Got::Json(m)) }
        }
        Got::Closed(code) => panic!("closed ({code}) before {what}"),
        other => Err(other),
    })
    .await
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_hold_on_the_crane_says_why_and_each_change_is_an_event(#[case] engine: Engine) {
    let (app, sims) = demo_app(engine, SLOW_CRANE, |_| {}).await;
    let crane = &sims.crane;
    wait_for_online(&app, "crane1").await;
    let place = cloc(1, 3, 2, 1);

    // Paused device.
    let (status, _) = app.post("/api/v1/devices/crane1/pause", &json!({"reason": "inspection"})).await;
    assert_eq!(status, 200);
    let first = submit(&app, json!({"kind": "store", "barcode": "W1", "to": place})).await;
    let job = wait_reason(&app, first, "device_paused").await;
    assert_eq!(
        (job["waiting"]["device"].clone(), job["waiting"]["by"].clone(), job["waiting"]["text"].clone()),
        (json!("crane1"), json!("anonymous"), json!("device crane1 is paused: inspection (by anonymous)"))
    );
    assert_eq!(waiting_ids(&app, "device_paused").await, vec![first]);

    // From here on, every change of reason alone reaches subscribers as a job.updated.
    let mut ws = Ws::connect(&app.base, "?topics=jobs").await;
    let snapshot = ws.json().await;
    let shown =
        snapshot["data"]["jobs"].as_array().unwrap().iter().find(|j| j["id"] == first).unwrap().clone();
    assert_eq!(shown["waiting"]["reason"], "device_paused", "the snapshot says why: {shown}");

    // A crane in alarm, with an aisle pause under it: the alarm is told first.
    crane.raise_alarm(7002);
    let (status, _) = app.post("/api/v1/aisles/2/pause", &json!({"reason": "maintenance"})).await;
    assert_eq!(status, 200);
    let (status, _) = app.post("/api/v1/devices/crane1/resume", &Value::Null).await;
    assert_eq!(status, 200);
    let event = told(&mut ws, first, "device_alarm").await;
    assert_eq!(
        (event["waiting"]["code"].clone(), event["state"].clone()),
        (json!(7002), json!("queued")),
        "{event}"
    );
    assert!(event["waiting"]["text"].as_str().unwrap().contains("emergency stop"), "{event}");
    assert_eq!(wait_reason(&app, first, "device_alarm").await["waiting"]["code"], 7002);

    // The alarm clears: the aisle pause holds it.
    crane.clear_alarm();
    let event = told(&mut ws, first, "aisle_paused").await;
    assert_eq!(event["waiting"]["text"], "aisle 2 is paused: maintenance (by anonymous)", "{event}");
    assert_eq!(waiting_ids(&app, "aisle_paused").await, vec![first]);

    // A location locked by hand comes before the aisle pause.
    let (status, _) = app.post("/api/v1/locations/2/1/3/2/1/lock", &json!({"reason": "box damaged"})).await;
    assert_eq!(status, 200);
    let event = told(&mut ws, first, "location_locked").await;
    assert_eq!(
        (event["waiting"]["by"].clone(), event["waiting"]["job"].clone()),
        (json!("anonymous"), Value::Null)
    );
    assert_eq!(event["waiting"]["text"], "location 2/1/3/2/1 is locked: box damaged");

    // Let it go: it runs, and says nothing while it does.
    app.post("/api/v1/locations/2/1/3/2/1/unlock", &Value::Null).await;
    app.post("/api/v1/aisles/2/resume", &Value::Null).await;
    let running = wait_job(&app, first, 10, |j| j["state"] == "running").await;
    assert!(running["waiting"].is_null(), "{running}");

    // Behind it on the same location, and the crane busy for another.
    let behind = submit(&app, json!({"kind": "store", "barcode": "W2", "to": place})).await;
    let busy = submit(&app, json!({"kind": "store", "barcode": "W3", "to": cloc(2, 5, 1, 1)})).await;
    let job = wait_reason(&app, behind, "behind_job").await;
    assert_eq!(job["waiting"]["job"], first, "{job}");
    assert_eq!(job["waiting"]["text"], format!("behind job {first} on location 2/1/3/2/1"));
    let job = wait_reason(&app, busy, "slots_busy").await;
    assert_eq!(job["waiting"]["text"], "crane1 is busy with another job", "{job}");
    assert_eq!(waiting_ids(&app, "behind_job").await, vec![behind]);
    assert_eq!(waiting_ids(&app, "any").await, vec![behind, busy]);
    assert_eq!(crane.violations(), 0);
    app.stop().await;
}

/// Waits until `device` is online.
pub async fn wait_for_online(app: &TestApp, device: &str) {
    eventually(format!("{device} to be online"), Duration::from_secs(10), async || {
        let (_, d) = app.get(&format!("/api/v1/devices/{device}")).await;
        if d["online"] == true { Ok(()) } else { Err(d) }
    })
    .await
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_location_locked_by_a_failed_job_names_the_job(#[case] engine: Engine) {
    let (app, sims) = demo_app(engine, SLOW_CRANE, |_| {}).await;
    wait_for_online(&app, "crane1").await;
    let place = cloc(1, 4, 2, 1);
    let failed = submit(&app, json!({"kind": "store", "barcode": "F1", "to": place})).await;
    wait_job(&app, failed, 10, |j| j["state"] == "running").await;
    sims.crane.raise_alarm(7069);
    let job = wait_job(&app, failed, 10, |j| j["state"] == "failed").await;
    assert_eq!(job["failure"]["kind"], "alarm", "{job}");
    let next = submit(&app, json!({"kind": "store", "barcode": "F2", "to": place})).await;
    let job = wait_reason(&app, next, "location_locked").await;
    assert_eq!(
        (job["waiting"]["job"].clone(), job["waiting"]["by"].clone()),
        (json!(failed), Value::Null),
        "{job}"
    );
    app.stop().await;
}
