//! An optional integration never blocks the machines (issue 51, item 4): a subscription
//! that cannot start (here one built in code whose `secret_file` is missing; one loaded
//! from a file has read it already, see `standby::webhook_files`) raises its `webhook`
//! alarm with code 3, its actions answer 503, and the machines are driven. Before the fix,
//! rackd did not start.

use std::time::Duration;

use rackd::cli::demo::{Pace, start_with};
use rackd::config::Config;
use rackd::store::Engine;
use serde_json::json;

use super::api::subscription;
use crate::support::receiver::Receiver;
use crate::support::{assert_error, eventually, spawn_with};

const PACE: Pace = Pace { task_time: Duration::from_millis(200), crane_step: Duration::from_millis(20) };

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_subscription_that_cannot_start_is_an_alarm_and_the_machines_are_driven() {
    let mut site = Config::demo();
    let _sims = start_with(&mut site, PACE).await.unwrap();
    let receiver = Receiver::start().await;
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("wms.secret");
    let mut webhook = subscription(&receiver);
    (webhook.secret, webhook.secret_file) = (None, Some(missing.clone()));
    let app = spawn_with(Engine::Sqlite, |c| {
        c.devices = site.devices.clone();
        c.webhooks = vec![webhook];
    })
    .await;

    let travel = json!({"kind": "travel", "reference": "driven",
                        "to": {"aisle": 2, "row": 1, "bay": 3, "level": 1, "position": 1}});
    let (status, job) = app.post("/api/v1/jobs", &travel).await;
    assert_eq!(status, 201, "{job}");
    let path = format!("/api/v1/jobs/{}", job["id"]);
    eventually("the job driven to its end", Duration::from_secs(30), async || {
        let (_, job) = app.get(&path).await;
        if job["state"] == "completed" { Ok(()) } else { Err(job) }
    })
    .await;

    let alarm = eventually("the subscription's alarm", Duration::from_secs(10), async || {
        let (_, page) = app.get("/api/v1/alarms?active=true&device=webhook:wms").await;
        match page["alarms"].as_array().unwrap().as_slice() {
            [alarm] => Ok(alarm.clone()),
            _ => Err(page),
        }
    })
    .await;
    assert_eq!((alarm["kind"].as_str(), alarm["code"].as_i64()), (Some("webhook"), Some(3)), "{alarm}");
    let text = alarm["text"].as_str().unwrap();
    assert!(text.contains("cannot start") && text.contains(&missing.display().to_string()), "{text}");
    let w = super::api::webhook(&app).await;
    assert_eq!(w["state"], "failing", "{w}");
    assert!(w["last_error"].as_str().unwrap().starts_with("cannot start: "), "{w}");
    assert_error(&app.post("/api/v1/webhooks/wms/pause", &json!({})).await, 503, "not_delivering");
    assert!(receiver.received().is_empty());
    app.stop().await;
}
