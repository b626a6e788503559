//! What the device adapters' runs over the seeded simulation of the wire share
//! (`shelf::wire`, `crane::wire`): the seeds the environment asks for, the weather of a
//! seed, and the run to the end of every job with the adapter killed and started again at
//! random moments (as `kill -9` of rackd: the dispatcher's records stay, as the database
//! would); then the checks every machine must pass.

use std::future::Future;
use std::time::Duration;

use rackd::domain::{FailureKind, JobState, Reported};
use rackd::protocols::simwire::{Weather, Wire};
use tokio::task::JoinHandle;
use tokio::time::Instant;

use super::port::TestPort;

fn env(name: &str) -> Option<u64> {
    std::env::var(name).ok().and_then(|v| v.parse().ok())
}

/// Runs `run` for each seed the environment asks for (`RACKD_WIRE_SEED=N` alone,
/// `RACKD_WIRE_FIRST` and `RACKD_WIRE_SEEDS`), or seeds `0..default`, each on its own
/// paused runtime; `run` answers how often it killed the adapter.
pub fn each_seed<F, Fut>(default: u64, run: F)
where
    F: Fn(u64) -> Fut,
    Fut: Future<Output = u32>,
{
    let (first, count) = match env("RACKD_WIRE_SEED") {
        Some(seed) => (seed, 1),
        None => (env("RACKD_WIRE_FIRST").unwrap_or(0), env("RACKD_WIRE_SEEDS").unwrap_or(default)),
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

/// The weather of a seed: no loss, 5% or 20%, a short or a long tail of delays, copies of
/// replies (and of requests where the replies carry ids).
pub fn weather(wire: &Wire, copies_requests: bool) -> Weather {
    let drop = [0.0, 0.05, 0.2][wire.roll(3) as usize];
    let tail = Duration::from_micros([200, 1000, 3000][wire.roll(3) as usize]);
    Weather {
        drop,
        duplicate: 0.02,
        copies_requests,
        base: Duration::from_micros(200),
        tail,
        longest: Duration::from_millis(45),
    }
}

/// Waits until every job of `jobs` has ended, killing the adapter `device` and starting a
/// new one with `start` at random moments; panics, naming `seed`, after `limit`. Returns
/// the kills.
pub async fn until_ended(
    seed: u64,
    wire: &Wire,
    port: &TestPort,
    jobs: &[i64],
    limit: Duration,
    mut start: impl FnMut() -> JoinHandle<()>,
) -> u32 {
    let mut device = start();
    let deadline = Instant::now() + limit;
    let mut kills = 0;
    loop {
        tokio::time::sleep(Duration::from_millis(10 + wire.roll(400))).await;
        if jobs.iter().all(|&id| port.job_as_held(id).state.is_terminal()) {
            break;
        }
        assert!(Instant::now() < deadline, "seed {seed}: jobs not ended in {limit:?}: {:?}", port.jobs());
        if wire.roll(100) < 15 {
            // kill -9: the task stops wherever it is, its link with it.
            if std::env::var_os("RACKD_WIRE_TRACE").is_some() {
                eprintln!("--- kill");
            }
            device.abort();
            let _ = device.await;
            device = start();
            kills += 1;
        }
    }
    device.abort();
    kills
}

/// Every job of `jobs` completed, none failed as lost (the machine never lost one), and
/// each reached the machine once (`received` counts the tasks the simulator took for it).
pub fn assert_each_completed_once(seed: u64, port: &TestPort, jobs: &[i64], received: impl Fn(i64) -> u32) {
    for &id in jobs {
        let job = port.job_as_held(id);
        let reports = port.reports_of(id);
        let lost = reports.iter().any(|r| matches!(r, Reported::Failed(f) if f.kind == FailureKind::Lost));
        assert!(
            !lost,
            "seed {seed}: job {id} failed as lost, though the machine never lost it: {job:?}, {reports:?}"
        );
        assert_eq!(job.state, JobState::Completed, "seed {seed}: job {id}: {job:?}");
        assert_eq!(received(id), 1, "seed {seed}: job {id}'s task reached the machine once");
    }
}
