//! The shelf adapter over the seeded simulation of the wire (`rackd::protocols::simwire`):
//! the real adapter and the real shelf simulator over Modbus UDP, answering with
//! transaction id 0 as the seed's PLC does (and, in a second test, echoing the ids), on
//! paused time, through a wire that delays (a long tail),
//! loses and copies frames; the adapter is killed and started again (as `kill -9` of
//! rackd: the dispatcher's records stay, as the database would) at random moments while
//! frames are under way, and the new link may be handed the old one's port. Over many
//! seeds: every job ends `completed`, none `lost`, no write lands in a busy slot, and every
//! task reaches the PLC once.
//!
//! A failure names its seed; `RACKD_WIRE_SEED=N cargo test --test it shelf::wire` replays
//! it, `RACKD_WIRE_SEEDS=K` runs more (see `protocols::simwire`).

use std::sync::Arc;
use std::time::Duration;

use rackd::config::devices::{DeviceKind, ShelfConfig};
use rackd::devices::shelf::Shelf;
use rackd::devices::{DeviceStatus, StatusCell};
use rackd::domain::{JobSpec, LightColor, Location};
use rackd::protocols::link::connect_over;
use rackd::protocols::simwire::Wire;
use rackd::sim::shelf::{ShelfSim, ShelfSimOptions};
use rackd::wire::task_id_for;
use tokio::task::JoinHandle;

use crate::support::port::TestPort;
use crate::support::wire::{assert_each_completed_once, each_seed, until_ended, weather};

/// Seeds in `cargo test`.
const SEEDS: u64 = 40;

/// Jobs per seed.
const JOBS: i64 = 24;

/// A light of its own for job `n`, so that every job is different work for the PLC.
fn light(n: i64) -> JobSpec {
    let n = n as u16;
    let location =
        Location { aisle: 1, row: 1 + n % 2, bay: 1 + n / 2 % 10, level: 1 + n / 20 % 6, position: 1 };
    JobSpec::Light { location, color: LightColor::Green, on: !n.is_multiple_of(3) }
}

/// A rackd's shelf adapter for `sim` over `wire`, with a fresh link (a new process).
fn start(wire: &Wire, sim: &ShelfSim, port: &Arc<TestPort>) -> JoinHandle<()> {
    let mut link = sim.link("simulated");
    link.timeout = Duration::from_millis(100);
    link.retries = 3;
    let plc = connect_over(&link, wire.datagrams()).unwrap();
    let mut config = ShelfConfig::on("shelf1", link, vec![1]);
    config.base = sim.base().to_owned();
    config.stride = sim.stride();
    config.slots = sim.slots();
    config.poll_ms = 20;
    let status = StatusCell::new(
        DeviceStatus::new("shelf1", DeviceKind::Shelf, "modbus-udp", "simulated", sim.slots()),
        Duration::from_secs(5),
    );
    let shelf = Shelf::new(config, plc, port.clone(), status).unwrap();
    let (_requests, inbox) = tokio::sync::mpsc::channel(4);
    tokio::spawn(async move {
        // The sender lives as long as the task: no stop is ever asked.
        let _keep = _requests;
        shelf.run(inbox).await
    })
}

/// One seed: the jobs, the weather, the kills; panics naming the seed on a breach. With
/// `ids` the PLC echoes transaction ids (and datagrams are copied both ways).
async fn run(seed: u64, ids: bool) -> u32 {
    let wire = Wire::new(seed);
    let options = ShelfSimOptions {
        slots: 8,
        task_time: Duration::from_millis(30),
        no_transaction_id: !ids,
        ..ShelfSimOptions::default()
    };
    let sim = ShelfSim::serve_datagrams(wire.server_port(), options).await.unwrap();
    let port = Arc::new(TestPort::default());
    let jobs: Vec<i64> = (0..JOBS).map(|n| port.queue(light(n))).collect();
    wire.set_weather(weather(&wire, ids));
    let kills =
        until_ended(seed, &wire, &port, &jobs, Duration::from_secs(600), || start(&wire, &sim, &port)).await;
    assert_eq!(sim.violations(), 0, "seed {seed}: a write into a busy slot");
    assert_each_completed_once(seed, &port, &jobs, |id| sim.received(task_id_for(id)));
    kills
}

#[test]
fn the_shelf_over_a_faulty_wire_without_transaction_ids_completes_every_job_once() {
    each_seed(SEEDS, |seed| run(seed, false));
}

#[test]
fn the_shelf_over_a_faulty_wire_with_transaction_ids_completes_every_job_once() {
    each_seed(SEEDS, |seed| run(seed, true));
}
