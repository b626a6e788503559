//! The crane adapter over the seeded simulation of the wire (`rackd::protocols::simwire`):
//! the real adapter and the real crane simulator over MC 3E UDP (whose replies name no
//! request), on paused time, through a wire that delays (a long tail), loses and copies
//! frames; the adapter is killed and started again (as `kill -9` of rackd: the
//! dispatcher's records stay, as the database would) at random moments, hand-overs
//! included, and the new link may be handed the old one's port. Over many seeds: every
//! job ends `completed`, none `lost`, the crane sees no breach of its interface (a strobe
//! without the handshake, a task written while it works), and every task reaches the crane
//! once.
//!
//! A failure names its seed; `RACKD_WIRE_SEED=N cargo test --test it crane::wire` replays
//! it, `RACKD_WIRE_SEEDS=K` runs more.

use std::sync::Arc;
use std::time::Duration;

use rackd::config::devices::{CraneConfig, DeviceKind};
use rackd::devices::crane::Crane;
use rackd::devices::{DeviceStatus, StatusCell};
use rackd::domain::{JobSpec, Location};
use rackd::protocols::Protocol;
use rackd::protocols::link::connect_over;
use rackd::protocols::mc3e::TransportKind;
use rackd::protocols::simwire::{DEVICE, Wire};
use rackd::sim::crane::{CraneSim, CraneSimOptions};
use rackd::wire::task_id_for;
use tokio::task::JoinHandle;

use crate::support::port::TestPort;
use crate::support::wire::{assert_each_completed_once, each_seed, until_ended, weather};

/// Seeds in `cargo test`.
const SEEDS: u64 = 25;

/// Jobs per seed.
const JOBS: i64 = 12;

/// Job `n`: stores, retrievals and travels to places of their own.
fn job(n: i64) -> JobSpec {
    let n = n as u16;
    let at = Location { aisle: 2, row: 1 + n % 2, bay: 1 + n % 19, level: 1 + n % 7, position: 1 };
    match n % 3 {
        0 => JobSpec::Store { to: at },
        1 => JobSpec::Retrieve { from: at },
        _ => JobSpec::Travel { to: at },
    }
}

/// A rackd's crane adapter over `wire`, with a fresh link (a new process).
fn start(wire: &Wire, port: &Arc<TestPort>) -> JoinHandle<()> {
    let mut config = CraneConfig::new("crane1", &DEVICE.to_string(), vec![2]);
    config.link.protocol = Protocol::Mc3eUdp;
    config.link.timeout = Duration::from_millis(100);
    config.link.retries = 3;
    config.poll_ms = 20;
    config.heartbeat_ms = 50;
    config.heartbeat_timeout_ms = 5_000;
    config.handshake_timeout_ms = 2_000;
    let plc = connect_over(&config.link, wire.datagrams()).unwrap();
    let status = StatusCell::new(
        DeviceStatus::new("crane1", DeviceKind::Crane, "mc3e-udp", "simulated", 1),
        Duration::from_secs(5),
    );
    let crane = Crane::new(config, plc, port.clone(), status).unwrap();
    let (requests, inbox) = tokio::sync::mpsc::channel(4);
    tokio::spawn(async move {
        // The sender lives as long as the task: no stop is ever asked.
        let _keep = requests;
        crane.run(inbox).await
    })
}

/// One seed: the jobs, the weather, the kills; panics naming the seed on a breach.
async fn run(seed: u64) -> u32 {
    let wire = Wire::new(seed);
    let options = CraneSimOptions {
        transport: TransportKind::Udp,
        step: Duration::from_millis(10),
        ..Default::default()
    };
    let sim = CraneSim::serve_datagrams(wire.server_port(), DEVICE, options).unwrap();
    let port = Arc::new(TestPort::default());
    let jobs: Vec<i64> = (0..JOBS).map(|n| port.queue(job(n))).collect();
    wire.set_weather(weather(&wire, false));
    let kills =
        until_ended(seed, &wire, &port, &jobs, Duration::from_secs(900), || start(&wire, &port)).await;
    assert_eq!(sim.violations(), 0, "seed {seed}: {:?}", sim.violation_log());
    assert_each_completed_once(seed, &port, &jobs, |id| sim.received(task_id_for(id)));
    kills
}

#[test]
fn the_crane_over_a_faulty_wire_completes_every_job_once_through_kills() {
    each_seed(SEEDS, run);
}
