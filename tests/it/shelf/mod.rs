//! The shelf PLC end to end: the real server on 127.0.0.1:0 with a temporary database,
//! driving the real shelf simulator over real UDP (and, in `protocols`, over every other
//! transport: TCP, RTU on a pty, PPI, MEWTOCOL).

use rackd::store::Engine;
mod control;
mod faults;
mod kills;
mod protocols;
mod reservations;
mod restart;
mod safety;
mod wire;
mod workload;

use rackd::config::devices::ShelfConfig;
use rackd::sim::shelf::{ShelfSim, ShelfSimOptions};

use crate::support::{TestApp, spawn_with};

/// A simulated shelf PLC and a rackd driving it (device `shelf1`, aisle 1, fast polling).
pub async fn shelf_app(options: ShelfSimOptions, edit: impl FnOnce(&mut ShelfConfig)) -> (TestApp, ShelfSim) {
    let sim = ShelfSim::start("127.0.0.1:0", options).await.unwrap();
    let device = device_for(&sim, edit);
    let app = spawn_with(Engine::Sqlite, |c| c.devices = vec![device.into()]).await;
    (app, sim)
}

/// The device entry for a simulator.
pub fn device_for(sim: &ShelfSim, edit: impl FnOnce(&mut ShelfConfig)) -> ShelfConfig {
    let address = sim.local_addr().expect("a network simulator").to_string();
    let mut device = rackd::cli::demo::shelf_device(sim, "shelf1", &address, vec![1]);
    device.poll_ms = 20;
    device.link.timeout = std::time::Duration::from_millis(100);
    device.link.retries = 3;
    edit(&mut device);
    device
}

/// Simulator options with tasks taking `ms` milliseconds.
pub fn sim(ms: u64) -> ShelfSimOptions {
    ShelfSimOptions { task_time: std::time::Duration::from_millis(ms), ..ShelfSimOptions::default() }
}

/// Asserts every job completed, ended exactly once in its history, and reached the PLC once.
pub async fn assert_each_completed_once(app: &TestApp, sim: &ShelfSim, jobs: &[serde_json::Value]) {
    for j in jobs {
        assert_eq!(j["state"], "completed", "{j}");
        let (_, history) = app.get(&format!("/api/v1/jobs/{}/history", j["id"])).await;
        let ends = history.as_array().unwrap().iter().filter(|h| h["state"] == "completed").count();
        assert_eq!(ends, 1, "job {} ended once: {history}", j["id"]);
        let task = rackd::wire::task_id_for(j["id"].as_i64().unwrap());
        assert_eq!(sim.received(task), 1, "job {} sent once", j["id"]);
    }
}
