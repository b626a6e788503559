//! `bench crane`: the crane planner, `fifo` against `travel`, on one workload, against the
//! crane simulator with its motion model and an inventory of its own.
//!
//! The workload is drawn once from `--seed`:
//! - aisle 2 of the demo site (2 rows, 20 bays, 8 levels, double-deep) starts with each
//!   location full with probability `--fill`; rackd's inventory and the simulator's agree;
//! - `--jobs` jobs follow, each a retrieve (of a box there at the start, each box once) or a
//!   store left to rackd (putaway, `{"kind": "store", "aisle": 2}`), half and half;
//! - the WMS keeps `--backlog` jobs open: it posts the next job as one ends.
//!
//! Each planner then runs the workload against a fresh simulator and a fresh rackd.
//!
//! Figures, from the simulator's own counters:
//! - **cycles per hour** are the tasks it completed per hour of its busy time (motion and
//!   fork cycles, simulated). The time rackd takes between tasks (hand-over, polls) is left
//!   out, because the time scale would multiply it a hundredfold;
//! - **empty travel** is metres along the aisle with nothing on the platform;
//! - **relocations** per retrieve are the `move` jobs rackd made, which name the job they
//!   serve;
//! - **business alarms** are what the crane raised (7091..7098 and the rest). rackd should
//!   cause none.

use std::collections::{BTreeMap, HashSet};
use std::time::{Duration, Instant};

use anyhow::{Context, ensure};
use serde_json::{Value, json};
use tokio::sync::oneshot;

use rackd::app::Application;
use rackd::config::Config;
use rackd::devices::config::{CraneConfig, Planner};
use rackd::protocols::mc3e::TransportKind;
use rackd::sim::crane::{CraneSim, CraneSimOptions, CraneStats};
use rackd::wire::motion::Motion;

/// `bench crane`'s options.
#[derive(clap::Args, Debug, Clone)]
pub struct CraneArgs {
    /// Jobs in the workload (retrieves and putaway stores, half and half).
    #[arg(long, default_value_t = 200)]
    pub jobs: usize,
    /// Jobs the WMS keeps open at once.
    #[arg(long, default_value_t = 30)]
    pub backlog: usize,
    /// Share of the aisle's locations full at the start.
    #[arg(long, default_value_t = 0.5)]
    pub fill: f64,
    /// Simulated seconds per real second.
    #[arg(long, default_value_t = 200.0)]
    pub time_scale: f64,
    /// Seed of the workload.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
}

/// What one planner made of the workload.
struct Figures {
    stats: CraneStats,
    completed: usize,
    failed: usize,
    relocations: usize,
    retrieves: usize,
    wall: Duration,
}

impl Figures {
    fn cycles_per_hour(&self) -> f64 {
        self.stats.cycles as f64 * 3600.0 / self.stats.busy_secs.max(f64::EPSILON)
    }

    fn alarms(&self) -> u32 {
        self.stats.alarms.values().sum()
    }
}

/// Runs both planners and prints the comparison.
pub async fn run(args: CraneArgs) -> anyhow::Result<()> {
    ensure!((0.0..=1.0).contains(&args.fill), "--fill is a share, 0..=1");
    ensure!(args.backlog > 0 && args.time_scale > 0.0, "--backlog and --time-scale must be above 0");
    let workload = Workload::draw(&args);
    println!(
        "bench crane: {} jobs ({} retrieves, {} putaway stores), {} boxes at the start ({:.0}% of {}), backlog {}, time x{}",
        workload.jobs.len(),
        workload.retrieves(),
        workload.jobs.len() - workload.retrieves(),
        workload.stock.len(),
        args.fill * 100.0,
        CELLS,
        args.backlog,
        args.time_scale
    );
    let fifo = one(Planner::Fifo, &workload, &args).await?;
    let travel = one(Planner::Travel, &workload, &args).await?;
    println!(
        "{:<8} {:>10} {:>8} {:>14} {:>16} {:>14} {:>16} {:>8}",
        "planner", "cycles/h", "cycles", "empty travel", "loaded travel", "reloc/retrieve", "business alarms", "wall"
    );
    for (name, f) in [("fifo", &fifo), ("travel", &travel)] {
        println!(
            "{name:<8} {:>10.1} {:>8} {:>12.0} m {:>14.0} m {:>14.2} {:>16} {:>6.1} s",
            f.cycles_per_hour(),
            f.stats.cycles,
            f.stats.travel_empty_m,
            f.stats.travel_loaded_m,
            f.relocations as f64 / f.retrieves.max(1) as f64,
            f.alarms(),
            f.wall.as_secs_f64()
        );
        ensure!(f.failed == 0, "{name}: {} jobs failed", f.failed);
        ensure!(f.completed == workload.jobs.len(), "{name}: {} of {} jobs completed", f.completed, workload.jobs.len());
    }
    println!(
        "travel / fifo: {:.2}x cycles per hour, {:.2}x empty travel",
        travel.cycles_per_hour() / fifo.cycles_per_hour(),
        travel.stats.travel_empty_m / fifo.stats.travel_empty_m.max(f64::EPSILON)
    );
    Ok(())
}

/// Locations in aisle 2 of the demo: 2 rows x 20 bays x 8 levels x 2 depths.
const CELLS: usize = 2 * 20 * 8 * 2;

/// The boxes at the start and the jobs, as request bodies.
struct Workload {
    stock: Vec<[u16; 4]>,
    jobs: Vec<Value>,
}

impl Workload {
    fn draw(args: &CraneArgs) -> Workload {
        let mut rng = SplitMix(args.seed);
        let mut stock = Vec::new();
        for row in 1..=2 {
            for bay in 1..=20 {
                for level in 1..=8 {
                    for side in 1..=2 {
                        if rng.unit() < args.fill {
                            stock.push([row, bay, level, side]);
                        }
                    }
                }
            }
        }
        let mut boxes = stock.clone();
        let mut free = CELLS - stock.len();
        let mut jobs = Vec::new();
        while jobs.len() < args.jobs {
            let retrieve = rng.unit() < 0.5;
            if retrieve && !boxes.is_empty() {
                let [row, bay, level, side] = boxes.swap_remove(rng.below(boxes.len()));
                let from = json!({"aisle": 2, "row": row, "bay": bay, "level": level, "position": side});
                jobs.push(json!({"kind": "retrieve", "from": from}));
                free += 1;
            } else if free > 0 {
                jobs.push(json!({"kind": "store", "aisle": 2}));
                free -= 1;
            }
        }
        Workload { stock, jobs }
    }

    fn retrieves(&self) -> usize {
        self.jobs.iter().filter(|j| j["kind"] == "retrieve").count()
    }
}

/// A seeded generator (SplitMix64), so that both planners get the same workload; the
/// benchmark needs no more than this of a random-number crate.
struct SplitMix(u64);

impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

/// The workload under one planner, against a fresh simulator and a fresh rackd.
async fn one(planner: Planner, workload: &Workload, args: &CraneArgs) -> anyhow::Result<Figures> {
    let options = CraneSimOptions {
        transport: TransportKind::Tcp,
        motion: Some(Motion::default()),
        time_scale: args.time_scale,
        inventory: Some(workload.stock.clone()),
        ..CraneSimOptions::default()
    };
    let sim = CraneSim::start("127.0.0.1:0", options).await?;
    let dir = tempfile::tempdir()?;
    let mut config = Config::demo();
    config.server.listen = "127.0.0.1:0".parse()?;
    config.database.path = dir.path().join("bench.db");
    let mut device = CraneConfig::new("crane1", &sim.local_addr().to_string(), vec![2]);
    (device.poll_ms, device.heartbeat_ms, device.planner) = (10, 100, planner);
    config.devices = vec![device.into()];
    let app = Application::build(&config, false).await?;
    let base = format!("http://{}", app.local_addr());
    let (stop, stopped) = oneshot::channel::<()>();
    let server = tokio::spawn(app.run_until(async {
        let _ = stopped.await;
    }));
    let client = reqwest::Client::new();
    let locations: Vec<Value> = workload
        .stock
        .iter()
        .map(|[row, bay, level, side]| {
            json!({"aisle": 2, "row": row, "bay": bay, "level": level, "position": side, "occupied": true})
        })
        .collect();
    let r = client.put(format!("{base}/api/v1/locations")).json(&json!({"locations": locations})).send().await?;
    ensure!(r.status() == 200, "inventory: {}", r.status());

    let started = Instant::now();
    let (mut next, mut open, mut ended) = (0, HashSet::new(), BTreeMap::new());
    while ended.len() < workload.jobs.len() {
        while open.len() < args.backlog && next < workload.jobs.len() {
            let r = client.post(format!("{base}/api/v1/jobs")).json(&workload.jobs[next]).send().await?;
            ensure!(r.status() == 201, "POST job {next}: {}", r.status());
            open.insert(r.json::<Value>().await?["id"].as_i64().context("job id")?);
            next += 1;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
        for id in open.clone() {
            let job: Value = client.get(format!("{base}/api/v1/jobs/{id}")).send().await?.json().await?;
            let state = job["state"].as_str().unwrap_or_default().to_owned();
            if ["completed", "failed", "cancelled"].contains(&state.as_str()) {
                open.remove(&id);
                ended.insert(id, state);
            }
        }
        ensure!(started.elapsed() < Duration::from_secs(1800), "the workload did not end in 30 minutes");
    }
    let wall = started.elapsed();
    let moves: Value = client.get(format!("{base}/api/v1/jobs?kind=move&limit=1000")).send().await?.json().await?;
    let relocations = moves["jobs"].as_array().map_or(0, |m| m.iter().filter(|j| !j["serves"].is_null()).count());
    let stats = sim.stats();
    let _ = stop.send(());
    server.await??;
    sim.shutdown().await;
    Ok(Figures {
        stats,
        completed: ended.values().filter(|s| *s == "completed").count(),
        failed: ended.values().filter(|s| *s != "completed").count(),
        relocations,
        retrieves: workload.retrieves(),
        wall,
    })
}
