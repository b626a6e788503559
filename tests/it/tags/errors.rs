//! Every way a tag write can be refused, each with its JSON error, and none of them
//! reaching the PLC; PLC refusals and silence as gateway errors.

use rackd::config::devices::ShelfConfig;
use rackd::protocols::faults::Faults;
use rackd::protocols::modbus::Exception;
use rackd::store::Engine;
use serde_json::json;

use super::*;
use crate::support::{assert_error, spawn_with, split, store};

#[tokio::test]
async fn bad_requests_get_json_errors_and_write_nothing() {
    let (bank, server) = modbus_sim().await;
    let tags = tags_device("tags1", "modbus-tcp", &server.local_addr().unwrap().to_string(), MODBUS_TAGS);
    // A shelf on a port nobody answers: a device of another kind.
    let shelf = ShelfConfig::new("shelf1", "127.0.0.1:9", vec![1]);
    let app = spawn_with(Engine::Sqlite, |c| c.devices = vec![tags.into(), shelf.into()]).await;
    wait_device(&app, "tags1", |d| d["online"] == true).await;
    let before = bank.lock().clone();

    let cases = [
        ("beacon.red", json!(1), 422, "invalid_tag_value"),
        ("beacon.red", json!("true"), 422, "invalid_tag_value"),
        ("beacon.red", json!(null), 422, "invalid_tag_value"),
        ("plain.u16", json!(1.5), 422, "invalid_tag_value"),
        ("plain.u16", json!(true), 422, "invalid_tag_value"),
        ("plain.u16", json!([1]), 422, "invalid_tag_value"),
        ("plain.f32", json!("1.0"), 422, "invalid_tag_value"),
        ("plain.u16", json!(65536), 422, "tag_out_of_range"),
        ("plain.u16", json!(-1), 422, "tag_out_of_range"),
        ("plain.i16", json!(40000), 422, "tag_out_of_range"),
        ("plain.u32", json!(-1), 422, "tag_out_of_range"),
        ("plain.u32", json!(4_294_967_296u64), 422, "tag_out_of_range"),
        ("plain.i32", json!(2_147_483_648u64), 422, "tag_out_of_range"),
        ("plain.limited", json!(9), 422, "tag_out_of_range"),
        ("plain.limited", json!(21), 422, "tag_out_of_range"),
        ("plain.f32", json!(10.6), 422, "tag_out_of_range"),
        ("plain.f32", json!(-10.01), 422, "tag_out_of_range"),
        ("plain.f32_low", json!(1e39), 422, "tag_out_of_range"),
        ("plain.fixed", json!(1), 422, "tag_read_only"),
        ("station1.box_present", json!(false), 422, "tag_read_only"),
        ("analog.level", json!(0), 422, "tag_read_only"),
        ("no.such_tag", json!(1), 404, "not_found"),
    ];
    for (name, value, status, code) in cases {
        let got = write(&app, "tags1", name, value.clone()).await;
        assert_error(&got, status, code);
        let message = got.1["error"]["message"].as_str().unwrap();
        assert!(message.contains(name), "{name} := {value}: the message names the tag: {message}");
    }
    let got = write(&app, "tags1", "plain.limited", json!(21)).await;
    assert!(got.1["error"]["message"].as_str().unwrap().contains("10..=20"), "{got:?}");

    // Bodies that are not `{"value": ...}`.
    let path = "/api/v1/devices/tags1/tags/plain.u16";
    assert_error(&app.post(path, &json!({})).await, 422, "invalid_body");
    assert_error(&app.post(path, &json!({"value": 1, "force": true})).await, 422, "invalid_body");
    let raw = app.client.post(app.url(path)).header("content-type", "application/json").body("{\"value\":");
    assert_error(&split(raw.send().await.unwrap()).await, 400, "malformed_json");
    // An unknown tag is a 404 whatever the body.
    assert_error(&app.post("/api/v1/devices/tags1/tags/nope", &json!({})).await, 404, "not_found");

    // Unknown devices, devices of another kind.
    assert_error(&write(&app, "nodev", "plain.u16", json!(1)).await, 404, "not_found");
    assert_error(&app.get("/api/v1/devices/nodev/tags").await, 404, "not_found");
    assert_error(&write(&app, "shelf1", "plain.u16", json!(1)).await, 409, "not_a_tags_device");
    assert_error(&app.get("/api/v1/devices/shelf1/tags").await, 409, "not_a_tags_device");
    let (_, shelf) = app.get("/api/v1/devices/shelf1").await;
    assert!(shelf.get("tags").is_none(), "only tags devices show tags: {shelf}");

    // A tags device is never given jobs.
    let mut job = store("TAGS-JOB-1");
    job["device"] = json!("tags1");
    let refused = app.post("/api/v1/jobs", &job).await;
    assert_error(&refused, 422, "invalid_job");
    assert!(refused.1["error"]["message"].as_str().unwrap().contains("cannot run store jobs"), "{refused:?}");

    assert_eq!(*bank.lock(), before, "no refused write reached the PLC");
}

#[tokio::test]
async fn plc_refusals_are_502_and_silence_504_until_the_device_is_offline() {
    let (bank, server) = modbus_sim().await;
    let mut device =
        tags_device("tags1", "modbus-tcp", &server.local_addr().unwrap().to_string(), MODBUS_TAGS);
    device.poll_ms = 60_000; // one poll at start, then only the writes talk to the PLC
    let app = spawn_with(Engine::Sqlite, |c| c.devices = vec![device.into()]).await;
    wait_device(&app, "tags1", |d| d["online"] == true).await;

    server.set_faults(Faults {
        device_error: Some(Exception::SERVER_DEVICE_FAILURE.0.into()),
        ..Faults::default()
    });
    let refused = write(&app, "tags1", "plain.u16", json!(5)).await;
    assert_error(&refused, 502, "plc_error");
    let message = refused.1["error"]["message"].as_str().unwrap();
    assert!(message.contains("modbus device error") && message.contains("0x0004"), "{message}");
    let (_, status) = app.get("/api/v1/devices/tags1").await;
    assert_eq!(status["online"], true, "a PLC that answers with an exception is reachable: {status}");

    // Silence: a timeout per write; after `offline_after` (2) of them the device is offline
    // and writes are refused without traffic.
    server.set_faults(Faults { drop_rate: 1.0, ..Faults::default() });
    assert_error(&write(&app, "tags1", "plain.u16", json!(5)).await, 504, "plc_timeout");
    assert_error(&write(&app, "tags1", "plain.u16", json!(5)).await, 504, "plc_timeout");
    let (_, status) = app.get("/api/v1/devices/tags1").await;
    assert_eq!(status["online"], false, "{status}");
    let requests = server.stats().requests;
    assert_error(&write(&app, "tags1", "plain.u16", json!(5)).await, 503, "device_offline");
    assert_eq!(server.stats().requests, requests, "an offline device is not asked");
    assert_eq!(bank.lock().holding_registers[10], 0);
}
