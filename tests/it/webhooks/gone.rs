//! A 410 Gone is not a silent off switch (issue 51, item 5). One 410 from the receiver (or
//! a proxy in front of it) paused the subscription with no alarm, and the log's retention
//! stopped holding its events, so the WMS could not catch up by replay. Now the pause
//! raises the `webhook` alarm (code 2), `GET /api/v1/webhooks` and the alarm say that the
//! receiver paused it, retention goes on holding its events, and a resume clears the alarm
//! and delivers them; an administrator's pause raises nothing and holds nothing. Before the
//! fix, no alarm came.

use std::time::Duration;

use rackd::service::webhooks::held_through;
use rackd::store::Engine;
use rstest::rstest;
use serde_json::{Value, json};

use super::api::{caught_up, post_job, subscription, webhook};
use crate::support::receiver::{Mode, Receiver};
use crate::support::{TestApp, eventually, spawn_with};

/// The active `webhook` alarms of the subscription, once there are `n`.
async fn alarms(app: &TestApp, n: usize) -> Vec<Value> {
    eventually(format!("{n} active webhook alarms"), Duration::from_secs(10), async || {
        let (_, page) = app.get("/api/v1/alarms?active=true&device=webhook:wms").await;
        let alarms = page["alarms"].as_array().unwrap().clone();
        if alarms.len() == n { Ok(alarms) } else { Err(page) }
    })
    .await
}

/// What retention may delete for the subscription, as the running one would read it.
async fn held(app: &TestApp, config: &rackd::config::WebhookConfig) -> i64 {
    let pool = rackd::store::open(&app.db, Duration::from_secs(5)).await.unwrap();
    let rows = rackd::store::webhooks::rows(&pool).await.unwrap();
    pool.close().await;
    held_through(std::slice::from_ref(config), &rows)
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_410_pauses_with_an_alarm_holds_the_events_and_is_told_from_an_administrators_pause(
    #[case] engine: Engine,
) {
    let receiver = Receiver::start().await;
    receiver.set(Mode { gone: true, ..Mode::default() });
    let config = subscription(&receiver);
    let app = spawn_with(engine, |c| c.webhooks = vec![config.clone()]).await;
    let first = post_job(&app, 0).await;
    let w = eventually("a pause by 410", Duration::from_secs(10), async || {
        let w = webhook(&app).await;
        if w["state"] == "paused" { Ok(w) } else { Err(w) }
    })
    .await;

    let alarm = &alarms(&app, 1).await[0];
    assert_eq!((alarm["kind"].as_str(), alarm["code"].as_i64()), (Some("webhook"), Some(2)), "{alarm}");
    let text = alarm["text"].as_str().unwrap();
    assert!(text.contains("paused by its receiver") && text.contains("410 Gone"), "{text}");
    assert!(alarm["action"].as_str().unwrap().contains("/api/v1/webhooks/wms/resume"), "{alarm}");
    assert_eq!(w["paused_by"], "receiver", "{w}");
    assert!(w["paused_reason"].as_str().unwrap().contains("410"), "{w}");

    // Its events are held: retention deletes nothing past its cursor.
    post_job(&app, 1).await;
    let cursor = webhook(&app).await["cursor"].as_i64().unwrap();
    assert_eq!(held(&app, &config).await, cursor, "held for the paused subscription");

    // Resumed: the alarm clears, and what it missed is delivered.
    receiver.set(Mode::default());
    let (status, w) = app.post("/api/v1/webhooks/wms/resume", &json!({})).await;
    assert_eq!((status, w["paused_by"].clone()), (200, Value::Null), "{w}");
    caught_up(&app).await;
    alarms(&app, 0).await;
    let job_of = |r: &crate::support::receiver::Received| {
        serde_json::from_slice::<Value>(&r.body).unwrap()["data"]["id"].as_i64()
    };
    let delivered: Vec<_> =
        receiver.received().iter().filter(|r| r.status == 200).filter_map(job_of).collect();
    assert!(delivered.contains(&first) && delivered.len() >= 2, "{delivered:?}");

    // An administrator's pause is told apart: no alarm, nothing held.
    let (status, w) = app.post("/api/v1/webhooks/wms/pause", &json!({"reason": "WMS upgrade"})).await;
    assert_eq!((status, w["paused_by"].as_str()), (200, Some("admin")), "{w}");
    assert_eq!(held(&app, &config).await, i64::MAX);
    let (_, page) = app.get("/api/v1/alarms?active=true&device=webhook:wms").await;
    assert_eq!(page["alarms"].as_array().map(Vec::len), Some(0), "{page}");
    app.stop().await;
}
