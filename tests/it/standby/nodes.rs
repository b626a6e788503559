//! Two rackd nodes of one cluster in this process, on one PostgreSQL and the demo's
//! simulated machines: what a standby serves itself (submissions, reads, `/readyz`), what
//! it forwards to the active node (devices, pauses), what both tell (`/api/v1/cluster`,
//! `/metrics`), and a clean handover (the active node stops and lets go of its lease: the
//! standby takes over at once, raises the takeover alarm and finishes the work).

use std::time::{Duration, Instant};

use rackd::cli::demo::{Pace, start_with};
use rackd::config::devices::DeviceConfig;
use rackd::config::{ClusterConfig, Config};
use rackd::store::Database;
use serde_json::{Value, json};

use crate::support::proxy::Proxy;
use crate::support::ws::Ws;
use crate::support::{TestApp, eventually, spawn_on};

const PACE: Pace = Pace { task_time: Duration::from_millis(200), crane_step: Duration::from_millis(20) };

/// A node on the site's devices with a lease long enough that a takeover by expiry (at
/// least 3.6 s) cannot pass for one after a release.
async fn node(db: &str, name: &str, site: &Config) -> TestApp {
    node_with(db, name, site.devices.clone(), 3000).await
}

async fn node_with(db: &str, name: &str, devices: Vec<DeviceConfig>, lease_ms: u64) -> TestApp {
    let name = name.to_owned();
    spawn_on(Database::Postgres(db.to_owned()), move |c| {
        c.devices = devices;
        c.cluster = Some(ClusterConfig { node: name, lease_ms, margin_ms: None, url: None, ca_file: None });
    })
    .await
}

/// Waits until `check` holds for `app`'s answer to `GET path` (bounded).
async fn until(app: &TestApp, path: &str, secs: u64, check: impl Fn(&Value) -> bool) -> Value {
    eventually(format!("GET {path} to come right"), Duration::from_secs(secs), async || {
        let (status, body) = app.get(path).await;
        if status == 200 && check(&body) { Ok(body) } else { Err(format!("{status} {body}")) }
    })
    .await
}

fn travel(reference: &str, bay: u16) -> Value {
    json!({"kind": "travel", "reference": reference,
           "to": {"aisle": 2, "row": 1, "bay": bay, "level": 1, "position": 1}})
}

async fn completed(app: &TestApp, id: i64) {
    until(app, &format!("/api/v1/jobs/{id}"), 30, |j| j["state"] == "completed").await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_standby_serves_forwards_and_takes_over_when_the_active_node_lets_go() {
    let db = crate::support::postgres::database().await;
    let mut site = Config::demo();
    let _sims = start_with(&mut site, PACE).await.unwrap();
    let a = node(&db, "a", &site).await;
    until(&a, "/api/v1/cluster", 10, |c| c["role"] == "active").await;
    let b = node(&db, "b", &site).await;

    // Both are ready; each says what it is.
    assert_eq!(a.get("/readyz").await, (200, json!({"status": "ok", "role": "active"})));
    assert_eq!(b.get("/readyz").await, (200, json!({"status": "ok", "role": "standby"})));
    let view =
        until(&b, "/api/v1/cluster", 10, |c| c["nodes"].as_array().is_some_and(|n| n.len() == 2)).await;
    assert_eq!((view["node"].clone(), view["role"].clone()), (json!("b"), json!("standby")));
    assert_eq!((view["lease"]["holder"].clone(), view["lease"]["epoch"].clone()), (json!("a"), json!(1)));

    // A job submitted to the standby is driven by the active node, and the standby's
    // subscribers see it run: its hub follows the log every node writes.
    // The active node logs its crane's status once it has polled it.
    let (mut ws, snapshot) =
        eventually("the standby to show devices from the log", Duration::from_secs(10), async || {
            let mut ws = Ws::connect(&b.base, "").await;
            let snapshot = ws.json().await;
            let devices = snapshot["data"]["devices"].as_array().unwrap();
            if devices.iter().any(|d| d["id"] == "crane1") {
                Ok((ws, snapshot))
            } else {
                Err(snapshot["data"]["devices"].clone())
            }
        })
        .await;
    let (status, job) = b.post("/api/v1/jobs", &travel("via-b", 3)).await;
    assert_eq!(status, 201, "{job}");
    completed(&b, job["id"].as_i64().unwrap()).await;
    let mut seen = Vec::new();
    while !seen.iter().any(|e: &Value| e["data"]["id"] == job["id"] && e["data"]["state"] == "completed") {
        seen.extend(ws.events(1).await);
    }
    let seqs: Vec<i64> = seen.iter().map(|e| e["seq"].as_i64().unwrap()).collect();
    assert_eq!(seqs[0], snapshot["seq"].as_i64().unwrap() + 1, "from the snapshot on");
    assert!(seqs.windows(2).all(|w| w[1] == w[0] + 1), "in order, without a gap: {seqs:?}");
    ws.close().await;

    // The standby has no devices of its own: it forwards, pauses included.
    let (status, devices) = b.get("/api/v1/devices").await;
    assert_eq!(status, 200, "{devices}");
    assert!(devices.as_array().unwrap().iter().any(|d| d["id"] == "crane1"), "{devices}");
    let (status, paused) = b.post("/api/v1/devices/crane1/pause", &json!({"reason": "check"})).await;
    assert_eq!((status, paused["paused"].clone()), (200, json!(true)), "{paused}");
    assert_eq!(a.get("/api/v1/devices/crane1").await.1["paused"], true);
    assert_eq!(b.post("/api/v1/devices/crane1/resume", &json!({})).await.0, 200);

    let metrics = |app: &TestApp| {
        let (client, url) = (app.client.clone(), app.url("/metrics"));
        async move { client.get(url).send().await.unwrap().text().await.unwrap() }
    };
    assert!(metrics(&a).await.contains("rackd_cluster_active{node=\"a\"} 1"));
    assert!(metrics(&b).await.contains("rackd_cluster_active{node=\"b\"} 0"));

    // a stops cleanly: it lets go, and b takes over without waiting out the lease.
    let let_go = Instant::now();
    a.stop().await;
    // The role reads active once the lease is won; the takeover is counted once the node
    // drives (it reads its configuration and starts its devices in between).
    until(&b, "/api/v1/cluster", 10, |c| c["role"] == "active").await;
    assert!(let_go.elapsed() < Duration::from_millis(2500), "took {:?}", let_go.elapsed());
    let view = until(&b, "/api/v1/cluster", 10, |c| c["takeovers"] == 1).await;
    assert_eq!((view["epoch"].clone(), view["takeovers"].clone()), (json!(2), json!(1)), "{view}");
    let alarms = until(&b, "/api/v1/alarms?active=true", 10, |a| {
        a["alarms"].as_array().is_some_and(|l| l.iter().any(|x| x["kind"] == "takeover"))
    })
    .await;
    assert!(alarms.to_string().contains("cluster"), "{alarms}");
    let (status, job) = b.post("/api/v1/jobs", &travel("after", 5)).await;
    assert_eq!(status, 201, "{job}");
    completed(&b, job["id"].as_i64().unwrap()).await;
    assert!(metrics(&b).await.contains("rackd_cluster_takeovers_total{node=\"b\"} 1"));
    b.stop().await;
}

/// The site's devices with the crane reached through a proxy of its own.
async fn crane_through_proxy(site: &Config) -> (Vec<DeviceConfig>, Proxy) {
    let mut devices = site.devices.clone();
    let crane = devices.iter_mut().find_map(|d| match d {
        DeviceConfig::Crane(c) => Some(c),
        _ => None,
    });
    let crane = crane.expect("the demo has a crane");
    let proxy = Proxy::to(&crane.link.address).await;
    crane.link.address = proxy.addr.to_string();
    (devices, proxy)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_active_node_cut_off_from_the_database_stops_driving_before_the_standby_starts() {
    let db = crate::support::postgres::database().await;
    let mut site = Config::demo();
    let sims = start_with(&mut site, PACE).await.unwrap();
    // a reaches the database and the crane through proxies, b the database directly and
    // the crane through a proxy of its own: what each node sent the crane, and when.
    let (db_proxy, db_via_proxy) = Proxy::to_postgres(&db).await;
    let (a_devices, a_crane) = crane_through_proxy(&site).await;
    let (b_devices, b_crane) = crane_through_proxy(&site).await;
    // A lease of 2 s: with 1 s, a standby renewing on a machine loaded by the whole suite
    // could itself miss its lease and stop: the likely cause of b refusing connections
    // once in a full run.
    let a = node_with(&db_via_proxy, "a", a_devices, 2000).await;
    until(&a, "/api/v1/cluster", 10, |c| c["role"] == "active").await;
    let b = node_with(&db, "b", b_devices, 2000).await;
    let (_, job) = b.post("/api/v1/jobs", &travel("before", 4)).await;
    completed(&b, job["id"].as_i64().unwrap()).await;
    assert!(a_crane.sent().is_some() && b_crane.sent().is_none(), "only the active node talks to the crane");

    db_proxy.block();
    // Bounds, not paces (the lease is 2 s): room for a machine the other tests load.
    let ended = a.ended(Duration::from_secs(30)).await.unwrap_err().to_string();
    assert!(ended.contains("lost the cluster's lease"), "{ended}");
    until(&b, "/api/v1/cluster", 30, |c| c["role"] == "active").await;
    let (_, job) = b.post("/api/v1/jobs", &travel("after", 6)).await;
    completed(&b, job["id"].as_i64().unwrap()).await;
    let (_, a_last) = a_crane.sent().unwrap();
    let (b_first, _) = b_crane.sent().expect("b drives the crane after the takeover");
    assert!(a_last < b_first, "a talked to the crane until {a_last:?}, b from {b_first:?}");
    assert_eq!(sims.1.violations(), 0, "{:?}", sims.1.violation_log());
    b.stop().await;
}
