//! Tags over Modbus TCP: what the PLC holds shows in the status, writes land with the right
//! words, and a stopped PLC takes the device offline and back.

use serde_json::{Value, json};

use super::*;
use crate::support;

#[tokio::test]
async fn polls_show_every_type_and_only_real_changes() {
    let (app, bank, server) = modbus_app().await;
    {
        let mut b = bank.lock();
        b.holding_registers[10] = 65535;
        b.holding_registers[11] = 0xFFFE;
        b.holding_registers[12..14].copy_from_slice(&[0x0001, 0x0002]);
        b.holding_registers[14..16].copy_from_slice(&[0x0000, 0x3FC0]); // 1.5, low word first
        b.holding_registers[16] = 0x0008;
        b.holding_registers[20..22].copy_from_slice(&[0xFFFE, 0x7960]); // -100000
        b.holding_registers[22..24].copy_from_slice(&[0xBDCC, 0xCCCD]); // -0.1
        b.coils[5] = true;
        b.discrete_inputs[7] = true;
        b.input_registers[2] = 0xFF9C; // -100
    }
    let expected = [
        ("plain.u16", json!(65535)),
        ("plain.i16", json!(-2)),
        ("plain.u32", json!(65538)),
        ("plain.f32_low", json!(1.5)),
        ("plain.i32", json!(-100_000)),
        ("plain.f32", json!(-0.1)),
        ("word.bit3", json!(true)),
        ("beacon.red", json!(true)),
        ("station1.box_present", json!(true)),
        ("analog.level", json!(-100)),
        ("plain.fixed", json!(0)),
    ];
    for (name, value) in &expected {
        let t = wait_tag(&app, "tags1", name, |t| t["value"] == *value).await;
        assert_eq!(t["quality"], "good", "{t}");
        assert!(t["changes"].as_u64().unwrap() >= 1 && t["changed_at"].is_string(), "{t}");
    }
    let f = tag(&app, "tags1", "plain.f32_low").await;
    assert_eq!((f["type"].as_str(), f["word_order"].as_str()), (Some("f32"), Some("low-first")));
    assert_eq!(tag(&app, "tags1", "plain.u32").await["word_order"], "high-first", "Modbus default");
    let (_, device) = app.get("/api/v1/devices/tags1").await;
    assert_eq!((device["kind"].as_str(), device["online"].as_bool()), (Some("tags"), Some(true)), "{device}");
    assert_eq!(device["slots_total"], 0);
    assert_eq!(device["tags"]["plain.u16"]["value"], 65535, "the values are in the device status");

    // Polls that find nothing new leave the tags exactly as they were.
    let before = device["tags"].clone();
    // A poll of these tags is one request per register range (four of them): 20 requests
    // are several whole polls.
    let faults = server.faults();
    support::wait_for_more("polls of the tags", 20, 5, || faults.requests_seen()).await;
    let (_, again) = app.get("/api/v1/devices/tags1").await;
    assert_eq!(again["tags"], before, "no change without a change in the PLC");

    // A change in the PLC is picked up and counted once.
    let changes = before["plain.u16"]["changes"].as_u64().unwrap();
    bank.lock().holding_registers[10] = 7;
    let t = wait_tag(&app, "tags1", "plain.u16", |t| t["value"] == 7).await;
    assert_eq!(t["changes"].as_u64(), Some(changes + 1), "{t}");
    assert_ne!(t["changed_at"], before["plain.u16"]["changed_at"]);
    bank.lock().holding_registers[16] = 0x0007;
    wait_tag(&app, "tags1", "word.bit3", |t| t["value"] == false).await;
}

async fn written(app: &support::TestApp, name: &str, value: Value) -> Value {
    let (status, body) = write(app, "tags1", name, value.clone()).await;
    assert_eq!(status, 200, "{name} := {value}: {body}");
    assert_eq!(
        (body["name"].as_str(), &body["value"]),
        (Some(name), &value),
        "answered as read back: {body}"
    );
    assert_eq!(body["quality"], "good");
    body
}

#[tokio::test]
async fn writes_land_in_the_plc_in_the_right_word_order() {
    let (app, bank, _server) = modbus_app().await;
    wait_device(&app, "tags1", |d| d["online"] == true).await;
    let holding = |from: usize, n: usize| bank.lock().holding_registers[from..from + n].to_vec();

    written(&app, "plain.u32", json!(0x1234_5678)).await;
    assert_eq!(holding(12, 2), [0x1234, 0x5678], "high word first");
    written(&app, "plain.f32_low", json!(-0.1)).await;
    assert_eq!(holding(14, 2), [0xCCCD, 0xBDCC], "low word first");
    written(&app, "plain.i32", json!(-100_000)).await;
    assert_eq!(holding(20, 2), [0xFFFE, 0x7960]);
    written(&app, "plain.f32", json!(10.5)).await;
    assert_eq!(holding(22, 2), [0x4128, 0x0000]);
    written(&app, "plain.i16", json!(-2)).await;
    assert_eq!(holding(11, 1), [0xFFFE]);
    written(&app, "plain.u16", json!(65535)).await;
    assert_eq!(holding(10, 1), [0xFFFF]);
    for edge in [10, 20] {
        written(&app, "plain.limited", json!(edge)).await;
        assert_eq!(holding(24, 1), [edge]);
    }

    // A bit of a word: the other bits stay as the PLC had them.
    bank.lock().holding_registers[16] = 0x00F0;
    wait_tag(&app, "tags1", "word.bit3", |t| t["value"] == false).await;
    written(&app, "word.bit3", json!(true)).await;
    assert_eq!(holding(16, 1), [0x00F8]);
    written(&app, "word.bit3", json!(false)).await;
    assert_eq!(holding(16, 1), [0x00F0]);

    written(&app, "beacon.red", json!(true)).await;
    assert!(bank.lock().coils[5]);
    let body = written(&app, "beacon.red", json!(false)).await;
    assert!(!bank.lock().coils[5]);
    assert!(body["changes"].as_u64().unwrap() >= 2, "{body}");

    // The status shows what was written.
    let (_, device) = app.get("/api/v1/devices/tags1").await;
    assert_eq!(device["tags"]["plain.u32"]["value"], 0x1234_5678);
    assert_eq!(device["tags"]["plain.f32_low"]["value"], -0.1);
}

#[tokio::test]
async fn a_stopped_plc_takes_the_device_offline_and_back() {
    // The PLC's port is held while it is off (connections refused), for it to come back on.
    let port = HeldPort::new();
    let (app, bank, server) = modbus_app_with(modbus_sim_on(&port)).await;
    bank.lock().holding_registers[10] = 42;
    wait_tag(&app, "tags1", "plain.u16", |t| t["value"] == 42).await;
    server.shutdown().await;

    let device = wait_device(&app, "tags1", |d| d["online"] == false).await;
    assert!(device["last_error"].is_string(), "{device}");
    let t = wait_tag(&app, "tags1", "plain.u16", |t| t["quality"] == "bad").await;
    assert_eq!(t["value"], 42, "the last value read is kept: {t}");
    assert!(t["error"].as_str().is_some_and(|e| !e.is_empty()), "{t}");
    let refused = write(&app, "tags1", "plain.u16", json!(1)).await;
    support::assert_error(&refused, 503, "device_offline");

    // The PLC comes back on the same address.
    let (bank, _server) = modbus_sim_on(&port);
    bank.lock().holding_registers[10] = 9;
    wait_device(&app, "tags1", |d| d["online"] == true).await;
    let t = wait_tag(&app, "tags1", "plain.u16", |t| t["value"] == 9).await;
    assert_eq!((t["quality"].as_str(), &t["error"]), (Some("good"), &Value::Null), "{t}");
    written(&app, "plain.u16", json!(3)).await;
    assert_eq!(bank.lock().holding_registers[10], 3);
}
