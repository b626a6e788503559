//! Reloads applied to a running site over real sockets: two shelf PLCs and a crane
//! simulated, jobs running on them, and the file changed one device at a time: a tags
//! device added, a shelf's poll period and a crane's timeout changed, a shelf with queued
//! jobs removed (they wait, then run once it is back), an address renamed. Every job runs
//! exactly once, the simulators see no breach, and the devices a reload does not name keep
//! their link (its request counter never starts again) and their work.

use std::path::Path;
use std::time::Duration;

use rackd::config::Config;
use rackd::config::devices::{CraneConfig, DeviceConfig};
use rackd::sim::crane::{CraneSim, CraneSimOptions};
use rackd::sim::shelf::ShelfSim;
use rackd::wire::task_id_for;
use serde_json::{Value, json};

use crate::shelf::{device_for, sim};
use crate::support::*;

/// Aisles 1 and 3 are shelves, 2 the crane.
fn site(shelf1: &ShelfSim, shelf3: &ShelfSim, crane: &CraneSim) -> Config {
    let mut config = Config::demo();
    let mut third = config.site.aisles[0].clone();
    third.aisle = 3;
    config.site.aisles.push(third);
    let mut crane2 = CraneConfig::new("crane-2", &crane.local_addr().to_string(), vec![2]);
    crane2.poll_ms = 50;
    config.devices = vec![
        device_for(shelf1, |d| d.id = "shelf-1".into()).into(),
        crane2.into(),
        device_for(shelf3, |d| (d.id, d.aisles) = ("shelf-3".into(), vec![3])).into(),
    ];
    config
}

/// Writes `config` to `file`, keeping the running file's listen address and database.
fn write(file: &Path, mut config: Config) {
    let running = Config::load(file).unwrap();
    config.server.listen = running.server.listen;
    config.database = running.database;
    std::fs::write(file, toml::to_string(&config).unwrap()).unwrap();
}

async fn reload(app: &TestApp) -> Value {
    let post = app.client.post(app.url("/api/v1/config/reload")).header("content-type", "application/json");
    let (status, body) = split(post.send().await.unwrap()).await;
    assert_eq!(status, 200, "{body}");
    body
}

/// A device's request counter.
async fn requests(app: &TestApp, id: &str) -> u64 {
    let (_, d) = app.get(&format!("/api/v1/devices/{id}")).await;
    d["link"]["requests"].as_u64().unwrap_or(0)
}

/// A light on aisle 1 or 3, or a travel on aisle 2, at its own place.
fn job(aisle: u16, n: u16) -> Value {
    let at = json!({"aisle": aisle, "row": 1 + n % 2, "bay": 1 + n / 2 % 10, "level": 1 + n / 20 % 6, "position": 1});
    match aisle {
        2 => json!({"kind": "travel", "to": at}),
        _ => json!({"kind": "light", "location": at, "color": "green", "on": true}),
    }
}

async fn post(app: &TestApp, body: Value) -> i64 {
    let (status, created) =
        split(app.client.post(app.url("/api/v1/jobs")).json(&body).send().await.unwrap()).await;
    assert_eq!(status, 201, "{created}");
    created["id"].as_i64().unwrap()
}

/// The devices that the reload does not name keep their link and their work: their request
/// counters go on from where they were.
struct Untouched(Vec<(String, u64)>);

impl Untouched {
    async fn now(app: &TestApp, ids: &[&str]) -> Untouched {
        let mut all = Vec::new();
        for id in ids {
            all.push((id.to_string(), requests(app, id).await));
        }
        Untouched(all)
    }

    async fn still(&self, app: &TestApp) {
        for (id, before) in &self.0 {
            let now = requests(app, id).await;
            assert!(now >= *before, "{id}: {now} requests after the reload, {before} before: it reconnected");
            eventually(format!("{id} to go on"), Duration::from_secs(10), async || {
                let after = requests(app, id).await;
                if after > *before { Ok(()) } else { Err(after) }
            })
            .await;
        }
    }
}

#[tokio::test]
async fn devices_change_one_at_a_time_while_the_others_run_jobs() {
    let shelf1 = ShelfSim::start("127.0.0.1:0", sim(150)).await.unwrap();
    let shelf3 = ShelfSim::start("127.0.0.1:0", sim(150)).await.unwrap();
    let options = CraneSimOptions { step: Duration::from_millis(10), ..Default::default() };
    let crane = CraneSim::start("127.0.0.1:0", options).await.unwrap();
    let mut config = site(&shelf1, &shelf3, &crane);
    let (app, file) = spawn_from_file(&toml::to_string(&config).unwrap()).await;
    let before = app.get("/api/v1/config").await.1;
    let mut posted: Vec<(i64, u16)> = Vec::new();
    let mut n = 0;
    let mut more = async |app: &TestApp, posted: &mut Vec<(i64, u16)>, aisles: &[u16]| {
        for &aisle in aisles {
            posted.push((post(app, job(aisle, n)).await, aisle));
        }
        n += 1;
    };
    for _ in 0..3 {
        more(&app, &mut posted, &[1, 2, 3]).await;
    }
    eventually("every device online", Duration::from_secs(10), async || {
        let (_, devices) = app.get("/api/v1/devices").await;
        let all = devices.as_array().unwrap().iter().all(|d| d["online"] == true);
        if all { Ok(()) } else { Err(devices) }
    })
    .await;

    // A tags device added on the first shelf's registers: nothing else is touched.
    let untouched = Untouched::now(&app, &["shelf-1", "crane-2", "shelf-3"]).await;
    let tags: DeviceConfig = Config::parse(
        &format!(
            "[[devices]]\nid = \"tower\"\nkind = \"tags\"\nprotocol = \"modbus-udp\"\naddress = \"{}\"\n\
             poll_ms = 50\nquirks = [\"length0\"]\n[devices.tags]\n\"slot1.task\" = \"4x0\"\n",
            shelf1.local_addr().unwrap()
        ),
        &file,
    )
    .unwrap()
    .devices
    .remove(0);
    config.devices.push(tags);
    write(&file, config.clone());
    let body = reload(&app).await;
    assert_eq!(body["devices"], json!([{"id": "tower", "change": "added"}]), "{body}");
    assert_ne!(body["hash"], before["hash"]);
    more(&app, &mut posted, &[1, 2, 3]).await;
    eventually("the tags device to read its tag", Duration::from_secs(10), async || {
        let (_, tags) = app.get("/api/v1/devices/tower/tags").await;
        if tags.to_string().contains("\"good\"") { Ok(()) } else { Err(tags) }
    })
    .await;
    untouched.still(&app).await;

    // A shelf's poll period, while the crane and the other shelf run jobs.
    let untouched = Untouched::now(&app, &["crane-2", "shelf-3", "tower"]).await;
    let DeviceConfig::Shelf(s) = &mut config.devices[0] else { unreachable!() };
    s.poll_ms = 30;
    write(&file, config.clone());
    more(&app, &mut posted, &[1, 2, 3]).await;
    let body = reload(&app).await;
    assert_eq!(body["devices"], json!([{"id": "shelf-1", "change": "changed", "keys": ["poll_ms"]}]));
    more(&app, &mut posted, &[1, 2, 3]).await;
    untouched.still(&app).await;

    // A crane's timeout, while the shelves run jobs.
    let untouched = Untouched::now(&app, &["shelf-1", "shelf-3", "tower"]).await;
    let DeviceConfig::Crane(c) = &mut config.devices[1] else { unreachable!() };
    c.handshake_timeout_ms += 500;
    write(&file, config.clone());
    more(&app, &mut posted, &[1, 2, 3]).await;
    let body = reload(&app).await;
    assert_eq!(
        body["devices"],
        json!([{"id": "crane-2", "change": "changed", "keys": ["handshake_timeout_ms"]}])
    );
    more(&app, &mut posted, &[1, 2, 3]).await;
    untouched.still(&app).await;

    // The second shelf removed with jobs queued for it (paused: they wait in rackd), and
    // the first shelf's address renamed (the same PLC, by name): both at once.
    let third: Vec<i64> = posted.iter().filter(|(_, a)| *a == 3).map(|(id, _)| *id).collect();
    eventually("the second shelf's jobs to end", Duration::from_secs(30), async || {
        for id in &third {
            let (_, j) = app.get(&format!("/api/v1/jobs/{id}")).await;
            if j["state"] != "completed" {
                return Err(j);
            }
        }
        Ok(())
    })
    .await;
    let pause = app.client.post(app.url("/api/v1/devices/shelf-3/pause")).json(&json!({"reason": "cable"}));
    assert!(pause.send().await.unwrap().status().is_success());
    let queued: Vec<i64> = {
        let mut ids = Vec::new();
        for k in 0..3 {
            ids.push(post(&app, job(3, 100 + k)).await);
        }
        ids
    };
    let untouched = Untouched::now(&app, &["crane-2", "tower"]).await;
    let removed = config.devices.remove(2);
    let DeviceConfig::Shelf(s) = &mut config.devices[0] else { unreachable!() };
    s.link.address = format!("localhost:{}", shelf1.local_addr().unwrap().port());
    write(&file, config.clone());
    let body = reload(&app).await;
    assert_eq!(
        body["devices"],
        json!([{"id": "shelf-1", "change": "changed", "keys": ["address"]}, {"id": "shelf-3", "change": "removed"}])
    );
    for id in &queued {
        let (_, j) = app.get(&format!("/api/v1/jobs/{id}")).await;
        assert_eq!(
            (j["state"].as_str(), j["waiting"]["reason"].as_str()),
            (Some("queued"), Some("no_device")),
            "{j}"
        );
    }
    let (status, _) = app.get("/api/v1/devices/shelf-3").await;
    assert_eq!(status, 404, "a removed device is not listed");
    more(&app, &mut posted, &[1, 2]).await;
    untouched.still(&app).await;

    // Back again (still paused, as its operator left it): resumed, its queued jobs run once.
    config.devices.push(removed);
    write(&file, config.clone());
    let body = reload(&app).await;
    assert_eq!(body["devices"], json!([{"id": "shelf-3", "change": "added"}]));
    let resume = app.client.post(app.url("/api/v1/devices/shelf-3/resume")).json(&json!({}));
    assert!(resume.send().await.unwrap().status().is_success());
    posted.extend(queued.iter().map(|id| (*id, 3)));

    let ended = wait_ended(&app, posted.len(), 60).await;
    for j in &ended {
        assert_eq!(j["state"], "completed", "{j}");
    }
    for (id, aisle) in &posted {
        let task = task_id_for(*id);
        let received = match aisle {
            1 => shelf1.received(task),
            2 => crane.received(task),
            _ => shelf3.received(task),
        };
        assert_eq!(received, 1, "job {id} (aisle {aisle}) reached its machine {received} times");
    }
    assert_eq!((shelf1.violations(), shelf3.violations()), (0, 0), "writes into busy slots");
    assert_eq!(crane.violations(), 0, "{:#?}", crane.violation_log());
    assert_eq!(crane.refused(), 0, "tasks handed to a busy crane");

    // Audited, each with the hash it loaded; the configuration now running says so too.
    let (_, audit) = app.get("/api/v1/audit?limit=100").await;
    let entries: Vec<&Value> =
        audit["entries"].as_array().unwrap().iter().filter(|e| e["action"] == "reload").collect();
    assert_eq!(entries.len(), 5, "{audit}");
    let now = app.get("/api/v1/config").await.1;
    assert!(entries[0]["reason"].as_str().unwrap().contains(now["hash"].as_str().unwrap()), "{audit}");
    assert_eq!(now["hash"], json!(Config::load(&file).unwrap().site_hash()));
    app.stop().await;
}

/// A device that holds a job on the machine is not removed (409 naming the job, nothing
/// applied, the job runs on); once the job has ended it is, and the reload is told on the
/// event stream.
#[tokio::test]
async fn a_device_holding_a_job_is_not_removed_until_it_ends() {
    let shelf1 = ShelfSim::start("127.0.0.1:0", sim(100)).await.unwrap();
    let shelf3 = ShelfSim::start("127.0.0.1:0", sim(1500)).await.unwrap();
    let options = CraneSimOptions { step: Duration::from_millis(10), ..Default::default() };
    let crane = CraneSim::start("127.0.0.1:0", options).await.unwrap();
    let mut config = site(&shelf1, &shelf3, &crane);
    let (app, file) = spawn_from_file(&toml::to_string(&config).unwrap()).await;
    let mut ws = crate::support::ws::Ws::connect(&app.base, "?topics=config").await;
    let _snapshot = ws.json().await;
    let id = post(&app, job(3, 1)).await;
    eventually("the job on the machine", Duration::from_secs(10), async || {
        let (_, j) = app.get(&format!("/api/v1/jobs/{id}")).await;
        if j["state"] == "dispatched" || j["state"] == "running" { Ok(()) } else { Err(j) }
    })
    .await;
    let before = app.get("/api/v1/config").await.1;
    config.devices.retain(|d| d.id() != "shelf-3");
    write(&file, config.clone());
    let post = app.client.post(app.url("/api/v1/config/reload")).header("content-type", "application/json");
    let refused = split(post.send().await.unwrap()).await;
    assert_error(&refused, 409, "device_busy");
    let message = refused.1["error"]["message"].as_str().unwrap();
    assert!(message.contains("shelf-3") && message.contains(&id.to_string()), "{message}");
    assert_eq!(app.get("/api/v1/config").await.1, before, "nothing was applied");
    let (status, _) = app.get("/api/v1/devices/shelf-3").await;
    assert_eq!(status, 200);

    let ended = wait_ended(&app, 1, 20).await;
    assert_eq!(ended[0]["state"], "completed", "{:?}", ended);
    assert_eq!(shelf3.received(task_id_for(id)), 1);
    // The job's end is in the store before the dispatcher's queues hear of it (they are
    // told after the commit): until they do, the reload is refused as before, and applies
    // nothing.
    let body = eventually("the reload once the job has ended", Duration::from_secs(10), async || {
        let post =
            app.client.post(app.url("/api/v1/config/reload")).header("content-type", "application/json");
        match split(post.send().await.unwrap()).await {
            (200, body) => Ok(body),
            (409, body) if body["error"]["code"] == "device_busy" => Err(body),
            (status, body) => panic!("{status} {body}"),
        }
    })
    .await;
    assert_eq!(body["devices"], json!([{"id": "shelf-3", "change": "removed"}]));
    let told = ws.events(1).await;
    assert_eq!(told[0]["type"], "config.reloaded", "{told:?}");
    assert_eq!(told[0]["data"]["hash"], body["hash"]);
    assert_eq!(told[0]["data"]["devices"], body["devices"]);
    assert_eq!(shelf3.violations(), 0);
    app.stop().await;
}
