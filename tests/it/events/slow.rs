//! A subscriber that does not keep up gets `resync`; the others keep their pace. One whose
//! socket stays full for the send timeout is let go without a word.
//!
//! A slow subscriber's connection can end in two ways, and each test allows exactly one:
//! the resync and its close (4000) when the session sees it has fallen `events.buffer`
//! commits behind, or the end of the connection without a close frame when a send to it
//! has been stuck for `events.send_timeout_secs`. The second is caused by the test itself
//! when it holds its reader longer than that, which a loaded machine can make it do (the
//! first test once failed so, "Connection reset without closing handshake", with the
//! default 10 s): so the resync test sets a send timeout it never reaches, and any end
//! without a close there is not its doing; the stall test makes the lag unreachable instead.

use std::time::{Duration, Instant};

use rackd::store::Engine;

use super::{assert_consecutive, submit};
use crate::support::ws::{Got, Ws};
use crate::support::{TestApp, eventually, spawn_with};

/// Batches of light jobs the producer posts, and jobs per batch: enough events (about 400
/// bytes each) to fill every socket buffer between a subscriber that reads nothing and
/// the server.
const BATCHES: usize = 200;
const PER_BATCH: usize = 200;

/// Two subscribers to jobs, the second with a small receive buffer, each past its hello.
async fn fast_and_slow(app: &TestApp) -> (Ws, Ws) {
    let mut fast = Ws::connect(&app.base, "?topics=jobs").await;
    let mut slow = Ws::connect_small_buffer(&app.base, "?topics=jobs").await;
    assert_eq!(fast.json().await["seq"], 0);
    assert_eq!(slow.json().await["seq"], 0);
    (fast, slow)
}

/// Posts [`BATCHES`] batches of [`PER_BATCH`] jobs, one after the other, in a task.
fn produce(app: &TestApp) -> tokio::task::JoinHandle<()> {
    let base = app.base.clone();
    tokio::spawn(async move {
        let client = reqwest::Client::new();
        for _ in 0..BATCHES {
            let jobs: Vec<serde_json::Value> = (0..PER_BATCH)
                .map(|_| {
                    serde_json::json!({"kind": "light", "location": crate::support::loc(1, 1, 1, 1),
                    "color": "green", "on": true})
                })
                .collect();
            let r = client
                .post(format!("{base}/api/v1/jobs/batch"))
                .json(&serde_json::json!({ "jobs": jobs }))
                .send()
                .await
                .unwrap();
            assert_eq!(r.status(), 201);
        }
    })
}

#[tokio::test]
async fn a_slow_subscriber_is_told_to_resync_and_others_miss_nothing() {
    // An hour: the test never holds its reader that long, so the session never gives up on
    // a stuck send, and no ping goes unanswered meanwhile. The resync is the only way out.
    let app = spawn_with(Engine::Sqlite, |c| {
        c.events.buffer = 8;
        c.events.send_timeout_secs = 3600;
        c.events.ping_secs = 3600;
    })
    .await;
    let (mut fast, mut slow) = fast_and_slow(&app).await;

    // The slow one reads nothing while the events go by.
    let producer = produce(&app);
    let total = BATCHES * PER_BATCH;
    let events = fast.events(total).await;
    assert_consecutive(&events, 1);
    producer.await.unwrap();

    // Now the slow one reads: what was buffered, then resync, then the close.
    let mut last_seq = 0;
    let resync = loop {
        match slow.next_or_end(Duration::from_secs(10)).await {
            Got::Json(v) if v["type"] == "resync" => break v,
            Got::Json(v) => {
                assert_eq!(v["seq"].as_i64(), Some(last_seq + 1), "no gap before the resync");
                last_seq += 1;
            }
            Got::Ended(e) => panic!(
                "the connection ended without a close after seq {last_seq} ({e}), though no send to it \
                 could time out (an hour): not the test's doing"
            ),
            other => panic!("expected events then resync, got {other:?} after seq {last_seq}"),
        }
    };
    assert!((last_seq as usize) < total, "the slow subscriber did fall behind");
    assert_eq!(resync["seq"], last_seq, "resync names the last event sent: {resync}");
    assert!(matches!(slow.next(Duration::from_secs(5)).await, Got::Closed(4000)));

    // It catches up with since.
    let mut again = Ws::connect(&app.base, &format!("?topics=jobs&since={last_seq}")).await;
    let rest = again.events(total - last_seq as usize).await;
    assert_consecutive(&rest, last_seq + 1);
    submit(&app, 1).await;
    assert_consecutive(&again.events(1).await, total as i64 + 1);
}

/// The hub's subscribers, as `/metrics` counts them.
async fn subscribers(app: &TestApp) -> u64 {
    let text = app.client.get(app.url("/metrics")).send().await.unwrap().text().await.unwrap();
    let line = text.lines().find(|l| l.starts_with("rackd_ws_subscribers "));
    line.and_then(|l| l.split_whitespace().nth(1)?.parse().ok()).unwrap_or_else(|| panic!("{text}"))
}

#[tokio::test]
async fn a_subscriber_stuck_for_the_send_timeout_is_let_go_and_others_miss_nothing() {
    // A buffer no test fills: the session never lags, so only the stuck send ends it.
    let send_timeout = Duration::from_secs(1);
    let app = spawn_with(Engine::Sqlite, |c| {
        c.events.buffer = 65_536;
        c.events.send_timeout_secs = send_timeout.as_secs();
        c.events.ping_secs = 3600;
    })
    .await;
    let (mut fast, mut slow) = fast_and_slow(&app).await;
    let stopped_reading = Instant::now();
    let with_both = subscribers(&app).await;

    let producer = produce(&app);
    let total = BATCHES * PER_BATCH;
    assert_consecutive(&fast.events(total).await, 1);
    producer.await.unwrap();
    // The server lets the slow one go (the test still reads nothing), a send timeout at
    // least after the test stopped reading.
    eventually("the stuck subscriber to be let go", Duration::from_secs(30), async || {
        subscribers(&app).await == with_both - 1
    })
    .await;
    assert!(stopped_reading.elapsed() >= send_timeout, "let go before its send could time out");

    // What reached its socket, in order, then the end without a close: the test's doing.
    let mut last_seq = 0;
    let end = loop {
        match slow.next_or_end(Duration::from_secs(10)).await {
            Got::Json(v) => {
                assert_ne!(v["type"], "resync", "a session stuck in a send tells nothing: {v}");
                assert_eq!(v["seq"].as_i64(), Some(last_seq + 1), "no gap before the end");
                last_seq += 1;
            }
            Got::Ended(e) => break e,
            other => {
                panic!("expected events then the end of the connection, got {other:?} after seq {last_seq}")
            }
        }
    };
    assert!(
        (last_seq as usize) < total,
        "the stuck subscriber missed the rest (after seq {last_seq}): {end}"
    );

    // The other one misses nothing after it either.
    submit(&app, 1).await;
    assert_consecutive(&fast.events(1).await, total as i64 + 1);
}
