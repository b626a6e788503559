//! Tags over the serial-line protocols (through their TCP gateways): a simulated S7-200 over
//! PPI and a simulated Panasonic PLC over MEWTOCOL-COM, each with its own notation and word
//! order.

use rackd::protocols::mewtocol::{self, ContactArea};
use rackd::protocols::ppi::{self, MemArea};
use rackd::store::Engine;
use serde_json::json;

use super::*;
use crate::support::{assert_error, spawn_with};

#[tokio::test]
async fn s7_200_tags_over_ppi() {
    let state = ppi::ServerState::new(ppi::Bank::default().shared());
    let server = ppi::server::serve_tcp("127.0.0.1:0", state.clone()).await.unwrap();
    let tags = r#"
        "beacon.red" = "Q0.1"
        "conveyor.speed" = { address = "VD4", type = "f32" }
        "counter" = "VW100"
        "level" = "VB3"
        "flag" = "VW102.3"
        "station.present" = "I0.0"
    "#;
    let mut device = tags_device("s7", "ppi-tcp", &server.local_addr().unwrap().to_string(), tags);
    device.link.unit = 2;
    device.link.timeout = std::time::Duration::from_millis(300);
    let app = spawn_with(Engine::Sqlite, |c| c.devices = vec![device.into()]).await;
    let v = |range: std::ops::Range<usize>| state.bank.lock().unwrap().bytes(MemArea::V)[range].to_vec();
    {
        let mut bank = state.bank.lock().unwrap();
        bank.bytes_mut(MemArea::V)[100..102].copy_from_slice(&[0x12, 0x34]);
        bank.bytes_mut(MemArea::V)[3] = 200;
        bank.bytes_mut(MemArea::I)[0] = 0x01;
    }
    for (name, value) in [("counter", json!(0x1234)), ("level", json!(200)), ("station.present", json!(true))]
    {
        wait_tag(&app, "s7", name, |t| t["value"] == value && t["quality"] == "good").await;
    }
    assert_eq!(tag(&app, "s7", "conveyor.speed").await["word_order"], "high-first", "S7 default");

    let (status, body) = write(&app, "s7", "conveyor.speed", json!(1.5)).await;
    assert_eq!((status, &body["value"]), (200, &json!(1.5)), "{body}");
    assert_eq!(v(4..8), [0x3F, 0xC0, 0x00, 0x00], "VD4 = 1.5, big-endian bytes");
    assert_eq!(write(&app, "s7", "beacon.red", json!(true)).await.0, 200);
    assert_eq!(state.bank.lock().unwrap().bytes(MemArea::Q)[0], 0b10);
    assert_eq!(write(&app, "s7", "flag", json!(true)).await.0, 200);
    assert_eq!(v(102..104), [0x00, 0x08], "bit 3 of the word's value is in its low byte VB103");
    assert_eq!(write(&app, "s7", "level", json!(255)).await.0, 200);
    assert_eq!(v(3..4), [255]);
    assert_error(&write(&app, "s7", "level", json!(256)).await, 422, "tag_out_of_range");
    assert_error(&write(&app, "s7", "station.present", json!(false)).await, 422, "tag_read_only");

    state.bank.lock().unwrap().bytes_mut(MemArea::V)[100..102].copy_from_slice(&[0x00, 0x07]);
    wait_tag(&app, "s7", "counter", |t| t["value"] == 7).await;
}

#[tokio::test]
async fn panasonic_tags_over_mewtocol() {
    let state = mewtocol::ServerState::new(mewtocol::Bank::default().shared());
    let server = mewtocol::server::serve_tcp("127.0.0.1:0", state.clone()).await.unwrap();
    let tags = r#"
        station1.box_present = "X0001"
        beacon.green = "Y1A"
        total = { address = "DT100", type = "u32" }
        speed = { address = "DT102", type = "f32", word_order = "high-first" }
        mode = "WR5.15"
    "#;
    let mut device = tags_device("fp", "mewtocol-tcp", &server.local_addr().unwrap().to_string(), tags);
    device.link.timeout = std::time::Duration::from_millis(300);
    let app = spawn_with(Engine::Sqlite, |c| c.devices = vec![device.into()]).await;
    {
        let mut bank = state.bank.lock().unwrap();
        bank.set_word(ContactArea::X, 0, 0x0002);
        bank.set_dt(100, 0x5678);
        bank.set_dt(101, 0x1234);
    }
    wait_tag(&app, "fp", "station1.box_present", |t| t["value"] == true).await;
    let total = wait_tag(&app, "fp", "total", |t| t["value"] == 0x1234_5678).await;
    assert_eq!(total["word_order"], "low-first", "Panasonic default: {total}");

    let dt = |n| state.bank.lock().unwrap().dt(n).unwrap();
    assert_eq!(write(&app, "fp", "total", json!(0x0002_0001)).await.0, 200);
    assert_eq!((dt(100), dt(101)), (0x0001, 0x0002), "low word first");
    assert_eq!(write(&app, "fp", "speed", json!(1.5)).await.0, 200);
    assert_eq!((dt(102), dt(103)), (0x3FC0, 0x0000), "high word first as configured");
    assert_eq!(write(&app, "fp", "beacon.green", json!(true)).await.0, 200);
    assert_eq!(state.bank.lock().unwrap().bit(ContactArea::Y, 0x1A), Some(true));
    assert_eq!(write(&app, "fp", "mode", json!(true)).await.0, 200);
    assert_eq!(state.bank.lock().unwrap().word(ContactArea::R, 5), Some(0x8000));
    assert_error(&write(&app, "fp", "station1.box_present", json!(false)).await, 422, "tag_read_only");
    let (_, device) = app.get("/api/v1/devices/fp").await;
    assert_eq!(device["tags"]["mode"]["value"], true, "{device}");
}
