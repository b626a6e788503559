//! `rackd_jobs` and `rackd_alarms_active` in `/metrics` are kept in memory (see
//! src/store/counts.rs): after submissions, dispatches, completions, failures, a retry,
//! cancels, alarms raised and cleared, and a restart, they are what the tables say, counted
//! by SQL here; and on both nodes of a cluster, whichever node took the jobs in.

use std::collections::BTreeMap;
use std::time::Duration;

use rackd::cli::demo::{Pace, start_with};
use rackd::config::devices::DeviceConfig;
use rackd::config::{ClusterConfig, Config};
use rackd::protocols::faults::Faults;
use rackd::sim::shelf::{ShelfSim, ShelfSimOptions};
use rackd::store::{self, Database, Engine, Pool};
use rstest::rstest;
use serde_json::{Value, json};

use crate::support::*;

type Counts = BTreeMap<(String, String), i64>;

/// The samples of `family` other than zero, by their two labels (`device` and `second`).
fn samples(text: &str, family: &str, second: &str) -> Counts {
    let prefix = format!("{family}{{device=\"");
    let between = format!("\",{second}=\"");
    text.lines()
        .filter_map(|line| {
            let rest = line.strip_prefix(&prefix)?;
            let (device, rest) = rest.split_once(&between)?;
            let (label, value) = rest.split_once("\"} ")?;
            let n: f64 = value.parse().ok()?;
            (n != 0.0).then(|| ((device.to_owned(), label.to_owned()), n as i64))
        })
        .collect()
}

/// What `/metrics` shows: jobs by device and state, active alarms by device and class.
async fn shown(app: &TestApp) -> (Counts, Counts) {
    let text = app.client.get(app.url("/metrics")).send().await.unwrap().text().await.unwrap();
    (samples(&text, "rackd_jobs", "state"), samples(&text, "rackd_alarms_active", "class"))
}

/// Rows of `(text, text, count)` grouped by SQL.
async fn grouped(pool: &Pool, sql: &'static str) -> Counts {
    let rows: Vec<(String, String, i64)> = match pool {
        Pool::Sqlite(p) => sqlx::query_as(sql).fetch_all(p).await.unwrap(),
        Pool::Postgres(p) => sqlx::query_as(sql).fetch_all(p).await.unwrap(),
    };
    rows.into_iter().map(|(a, b, n)| ((a, b), n)).collect()
}

/// What the tables hold, counted row by row.
async fn counted(pool: &Pool) -> (Counts, Counts) {
    let jobs = "SELECT COALESCE(device, ''), state, COUNT(*) FROM jobs GROUP BY COALESCE(device, ''), state";
    let alarms = "SELECT device, class, COUNT(*) FROM alarms WHERE cleared_at IS NULL GROUP BY device, class";
    (grouped(pool, jobs).await, grouped(pool, alarms).await)
}

/// Waits (bounded) until `app`'s `/metrics` shows what the tables hold; returns it.
async fn agree(app: &TestApp, pool: &Pool) -> (Counts, Counts) {
    eventually("/metrics to show the tables' counts", Duration::from_secs(10), async || {
        let (metrics, tables) = (shown(app).await, counted(pool).await);
        if metrics == tables { Ok(tables) } else { Err(format!("metrics {metrics:?}, tables {tables:?}")) }
    })
    .await
}

fn at(aisle: u16, bay: u16, level: u16) -> Value {
    json!({"aisle": aisle, "row": 1, "bay": bay, "level": level, "position": 1})
}

/// Waits until the alarms of `device` active through the API are `n`.
async fn active_alarms(app: &TestApp, device: &str, n: usize) {
    let path = format!("/api/v1/alarms?active=true&device={device}");
    eventually(format!("{n} active alarms on {device}"), Duration::from_secs(10), async || {
        let (_, page) = app.get(&path).await;
        let got = page["alarms"].as_array().map_or(0, Vec::len);
        if got == n { Ok(()) } else { Err(page) }
    })
    .await
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_counts_in_metrics_are_the_tables_through_work_alarms_and_a_restart(#[case] engine: Engine) {
    let options = ShelfSimOptions { task_time: Duration::from_millis(10), ..ShelfSimOptions::default() };
    let sim = ShelfSim::start("127.0.0.1:0", options).await.unwrap();
    let silent = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let device = |id: &str, address: String, aisle: u16| {
        let mut d = rackd::cli::demo::shelf_device(&sim, id, &address, vec![aisle]);
        d.poll_ms = 20;
        // Short enough that shelf2 is offline at once, long enough (with a fixed timer)
        // that a loaded machine's late replies do not take shelf1 offline too.
        d.link.timeout = Duration::from_millis(200);
        d.link.tuning.min_timeout = d.link.timeout;
        d.link.retries = 0;
        d.offline_after = 2;
        DeviceConfig::from(d)
    };
    // shelf1 works; shelf2 never answers, so its jobs wait and it has a link alarm.
    let devices = vec![
        device("shelf1", sim.local_addr().unwrap().to_string(), 1),
        device("shelf2", silent.local_addr().unwrap().to_string(), 2),
    ];
    let setup = |c: &mut Config| c.devices = devices.clone();
    let app = spawn_with(engine, setup).await;
    let pool = store::open(&app.db, Duration::from_secs(5)).await.unwrap();

    // Stores that complete, retrieves of empty places that fail, jobs that wait on shelf2.
    let mut jobs: Vec<Value> = (1..=5)
        .map(|bay| json!({"kind": "store", "barcode": format!("B{bay}"), "to": at(1, bay, 1)}))
        .collect();
    jobs.extend((1..=2).map(|bay| json!({"kind": "retrieve", "from": at(1, bay, 5)})));
    jobs.extend((1..=3).map(|bay| json!({"kind": "store", "to": at(2, bay, 1)})));
    let (status, batch) = app.post("/api/v1/jobs/batch", &json!({ "jobs": jobs })).await;
    assert_eq!(status, 201, "{batch}");
    let ended = wait_ended(&app, 7, 20).await;
    let failed: Vec<&Value> = ended.iter().filter(|j| j["state"] == "failed").collect();
    assert_eq!(failed.len(), 2, "{ended:?}");
    // A failed job retried (back to queued: its place is locked, so it waits), then
    // cancelled, and a job waiting on shelf2 re-prioritised.
    let (status, retried) = app.post(&format!("/api/v1/jobs/{}/retry", failed[0]["id"]), &json!({})).await;
    assert_eq!((status, retried["state"].as_str()), (200, Some("queued")), "{retried}");
    assert_eq!(
        shown(&app).await.0[&("shelf1".into(), "failed".into())],
        1,
        "a retried job is no longer failed"
    );
    let (status, cancelled) = app.post(&format!("/api/v1/jobs/{}/cancel", failed[0]["id"]), &json!({})).await;
    assert_eq!((status, cancelled["state"].as_str()), (200, Some("cancelled")), "{cancelled}");
    let (status, _) =
        app.patch(&format!("/api/v1/jobs/{}", batch["jobs"][8]["id"]), &json!({"priority": 1})).await;
    assert_eq!(status, 200);

    // shelf1 stops answering (a link alarm raised), then answers again (cleared).
    active_alarms(&app, "shelf2", 1).await;
    sim.set_faults(Faults { drop_rate: 1.0, ..Faults::default() });
    active_alarms(&app, "shelf1", 1).await;
    sim.set_faults(Faults::default());
    active_alarms(&app, "shelf1", 0).await;

    let (jobs, alarms) = agree(&app, &pool).await;
    let states: Vec<&str> = jobs.keys().map(|(_, s)| s.as_str()).collect();
    for state in ["queued", "completed", "failed", "cancelled"] {
        assert!(states.contains(&state), "no {state} job: {jobs:?}");
    }
    assert_eq!(alarms, BTreeMap::from([(("shelf2".into(), "link".into()), 1)]));
    let cleared =
        "SELECT device, class, COUNT(*) FROM alarms WHERE cleared_at IS NOT NULL GROUP BY device, class";
    assert!(grouped(&pool, cleared).await.contains_key(&("shelf1".into(), "link".into())), "one cleared");

    // After a restart the counts are read back from the store as they were.
    let (db, dir) = app.stop().await;
    let app = spawn_on(db, setup).await;
    assert_eq!(agree(&app, &pool).await, (jobs.clone(), alarms));
    let (status, _) = app.post("/api/v1/jobs", &json!({"kind": "store", "to": at(2, 9, 1)})).await;
    assert_eq!(status, 201);
    let (after, _) = agree(&app, &pool).await;
    assert_eq!(after[&("shelf2".into(), "queued".into())], jobs[&("shelf2".into(), "queued".into())] + 1);
    app.stop().await;
    pool.close().await;
    drop((dir, silent));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn both_nodes_of_a_cluster_show_the_counts_the_tables_hold() {
    let db = crate::support::postgres::database().await;
    let mut site = Config::demo();
    let pace = Pace { task_time: Duration::from_millis(20), crane_step: Duration::from_millis(5) };
    let _sims = start_with(&mut site, pace).await.unwrap();
    let node = |name: &str| {
        let (devices, name) = (site.devices.clone(), name.to_owned());
        spawn_on(Database::Postgres(db.clone()), move |c| {
            c.devices = devices;
            let lease_ms = 3000;
            c.cluster =
                Some(ClusterConfig { node: name, lease_ms, margin_ms: None, url: None, ca_file: None });
        })
    };
    let a = node("a").await;
    eventually("a to drive", Duration::from_secs(10), async || {
        let (_, view) = a.get("/api/v1/cluster").await;
        if view["role"] == "active" { Ok(()) } else { Err(view) }
    })
    .await;
    let b = node("b").await;
    let pool = store::open(&Database::Postgres(db.clone()), Duration::from_secs(5)).await.unwrap();

    // Jobs taken in by either node, driven by the active one.
    for (app, bay) in [(&b, 3), (&a, 4), (&b, 5)] {
        let travel =
            json!({"kind": "travel", "to": {"aisle": 2, "row": 1, "bay": bay, "level": 1, "position": 1}});
        assert_eq!(app.post("/api/v1/jobs", &travel).await.0, 201);
        let (status, _) = app.post("/api/v1/jobs", &json!({"kind": "store", "to": at(1, bay, 2)})).await;
        assert_eq!(status, 201);
    }
    wait_ended(&b, 6, 30).await;
    let (jobs, _) = agree(&a, &pool).await;
    assert_eq!(agree(&b, &pool).await.0, jobs, "the standby shows what the active node shows");
    assert_eq!(jobs.values().sum::<i64>(), 6, "{jobs:?}");
    assert!(jobs.keys().all(|(_, state)| state == "completed"), "{jobs:?}");
    b.stop().await;
    a.stop().await;
    pool.close().await;
}
