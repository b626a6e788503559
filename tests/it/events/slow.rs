//! A subscriber that does not keep up gets `resync`; the others keep their pace.

use std::time::Duration;

use rackd::store::Engine;

use super::{assert_consecutive, submit};
use crate::support::spawn_with;
use crate::support::ws::{Got, Ws};

#[tokio::test]
async fn a_slow_subscriber_is_told_to_resync_and_others_miss_nothing() {
    let app = spawn_with(Engine::Sqlite, |c| c.events.buffer = 8).await;
    let mut fast = Ws::connect(&app.base, "?topics=jobs").await;
    let mut slow = Ws::connect_small_buffer(&app.base, "?topics=jobs").await;
    assert_eq!(fast.json().await["seq"], 0);
    assert_eq!(slow.json().await["seq"], 0);

    // The slow one reads nothing while enough events to fill every socket buffer between
    // it and the server go by (each event is about 400 bytes).
    let (batches, per_batch) = (200, 200);
    let producer = tokio::spawn({
        let app_base = app.base.clone();
        async move {
            let client = reqwest::Client::new();
            for _ in 0..batches {
                let jobs: Vec<serde_json::Value> = (0..per_batch)
                    .map(|_| {
                        serde_json::json!({"kind": "light", "location": crate::support::loc(1, 1, 1, 1),
                        "color": "green", "on": true})
                    })
                    .collect();
                let r = client
                    .post(format!("{app_base}/api/v1/jobs/batch"))
                    .json(&serde_json::json!({ "jobs": jobs }))
                    .send()
                    .await
                    .unwrap();
                assert_eq!(r.status(), 201);
            }
        }
    });
    let total = batches * per_batch;
    let events = fast.events(total).await;
    assert_consecutive(&events, 1);
    producer.await.unwrap();

    // Now the slow one reads: what was buffered, then resync, then the close.
    let mut last_seq = 0;
    let resync = loop {
        match slow.next(Duration::from_secs(10)).await {
            Got::Json(v) if v["type"] == "resync" => break v,
            Got::Json(v) => {
                assert_eq!(v["seq"].as_i64(), Some(last_seq + 1), "no gap before the resync");
                last_seq += 1;
            }
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
