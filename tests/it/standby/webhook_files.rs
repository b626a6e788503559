//! An optional integration never blocks failover (issue 51, item 4). A webhook's
//! `secret_file` and `ca_file` were read again when a node took over: a file rotated or
//! removed since the start made the standby exit with "won the lease but cannot drive",
//! and with both nodes alike no node drove the machines. They are read when the
//! configuration is loaded: a standby whose files are gone by its takeover drives the
//! machines, and delivers signed with the secret it read; a reload meanwhile reads them
//! again and is refused, as `check-config` would refuse the file, keeping what was loaded.
//! Before the fix, the standby exited at its takeover.

use std::time::Duration;

use rackd::cli::demo::{Pace, start_with};
use rackd::config::{ClusterConfig, Config};
use rackd::store::Database;
use serde_json::{Value, json};

use crate::support::receiver::{Receiver, SECRET};
use crate::support::tls::Ca;
use crate::support::{TestApp, assert_error, eventually, spawn_from_file_on, split};

const PACE: Pace = Pace { task_time: Duration::from_millis(200), crane_step: Duration::from_millis(20) };

/// A node started from a file, as `serve --config` starts it.
async fn node(db: &str, name: &str, site: &Config) -> TestApp {
    let mut config = site.clone();
    let node = name.to_owned();
    config.cluster = Some(ClusterConfig { node, lease_ms: 2000, margin_ms: None, url: None, ca_file: None });
    spawn_from_file_on(Database::Postgres(db.to_owned()), config, tempfile::tempdir().unwrap()).await.0
}

/// Waits until `check` holds for `app`'s answer to `GET path` (bounded).
async fn until(app: &TestApp, path: &str, secs: u64, check: impl Fn(&Value) -> bool) -> Value {
    eventually(format!("GET {path} to come right"), Duration::from_secs(secs), async || {
        let (status, body) = app.get(path).await;
        if status == 200 && check(&body) { Ok(body) } else { Err(format!("{status} {body}")) }
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_standby_takes_over_though_the_webhook_files_it_read_at_start_are_gone() {
    let db = crate::support::postgres::database().await;
    let mut site = Config::demo();
    let _sims = start_with(&mut site, PACE).await.unwrap();
    let receiver = Receiver::start().await;
    let files = tempfile::tempdir().unwrap();
    let secret = files.path().join("wms.secret");
    std::fs::write(&secret, format!("{SECRET}\n")).unwrap();
    let ca = Ca::new("WMS CA").write(files.path(), "wms-ca.pem");
    let mut webhook = crate::webhooks::api::subscription(&receiver);
    (webhook.secret, webhook.secret_file, webhook.ca_file) = (None, Some(secret.clone()), Some(ca.clone()));
    site.webhooks = vec![webhook];
    let a = node(&db, "a", &site).await;
    until(&a, "/api/v1/cluster", 10, |c| c["role"] == "active").await;
    let b = node(&db, "b", &site).await;
    until(&b, "/api/v1/cluster", 10, |c| c["role"] == "standby").await;

    // The site's tooling rotates the files away. A reload reads them again, as
    // `check-config` would: refused, naming the file, and what was loaded stays.
    std::fs::remove_file(&secret).unwrap();
    std::fs::remove_file(&ca).unwrap();
    let post = b.client.post(b.url("/api/v1/config/reload")).header("content-type", "application/json");
    let refused = split(post.send().await.unwrap()).await;
    assert_error(&refused, 422, "invalid_config");
    let message = refused.1["error"]["message"].as_str().unwrap();
    assert!(message.contains("wms.secret") && message.contains("cannot be read"), "{message}");
    // Then the active node lets go.
    a.stop().await;
    until(&b, "/api/v1/cluster", 10, |c| c["role"] == "active").await;
    let travel = json!({"kind": "travel", "reference": "after",
                        "to": {"aisle": 2, "row": 1, "bay": 5, "level": 1, "position": 1}});
    let (status, job) = b.post("/api/v1/jobs", &travel).await;
    assert_eq!(status, 201, "{job}");
    until(&b, &format!("/api/v1/jobs/{}", job["id"]), 30, |j| j["state"] == "completed").await;

    // Its events reach the WMS, signed with the secret read at the start.
    eventually("the job's completion delivered", Duration::from_secs(20), async || {
        let completed = receiver.acked().into_iter().any(|seq| {
            receiver.received().iter().any(|r| {
                let event: Value = serde_json::from_slice(&r.body).unwrap();
                r.seq == seq && event["data"]["id"] == job["id"] && event["data"]["state"] == "completed"
            })
        });
        if completed { Ok(()) } else { Err(receiver.received().len()) }
    })
    .await;
    receiver.check("wms", "job.");
    let (_, alarms) = b.get("/api/v1/alarms?active=true&device=webhook:wms").await;
    assert_eq!(alarms["alarms"].as_array().map(Vec::len), Some(0), "{alarms}");
    b.stop().await;
}
