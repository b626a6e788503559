//! Reloading a cluster's nodes: each tells the hash of the `[site]` and `[[devices]]` it
//! runs; a standby reloaded with another file keeps it for its takeover (it runs no device
//! to change), the active node raises `config_drift` while the nodes differ, and the
//! standby takes over with what it kept; the drift clears once the other node is reloaded
//! the same.

use std::time::Duration;

use rackd::cli::demo::{Pace, start_with};
use rackd::config::devices::DeviceConfig;
use rackd::config::{ClusterConfig, Config};
use rackd::store::Database;
use serde_json::Value;

use crate::support::{TestApp, eventually, spawn_from_file_on, split};

const PACE: Pace = Pace { task_time: Duration::from_millis(200), crane_step: Duration::from_millis(20) };

async fn node(db: &str, name: &str, site: &Config) -> (TestApp, std::path::PathBuf) {
    let mut config = site.clone();
    let node = name.to_owned();
    config.cluster = Some(ClusterConfig { node, lease_ms: 2000, margin_ms: None, url: None, ca_file: None });
    spawn_from_file_on(Database::Postgres(db.to_owned()), config, tempfile::tempdir().unwrap()).await
}

/// Waits until `check` holds for `app`'s answer to `GET path` (bounded).
async fn until(app: &TestApp, path: &str, secs: u64, check: impl Fn(&Value) -> bool) -> Value {
    eventually(format!("GET {path} to come right"), Duration::from_secs(secs), async || {
        let (status, body) = app.get(path).await;
        if status == 200 && check(&body) { Ok(body) } else { Err(format!("{status} {body}")) }
    })
    .await
}

async fn reload(app: &TestApp) -> Value {
    let post = app.client.post(app.url("/api/v1/config/reload")).header("content-type", "application/json");
    let (status, body) = split(post.send().await.unwrap()).await;
    assert_eq!(status, 200, "{body}");
    body
}

/// Rewrites the node's file with the crane at `address` (keeping its listen address,
/// database and cluster).
fn crane_at(file: &std::path::Path, address: &str) -> String {
    let mut config = Config::load(file).unwrap();
    for d in &mut config.devices {
        if let DeviceConfig::Crane(c) = d {
            c.link.address = address.to_owned();
        }
    }
    std::fs::write(file, toml::to_string(&config).unwrap()).unwrap();
    config.site_hash()
}

fn drift_alarm(alarms: &Value) -> bool {
    alarms["alarms"].as_array().unwrap().iter().any(|a| a["kind"] == "config_drift")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_standby_keeps_its_reload_for_its_takeover_and_drift_is_raised_until_the_nodes_agree() {
    let db = crate::support::postgres::database().await;
    let mut site = Config::demo();
    let _sims = start_with(&mut site, PACE).await.unwrap();
    let (a, file_a) = node(&db, "a", &site).await;
    until(&a, "/api/v1/cluster", 10, |c| c["role"] == "active").await;
    let (b, file_b) = node(&db, "b", &site).await;
    let same = until(&a, "/api/v1/cluster", 10, |c| {
        c["nodes"]
            .as_array()
            .is_some_and(|n| n.len() == 2 && n.iter().all(|n| n["config_hash"] == c["config_hash"]))
    })
    .await;
    assert_eq!(same["config_drift"], false, "{same}");

    // The standby reloads a file with the crane under another name: kept, not driven.
    let crane = site.devices.iter().find_map(|d| match d {
        DeviceConfig::Crane(c) => Some(c.link.address.clone()),
        _ => None,
    });
    let renamed = crane.unwrap().replace("127.0.0.1", "localhost");
    let hash = crane_at(&file_b, &renamed);
    let body = reload(&b).await;
    assert_eq!(
        (body["kept_for_takeover"].as_bool(), body["hash"].as_str()),
        (Some(true), Some(hash.as_str()))
    );
    assert_eq!(body["devices"][0]["keys"], serde_json::json!(["address"]), "{body}");
    // The active node sees the drift and says so, as an alarm and in the cluster view.
    until(&a, "/api/v1/alarms?active=true", 10, drift_alarm).await;
    until(&b, "/api/v1/cluster", 10, |c| c["config_drift"] == true).await;

    // The active node stops and lets go: the standby takes over with the file it kept.
    let (_, _kept) = a.stop().await;
    until(&b, "/api/v1/cluster", 10, |c| c["role"] == "active").await;
    until(&b, "/api/v1/devices", 10, |d| d.to_string().contains(&renamed)).await;

    // The old node comes back as a standby with the old file: drift again, from the new
    // active node; reloaded with the same file as the active one, it clears.
    let (a, file_a2) = node(&db, "a", &Config::load(&file_a).unwrap()).await;
    until(&b, "/api/v1/alarms?active=true", 15, drift_alarm).await;
    crane_at(&file_a2, &renamed);
    let body = reload(&a).await;
    assert_eq!(body["hash"].as_str(), Some(hash.as_str()));
    until(&b, "/api/v1/alarms?active=true", 15, |alarms| !drift_alarm(alarms)).await;
    until(&a, "/api/v1/cluster", 10, |c| c["config_drift"] == false).await;
    a.stop().await;
    b.stop().await;
}

/// A site of one shelf at an address where nothing answers (no other test's simulator).
const SHELF_SITE: &str = r#"
[[site.aisles]]
aisle = 1
rows = 1
bays = 2
levels = 1
positions = 1

[[devices]]
id = "shelf-1"
kind = "shelf"
address = "127.0.0.1:9"
aisles = [1]
"#;

/// A reload that runs while a standby takes over (issue 51, item 3): the takeover waits
/// for it, and then drives what the reload kept, so the node reports the hash of what it
/// drives. The interleaving is forced, not timed: the reload is held inside (its write of
/// the locations waits on a lock this test holds, which PostgreSQL shows) before the lease
/// is let go, and let on only once the node has won it. Without the takeover holding the
/// reload's lock, the node read the old configuration, drove its devices and reported the
/// new one's hash.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_reload_during_a_takeover_changes_what_the_node_drives() {
    use sqlx::Connection;
    let db = crate::support::postgres::database().await;
    let pg = rackd::store::Database::Postgres(db.clone());
    drop(rackd::store::open(&pg, Duration::from_secs(5)).await.expect("the schema"));
    // A node that holds the lease and beats until the test lets it go.
    let mut ghost = sqlx::PgConnection::connect(&db).await.unwrap();
    sqlx::query(
        "INSERT INTO cluster_lease (name, holder, epoch, beat, renewed_at) VALUES ('dispatch', 'ghost', 1, 0, 0)",
    )
    .execute(&mut ghost)
    .await
    .unwrap();
    let beating = tokio::spawn(async move {
        loop {
            let beat = "UPDATE cluster_lease SET beat = beat + 1 WHERE holder = 'ghost' AND NOT released";
            sqlx::query(beat).execute(&mut ghost).await.unwrap();
            tokio::time::sleep(Duration::from_millis(300)).await;
        }
    });

    let mut config = Config::parse(SHELF_SITE, std::path::Path::new("rackd.toml")).unwrap();
    config.cluster = Some(ClusterConfig {
        node: "b".into(),
        lease_ms: 5000,
        margin_ms: Some(5000),
        url: None,
        ca_file: None,
    });
    let (b, file) = spawn_from_file_on(pg, config, tempfile::tempdir().unwrap()).await;
    until(&b, "/api/v1/cluster", 10, |c| c["role"] == "standby").await;
    let mut changed = Config::load(&file).unwrap();
    let DeviceConfig::Shelf(shelf) = &mut changed.devices[0] else { panic!("a shelf") };
    shelf.link.address = "localhost:9".into();
    std::fs::write(&file, toml::to_string(&changed).unwrap()).unwrap();
    let new_hash = changed.site_hash();

    // The reload, held at its write of the locations: past its choice of a standby's path.
    let mut lock = sqlx::PgConnection::connect(&db).await.unwrap();
    sqlx::raw_sql("BEGIN; LOCK TABLE locations IN ACCESS EXCLUSIVE MODE").execute(&mut lock).await.unwrap();
    let (client, url) = (b.client.clone(), b.url("/api/v1/config/reload"));
    let reloading = tokio::spawn(async move {
        let post = client.post(url).header("content-type", "application/json");
        split(post.send().await.unwrap()).await
    });
    let mut watch = sqlx::PgConnection::connect(&db).await.unwrap();
    eventually("the reload to wait on the locations' lock", Duration::from_secs(10), async || {
        let waiting: i64 = sqlx::query_scalar(
            "SELECT count(*) FROM pg_stat_activity WHERE datname = current_database() \
             AND wait_event_type = 'Lock' AND query ILIKE 'INSERT INTO locations%'",
        )
        .fetch_one(&mut watch)
        .await
        .unwrap();
        waiting > 0
    })
    .await;

    // The lease let go: the node wins it and its takeover begins, the reload still held.
    beating.abort();
    let _ = beating.await;
    let release = "UPDATE cluster_lease SET released = TRUE WHERE name = 'dispatch'";
    sqlx::query(release).execute(&mut watch).await.unwrap();
    until(&b, "/api/v1/cluster", 10, |c| c["takeovers"] == 1).await;
    sqlx::raw_sql("ROLLBACK").execute(&mut lock).await.unwrap();

    let (status, body) = reloading.await.unwrap();
    assert_eq!((status, body["hash"].as_str()), (200, Some(new_hash.as_str())), "{body}");
    let devices = until(&b, "/api/v1/devices", 10, |d| d.as_array().is_some_and(|d| !d.is_empty())).await;
    let cluster = b.get("/api/v1/cluster").await.1;
    assert_eq!(
        (devices[0]["address"].as_str(), cluster["config_hash"].as_str()),
        (Some("localhost:9"), Some(new_hash.as_str())),
        "the node drives the shelf at the address of the configuration it reports: {devices} {cluster}"
    );
    b.stop().await;
}
