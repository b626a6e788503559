//! Capture downloads cannot take rackd down (issue 51): `GET /api/v1/devices/{id}/capture`
//! streams its file, at most `server.capture_downloads` (2) are built at once and the next
//! one is answered 429 `capture_busy` with `Retry-After`, and the device polls on, without
//! a timeout, while downloads are under way. A download held open by a client that reads
//! nothing keeps its place until it lets go; then the place is free again.
//!
//! The device's ring is filled through its own recorder with 20 MB of 1000-byte frames (the
//! simulator's traffic would take minutes to fill it), so a file is some 22 MB: twice what
//! the sockets (4 MiB of send buffer, the receiver's window) and the server's buffers can
//! hold, so a download whose client reads nothing stays under way, deterministically. What 50 downloads at once cost in memory is measured by
//! `bench capture` (docs/development/benchmarks/capture.md), not here.

use std::time::Duration;

use rackd::capture::{Annotations, Direction};
use rackd::sim::shelf::ShelfSim;
use rackd::store::Engine;
use serde_json::Value;

use crate::shelf::{device_for, sim};
use crate::support::{TestApp, eventually, spawn_with};

/// Frames put into the ring, of [`FRAME`] bytes each.
const FRAMES: usize = 20_000;
const FRAME: usize = 1000;

/// The device's link as `GET /api/v1/devices/shelf1` shows it.
async fn link(app: &TestApp) -> Value {
    let (status, device) = app.get("/api/v1/devices/shelf1").await;
    assert_eq!(status, 200, "{device}");
    device["link"].clone()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn downloads_past_the_cap_wait_their_turn_and_the_device_polls_on() {
    let shelf = ShelfSim::start("127.0.0.1:0", sim(50)).await.unwrap();
    let device = device_for(&shelf, |d| {
        d.link.capture.bytes = 32 * 1024 * 1024;
        // Generous timeouts: the test is about a poll that waits on a download, not about a
        // busy machine's round trips.
        d.link.timeout = Duration::from_secs(2);
        d.link.tuning.min_timeout = d.link.timeout;
    });
    let app = spawn_with(Engine::Sqlite, |c| c.devices = vec![device.into()]).await;
    let recorder = app.recorder("shelf1").expect("shelf1 records");
    for i in 0..FRAMES {
        recorder.record(Direction::Received, &[i as u8; FRAME], Annotations::default());
    }
    drop(recorder);
    let url = app.url("/api/v1/devices/shelf1/capture");
    let before = link(&app).await;

    // Two downloads whose clients read nothing past the headers: both under way.
    let first = app.client.get(&url).send().await.unwrap();
    let second = app.client.get(&url).send().await.unwrap();
    assert_eq!((first.status().as_u16(), second.status().as_u16()), (200, 200));
    let third = app.client.get(&url).send().await.unwrap();
    let status = third.status().as_u16();
    let retry_after = third.headers().get("retry-after").map(|v| v.to_str().unwrap().to_owned());
    let body: Value = third.json().await.unwrap_or_default();
    assert_eq!(status, 429, "a third download while two are built: {body}");
    assert_eq!(body["error"]["code"], "capture_busy", "{body}");
    assert!(retry_after.is_some_and(|s| s.parse::<u64>().is_ok_and(|s| s >= 1)), "Retry-After in seconds");

    // The document promises the 429, with its Retry-After.
    let (_, doc) = app.get("/openapi.json").await;
    let refused = &doc["paths"]["/api/v1/devices/{id}/capture"]["get"]["responses"]["429"];
    assert!(refused["description"].as_str().is_some_and(|d| d.contains("capture_busy")), "{refused}");
    assert!(refused["headers"]["Retry-After"].is_object(), "{refused}");
    assert_eq!(refused["content"]["application/json"]["schema"]["$ref"], "#/components/schemas/ErrorBody");

    // The device polls on meanwhile, without a timeout.
    let from = before["requests"].as_u64().unwrap();
    eventually("polls while two downloads are held", Duration::from_secs(20), async || {
        let now = link(&app).await;
        if now["requests"].as_u64().unwrap() >= from + 20 { Ok(()) } else { Err(now) }
    })
    .await;

    // One client lets go: its place is free.
    drop(first);
    let response = eventually("a place for a download", Duration::from_secs(20), async || {
        let response = app.client.get(&url).send().await.unwrap();
        match response.status().as_u16() {
            200 => Ok(response),
            other => Err(other),
        }
    })
    .await;
    // The file's start (a build runs at a low priority: on a machine busy with other work
    // a whole file of 20 MB takes its time; the endpoint test reads whole files).
    let mut response = response;
    let first_part = response.chunk().await.unwrap().expect("a first part");
    assert_eq!(first_part[..4], [0x0A, 0x0D, 0x0D, 0x0A], "a pcapng section header first");
    drop(response);
    drop(second);

    let after = link(&app).await;
    assert_eq!(after["timeouts"], before["timeouts"], "no poll timed out: {after}");
    app.stop().await;
}
