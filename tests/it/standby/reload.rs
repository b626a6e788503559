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
