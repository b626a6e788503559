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
use rackd::domain::{FailureKind, JobSpec, JobState, Location, Reported};
use rackd::protocols::Protocol;
use rackd::protocols::link::connect_over;
use rackd::protocols::mc3e::TransportKind;
use rackd::protocols::simwire::{DEVICE, Weather, Wire};
use rackd::sim::crane::{CraneSim, CraneSimOptions};
use rackd::wire::task_id_for;
use tokio::task::JoinHandle;
use tokio::time::Instant;

use crate::support::port::TestPort;

/// Seeds in `cargo test`.
const SEEDS: u64 = 25;

/// Jobs per seed.
const JOBS: i64 = 12;

fn env(name: &str) -> Option<u64> {
    std::env::var(name).ok().and_then(|v| v.parse().ok())
}

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
    let drop = [0.0, 0.05, 0.2][wire.roll(3) as usize];
    let tail = Duration::from_micros([200, 1000, 3000][wire.roll(3) as usize]);
    wire.set_weather(Weather {
        drop,
        duplicate: 0.02,
        copies_requests: false,
        base: Duration::from_micros(200),
        tail,
        longest: Duration::from_millis(45),
    });
    let mut device = start(&wire, &port);
    let deadline = Instant::now() + Duration::from_secs(900);
    let mut kills = 0;
    loop {
        tokio::time::sleep(Duration::from_millis(10 + wire.roll(500))).await;
        if jobs.iter().all(|&id| port.job_as_held(id).state.is_terminal()) {
            break;
        }
        assert!(Instant::now() < deadline, "seed {seed}: jobs not ended in 15 minutes: {:?}", port.jobs());
        if wire.roll(100) < 15 {
            // kill -9: the task stops wherever it is, its link with it.
            if std::env::var_os("RACKD_WIRE_TRACE").is_some() {
                eprintln!("--- kill");
            }
            device.abort();
            let _ = device.await;
            device = start(&wire, &port);
            kills += 1;
        }
    }
    device.abort();
    assert_eq!(sim.violations(), 0, "seed {seed}: {:?}", sim.violation_log());
    for &id in &jobs {
        let job = port.job_as_held(id);
        let lost = port
            .reports_of(id)
            .iter()
            .any(|r| matches!(r, Reported::Failed(f) if f.kind == FailureKind::Lost));
        let reports = port.reports_of(id);
        assert!(
            !lost,
            "seed {seed}: job {id} failed as lost, though the crane never lost it: {job:?}, {reports:?}"
        );
        assert_eq!(job.state, JobState::Completed, "seed {seed}: job {id}: {job:?}");
        assert_eq!(sim.received(task_id_for(id)), 1, "seed {seed}: job {id}'s task reached the crane once");
    }
    kills
}

#[test]
fn the_crane_over_a_faulty_wire_completes_every_job_once_through_kills() {
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
        kills += runtime.block_on(run(seed));
    }
    assert!(count < 10 || u64::from(kills) > count, "the adapter was killed often enough to matter: {kills}");
}
