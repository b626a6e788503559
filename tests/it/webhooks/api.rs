//! One rackd in this process, no devices (its jobs wait queued, each telling of itself in a
//! `job.updated`), and one subscription to the test receiver.

use std::time::Duration;

use rackd::config::WebhookConfig;
use rackd::store::Engine;
use rstest::rstest;
use serde_json::{Value, json};

use crate::support::receiver::{Mode, Receiver, SECRET};
use crate::support::{TestApp, assert_error, eventually, loc, spawn_with};

/// A subscription to `receiver` for `job.*`, retrying fast, alarmed after a second.
pub fn subscription(receiver: &Receiver) -> WebhookConfig {
    let mut config = WebhookConfig::new("wms", &receiver.url(), &["job.*"], SECRET);
    (config.backoff_ms, config.max_backoff_ms, config.timeout_ms, config.alarm_after_secs) =
        (20, 100, 500, 1);
    config
}

/// Posts a store job to its own place (`n` < 160).
pub async fn post_job(app: &TestApp, n: u16) -> i64 {
    let to = loc(1 + n % 2, 1 + n / 2 % 10, 1 + n / 20 % 8, 1);
    let (status, job) =
        app.post("/api/v1/jobs", &json!({"kind": "store", "barcode": format!("B{n}"), "to": to})).await;
    assert_eq!(status, 201, "{job}");
    job["id"].as_i64().unwrap()
}

/// The seqs of the log's `job.*` events.
async fn job_events(app: &TestApp) -> Vec<i64> {
    let pool = rackd::store::open(&app.db, Duration::from_secs(5)).await.unwrap();
    let events = rackd::store::events::after(&pool, 0, 100_000).await.unwrap();
    events.iter().filter(|e| e.kind.starts_with("job.")).map(|e| e.seq).collect()
}

pub async fn webhook(app: &TestApp) -> Value {
    let (status, list) = app.get("/api/v1/webhooks").await;
    assert_eq!(status, 200, "{list}");
    list["webhooks"][0].clone()
}

pub async fn caught_up(app: &TestApp) -> Value {
    eventually("the subscription to catch up", Duration::from_secs(20), async || {
        let w = webhook(app).await;
        if w["state"] == "caught_up" { Ok(w) } else { Err(w) }
    })
    .await
}

async fn active_webhook_alarms(app: &TestApp) -> usize {
    let (status, page) = app.get("/api/v1/alarms?active=true").await;
    assert_eq!(status, 200, "{page}");
    page["alarms"].as_array().unwrap().iter().filter(|a| a["kind"] == "webhook").count()
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn events_reach_the_receiver_signed_in_order_and_can_be_paused_replayed_and_alarmed(
    #[case] engine: Engine,
) {
    let mut receiver = Receiver::start().await;
    let config = subscription(&receiver);
    let app = spawn_with(engine, |c| c.webhooks = vec![config]).await;
    for n in 0..20 {
        post_job(&app, n).await;
    }
    let w = caught_up(&app).await;
    let wanted = job_events(&app).await;
    assert_eq!(wanted.len(), 20, "one job.updated per queued job");
    assert_eq!(receiver.acked(), wanted.iter().copied().collect(), "every job event, acknowledged");
    assert_eq!(w["cursor"].as_i64(), wanted.last().copied(), "{w}");
    assert_eq!(w["url"], receiver.url());
    receiver.check("wms", "job.");
    let (status, log) = app.get("/api/v1/webhooks/wms/deliveries?limit=5").await;
    assert_eq!(status, 200, "{log}");
    let tries = log["deliveries"].as_array().unwrap();
    assert_eq!(tries.len(), 5, "{log}");
    assert_eq!(tries[0]["seq"].as_i64(), wanted.last().copied(), "newest first: {log}");
    assert_eq!((tries[0]["outcome"].as_str(), tries[0]["status"].as_i64()), (Some("delivered"), Some(200)));
    assert!(log["next_cursor"].is_string(), "{log}");

    // Failing: retried with backoff, the alarm raised after a second, cleared by a success.
    receiver.set(Mode { fail: 1.0, ..Mode::default() });
    post_job(&app, 20).await;
    eventually("the webhook alarm", Duration::from_secs(10), async || {
        let n = active_webhook_alarms(&app).await;
        if n == 1 { Ok(()) } else { Err(n) }
    })
    .await;
    let w = webhook(&app).await;
    assert_eq!(w["state"], "failing", "{w}");
    assert!(w["last_error"].as_str().unwrap().contains("500"), "{w}");
    assert!(w["behind"].as_i64().unwrap() >= 1, "{w}");
    receiver.down();
    // Up again once a try found it down (its own backoff, however busy the machine).
    eventually("a try while the receiver is down", Duration::from_secs(10), async || {
        let w = webhook(&app).await;
        if w["last_error"].as_str().is_some_and(|e| e.contains("connect")) { Ok(()) } else { Err(w) }
    })
    .await;
    receiver.up().await;
    receiver.set(Mode::default());
    caught_up(&app).await;
    eventually("the alarm to clear", Duration::from_secs(10), async || {
        let n = active_webhook_alarms(&app).await;
        if n == 0 { Ok(()) } else { Err(n) }
    })
    .await;
    let (_, log) = app.get("/api/v1/webhooks/wms/deliveries?limit=1000").await;
    let failed = log["deliveries"].as_array().unwrap().iter().filter(|d| d["outcome"] == "failed").count();
    assert!(failed >= 3, "tries of the failing second: {log}");
    assert!(
        log["deliveries"]
            .as_array()
            .unwrap()
            .iter()
            .any(|d| d["error"].as_str().is_some_and(|e| e.contains("connect"))),
        "a try while the receiver was down: {log}"
    );

    // Paused: nothing goes; resumed: it does.
    let (status, w) = app.post("/api/v1/webhooks/wms/pause", &json!({"reason": "WMS upgrade"})).await;
    assert_eq!((status, w["state"].as_str()), (200, Some("paused")), "{w}");
    let before = receiver.received().len();
    let held = post_job(&app, 21).await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(receiver.received().len(), before, "nothing is sent while paused");
    // The job's event and the pause's own `audit.recorded`, which this subscription skips.
    assert_eq!(webhook(&app).await["behind"], 2);
    let (status, w) = app.post("/api/v1/webhooks/wms/resume", &json!({})).await;
    assert_eq!(status, 200, "{w}");
    caught_up(&app).await;
    let job_of = |body: &[u8]| serde_json::from_slice::<Value>(body).unwrap()["data"]["id"].as_i64();
    assert!(receiver.received().iter().any(|r| job_of(&r.body) == Some(held)), "the job posted while paused");

    // Replayed: the same ids and bodies again, in order.
    let first = job_events(&app).await[0];
    let (status, w) = app.post("/api/v1/webhooks/wms/replay", &json!({"from_seq": first})).await;
    assert_eq!((status, w["cursor"].as_i64()), (200, Some(first - 1)), "{w}");
    caught_up(&app).await;
    let received = receiver.received();
    let again = received.iter().filter(|r| r.seq == first).count();
    assert!(again >= 2, "the first event twice: {again}");
    receiver.check("wms", "job.");

    // The audit entries of the actions are not of its types: the cursor moves over them,
    // and is written within a second or so even with nothing else to deliver.
    let pool = rackd::store::open(&app.db, Duration::from_secs(5)).await.unwrap();
    eventually("the cursor written past the last event", Duration::from_secs(5), async || {
        let (_, newest) = rackd::store::events::bounds(&pool).await.unwrap();
        let rows = rackd::store::webhooks::rows(&pool).await.unwrap();
        if rows[0].cursor == newest { Ok(()) } else { Err((rows[0].cursor, newest)) }
    })
    .await;

    // Refusals.
    assert_error(&app.post("/api/v1/webhooks/wms/replay", &json!({"from_seq": 0})).await, 409, "not_in_log");
    assert_error(&app.post("/api/v1/webhooks/nope/pause", &json!({})).await, 404, "not_found");
    assert_error(&app.get("/api/v1/webhooks/nope/deliveries").await, 404, "not_found");
    let (status, body) = app.post("/api/v1/webhooks/wms/replay", &json!({"from": 1})).await;
    assert_eq!(status, 422, "{body}");
    let (_, audit) = app.get("/api/v1/audit").await;
    let actions: Vec<(&str, &str)> = audit["entries"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["target"] == "webhook:wms")
        .map(|e| (e["action"].as_str().unwrap(), e["reason"].as_str().unwrap_or_default()))
        .collect();
    assert_eq!(
        actions,
        [("replay", format!("from seq {first}").as_str()), ("resume", ""), ("pause", "WMS upgrade")],
        "{audit}"
    );

    // 410 Gone pauses it.
    receiver.set(Mode { gone: true, ..Mode::default() });
    post_job(&app, 22).await;
    let w = eventually("a pause by 410", Duration::from_secs(10), async || {
        let w = webhook(&app).await;
        if w["state"] == "paused" { Ok(w) } else { Err(w) }
    })
    .await;
    assert!(w["paused_reason"].as_str().unwrap().contains("410"), "{w}");
    app.stop().await;
}
