//! `bench crane`: the crane planner, `fifo` against `travel`, on one workload, against the
//! crane simulator with its motion model and an inventory of its own.
//!
//! The workload is drawn once from `--seed`:
//! - aisle 2 of the demo site (2 rows, 20 bays, 8 levels, double-deep) starts with each
//!   location full with probability `--fill`; rackd's inventory and the simulator's agree;
//! - `--jobs` jobs follow, half retrieves, half stores, shuffled, in an order a WMS could send them
//!   (drawn against the rack as it would be if they ran in that order): a retrieve takes a
//!   box that is there, a store names a free location (far only behind an empty near), or,
//!   for a `--putaway` share of the stores, leaves it to rackd (`{"kind": "store", "aisle": 2}`);
//! - the WMS keeps `--backlog` jobs open: it posts the next job as one ends.
//!
//! Each planner then runs the workload against a fresh simulator and a fresh rackd.
//!
//! Figures, from the simulator's own counters:
//! - **cycles per hour** are the WMS's jobs (store and retrieve cycles) completed per hour of
//!   the crane's busy time (motion and fork cycles, simulated); relocations are overhead,
//!   counted in that time but not as cycles. The time rackd takes between tasks (hand-over,
//!   polls) is left out, because the time scale would multiply it a hundredfold; `tasks`
//!   are all the crane ran, relocations included;
//! - **empty travel** is metres along the aisle with nothing on the platform;
//! - **relocations** per retrieve are the `move` jobs rackd made, which name the job they
//!   serve;
//! - **business alarms** are what the crane raised (7091..7098 and the rest). rackd should
//!   cause none.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::time::{Duration, Instant};

use anyhow::{Context, ensure};
use serde_json::{Value, json};

use rackd::config::Config;
use rackd::config::devices::{CraneConfig, Planner};
use rackd::protocols::mc3e::TransportKind;
use rackd::sim::crane::{CraneSim, CraneSimOptions, CraneStats};
use rackd::wire::motion::Motion;

use crate::served::Served;

pub(crate) mod bound;

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
    /// Bays of the aisle (1.4 m each).
    #[arg(long, default_value_t = 50)]
    pub bays: u16,
    /// Levels of the aisle (1.5 m each).
    #[arg(long, default_value_t = 12)]
    pub levels: u16,
    /// The travel planner's `max_overtaken` (default: the crane's default).
    #[arg(long)]
    pub max_overtaken: Option<u32>,
    /// Share of the stores that leave the location to rackd (putaway).
    #[arg(long, default_value_t = 0.0)]
    pub putaway: f64,
}

/// What one planner made of the workload.
struct Figures {
    stats: CraneStats,
    completed: usize,
    /// The jobs that did not complete: id, kind, locations and failure.
    failed: Vec<String>,
    relocations: usize,
    retrieves: usize,
    wall: Duration,
}

impl Figures {
    /// The WMS's jobs (store and retrieve cycles; relocations are overhead, not cycles)
    /// per hour of the crane's busy time.
    fn cycles_per_hour(&self) -> f64 {
        self.completed as f64 * 3600.0 / self.stats.busy_secs.max(f64::EPSILON)
    }

    /// Crane seconds per cycle of the WMS's jobs.
    fn per_cycle(&self, secs: f64) -> f64 {
        secs / self.completed.max(1) as f64
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
        "bench crane: {} jobs ({} retrieves, {} stores), {} boxes at the start ({:.0}% of {}: 2 rows x {} bays x {} levels x 2 deep), backlog {}, time x{}",
        workload.jobs.len(),
        workload.retrieves(),
        workload.jobs.len() - workload.retrieves(),
        workload.stock.len(),
        args.fill * 100.0,
        all_cells(&args).count(),
        args.bays,
        args.levels,
        args.backlog,
        args.time_scale
    );
    let fifo = one(Planner::Fifo, &workload, &args).await?;
    let travel = one(Planner::Travel, &workload, &args).await?;
    println!(
        "{:<8} {:>10} {:>8} {:>14} {:>16} {:>14} {:>16} {:>8}",
        "planner",
        "cycles/h",
        "tasks",
        "empty travel",
        "loaded travel",
        "reloc/retrieve",
        "business alarms",
        "wall"
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
        ensure!(f.failed.is_empty(), "{name}: jobs did not complete: {:#?}, crane: {}", f.failed, f.stats);
        ensure!(
            f.completed == workload.jobs.len(),
            "{name}: {} of {} jobs completed",
            f.completed,
            workload.jobs.len()
        );
    }
    println!("crane seconds per cycle (relocations included): busy = empty travel + loaded travel + forks");
    for (name, f) in [("fifo", &fifo), ("travel", &travel)] {
        println!(
            "{name:<8} {:>6.1} s = {:>5.1} s + {:>5.1} s + {:>5.1} s",
            f.per_cycle(f.stats.busy_secs),
            f.per_cycle(f.stats.empty_secs),
            f.per_cycle(f.stats.loaded_secs),
            f.per_cycle(f.stats.fork_secs)
        );
    }
    println!("empty travel by the task before and the next: tasks x mean run = seconds per cycle");
    for (name, f) in [("fifo", &fifo), ("travel", &travel)] {
        let mut pairs: Vec<_> = f.stats.empty_by_pair.iter().filter(|(_, r)| r.secs > 0.0).collect();
        pairs.sort_by(|a, b| b.1.secs.total_cmp(&a.1.secs));
        for (pair, runs) in pairs {
            println!(
                "{name:<8} {:<20} {:>4} x {:>5.1} s = {:>4.1} s",
                pair.to_string(),
                runs.tasks,
                runs.secs / f64::from(runs.tasks.max(1)),
                f.per_cycle(runs.secs)
            );
        }
    }
    // What sequencing can reach at most: every job's loaded runs and forks are the
    // workload's own, so only travel's empty seconds can go.
    let fixed = travel.per_cycle(travel.stats.busy_secs - travel.stats.empty_secs);
    let fifo_cycle = fifo.per_cycle(fifo.stats.busy_secs);
    println!(
        "with no empty travel at all, travel would be {:.2}x fifo; 1.3x allows {:.1} s of empty travel per cycle",
        fifo_cycle / fixed.max(f64::EPSILON),
        fifo_cycle / 1.3 - fixed
    );
    let bound = bound::Bound::of(&workload, &Motion::default());
    let least = bound.per_cycle();
    println!(
        "knowing all {} jobs in advance, no order could beat {least:.1} s per cycle ({:.2}x fifo): {:.1} s of the jobs' own runs and forks + {:.1} s for the {} relocations no order avoids + {:.1} s of empty travel",
        bound.jobs,
        fifo_cycle / least,
        bound.own_secs / bound.jobs as f64,
        bound.relocation_secs / bound.jobs as f64,
        bound.relocations,
        bound.empty_secs / bound.jobs as f64,
    );
    let with_its_relocations = fixed + bound.empty_secs / bound.jobs as f64;
    println!(
        "with travel's relocations as they ran ({fixed:.1} s of loaded runs and forks per cycle) and that least empty travel: {with_its_relocations:.1} s per cycle ({:.2}x fifo)",
        fifo_cycle / with_its_relocations
    );
    println!(
        "travel / fifo: {:.2}x cycles per hour, {:.2}x empty travel",
        travel.cycles_per_hour() / fifo.cycles_per_hour(),
        travel.stats.travel_empty_m / fifo.stats.travel_empty_m.max(f64::EPSILON)
    );
    Ok(())
}

/// A job of the workload, as the WMS means it: boxes by barcode.
pub(crate) enum Order {
    /// Bring out this box, wherever rackd says it is when the order is sent.
    Retrieve(String),
    /// Put this box here (or, for a `--putaway` share, anywhere in aisle 2).
    Store { cell: [u16; 4], barcode: String, putaway: bool },
}

/// The boxes at the start and the orders (`bench site` makes one per aisle for the bound).
pub(crate) struct Workload {
    pub(crate) stock: Vec<([u16; 4], String)>,
    pub(crate) jobs: Vec<Order>,
}

impl Workload {
    fn draw(args: &CraneArgs) -> Workload {
        let mut rng = SplitMix(args.seed);
        let stock: Vec<([u16; 4], String)> = all_cells(args)
            .filter(|_| rng.unit() < args.fill)
            .enumerate()
            .map(|(n, cell)| (cell, format!("BOX-{n:04}")))
            .collect();
        let mut boxes = stock.clone();
        let mut jobs = Vec::new();
        // Half retrieves, half stores, in a shuffled order.
        let mut kinds: Vec<bool> = (0..args.jobs).map(|i| i % 2 == 0).collect();
        for i in (1..kinds.len()).rev() {
            kinds.swap(i, rng.below(i + 1));
        }
        for retrieve in kinds {
            if retrieve && !boxes.is_empty() {
                let (_, barcode) = boxes.swap_remove(rng.below(boxes.len()));
                jobs.push(Order::Retrieve(barcode));
                continue;
            }
            // Where a store may go now: a free place, far only behind an empty near.
            let full: HashSet<[u16; 4]> = boxes.iter().map(|(c, _)| *c).collect();
            let open: Vec<[u16; 4]> = all_cells(args)
                .filter(|c| !full.contains(c))
                .filter(|&[row, bay, level, side]| side == 1 || !full.contains(&[row, bay, level, 1]))
                .collect();
            let Some(&cell) = open.get(rng.below(open.len().max(1))) else { continue };
            let barcode = format!("NEW-{:04}", jobs.len());
            jobs.push(Order::Store { cell, barcode: barcode.clone(), putaway: rng.unit() < args.putaway });
            boxes.push((cell, barcode));
        }
        Workload { stock, jobs }
    }

    fn retrieves(&self) -> usize {
        self.jobs.iter().filter(|j| matches!(j, Order::Retrieve(_))).count()
    }
}

/// A crane location of aisle 2 as the API writes it.
fn at([row, bay, level, side]: [u16; 4]) -> Value {
    json!({"aisle": 2, "row": row, "bay": bay, "level": level, "position": side})
}

/// Every location of aisle 2 as `[row, bay, level, side]`.
fn all_cells(args: &CraneArgs) -> impl Iterator<Item = [u16; 4]> + use<> {
    let (bays, levels) = (args.bays, args.levels);
    (1..=2).flat_map(move |row| {
        (1..=bays).flat_map(move |bay| {
            (1..=levels).flat_map(move |level| (1..=2).map(move |side| [row, bay, level, side]))
        })
    })
}

/// A seeded generator (SplitMix64), so that both planners get the same workload; the
/// benchmark needs no more than this of a random-number crate (`bench site` draws with it too).
pub(crate) struct SplitMix(pub(crate) u64);

impl SplitMix {
    pub(crate) fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    pub(crate) fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }

    pub(crate) fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

/// The workload under one planner, against a fresh simulator and a fresh rackd.
async fn one(planner: Planner, workload: &Workload, args: &CraneArgs) -> anyhow::Result<Figures> {
    let options = CraneSimOptions {
        transport: TransportKind::Tcp,
        motion: Some(Motion::default()),
        time_scale: args.time_scale,
        inventory: Some(workload.stock.iter().map(|(cell, _)| *cell).collect()),
        ..CraneSimOptions::default()
    };
    let sim = CraneSim::start("127.0.0.1:0", options).await?;
    let dir = tempfile::tempdir()?;
    let mut config = Config::demo();
    for a in config.site.aisles.iter_mut().filter(|a| a.aisle == 2) {
        (a.bays, a.levels) = (args.bays, args.levels);
    }
    config.server.listen = "127.0.0.1:0".parse()?;
    config.database.path = dir.path().join("bench.db");
    let mut device = CraneConfig::new("crane1", &sim.local_addr().to_string(), vec![2]);
    (device.poll_ms, device.heartbeat_ms, device.planner) = (10, 100, planner);
    device.max_overtaken = args.max_overtaken.unwrap_or(device.max_overtaken);
    config.devices = vec![device.into()];
    let served = Served::start(&config).await?;
    let base = served.base.clone();
    let client = reqwest::Client::new();
    let locations: Vec<Value> = workload
        .stock
        .iter()
        .map(|(cell, barcode)| {
            let mut l = at(*cell);
            (l["occupied"], l["barcode"]) = (json!(true), json!(barcode));
            l
        })
        .collect();
    let r =
        client.put(format!("{base}/api/v1/locations")).json(&json!({"locations": locations})).send().await?;
    ensure!(r.status() == 200, "inventory: {}", r.status());

    let started = Instant::now();
    let (mut next, mut open, mut ended) = (0, HashSet::new(), BTreeMap::new());
    let mut wms = Wms::default();
    let mut failed = Vec::new();
    while ended.len() < workload.jobs.len() {
        while open.len() < args.backlog && next < workload.jobs.len() {
            let Some(body) = wms.request(&client, &base, &workload.jobs[next]).await? else { break };
            let r = client.post(format!("{base}/api/v1/jobs")).json(&body).send().await?;
            ensure!(r.status() == 201, "POST job {next} {body}: {} {}", r.status(), r.text().await?);
            open.insert(r.json::<Value>().await?["id"].as_i64().context("job id")?);
            next += 1;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
        for id in open.clone() {
            let job: Value = client.get(format!("{base}/api/v1/jobs/{id}")).send().await?.json().await?;
            let state = job["state"].as_str().unwrap_or_default().to_owned();
            if ["completed", "failed", "cancelled"].contains(&state.as_str()) {
                open.remove(&id);
                if state != "completed" {
                    failed.push(format!(
                        "job {id} {} from {} to {}: {state}, {}",
                        job["kind"], job["from"], job["to"], job["failure"]
                    ));
                }
                ended.insert(id, state);
            }
        }
        ensure!(started.elapsed() < Duration::from_secs(1800), "the workload did not end in 30 minutes");
    }
    let wall = started.elapsed();
    let moves: Value =
        client.get(format!("{base}/api/v1/jobs?kind=move&limit=1000")).send().await?.json().await?;
    let relocations =
        moves["jobs"].as_array().map_or(0, |m| m.iter().filter(|j| !j["serves"].is_null()).count());
    let stats = sim.stats();
    served.stop().await?;
    sim.shutdown().await;
    Ok(Figures {
        stats,
        completed: ended.values().filter(|s| *s == "completed").count(),
        failed,
        relocations,
        retrieves: workload.retrieves(),
        wall,
    })
}

/// The WMS's side: it sends each order as rackd's location model stands when it sends it,
/// as a WMS following rackd's `location.updated` events would. A relocation moves a box the
/// workload will ask for later, and may fill a place a later store names.
#[derive(Default)]
struct Wms {
    /// Boxes sent to a named place and not yet there (their store has not completed).
    sent: HashMap<String, [u16; 4]>,
    /// Stores redirected to putaway: the place a relocated box took.
    pub redirected: usize,
}

impl Wms {
    /// The request for `order`, or None while the box it retrieves is on its way in
    /// (a putaway store not yet placed).
    async fn request(
        &mut self,
        client: &reqwest::Client,
        base: &str,
        order: &Order,
    ) -> anyhow::Result<Option<Value>> {
        let (where_is, full) = self.rack(client, base).await?;
        Ok(Some(match order {
            Order::Retrieve(barcode) => {
                let Some(cell) = where_is.get(barcode).or_else(|| self.sent.get(barcode)) else {
                    return Ok(None);
                };
                json!({"kind": "retrieve", "from": at(*cell), "barcode": barcode})
            }
            Order::Store { cell, barcode, putaway } => {
                let [row, bay, level, _] = *cell;
                let walled = cell[3] == 2 && full.contains(&[row, bay, level, 1]);
                if *putaway || full.contains(cell) || walled {
                    self.redirected += usize::from(!*putaway);
                    json!({"kind": "store", "aisle": 2, "barcode": barcode})
                } else {
                    self.sent.insert(barcode.clone(), *cell);
                    json!({"kind": "store", "to": at(*cell), "barcode": barcode})
                }
            }
        }))
    }

    /// Where each box is, and the places that hold a box or are held by a job.
    async fn rack(
        &self,
        client: &reqwest::Client,
        base: &str,
    ) -> anyhow::Result<(HashMap<String, [u16; 4]>, HashSet<[u16; 4]>)> {
        let all: Vec<Value> =
            client.get(format!("{base}/api/v1/locations?aisle=2")).send().await?.json().await?;
        let (mut where_is, mut full) = (HashMap::new(), HashSet::new());
        for l in all {
            let n = |k: &str| l[k].as_u64().unwrap_or(0) as u16;
            let cell = [n("row"), n("bay"), n("level"), n("position")];
            if l["occupied"] == true || !l["reserved_by"].is_null() {
                full.insert(cell);
            }
            if let Some(b) = l["barcode"].as_str() {
                where_is.insert(b.to_owned(), cell);
            }
        }
        Ok((where_is, full))
    }
}
