//! The live event stream end to end: the real server on 127.0.0.1:0 with a temporary
//! database, real WebSocket clients.

mod alarms;
mod replay;
mod slow;
mod stream;

// What the event-log tests share: submitting jobs that make events, and checking numbers.

use serde_json::{Value, json};

use crate::support::ws;
use crate::support::{self, TestApp};

/// Submits `n` light jobs (no device runs them in these tests, so they stay queued) in one
/// batch; returns their ids. Each makes one `job.updated` event.
pub async fn submit(app: &TestApp, n: usize) -> Vec<i64> {
    let jobs: Vec<Value> = (0..n)
        .map(|i| {
            let bay = (i % 10) as u16 + 1;
            json!({"kind": "light", "location": support::loc(1, bay, 1, 1), "color": "green", "on": true})
        })
        .collect();
    let (status, body) = app.post("/api/v1/jobs/batch", &json!({ "jobs": jobs })).await;
    assert_eq!(status, 201, "{body}");
    body["jobs"].as_array().unwrap().iter().map(|j| j["id"].as_i64().unwrap()).collect()
}

/// Asserts `events` have consecutive sequence numbers starting at `first`.
pub fn assert_consecutive(events: &[Value], first: i64) {
    for (i, e) in events.iter().enumerate() {
        assert_eq!(e["seq"].as_i64(), Some(first + i as i64), "event {i} of {}: {e}", events.len());
    }
}

/// Asserts that `ws` received nothing after the events it has read, the last of which had
/// sequence number `last`: one more job is submitted (a sentinel), and since events come in
/// order, the next message must be that job's event, numbered `last + 1`. A positive signal
/// instead of waiting a fixed time for silence.
pub async fn assert_nothing_more(app: &TestApp, ws: &mut ws::Ws, last: i64) {
    let sentinel = submit(app, 1).await[0];
    let next = ws.json().await;
    assert_eq!(next["seq"].as_i64(), Some(last + 1), "nothing came between: {next}");
    assert_eq!(
        (next["type"].as_str(), next["data"]["id"].as_i64()),
        (Some("job.updated"), Some(sentinel)),
        "{next}"
    );
}
