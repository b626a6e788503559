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
use rackd::domain::{FailureKind, JobSpec, JobState, LightColor, Location, Reported};
use rackd::protocols::link::connect_over;
use rackd::protocols::simwire::{Weather, Wire};
use rackd::sim::shelf::{ShelfSim, ShelfSimOptions};
use rackd::wire::task_id_for;
use tokio::task::JoinHandle;
use tokio::time::Instant;

use crate::support::port::TestPort;

/// Seeds in `cargo test`.
const SEEDS: u64 = 40;

/// Jobs per seed.
const JOBS: i64 = 24;

fn env(name: &str) -> Option<u64> {
    std::env::var(name).ok().and_then(|v| v.parse().ok())
}

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
    let drop = [0.0, 0.05, 0.2][wire.roll(3) as usize];
    let tail = Duration::from_micros([200, 1000, 3000][wire.roll(3) as usize]);
    wire.set_weather(Weather {
        drop,
        duplicate: 0.02,
        copies_requests: ids,
        base: Duration::from_micros(200),
        tail,
        longest: Duration::from_millis(45),
    });
    let mut device = start(&wire, &sim, &port);
    let deadline = Instant::now() + Duration::from_secs(600);
    let mut kills = 0;
    loop {
        tokio::time::sleep(Duration::from_millis(10 + wire.roll(400))).await;
        if jobs.iter().all(|&id| port.job_as_held(id).state.is_terminal()) {
            break;
        }
        assert!(Instant::now() < deadline, "seed {seed}: jobs not ended in 10 minutes: {:?}", port.jobs());
        if wire.roll(100) < 15 {
            // kill -9: the task stops wherever it is, its link with it.
            if std::env::var_os("RACKD_WIRE_TRACE").is_some() {
                eprintln!("--- kill at {:?}", Instant::now() - (deadline - Duration::from_secs(600)));
            }
            device.abort();
            let _ = device.await;
            device = start(&wire, &sim, &port);
            kills += 1;
        }
    }
    device.abort();
    eprintln!(
        "seed {seed}: {kills} kills, {:?} virtual, {:?} finished",
        Instant::now() - (deadline - Duration::from_secs(600)),
        sim.finished()
    );
    assert_eq!(sim.violations(), 0, "seed {seed}: a write into a busy slot");
    for &id in &jobs {
        let job = port.job_as_held(id);
        let lost = port
            .reports_of(id)
            .iter()
            .any(|r| matches!(r, Reported::Failed(f) if f.kind == FailureKind::Lost));
        let reports = port.reports_of(id);
        assert!(
            !lost,
            "seed {seed}: job {id} failed as lost, though the PLC never lost it: {job:?}, {reports:?}"
        );
        assert_eq!(job.state, JobState::Completed, "seed {seed}: job {id}: {job:?}");
        assert_eq!(sim.received(task_id_for(id)), 1, "seed {seed}: job {id}'s task reached the PLC once");
    }
    kills
}

/// Runs the environment's seeds (or the suite's) with or without transaction ids.
fn seeds(ids: bool) {
    let (first, count) = match env("RACKD_WIRE_SEED") {
        Some(seed) => (seed, 1),
        None => (env("RACKD_WIRE_FIRST").unwrap_or(0), env("RACKD_WIRE_SEEDS").unwrap_or(SEEDS)),
    };
    if std::env::var_os("RACKD_WIRE_TRACE").is_some() {
        let _ = tracing_subscriber::fmt().with_env_filter("rackd=debug").with_test_writer().try_init();
    }
    let mut kills = 0;
    for seed in first..first + count {
        let runtime =
            tokio::runtime::Builder::new_current_thread().enable_all().start_paused(true).build().unwrap();
        kills += runtime.block_on(run(seed, ids));
    }
    assert!(count < 10 || u64::from(kills) > count, "the adapter was killed often enough to matter: {kills}");
}

#[test]
fn the_shelf_over_a_faulty_wire_without_transaction_ids_completes_every_job_once() {
    seeds(false);
}

#[test]
fn the_shelf_over_a_faulty_wire_with_transaction_ids_completes_every_job_once() {
    seeds(true);
}
