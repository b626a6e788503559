//! Alarm captures are bounded on disk and belong to their incident (issue 51): a flapping
//! link freezes one capture per device and alarm every `retention.alarm_capture_interval_secs`,
//! the folder keeps within `retention.captures_max_bytes` (the oldest files go first), a
//! `.part` file a crash left is removed, and an alarm id that a fresh database hands out
//! again never gets the file of the old incident that had that id.

use std::path::Path;
use std::time::{Duration, SystemTime};

use rackd::config::devices::ShelfConfig;
use rackd::protocols::faults::Faults;
use rackd::sim::shelf::ShelfSim;
use rackd::store::Engine;
use serde_json::Value;

use crate::shelf::{device_for, sim};
use crate::support::{TestApp, eventually, spawn_with};

/// A shelf that gives up on a request at once: its link alarm comes within a second.
fn quick(shelf: &ShelfSim) -> ShelfConfig {
    device_for(shelf, |d| d.link.retries = 0)
}

fn drop_all(shelf: &ShelfSim) {
    shelf.set_faults(Faults { drop_rate: 1.0, ..Faults::default() });
}

/// The id of the active link alarm, once there is one other than `not`.
async fn link_alarm(app: &TestApp, not: Option<i64>) -> i64 {
    eventually("the link alarm", Duration::from_secs(20), async || {
        let (_, page) = app.get("/api/v1/alarms?active=true").await;
        let found = page["alarms"].as_array().unwrap().iter().find(|a| a["kind"] == "link").cloned();
        found.and_then(|a| a["id"].as_i64()).filter(|id| Some(*id) != not).ok_or(page)
    })
    .await
}

/// Waits until alarm `id` is cleared.
async fn cleared(app: &TestApp, id: i64) {
    eventually("the link alarm cleared", Duration::from_secs(20), async || {
        let (_, page) = app.get("/api/v1/alarms?active=false").await;
        let found = page["alarms"].as_array().unwrap().iter().any(|a| a["id"] == id);
        if found { Ok(()) } else { Err(page) }
    })
    .await
}

async fn capture_status(app: &TestApp, id: i64) -> u16 {
    let response = app.client.get(app.url(&format!("/api/v1/alarms/{id}/capture"))).send().await.unwrap();
    response.status().as_u16()
}

/// Waits for alarm `id`'s capture to be served.
async fn captured(app: &TestApp, id: i64) {
    eventually("the alarm's capture", Duration::from_secs(10), async || match capture_status(app, id).await {
        200 => Ok(()),
        other => Err(other),
    })
    .await
}

/// The names in `folder` and their sizes, by name.
fn listing(folder: &Path) -> Vec<(String, u64)> {
    let mut names: Vec<(String, u64)> = std::fs::read_dir(folder)
        .unwrap()
        .map(|e| e.unwrap())
        .map(|e| (e.file_name().into_string().unwrap(), e.metadata().unwrap().len()))
        .collect();
    names.sort();
    names
}

/// A file of `size` bytes last written `hours_ago`.
fn old_file(folder: &Path, name: &str, hours_ago: u64, size: usize) {
    let file = std::fs::File::create(folder.join(name)).unwrap();
    file.set_len(size as u64).unwrap();
    file.set_modified(SystemTime::now() - Duration::from_secs(hours_ago * 3600)).unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_alarm_id_a_fresh_database_hands_out_again_never_gets_the_old_incidents_capture() {
    let folder = tempfile::tempdir().unwrap();
    let shelf = ShelfSim::start("127.0.0.1:0", sim(50)).await.unwrap();
    drop_all(&shelf);
    let device = quick(&shelf);
    let first = spawn_with(Engine::Sqlite, |c| {
        c.devices = vec![device.clone().into()];
        c.retention.captures_dir = Some(folder.path().to_owned());
        c.retention.alarm_capture_seconds = 30;
    })
    .await;
    let id = link_alarm(&first, None).await;
    captured(&first, id).await;
    first.stop().await;

    // A fresh database on the same folder, keeping no captures of its own: its first link
    // alarm has the old one's id.
    let second = spawn_with(Engine::Sqlite, |c| {
        c.devices = vec![device.into()];
        c.retention.captures_dir = Some(folder.path().to_owned());
        c.retention.alarm_capture_seconds = 0;
    })
    .await;
    let again = link_alarm(&second, None).await;
    assert_eq!(again, id, "a fresh database numbers its alarms from the start again");
    let status = capture_status(&second, id).await;
    assert_eq!(
        status, 404,
        "alarm {id} of the fresh database has no capture: the old incident's file is not its"
    );
    second.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flapping_link_freezes_once_and_the_folder_keeps_within_its_cap() {
    let folder = tempfile::tempdir().unwrap();
    let dir = folder.path();
    // Left by an earlier run: three captures of 450 kB, oldest first, a temporary file a
    // crash left, and a file of the site's own.
    old_file(dir, "alarm-91-1000.pcapng", 3, 450_000);
    old_file(dir, "alarm-92-2000.pcapng", 2, 450_000);
    old_file(dir, "alarm-93-3000.pcapng", 1, 450_000);
    old_file(dir, "alarm-94-4000.pcapng.4242-0badcafe.part", 1, 10_000);
    old_file(dir, "notes.txt", 3, 100);
    let cap = 1024 * 1024;
    let shelf = ShelfSim::start("127.0.0.1:0", sim(50)).await.unwrap();
    let app = spawn_with(Engine::Sqlite, |c| {
        c.devices = vec![quick(&shelf).into()];
        c.retention.captures_dir = Some(dir.to_owned());
        c.retention.alarm_capture_seconds = 30;
        c.retention.captures_max_bytes = cap;
    })
    .await;

    // At start: the leftover is removed, and the oldest capture, which the cap has no room for.
    eventually("the leftover and the oldest capture removed", Duration::from_secs(10), async || {
        let names = listing(dir);
        let gone = |n: &str| !names.iter().any(|(name, _)| name == n);
        if gone("alarm-94-4000.pcapng.4242-0badcafe.part") && gone("alarm-91-1000.pcapng") {
            Ok(())
        } else {
            Err(names)
        }
    })
    .await;
    let names: Vec<String> = listing(dir).into_iter().map(|(n, _)| n).collect();
    assert_eq!(names, ["alarm-92-2000.pcapng", "alarm-93-3000.pcapng", "notes.txt"]);

    // The link fails: its capture is kept, within the cap, the oldest going first.
    drop_all(&shelf);
    let a = link_alarm(&app, None).await;
    captured(&app, a).await;
    let names = listing(dir);
    let ours: u64 = names.iter().filter(|(n, _)| n.starts_with("alarm-")).map(|(_, size)| size).sum();
    assert!(ours <= cap, "{ours} bytes of captures over the cap: {names:?}");
    let has = |n: &str| names.iter().any(|(name, _)| name == n);
    assert!(has("alarm-92-2000.pcapng") || !has("alarm-93-3000.pcapng"), "oldest first: {names:?}");
    assert!(has("notes.txt"), "the site's file stays");

    // It comes back and fails again within the interval: that alarm keeps no capture. Its
    // freeze (or none) is done before the monitor clears it.
    shelf.set_faults(Faults::default());
    cleared(&app, a).await;
    drop_all(&shelf);
    let b = link_alarm(&app, Some(a)).await;
    shelf.set_faults(Faults::default());
    cleared(&app, b).await;
    let (status, body) = {
        let response = app.client.get(app.url(&format!("/api/v1/alarms/{b}/capture"))).send().await.unwrap();
        let status = response.status().as_u16();
        (status, response.json::<Value>().await.unwrap_or_default())
    };
    assert_eq!(status, 404, "a second link alarm within the interval keeps no capture: {body}");
    assert_eq!(capture_status(&app, a).await, 200, "the first one's stays");
    app.stop().await;
}
