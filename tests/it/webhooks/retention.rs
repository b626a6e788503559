//! The log's retention waits for a subscription that has not delivered yet, up to
//! `events.webhook_hold_hours`; past that the events go, and the subscription says which
//! it lost (the `webhook` alarm, code 1) until it has caught up. A subscription that never
//! delivered raises its failing alarm (code 0) too, and the next start clears it with the
//! first success.

use std::time::Duration;

use rackd::store::Engine;
use rackd::store::writer::{Hooks, Record, Writer};
use rstest::rstest;
use serde_json::Value;

use super::api::{post_job, subscription};
use crate::support::receiver::Receiver;
use crate::support::{eventually, spawn_on, spawn_with};

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn retention_holds_what_a_subscription_needs_until_its_limit_then_the_loss_is_alarmed(
    #[case] engine: Engine,
) {
    let mut receiver = Receiver::start().await;
    receiver.down();
    let mut config = subscription(&receiver);
    config.events = vec!["*".into()];
    let app = spawn_with(engine, |c| c.webhooks = vec![config.clone()]).await;
    for n in 0..5 {
        post_job(&app, n).await;
    }
    // Failing from its first try: the alarm comes after `alarm_after_secs` all the same.
    eventually("the failing alarm", Duration::from_secs(10), async || {
        let (_, page) = app.get("/api/v1/alarms?active=true&device=webhook:wms").await;
        if page["alarms"].as_array().is_some_and(|a| a.iter().any(|a| a["code"] == 0)) {
            Ok(())
        } else {
            Err(page)
        }
    })
    .await;
    let (db, dir) = app.stop().await;

    let pool = rackd::store::open(&db, Duration::from_secs(5)).await.unwrap();
    let rows = rackd::store::webhooks::rows(&pool).await.unwrap();
    let through = rackd::service::webhooks::held_through(std::slice::from_ref(&config), &rows);
    assert_eq!(through, 0, "nothing delivered: {rows:?}");
    let (writer, task) = Writer::start(&pool, 16, 16, Hooks::default()).await.unwrap();
    let now = rackd::domain::time::now_ms() + 1;
    let (_, newest) = rackd::store::events::bounds(&pool).await.unwrap();
    // Past the retention, within the hold: every event stays.
    writer.record(Record::Prune { before_ms: now, through, hard_ms: now - 3_600_000 }).await.unwrap();
    assert_eq!(rackd::store::events::bounds(&pool).await.unwrap(), (1, newest), "held for the subscription");
    // Past the hold too: they go (the newest stays, as always).
    writer.record(Record::Prune { before_ms: now, through, hard_ms: now }).await.unwrap();
    assert_eq!(rackd::store::events::bounds(&pool).await.unwrap(), (newest, newest));
    drop(writer);
    task.await.unwrap();
    pool.close().await;

    receiver.up().await;
    let app = spawn_on(db, |c| c.webhooks = vec![config]).await;
    let alarm = eventually("the loss alarmed and cleared", Duration::from_secs(10), async || {
        let (_, page) = app.get("/api/v1/alarms?device=webhook:wms").await;
        let lost: Vec<Value> =
            page["alarms"].as_array().unwrap().iter().filter(|a| a["code"] == 1).cloned().collect();
        match lost.as_slice() {
            [alarm] if !alarm["cleared_at"].is_null() => Ok(alarm.clone()),
            _ => Err(page),
        }
    })
    .await;
    let text = alarm["text"].as_str().unwrap();
    assert!(text.contains(&format!("events 1 to {}", newest - 1)), "{alarm}");
    let acked = receiver.acked();
    assert_eq!(acked.first(), Some(&newest), "from what the log still held on: {acked:?}");
    let (_, page) = app.get("/api/v1/alarms?active=true&device=webhook:wms").await;
    assert_eq!(page["alarms"].as_array().map(Vec::len), Some(0), "the failing alarm cleared: {page}");
    app.stop().await;
    drop(dir);
}
