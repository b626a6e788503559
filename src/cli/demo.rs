//! The demo site: `rackd serve` with no configuration.
//!
//! The demo layout (one aisle, 2 rows x 10 bays x 6 levels x 4 positions) with a simulated
//! shelf PLC started inside the process on a free loopback UDP port and a device `shelf1`
//! bound to it, so the first command of the README gives a working store. A real site
//! replaces the simulator with its PLC's address in `[[devices]]` (see
//! `config/rackd.example.toml`).

use std::time::Duration;

use crate::config::Config;
use crate::devices::DeviceConfig;
use crate::sim::shelf::{ShelfSim, ShelfSimOptions};

/// How long each simulated task takes in the demo: slow enough to watch a job run.
const DEMO_TASK_TIME: Duration = Duration::from_millis(1500);

/// Starts the demo's simulated PLC and adds its device to `config`.
pub async fn start(config: &mut Config) -> anyhow::Result<ShelfSim> {
    let options = ShelfSimOptions { task_time: DEMO_TASK_TIME, ..ShelfSimOptions::default() };
    let sim = ShelfSim::start("127.0.0.1:0", options).await?;
    let mut device = DeviceConfig::shelf("shelf1", &sim.local_addr().to_string(), vec![1]);
    device.poll_ms = 100;
    config.devices = vec![device];
    tracing::info!(plc = %sim.local_addr(), "demo site: simulated shelf PLC started (device shelf1)");
    Ok(sim)
}
