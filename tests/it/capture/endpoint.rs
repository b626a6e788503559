//! Captures served by the real server: a shelf's recent traffic from
//! `GET /api/v1/devices/{id}/capture`, and the seconds before a link alarm frozen into the
//! alarm's own file (`GET /api/v1/alarms/{id}/capture`); both audited, both decoded by
//! tshark with Wireshark's Modbus/UDP dissector, the frames annotated with the jobs.

use std::time::Duration;

use rackd::capture::{Direction, Verdict};
use rackd::protocols::faults::Faults;
use rackd::sim::shelf::ShelfSim;
use rackd::store::Engine;
use serde_json::{Value, json};

use super::{Frames, decode};
use crate::shelf::{device_for, sim};
use crate::support::{eventually, spawn_with, wait_ended};

async fn download(app: &crate::support::TestApp, path: &str) -> (u16, String, Vec<u8>) {
    let response = app.client.get(app.url(path)).send().await.unwrap();
    let status = response.status().as_u16();
    let kind =
        response.headers().get("content-type").map(|v| v.to_str().unwrap().to_owned()).unwrap_or_default();
    (status, kind, response.bytes().await.unwrap().to_vec())
}

#[tokio::test]
async fn a_devices_traffic_and_an_alarms_last_seconds_are_served_as_pcapng() {
    let shelf = ShelfSim::start("127.0.0.1:0", sim(50)).await.unwrap();
    let port = shelf.local_addr().unwrap().port();
    let device = device_for(&shelf, |d| d.link.retries = 1);
    let app = spawn_with(Engine::Sqlite, |c| {
        c.devices = vec![device.into()];
        c.retention.alarm_capture_seconds = 30;
    })
    .await;
    let mut ids = Vec::new();
    for bay in 1..=3 {
        let light = json!({"kind": "light", "location": {"aisle": 1, "row": 1, "bay": bay, "level": 1, "position": 1},
            "color": "green", "on": true});
        let (status, job) = app.post("/api/v1/jobs", &light).await;
        assert_eq!(status, 201, "{job}");
        ids.push(job["id"].as_i64().unwrap());
    }
    wait_ended(&app, 3, 20).await;

    let (status, kind, bytes) = download(&app, "/api/v1/devices/shelf1/capture?seconds=60").await;
    assert_eq!((status, kind.as_str()), (200, "application/x-pcapng"));
    let capture = rackd::capture::read::read(&bytes).unwrap();
    let sent = capture.frames.iter().filter(|f| f.direction == Direction::Sent).count();
    let received = capture.frames.iter().filter(|f| f.direction == Direction::Received).count();
    assert!(sent > 10 && received > 10, "{sent} sent, {received} received");
    for id in &ids {
        assert!(capture.frames.iter().any(|f| f.annotations.job == Some(*id)), "no frame of job {id}");
    }
    let option = format!("mbudp.udp.port:{port}");
    let packets =
        decode(&capture.link, &Frames(capture.frames.clone()), &["-o", &option], &["modbus.func_code"]);
    // rackd's requests are Modbus/UDP as Wireshark reads it; this PLC's replies carry the
    // MBAP length 0 of its spec (the `length0` quirk), which Wireshark does not take.
    let requests = capture.frames.iter().zip(&packets).filter(|(f, _)| f.direction == Direction::Sent);
    for (_, p) in requests {
        assert!(!p.get("modbus.func_code").is_empty(), "a request not decoded as Modbus");
    }
    let text = String::from_utf8_lossy(&bytes);
    assert!(!text.contains("key-") && !text.contains("Bearer"), "no key in a capture");
    let (_, audit) = app.get("/api/v1/audit?limit=5").await;
    let entry = &audit["entries"][0];
    assert_eq!(
        (entry["action"].as_str(), entry["target"].as_str()),
        (Some("capture"), Some("device:shelf1"))
    );
    assert_eq!(download(&app, "/api/v1/devices/shelf1/capture?seconds=0").await.0, 422);
    assert_eq!(download(&app, "/api/v1/devices/nope/capture").await.0, 404);

    // The PLC stops answering: the link alarm keeps the seconds before it.
    shelf.set_faults(Faults { drop_rate: 1.0, ..Faults::default() });
    let alarm: Value = eventually("the link alarm", Duration::from_secs(20), async || {
        let (_, page) = app.get("/api/v1/alarms?active=true").await;
        let found = page["alarms"].as_array().unwrap().iter().find(|a| a["kind"] == "link").cloned();
        found.ok_or(page)
    })
    .await;
    let id = alarm["id"].as_i64().unwrap();
    let path = format!("/api/v1/alarms/{id}/capture");
    let (status, kind, bytes) = eventually("the alarm's capture", Duration::from_secs(10), async || {
        let got = download(&app, &path).await;
        if got.0 == 200 { Ok(got) } else { Err(got.0) }
    })
    .await;
    assert_eq!((status, kind.as_str()), (200, "application/x-pcapng"));
    let frozen = rackd::capture::read::read(&bytes).unwrap();
    let first = frozen.frames.first().unwrap().time_us;
    let last = frozen.frames.last().unwrap().time_us;
    assert!(last - first <= 30_000_000, "at most the 30 s asked");
    assert!(frozen.frames.iter().any(|f| f.annotations.job.is_some()), "the jobs before the fault are in it");
    let retried = frozen.frames.iter().filter(|f| f.annotations.verdict == Some(Verdict::Retry)).count();
    assert!(retried > 0, "the requests that went unanswered were retried, and marked so");
    assert_eq!(download(&app, "/api/v1/alarms/999999/capture").await.0, 404);
    app.stop().await;
}
