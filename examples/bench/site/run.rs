//! One run: N crane simulators, one rackd with a crane per aisle, the WMS's stream in one
//! mode, and what each side counted.

use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::ensure;
use serde_json::{Value, json};
use time::OffsetDateTime;
use tokio::runtime::Runtime;

use rackd::config::devices::CraneConfig;
use rackd::config::{AisleConfig, Config, StationConfig, Transit};
use rackd::protocols::mc3e::TransportKind;
use rackd::sim::crane::{CraneSim, CraneSimOptions, CraneStats, TaskTimes};
use rackd::wire::motion::{Axis, Motion};

use super::cpu::{self, Cpu};
use super::wms::{self, Clock, Posted};
use super::workload::Workload;
use super::{Mode, SiteArgs};
use crate::served::Served;

/// How long rackd's CPU is read with the cranes online and no work, for its idle share.
pub const IDLE: Duration = Duration::from_secs(2);

/// The runtimes the simulators and the WMS run on, apart from rackd's (see `cpu.rs`).
pub struct Runtimes {
    sims: Runtime,
    wms: Runtime,
}

impl Runtimes {
    /// Two named runtimes whose threads live as long as they do.
    pub fn new() -> anyhow::Result<Runtimes> {
        let named = |name: &str, workers: usize| {
            tokio::runtime::Builder::new_multi_thread()
                .worker_threads(workers)
                .thread_name(name)
                .thread_keep_alive(Duration::from_secs(24 * 3600))
                .enable_all()
                .build()
        };
        Ok(Runtimes { sims: named(cpu::SIMS, 2)?, wms: named(cpu::WMS, 1)? })
    }

    /// Stops both without waiting (a runtime may not be dropped inside another's task).
    pub fn stop(self) {
        self.sims.shutdown_background();
        self.wms.shutdown_background();
    }
}

/// What one crane did.
pub struct Crane {
    /// Its counters.
    pub stats: CraneStats,
    /// Each task's instants.
    pub tasks: Vec<TaskTimes>,
}

/// What one run measured.
pub struct Run {
    /// The mode.
    pub mode: Mode,
    /// The clock of the run.
    pub clock: Clock,
    /// From the first post to the last job's end.
    pub wall: Duration,
    /// Each job, as the WMS saw it.
    pub jobs: Vec<Posted>,
    /// Each crane, aisle 1 first.
    pub cranes: Vec<Crane>,
    /// CPU used in the [`IDLE`] seconds with the cranes online and no work.
    pub idle: Cpu,
    /// CPU used from the first post to the last end.
    pub cpu: Cpu,
    /// Tasks a crane refused, and breaches of the interface: rackd should cause none.
    pub refused: u32,
    /// The breaches, in words.
    pub violations: Vec<String>,
}

/// Runs `workload` in `mode` against fresh simulators and a fresh rackd.
pub async fn one(
    workload: &Arc<Workload>,
    mode: Mode,
    args: &SiteArgs,
    runtimes: &Runtimes,
) -> anyhow::Result<Run> {
    let mut sims = Vec::new();
    for stock in &workload.stock {
        let options = CraneSimOptions {
            transport: TransportKind::Tcp,
            motion: Some(Motion::default()),
            time_scale: args.time_scale,
            inventory: Some(stock.iter().map(|(cell, _)| *cell).collect()),
            ..CraneSimOptions::default()
        };
        let sim = runtimes.sims.spawn(CraneSim::start("127.0.0.1:0", options)).await??;
        sim.record_tasks();
        sims.push(sim);
    }
    let dir = tempfile::tempdir()?;
    let config = config(workload, args, &sims, dir.path())?;
    let served = Served::start(&config).await?;
    let base = served.base.clone();
    let client = reqwest::Client::new();
    for (aisle, stock) in (1..).zip(&workload.stock) {
        let locations: Vec<Value> = stock
            .iter()
            .map(|([row, bay, level, side], barcode)| {
                json!({"aisle": aisle, "row": row, "bay": bay, "level": level, "position": side,
                    "occupied": true, "barcode": barcode})
            })
            .collect();
        let r = client
            .put(format!("{base}/api/v1/locations"))
            .json(&json!({"locations": locations}))
            .send()
            .await?;
        ensure!(r.status() == 200, "inventory of aisle {aisle}: {} {}", r.status(), r.text().await?);
    }
    online(&client, &base, sims.len()).await?;
    let before = Cpu::now()?;
    tokio::time::sleep(IDLE).await;
    let idle = Cpu::now()?.since(&before);

    let clock = Clock { start: Instant::now(), wall: OffsetDateTime::now_utc(), scale: args.time_scale };
    let before = Cpu::now()?;
    let stream = {
        let (base, backlog, workload) = (base.clone(), args.backlog, workload.clone());
        runtimes.wms.spawn(async move { wms::run(base, &workload, mode, backlog, clock).await })
    };
    let jobs = stream.await?;
    let wall = clock.start.elapsed();
    let cpu = Cpu::now()?.since(&before);
    let jobs = jobs?;
    let cranes = sims.iter().map(|s| Crane { stats: s.stats(), tasks: s.tasks() }).collect();
    let refused = sims.iter().map(|s| s.refused()).sum();
    let violations = sims.iter().flat_map(|s| s.violation_log()).collect();
    served.stop().await?;
    for sim in sims {
        runtimes.sims.spawn(sim.shutdown()).await?;
    }
    Ok(Run { mode, clock, wall, jobs, cranes, idle, cpu, refused, violations })
}

/// rackd's configuration: the aisles, one crane each, the stations and their transit
/// times, every time of rackd's divided by the time scale (see the module doc of
/// `site.rs`), and the motion it plans with in wall-clock seconds.
fn config(
    workload: &Workload,
    args: &SiteArgs,
    sims: &[CraneSim],
    dir: &std::path::Path,
) -> anyhow::Result<Config> {
    let scale = args.time_scale;
    let mut config = Config::default();
    config.site.aisles = (1..=workload.aisles)
        .map(|aisle| AisleConfig {
            aisle,
            rows: 2,
            bays: args.bays,
            levels: args.levels,
            positions: 1,
            depth: 1,
        })
        .collect();
    // rackd holds a member back by the transit difference on the wall clock.
    config.site.stations = workload
        .stations
        .iter()
        .map(|s| StationConfig {
            id: s.id,
            name: None,
            transit: (1..=workload.aisles)
                .map(|aisle| Transit { aisle, seconds: s.transit(aisle) / scale })
                .collect(),
        })
        .collect();
    config.server.listen = "127.0.0.1:0".parse()?;
    config.database.path = dir.join("bench.db");
    let scaled = |ms: u64| ((ms as f64 / scale).round() as u64).max(1);
    config.devices = (1..)
        .zip(sims)
        .map(|(aisle, sim)| {
            let mut crane =
                CraneConfig::new(&format!("crane{aisle}"), &sim.local_addr().to_string(), vec![aisle]);
            (crane.poll_ms, crane.heartbeat_ms) = (scaled(args.poll_ms), scaled(crane.heartbeat_ms));
            crane.motion = faster(Motion::default(), scale);
            // Whole seconds: 30 s at the site's pace is 1.5 s at x20, taken as 2 (40 s simulated).
            crane.deadline_margin_s = (f64::from(crane.deadline_margin_s) / scale).round() as u32;
            crane.into()
        })
        .collect();
    Ok(config)
}

/// A motion model whose every time is `scale` times shorter: speeds times the scale,
/// accelerations times its square, fork cycles divided by it. Distances and the order of
/// any two moves stay the same.
fn faster(m: Motion, scale: f64) -> Motion {
    let axis = |a: Axis| Axis { speed: a.speed * scale, accel: a.accel * scale * scale };
    Motion {
        travel: axis(m.travel),
        lift: axis(m.lift),
        fork_near: m.fork_near / scale,
        fork_far: m.fork_far / scale,
        ..m
    }
}

/// Waits until rackd has every crane online.
async fn online(client: &reqwest::Client, base: &str, cranes: usize) -> anyhow::Result<()> {
    let started = Instant::now();
    loop {
        let devices: Vec<Value> = client.get(format!("{base}/api/v1/devices")).send().await?.json().await?;
        if devices.iter().filter(|d| d["online"] == true).count() == cranes {
            return Ok(());
        }
        ensure!(started.elapsed() < Duration::from_secs(30), "the cranes did not come online: {devices:?}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rackd::wire::motion::Spot;

    #[test]
    fn a_faster_motion_takes_every_time_divided_by_the_scale() {
        let (m, f) = (Motion::default(), faster(Motion::default(), 40.0));
        for (a, b) in [((0, 1), (50, 12)), ((3, 2), (4, 2)), ((10, 1), (10, 9))] {
            let (a, b) = (Spot { bay: a.0, level: a.1 }, Spot { bay: b.0, level: b.1 });
            assert!((f.move_time(a, b) * 40.0 - m.move_time(a, b)).abs() < 1e-9);
        }
        assert!((f.fork_time(2) * 40.0 - m.fork_time(2)).abs() < 1e-12);
    }
}
