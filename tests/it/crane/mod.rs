//! The stacker crane end to end: the real server on 127.0.0.1:0 with a temporary database,
//! driving the real crane simulator over real MC 3E TCP and UDP.

use rackd::store::Engine;
mod alarms;
mod handover;
mod heartbeat;
mod jobs;
mod pause_restart;
mod paused;
mod planner;
mod restart;
mod wire;

use std::time::Duration;

use rackd::config::devices::CraneConfig;
use rackd::config::{AisleConfig, Config};
use rackd::protocols::Protocol;
use rackd::protocols::mc3e::TransportKind;
use rackd::sim::crane::{CraneSim, CraneSimOptions};
use serde_json::{Value, json};

use crate::support::eventually;
use crate::support::{TestApp, spawn_with};

/// Requests to wait for, after a job is committed or a state is shown, before asserting
/// that rackd did NOT act: at least 5 polls (a poll is one or two requests), each followed by
/// a dispatch attempt.
pub const POLLS: u64 = 10;

/// A simulated crane with `step_ms` per action state.
pub async fn crane(transport: TransportKind, step_ms: u64) -> CraneSim {
    let options = CraneSimOptions { transport, step: Duration::from_millis(step_ms), ..Default::default() };
    CraneSim::start("127.0.0.1:0", options).await.unwrap()
}

/// The device entry for a simulator: `crane1` on aisle 2, fast polling, short timeouts.
pub fn device_for(
    sim: &CraneSim,
    transport: TransportKind,
    edit: impl FnOnce(&mut CraneConfig),
) -> CraneConfig {
    device_at(&sim.local_addr().to_string(), transport, edit)
}

/// As [`device_for`], for a crane at `address` (a proxy in front of one, a replay).
pub fn device_at(
    address: &str,
    transport: TransportKind,
    edit: impl FnOnce(&mut CraneConfig),
) -> CraneConfig {
    let mut d = CraneConfig::new("crane1", address, vec![2]);
    if transport == TransportKind::Udp {
        d.link.protocol = Protocol::Mc3eUdp;
    }
    d.poll_ms = 20;
    d.link.timeout = Duration::from_millis(200);
    d.link.retries = 3;
    d.heartbeat_ms = 20;
    d.heartbeat_timeout_ms = 500;
    d.handshake_timeout_ms = 1000;
    edit(&mut d);
    d
}

/// The demo site plus the crane aisle 2 (2 rows x 20 bays x 8 levels x 2 sides), served
/// by `device` alone; single-deep, so that rackd sends what the tests ask whatever its
/// location model holds (the planner's double-deep rules are tested in [`planner`]).
pub fn with_crane(config: &mut Config, device: CraneConfig) {
    config.site.aisles.retain(|a| a.aisle != 2);
    config.site.aisles.push(AisleConfig { aisle: 2, rows: 2, bays: 20, levels: 8, positions: 2, depth: 1 });
    config.devices = vec![device.into()];
}

/// A crane simulator and a rackd driving it.
pub async fn crane_app(
    transport: TransportKind,
    step_ms: u64,
    edit: impl FnOnce(&mut CraneConfig),
) -> (TestApp, CraneSim) {
    let sim = crane(transport, step_ms).await;
    let device = device_for(&sim, transport, edit);
    let app = spawn_with(Engine::Sqlite, |c| with_crane(c, device)).await;
    (app, sim)
}

/// A location in the crane aisle.
pub fn cloc(row: u16, bay: u16, level: u16, side: u16) -> Value {
    json!({"aisle": 2, "row": row, "bay": bay, "level": level, "position": side})
}

/// Submits a job and returns its id.
pub async fn submit(app: &TestApp, mut body: Value, reference: &str) -> i64 {
    body["reference"] = json!(reference);
    let (status, job) = app.post("/api/v1/jobs", &body).await;
    assert_eq!(status, 201, "{job}");
    assert_eq!(job["device"], "crane1", "{job}");
    job["id"].as_i64().unwrap()
}

/// Waits (bounded) until job `id` is in one of `states`; returns it.
pub async fn wait_job(app: &TestApp, id: i64, states: &[&str], secs: u64) -> Value {
    eventually(format!("job {id} to reach {states:?}"), Duration::from_secs(secs), async || {
        let (_, job) = app.get(&format!("/api/v1/jobs/{id}")).await;
        if states.contains(&job["state"].as_str().unwrap_or("")) { Ok(job) } else { Err(job) }
    })
    .await
}

/// Waits (bounded) until the crane's device status satisfies `pred`; returns it.
pub async fn wait_device(app: &TestApp, what: &str, secs: u64, pred: impl Fn(&Value) -> bool) -> Value {
    eventually(format!("the device {what}"), Duration::from_secs(secs), async || {
        let (_, status) = app.get("/api/v1/devices/crane1").await;
        if pred(&status) { Ok(status) } else { Err(status) }
    })
    .await
}

/// The job's history as (state, cause) pairs.
pub async fn history(app: &TestApp, id: i64) -> Vec<(String, String)> {
    let (_, h) = app.get(&format!("/api/v1/jobs/{id}/history")).await;
    h.as_array()
        .unwrap()
        .iter()
        .map(|e| (e["state"].as_str().unwrap_or("").to_owned(), e["cause"].as_str().unwrap_or("").to_owned()))
        .collect()
}
