//! The demo site: `rackd serve` with no configuration.
//!
//! The demo layout ([`Config::demo`]: shelf aisle 1, 2 rows x 10 bays x 6 levels x 4
//! positions; crane aisle 2, 2 rows x 20 bays x 8 levels x 2 depths) with a simulated shelf
//! PLC on a free loopback UDP port (device `shelf1`, aisle 1) and a simulated stacker crane
//! on a free loopback MC 3E TCP port (device `crane1`, aisle 2), both inside the process, so
//! the first command of the README gives a working store; jobs go to the device of their
//! location's aisle. A real site
//! replaces the simulator with its PLC's address in `[[devices]]` (see
//! `config/rackd.example.toml`).

use std::time::Duration;

use anyhow::Context;

use crate::config::Config;
use crate::devices::DeviceConfig;
use crate::protocols::mc3e::TransportKind;
use crate::sim::crane::{CraneSim, CraneSimOptions};
use crate::sim::shelf::{ShelfSim, ShelfSimOptions};

/// How long each simulated task takes in the demo: slow enough to watch a job run.
const DEMO_TASK_TIME: Duration = Duration::from_millis(1500);

/// Time of each simulated crane action state in the demo (a transfer has 16).
const DEMO_CRANE_STEP: Duration = Duration::from_millis(250);

/// Starts the demo's simulated machines and adds their devices to `config`; keep the
/// returned simulators alive as long as the service runs.
pub async fn start(config: &mut Config) -> anyhow::Result<(ShelfSim, CraneSim)> {
    let options = ShelfSimOptions { task_time: DEMO_TASK_TIME, ..ShelfSimOptions::default() };
    let sim = ShelfSim::start("127.0.0.1:0", options).await?;
    let plc = sim.local_addr().context("a UDP simulator has an address")?;
    let mut device = sim.device_config("shelf1", &plc.to_string(), vec![1]);
    device.poll_ms = 100;
    let crane_options =
        CraneSimOptions { transport: TransportKind::Tcp, step: DEMO_CRANE_STEP, wcs_timeout: None };
    let crane = CraneSim::start("127.0.0.1:0", crane_options).await?;
    let mut crane_device = DeviceConfig::crane("crane1", &crane.local_addr().to_string(), vec![2]);
    crane_device.poll_ms = 100;
    if !config.site.aisles.iter().any(|a| a.aisle == 2) {
        crane_device.aisles.clear();
    }
    config.devices = vec![device];
    if !crane_device.aisles.is_empty() {
        config.devices.push(crane_device);
    }
    tracing::info!(plc = %plc, crane = %crane.local_addr(), "demo site: simulated shelf PLC (device shelf1) and crane (device crane1) started");
    Ok((sim, crane))
}
