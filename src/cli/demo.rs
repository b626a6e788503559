//! The demo site: `rackd serve` with no configuration.
//!
//! The demo layout ([`Config::demo`]: shelf aisle 1, 2 rows x 10 bays x 6 levels x 4
//! positions; crane aisle 2, 2 rows x 20 bays x 8 levels x 2 depths) with a simulated shelf
//! PLC on a free loopback UDP port (device `shelf1`, aisle 1) and a simulated stacker crane
//! on a free loopback MC 3E TCP port (device `crane1`, aisle 2), both inside the process, so
//! the first command of the README gives a working store; jobs go to the device of their
//! location's aisle. A simulated light tower on Modbus TCP (device `tower1`, a tags device:
//! lamps, buzzer, a box sensor that changes every few seconds, a conveyor speed) shows tag
//! I/O. A real site
//! replaces the simulator with its PLC's address in `[[devices]]` (see
//! `config/rackd.example.toml`).

use std::time::Duration;

use anyhow::Context;

use crate::config::Config;
use crate::config::devices::{CraneConfig, DeviceConfig, ShelfConfig, TagsConfig};
use crate::protocols::Protocol;
use crate::protocols::link::LinkConfig;
use crate::protocols::mc3e::TransportKind;
use crate::sim::crane::{CraneSim, CraneSimOptions};
use crate::sim::shelf::{ShelfSim, ShelfSimOptions};
use crate::sim::tower::{self, TowerSim};
use crate::wire::tags::TagTable;

/// A `[[devices]]` entry that drives the shelf simulator `sim`, reached at `address` (its
/// local address, or the serial device at the other end of its line), serving `aisles`.
pub fn shelf_device(sim: &ShelfSim, id: &str, address: &str, aisles: Vec<u16>) -> ShelfConfig {
    let mut device = ShelfConfig::on(id, sim.link(address), aisles);
    device.base = sim.base().to_owned();
    device.stride = sim.stride();
    device.slots = sim.slots();
    device
}

/// How fast the demo's simulated machines work.
#[derive(Clone, Copy, Debug)]
pub struct Pace {
    /// How long each simulated shelf task takes.
    pub task_time: Duration,
    /// Time of each simulated crane action state (a transfer has 16).
    pub crane_step: Duration,
}

impl Pace {
    /// `rackd serve`'s pace: slow enough to watch a job run.
    pub const DEMO: Pace =
        Pace { task_time: Duration::from_millis(1500), crane_step: Duration::from_millis(250) };
}

/// How often a box arrives at (or leaves) the demo tower's station sensor.
const DEMO_BOX_PERIOD: Duration = Duration::from_secs(5);

/// The tags device `id` for a simulated light tower at `address` (Modbus TCP), with the
/// tower's tags ([`tower::TAGS`]) and fast polling.
pub fn tower_device(id: &str, address: &str) -> DeviceConfig {
    let tags: TagTable = toml::from_str(tower::TAGS).expect("the tower's tag table");
    let mut device = TagsConfig::new(id, LinkConfig::new(Protocol::ModbusTcp, address), tags.0);
    device.poll_ms = 100;
    device.into()
}

/// Starts the demo's simulated machines and adds their devices to `config`; keep the
/// returned simulators alive as long as the service runs.
pub async fn start(config: &mut Config) -> anyhow::Result<(ShelfSim, CraneSim, TowerSim)> {
    start_with(config, Pace::DEMO).await
}

/// [`start`] at another pace (tests run the demo site faster).
pub async fn start_with(config: &mut Config, pace: Pace) -> anyhow::Result<(ShelfSim, CraneSim, TowerSim)> {
    // The seed's PLC: MBAP length 0 and transaction id 0 in every reply.
    let options =
        ShelfSimOptions { task_time: pace.task_time, no_transaction_id: true, ..ShelfSimOptions::default() };
    let sim = ShelfSim::start("127.0.0.1:0", options).await?;
    let plc = sim.local_addr().context("a UDP simulator has an address")?;
    let mut device = shelf_device(&sim, "shelf1", &plc.to_string(), vec![1]);
    device.poll_ms = 100;
    let crane_options =
        CraneSimOptions { transport: TransportKind::Tcp, step: pace.crane_step, ..Default::default() };
    let crane = CraneSim::start("127.0.0.1:0", crane_options).await?;
    let mut crane_device = CraneConfig::new("crane1", &crane.local_addr().to_string(), vec![2]);
    crane_device.poll_ms = 100;
    if !config.site.aisles.iter().any(|a| a.aisle == 2) {
        crane_device.aisles.clear();
    }
    let tower = TowerSim::start("127.0.0.1:0", Some(DEMO_BOX_PERIOD)).await?;
    config.devices = vec![device.into()];
    if !crane_device.aisles.is_empty() {
        config.devices.push(crane_device.into());
    }
    config.devices.push(tower_device("tower1", &tower.local_addr().to_string()));
    tracing::info!(
        plc = %plc, crane = %crane.local_addr(), tower = %tower.local_addr(),
        "demo site: simulated shelf PLC (device shelf1), crane (device crane1) and light tower (device tower1) started"
    );
    Ok((sim, crane, tower))
}
