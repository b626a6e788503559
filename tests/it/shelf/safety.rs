//! Safe under faults, end to end: a PLC that forgets its tasks, location locks (automatic
//! and by hand), waiting jobs that say why, retries, and pauses that outlast a restart.

use rackd::store::Engine;
use serde_json::{Value, json};

use super::{device_for, shelf_app, sim};
use crate::support::*;

async fn job(app: &TestApp, id: &Value) -> Value {
    app.get(&format!("/api/v1/jobs/{id}")).await.1
}

/// Waits until `check` holds for the job, failing after `secs` seconds.
async fn wait_job(app: &TestApp, id: &Value, secs: u64, check: impl Fn(&Value) -> bool) -> Value {
    eventually(format!("job {id} to get there"), std::time::Duration::from_secs(secs), async || {
        let j = job(app, id).await;
        if check(&j) { Ok(j) } else { Err(j) }
    })
    .await
}

async fn location(app: &TestApp, l: &Value) -> Value {
    let (_, all) = app.get("/api/v1/locations?aisle=1").await;
    all.as_array()
        .unwrap()
        .iter()
        .find(|s| ["row", "bay", "level", "position"].iter().all(|k| s[*k] == l[*k]))
        .cloned()
        .unwrap()
}

fn path(l: &Value) -> String {
    format!("/api/v1/locations/1/{}/{}/{}/{}", l["row"], l["bay"], l["level"], l["position"])
}

async fn active_alarms(app: &TestApp) -> Vec<Value> {
    app.get("/api/v1/alarms?active=true").await.1["alarms"].as_array().unwrap().clone()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_plc_that_forgets_its_tasks_is_one_decision_and_its_locations_lock() {
    // Tasks take 3 s: all six sit in their slots when the PLC loses its memory.
    let (app, sim) = shelf_app(sim(3_000), |_| {}).await;
    let places: Vec<Value> = (1..=6).map(|p| loc(1, 1, 1 + (p - 1) / 2, 1 + (p - 1) % 2)).collect();
    let mut ids = Vec::new();
    for (k, to) in places.iter().enumerate() {
        let (status, j) =
            app.post("/api/v1/jobs", &json!({"kind": "store", "to": to, "reference": format!("M{k}")})).await;
        assert_eq!(status, 201, "{j}");
        ids.push(j["id"].clone());
    }
    for id in &ids {
        wait_job(&app, id, 10, |j| j["state"] == "dispatched" || j["state"] == "running").await;
    }
    sim.power_cycle();
    for id in &ids {
        let j = wait_job(&app, id, 10, |j| j["state"] == "failed").await;
        assert_eq!(j["failure"]["kind"], "lost", "{j}");
        let text = j["failure"]["text"].as_str().unwrap();
        assert!(text.starts_with("the PLC lost its task memory (power cycle?)"), "{text}");
    }
    let alarms = eventually("a memory_lost alarm", std::time::Duration::from_secs(10), async || {
        let alarms = active_alarms(&app).await;
        if alarms.iter().any(|a| a["kind"] == "memory_lost") { Ok(alarms) } else { Err(alarms) }
    })
    .await;
    let lost: Vec<&Value> = alarms.iter().filter(|a| a["kind"] == "memory_lost").collect();
    assert_eq!(lost.len(), 1, "one alarm, not six: {alarms:?}");
    assert_eq!(lost[0]["device"], "shelf1");
    for to in &places {
        let l = location(&app, to).await;
        assert_eq!(l["lock"]["by"], "rackd", "{l}");
        assert!(l["lock"]["reason"].as_str().unwrap().contains("lost"), "{l}");
    }

    // A later job on a locked location waits and says why; one elsewhere runs, and the PLC
    // taking work again clears the alarm.
    let (_, waiting) = app.post("/api/v1/jobs", &json!({"kind": "retrieve", "from": places[0]})).await;
    let (_, elsewhere) = app.post("/api/v1/jobs", &json!({"kind": "store", "to": loc(2, 5, 1, 1)})).await;
    wait_job(&app, &elsewhere["id"], 10, |j| j["state"] != "queued").await;
    let j = job(&app, &waiting["id"]).await;
    assert_eq!(j["state"], "queued", "{j}");
    assert!(j["waiting"]["text"].as_str().unwrap().contains("is locked"), "{j}");
    assert_eq!(j["waiting"]["reason"], "location_locked", "{j}");
    eventually(
        "the memory alarm to clear once the PLC took work",
        std::time::Duration::from_secs(10),
        async || {
            let alarms = active_alarms(&app).await;
            if alarms.iter().any(|a| a["kind"] == "memory_lost") { Err(alarms) } else { Ok(()) }
        },
    )
    .await;

    // The WMS re-POSTs: the same failed job. An operator retries it once the location is
    // checked: the same job, a new attempt, its history kept.
    let (status, again) =
        app.post("/api/v1/jobs", &json!({"kind": "store", "to": places[1], "reference": "M1"})).await;
    assert_eq!((status, again["state"].clone()), (200, json!("failed")), "{again}");
    let (status, retried) = app.post(&format!("/api/v1/jobs/{}/retry", ids[1]), &json!({})).await;
    assert_eq!(
        (status, retried["state"].clone(), retried["attempt"].clone()),
        (200, json!("queued"), json!(2)),
        "{retried}"
    );
    assert!(retried["failure"].is_null());
    assert!(retried["waiting"]["text"].as_str().unwrap().contains("is locked"), "still locked: {retried}");
    let (status, unlocked) =
        app.post(&format!("{}/unlock", path(&places[1])), &json!({"reason": "checked: empty"})).await;
    assert_eq!((status, unlocked["lock"].clone()), (200, Value::Null), "{unlocked}");
    let done = wait_job(&app, &ids[1], 30, |j| j["state"] == "running" || j["state"] == "completed").await;
    assert_eq!(done["attempt"], 2);
    let (_, history) = app.get(&format!("/api/v1/jobs/{}/history", ids[1])).await;
    let states: Vec<&str> =
        history.as_array().unwrap().iter().map(|h| h["state"].as_str().unwrap()).collect();
    assert!(states.starts_with(&["queued", "dispatched"]) && states.contains(&"failed"), "{states:?}");
    let retry = history
        .as_array()
        .unwrap()
        .iter()
        .find(|h| h["cause"].as_str().unwrap().starts_with("retried by"))
        .unwrap();
    assert_eq!(retry["cause"], "retried by anonymous (attempt 2)");
    assert_error(
        &app.post(&format!("/api/v1/jobs/{}/retry", elsewhere["id"]), &json!({})).await,
        409,
        "job_not_failed",
    );
    assert_error(&app.post("/api/v1/jobs/999999/retry", &json!({})).await, 404, "not_found");

    let (_, audit) = app.get("/api/v1/audit").await;
    let actions: Vec<&str> =
        audit["entries"].as_array().unwrap().iter().map(|e| e["action"].as_str().unwrap()).collect();
    // After the jobs' submissions (audited too), the operator's retry and unlock.
    assert_eq!(actions[..2], ["unlock", "retry"], "newest first: {audit}");
    assert!(actions[2..].iter().all(|a| *a == "submit"), "{audit}");
    assert_eq!(sim.violations(), 0, "no task into a busy slot");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn locks_by_hand_hold_jobs_back_until_unlocked() {
    let (app, sim) = shelf_app(sim(0), |_| {}).await;
    let place = loc(1, 3, 2, 1);
    assert_error(&app.post(&format!("{}/lock", path(&place)), &json!({})).await, 422, "invalid_body");
    assert_error(
        &app.post(&format!("{}/lock", path(&place)), &json!({"reason": "  "})).await,
        422,
        "invalid_reason",
    );
    assert_error(
        &app.post("/api/v1/locations/1/99/1/1/1/lock", &json!({"reason": "x"})).await,
        404,
        "not_found",
    );
    assert_error(
        &app.post("/api/v1/locations/1/a/1/1/1/lock", &json!({"reason": "x"})).await,
        400,
        "bad_path",
    );
    let (status, locked) =
        app.post(&format!("{}/lock", path(&place)), &json!({"reason": "box damaged"})).await;
    assert_eq!(status, 200, "{locked}");
    assert_eq!(
        (locked["lock"]["reason"].clone(), locked["lock"]["by"].clone()),
        (json!("box damaged"), json!("anonymous"))
    );

    let (_, held) = app.post("/api/v1/jobs", &json!({"kind": "store", "to": place})).await;
    let (_, free) = app.post("/api/v1/jobs", &json!({"kind": "store", "to": loc(1, 3, 2, 2)})).await;
    wait_job(&app, &free["id"], 10, |j| j["state"] == "completed").await;
    let faults = sim.faults();
    wait_for_more("polls with the job held back", 5, 10, || faults.requests_seen()).await;
    let j = job(&app, &held["id"]).await;
    assert_eq!(j["state"], "queued");
    assert_eq!(j["waiting"]["text"], "location 1/1/3/2/1 is locked: box damaged", "{j}");
    assert_eq!(
        (j["waiting"]["reason"].clone(), j["waiting"]["by"].clone()),
        (json!("location_locked"), json!("anonymous"))
    );
    let (_, listed) = app.get("/api/v1/jobs?state=queued").await;
    assert_eq!(listed["jobs"][0]["waiting"], j["waiting"]);

    let (status, _) = app.post(&format!("{}/unlock", path(&place)), &Value::Null).await;
    assert_eq!(status, 200);
    let done = wait_job(&app, &held["id"], 10, |j| j["state"] == "completed").await;
    assert!(done["waiting"].is_null(), "{done}");
    assert_eq!(sim.violations(), 0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pause_outlasts_a_restart_and_an_aisle_pause_holds_its_jobs() {
    let sim = rackd::sim::shelf::ShelfSim::start("127.0.0.1:0", sim(0)).await.unwrap();
    let device = device_for(&sim, |_| {});
    let app = spawn_with(Engine::Sqlite, |c| c.devices = vec![device.clone().into()]).await;
    let (status, shown) =
        app.post("/api/v1/devices/shelf1/pause", &json!({"reason": "fork inspection"})).await;
    assert_eq!(status, 200, "{shown}");
    assert_eq!(
        (shown["paused"].clone(), shown["pause"]["reason"].clone()),
        (json!(true), json!("fork inspection"))
    );
    let (_, queued) = app.post("/api/v1/jobs", &store("PAUSED-1")).await;
    let (db, dir) = app.stop().await;

    let app = spawn_on(db.clone(), |c| c.devices = vec![device.clone().into()]).await;
    let (_, shown) = app.get("/api/v1/devices/shelf1").await;
    assert_eq!(shown["paused"], true, "restored: {shown}");
    assert_eq!(
        (shown["pause"]["by"].clone(), shown["pause"]["reason"].clone()),
        (json!("anonymous"), json!("fork inspection"))
    );
    let faults = sim.faults();
    wait_for_more("polls of the paused shelf", 70, 10, || faults.requests_seen()).await;
    let j = job(&app, &queued["id"]).await;
    assert_eq!(j["state"], "queued", "a paused device runs nothing after a restart");
    assert_eq!(j["waiting"]["text"], "device shelf1 is paused: fork inspection (by anonymous)");

    // The aisle pause takes over: the device resumes but its only aisle is paused.
    let (status, aisle) = app.post("/api/v1/aisles/1/pause", &json!({"reason": "maintenance"})).await;
    assert_eq!(
        (status, aisle["paused"].clone(), aisle["devices"].clone()),
        (200, json!(true), json!(["shelf1"])),
        "{aisle}"
    );
    let (_, shown) = app.post("/api/v1/devices/shelf1/resume", &Value::Null).await;
    assert_eq!(
        (shown["paused"].clone(), shown["paused_aisles"].clone()),
        (json!(true), json!([1])),
        "{shown}"
    );
    wait_for_more("polls with the aisle paused", 5, 10, || faults.requests_seen()).await;
    let j = job(&app, &queued["id"]).await;
    assert_eq!(
        (j["state"].clone(), j["waiting"]["text"].clone()),
        (json!("queued"), json!("aisle 1 is paused: maintenance (by anonymous)"))
    );
    app.stop().await;

    let app = spawn_on(db, |c| c.devices = vec![device.into()]).await;
    let (_, aisles) = app.get("/api/v1/aisles").await;
    let one = aisles.as_array().unwrap().iter().find(|a| a["aisle"] == 1).unwrap().clone();
    assert_eq!((one["paused"].clone(), one["pause"]["reason"].clone()), (json!(true), json!("maintenance")));
    assert_error(&app.post("/api/v1/aisles/99/pause", &Value::Null).await, 404, "not_found");
    let long = "x".repeat(501);
    assert_error(&app.post("/api/v1/aisles/1/pause", &json!({"reason": long})).await, 422, "invalid_reason");
    assert_error(&app.post("/api/v1/aisles/1/pause", &json!({"why": "x"})).await, 422, "invalid_body");
    app.post("/api/v1/aisles/1/resume", &json!({"reason": "done"})).await;
    assert_eq!(wait_job(&app, &queued["id"], 10, |j| j["state"] == "completed").await["attempt"], 1);

    let (_, audit) = app.get("/api/v1/audit?limit=10").await;
    let seen: Vec<(String, String)> = audit["entries"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| (e["action"].as_str().unwrap().to_owned(), e["target"].as_str().unwrap().to_owned()))
        .collect();
    let want = [
        ("resume", "aisle:1"),
        ("resume", "device:shelf1"),
        ("pause", "aisle:1"),
        ("submit", "job:1"),
        ("pause", "device:shelf1"),
    ];
    assert_eq!(seen, want.map(|(a, t)| (a.to_owned(), t.to_owned())).to_vec(), "newest first: {audit}");
    assert_eq!(sim.violations(), 0);
    drop(dir);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_lossy_link_is_a_degraded_warning_that_keeps_working_and_clears() {
    let (app, sim) = shelf_app(sim(0), |_| {}).await;
    sim.set_faults(rackd::protocols::faults::Faults { drop_rate: 0.3, ..Default::default() });
    let alarm = eventually("a degraded warning", std::time::Duration::from_secs(20), async || {
        let found = active_alarms(&app).await.into_iter().find(|a| a["kind"] == "degraded");
        found.ok_or(app.get("/api/v1/devices/shelf1").await.1)
    })
    .await;
    assert_eq!(alarm["class"], "link", "{alarm}");
    assert!(alarm["detail"].as_str().unwrap().contains("retries"), "{alarm}");
    let (_, device) = app.get("/api/v1/devices/shelf1").await;
    assert_eq!(
        (device["link"]["degraded"].clone(), device["online"].clone()),
        (json!(true), json!(true)),
        "{device}"
    );
    assert!(device["link"]["retries"].as_u64().unwrap() > 0, "{device}");
    // A warning, not a stop: work goes on over the lossy link.
    let (_, job) = app.post("/api/v1/jobs", &store("LOSSY-1")).await;
    assert_eq!(wait_job(&app, &job["id"], 30, |j| j["state"] == "completed").await["state"], "completed");
    sim.set_faults(rackd::protocols::faults::Faults::default());
    eventually("the warning to clear", std::time::Duration::from_secs(20), async || {
        let alarms = active_alarms(&app).await;
        if alarms.iter().any(|a| a["kind"] == "degraded") { Err(alarms) } else { Ok(()) }
    })
    .await;
    assert_eq!(app.get("/api/v1/devices/shelf1").await.1["link"]["degraded"], false);
    assert_eq!(sim.violations(), 0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn started_on_a_lossy_link_it_recovers_and_works_at_once() {
    // The shipped timings (200 ms poll, 300 ms timeout, 2 retries) on a link that loses a
    // fifth of the requests from the start: recovery reads all 60 slots through the loss.
    let options = rackd::sim::shelf::ShelfSimOptions {
        faults: rackd::protocols::faults::Faults { drop_rate: 0.2, ..Default::default() },
        ..sim(0)
    };
    let (app, sim) = shelf_app(options, |d| {
        d.poll_ms = 200;
        d.link.timeout = std::time::Duration::from_millis(300);
        d.link.retries = 2;
    })
    .await;
    let started = std::time::Instant::now();
    let mut ids = Vec::new();
    for k in 0..30u16 {
        let to = loc(1 + k / 24, 1 + (k / 4) % 6, 1 + k % 4, 1);
        let (status, j) = app.post("/api/v1/jobs", &json!({"kind": "store", "to": to})).await;
        assert_eq!(status, 201, "{j}");
        ids.push(j["id"].clone());
    }
    for id in &ids {
        wait_job(&app, id, 20, |j| j["state"] == "completed").await;
    }
    assert!(started.elapsed() < std::time::Duration::from_secs(20), "{:?}", started.elapsed());
    assert_eq!(sim.violations(), 0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_site_health_names_a_device_that_does_not_answer() {
    let (app, sim) = shelf_app(sim(0), |d| d.offline_after = 2).await;
    let healthy = eventually("the site to be healthy", std::time::Duration::from_secs(10), async || {
        let (status, h) = app.get("/api/v1/health").await;
        if h["status"] == "ok" { Ok((status, h)) } else { Err(h) }
    })
    .await;
    assert_eq!(healthy.0, 200);
    assert_eq!(healthy.1["store"], "ok");
    assert_eq!(healthy.1["devices"][0]["id"], "shelf1");
    assert!(healthy.1["devices"][0]["seconds_since_contact"].as_f64().unwrap() < 5.0, "{}", healthy.1);
    sim.set_faults(rackd::protocols::faults::Faults { drop_rate: 1.0, ..Default::default() });
    let (status, h) = eventually("the site to be degraded", std::time::Duration::from_secs(10), async || {
        let (status, h) = app.get("/api/v1/health").await;
        if h["status"] == "degraded" { Ok((status, h)) } else { Err(h) }
    })
    .await;
    assert_eq!(status, 200, "the store works: still 200");
    assert_eq!(h["devices"][0]["online"], false, "{h}");
    assert_eq!(app.get("/readyz").await.0, 200, "readiness is the store's, not the devices'");
}
