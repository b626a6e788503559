//! Tag changes reach WebSocket subscribers as `device.updated` events, once per change.

use std::time::Duration;

use super::*;
use crate::support::eventually;
use crate::support::ws::{Got, Ws};

/// The next `device.updated` event of `tags1` whose tag `name` has `value`.
async fn event_with(ws: &mut Ws, name: &str, value: serde_json::Value) -> Value {
    eventually(format!("an event with {name} = {value}"), Duration::from_secs(10), async || {
        let v = ws.json().await;
        if v["type"] == "device.updated" && v["data"]["tags"][name]["value"] == value {
            Ok(v)
        } else {
            Err(v)
        }
    })
    .await
}

#[tokio::test]
async fn a_tag_change_is_published_as_a_device_event() {
    let (app, bank, _server) = modbus_app().await;
    wait_device(&app, "tags1", |d| d["online"] == true).await;
    let mut ws = Ws::connect(&app.base, "?topics=devices").await;
    let snapshot = ws.json().await;
    assert_eq!(snapshot["data"]["devices"][0]["id"], "tags1", "{snapshot}");

    bank.lock().holding_registers[10] = 1234;
    let event = event_with(&mut ws, "plain.u16", json!(1234)).await;
    assert_eq!(event["data"]["kind"], "tags");
    // A write through the API is a change too.
    let (status, body) = write(&app, "tags1", "beacon.red", json!(true)).await;
    assert_eq!(status, 200, "{body}");
    event_with(&mut ws, "beacon.red", json!(true)).await;
    // Nothing changes: no events but the occasional last-contact refresh (5 s by default).
    match ws.next(Duration::from_millis(500)).await {
        Got::Nothing => {}
        other => panic!("an event without a change: {other:?}"),
    }
}
