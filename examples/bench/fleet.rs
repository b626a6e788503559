//! `bench fleet`: the polling path under a fleet of tag devices.
//!
//! Runs rackd as a child process (so its CPU time is read apart from everything else, see
//! `child.rs`) with N `kind = "tags"` devices on Modbus TCP, each with T u16 tags,
//! polled every P ms, against one Modbus TCP server in this process (its CPU is this
//! process's, never counted as rackd's). The default workload, 500 devices x 30 tags every
//! 500 ms = 30,000 tag reads/s, is that of emqx/neuron's published gateway benchmark.
//!
//! Two phases over equal steady-state windows: every value static, then a share of each
//! device's tags changing on every poll (this process writes new values into the server's
//! bank twice per poll period, so each poll reads a new value whatever the phase of the
//! device's timer).
//!
//! Decisions where the issue is silent:
//! - Each device's tags are one block of adjoining holding registers in a range of its own
//!   on one server (unit 1), so a poll is one read of T registers: tag reads are counted at
//!   the simulator as requests x T. rackd has no read counter; its side is checked through
//!   the device status instead: every tag must be `good` at the end of a phase, and in the
//!   changing phase the sum of the tags' `changes` counters must grow by one per changing
//!   tag and poll.
//! - The config is generated as TOML text (the file format is the stable contract), so the
//!   benchmark does not depend on the device configuration's Rust types.
//! - Figures are rates and ratios: CPU per 1000 tag reads, the changing phase against the
//!   static one, and rackd's CPU against the simulator's for the same requests (a yardstick
//!   from the same run, since the machine is shared and noisy).
//! - `--capture on` (the default, as in service) keeps every device's flight recorder;
//!   `off` sets `capture_bytes = 0`; `both` compares them in one invocation
//!   (`fleet_capture.rs`).

use std::fmt::Write as _;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail, ensure};

use rackd::protocols::modbus::server::{Bank, ModbusServer, ServerHandle, ServerOptions};

use crate::child::{Server, cpu_secs};

/// The benchmark's settings.
#[derive(Clone, Copy, Debug, clap::Args)]
pub struct FleetArgs {
    /// Tag devices, each on its own Modbus TCP connection.
    #[arg(long, default_value_t = 500)]
    pub devices: usize,
    /// Tags per device (adjoining u16 holding registers, one read per poll).
    #[arg(long, default_value_t = 30)]
    pub tags: u16,
    /// Poll period of every device in milliseconds.
    #[arg(long, default_value_t = 500)]
    pub poll_ms: u64,
    /// Seconds per measured phase.
    #[arg(long, default_value_t = 20)]
    pub seconds: u64,
    /// Share of each device's tags that change on every poll in the second phase.
    #[arg(long, default_value_t = 0.1)]
    pub changing: f64,
    /// The devices' flight recorders: on (the default), off, or both compared in
    /// alternating rounds of the static phase.
    #[arg(long, value_enum, default_value_t = Capture::On)]
    pub capture: Capture,
    /// Rounds of each setting with `--capture both`.
    #[arg(long, default_value_t = 3)]
    pub rounds: u32,
    /// With the recorders on: each device's `capture_seconds` (the default, 600, when not
    /// given). A short bound fills the rings before the measurement, so the figure is a
    /// frame's cost in the steady state, not the rings' first filling.
    #[arg(long)]
    pub capture_seconds: Option<u64>,
}

/// Whether the devices record their frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Capture {
    /// `capture_bytes = 0`.
    Off,
    /// The default bounds (4 MiB or 10 minutes per device).
    On,
    /// Off and on in alternating rounds, compared.
    Both,
}

/// What one phase measured.
pub(crate) struct Phase {
    pub name: String,
    pub wall: Duration,
    pub requests: u64,
    pub rackd_cpu: f64,
    pub sim_cpu: f64,
    pub changes: u64,
    pub changes_wall: Duration,
    pub not_good: usize,
}

/// Runs the benchmark and prints its figures.
pub async fn run(args: FleetArgs) -> anyhow::Result<()> {
    let FleetArgs { devices, tags, poll_ms, seconds, changing, capture, .. } = args;
    ensure!(
        devices >= 1 && (1..=120).contains(&tags),
        "--devices at least 1, --tags 1..=120 (one read each)"
    );
    ensure!(devices * tags as usize <= 65_536, "devices x tags must fit in 65536 holding registers");
    ensure!((0.0..=1.0).contains(&changing), "--changing is a share between 0 and 1");
    ensure!(poll_ms >= 2 && seconds >= 1, "--poll-ms at least 2, --seconds at least 1");
    let (bank, server) = simulator(devices, tags).await?;
    let plc = server.local_addr().context("a TCP server has an address")?;
    if capture == Capture::Both {
        return crate::fleet_capture::compare(args, &server, &plc.to_string()).await;
    }

    let dir = tempfile::tempdir()?;
    let config = dir.path().join("fleet.toml");
    let on = (capture == Capture::On).then_some(args.capture_seconds);
    let text = config_text(devices, tags, poll_ms, &plc.to_string(), on);
    std::fs::write(&config, text)?;
    let rackd = Server::start(&config, dir.path()).await?;
    let client = reqwest::Client::new();
    let devices_url = format!("http://{}/api/v1/devices", rackd.addr);
    wait_all_good(&client, &devices_url, devices * tags as usize).await?;

    let changing_tags = (changing * tags as f64).round() as u16;
    println!(
        "bench fleet: {devices} tag devices x {tags} u16 tags every {poll_ms} ms over Modbus TCP \
         (target {:.0} tag reads/s), {seconds} s per phase, {} cores, capture {capture:?}",
        target(args),
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    println!(
        "tag reads counted at the simulator (requests x {tags} tags: one read per device poll); \
         rackd's CPU from the CPU clock of process {}",
        rackd.pid
    );
    // Settle after the start-up burst (every device coming online at once) before measuring.
    tokio::time::sleep(Duration::from_secs(5)).await;
    let idle = phase("static".into(), &client, &devices_url, &server, &rackd, seconds).await?;

    let changer = tokio::spawn(change_values(bank.clone(), devices, tags, changing_tags, poll_ms));
    tokio::time::sleep(Duration::from_millis(2 * poll_ms).max(Duration::from_secs(1))).await;
    let name = format!("changing ({changing_tags}/{tags})");
    let busy = phase(name, &client, &devices_url, &server, &rackd, seconds).await?;
    changer.abort();

    let expected = devices as f64 * changing_tags as f64 * 1000.0 / poll_ms as f64;
    print(&idle, &busy, tags, args, expected);
    rackd.stop().await;
    server.shutdown().await;
    ensure!(idle.not_good == 0 && busy.not_good == 0, "some tags were not good at the end of a phase");
    Ok(())
}

/// The Modbus TCP simulator, its bank holding every device's tags.
pub(crate) async fn simulator(devices: usize, tags: u16) -> anyhow::Result<(Bank, ServerHandle)> {
    let bank = Bank::new();
    for d in 0..devices {
        let values: Vec<u16> = (0..tags).map(|t| (d as u16).wrapping_mul(tags).wrapping_add(t)).collect();
        bank.set_holding(base(d, tags), &values);
    }
    let server = ModbusServer::new(Arc::new(bank.clone()), ServerOptions::default())
        .serve_tcp("127.0.0.1:0")
        .await
        .context("starting the Modbus simulator")?;
    Ok((bank, server))
}

/// The first holding register of device `d`'s tags.
fn base(d: usize, tags: u16) -> u16 {
    (d * tags as usize) as u16
}

/// Tag reads per second the workload asks for.
pub(crate) fn target(args: FleetArgs) -> f64 {
    args.devices as f64 * args.tags as f64 * 1000.0 / args.poll_ms as f64
}

/// rackd's configuration: `devices` tags devices on the simulator at `plc`, recording
/// their frames (`Some`, with their `capture_seconds` if given) or not.
pub(crate) fn config_text(
    devices: usize,
    tags: u16,
    poll_ms: u64,
    plc: &str,
    capture: Option<Option<u64>>,
) -> String {
    let capture = match capture {
        None => "capture_bytes = 0\n".to_owned(),
        Some(None) => String::new(),
        Some(Some(seconds)) => format!("capture_seconds = {seconds}\n"),
    };
    let mut text = String::from("# bench fleet: generated\n");
    for d in 0..devices {
        let _ = write!(
            text,
            "\n[[devices]]\nid = \"fleet{d:04}\"\nkind = \"tags\"\nprotocol = \"modbus-tcp\"\n\
             address = \"{plc}\"\npoll_ms = {poll_ms}\n{capture}\n[devices.tags]\n"
        );
        for t in 0..tags {
            let _ = writeln!(text, "\"tag.t{t:03}\" = \"4x{}\"", base(d, tags) + t);
        }
    }
    text
}

/// Writes new values into the first `changing` tags of every device, twice per poll period.
async fn change_values(bank: Bank, devices: usize, tags: u16, changing: u16, poll_ms: u64) {
    if changing == 0 {
        return;
    }
    let mut tick = tokio::time::interval(Duration::from_millis(poll_ms) / 2);
    let mut n: u16 = 0;
    loop {
        tick.tick().await;
        n = n.wrapping_add(1);
        for d in 0..devices {
            let values: Vec<u16> = (0..changing).map(|t| n.wrapping_add(t)).collect();
            bank.set_holding(base(d, tags), &values);
        }
    }
}

/// Waits until rackd has read every one of `total` tags successfully.
pub(crate) async fn wait_all_good(client: &reqwest::Client, url: &str, total: usize) -> anyhow::Result<()> {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let census = tag_census(client, url).await?;
        if census.good == total {
            return Ok(());
        }
        if Instant::now() > deadline {
            bail!("only {} of {total} tags were read after 60 s", census.good);
        }
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
}

/// rackd's view of the tags, from its device list.
#[derive(Clone, Copy, Debug, Default)]
struct Census {
    /// Tags rackd serves.
    total: usize,
    /// Tags whose last read succeeded.
    good: usize,
    /// The sum of every tag's `changes` counter.
    changes: u64,
}

/// Takes rackd's view of the tags.
async fn tag_census(client: &reqwest::Client, url: &str) -> anyhow::Result<Census> {
    let list: serde_json::Value = client.get(url).send().await?.error_for_status()?.json().await?;
    let mut census = Census::default();
    for device in list.as_array().context("a device list")? {
        for tag in device["tags"].as_object().into_iter().flat_map(|t| t.values()) {
            census.total += 1;
            census.good += usize::from(tag["quality"] == "good");
            census.changes += tag["changes"].as_u64().unwrap_or(0);
        }
    }
    Ok(census)
}

/// One steady-state window: rackd's and this process's CPU, the simulator's requests, and
/// rackd's view of the tags (taken just outside the window, so its cost is not counted).
pub(crate) async fn phase(
    name: String,
    client: &reqwest::Client,
    url: &str,
    server: &ServerHandle,
    rackd: &Server,
    seconds: u64,
) -> anyhow::Result<Phase> {
    let before = tag_census(client, url).await?;
    let census_start = Instant::now();
    let (rackd_before, sim_before) = (rackd.cpu_secs()?, own_cpu_secs()?);
    let requests_before = server.stats().requests;
    let started = Instant::now();
    tokio::time::sleep(Duration::from_secs(seconds)).await;
    let requests = server.stats().requests - requests_before;
    let (rackd_after, sim_after) = (rackd.cpu_secs()?, own_cpu_secs()?);
    let wall = started.elapsed();
    let after = tag_census(client, url).await?;
    Ok(Phase {
        name,
        wall,
        requests,
        rackd_cpu: rackd_after - rackd_before,
        sim_cpu: sim_after - sim_before,
        changes: after.changes - before.changes,
        changes_wall: census_start.elapsed(),
        not_good: after.total - after.good,
    })
}

/// This process's CPU seconds (the simulator and the load it generates).
fn own_cpu_secs() -> anyhow::Result<f64> {
    cpu_secs(std::process::id())
}

fn print(idle: &Phase, busy: &Phase, tags: u16, args: FleetArgs, expected_changes: f64) {
    println!(
        "{:<18} {:>12} {:>10} {:>10} {:>16} {:>10} {:>12} {:>16}",
        "phase",
        "tag reads/s",
        "vs target",
        "rackd CPU",
        "CPU/1000 reads",
        "sim CPU",
        "rackd/sim",
        "changes/s seen"
    );
    for p in [idle, busy] {
        let reads = p.requests as f64 * tags as f64 / p.wall.as_secs_f64();
        let cpu = p.rackd_cpu / p.wall.as_secs_f64();
        println!(
            "{:<18} {:>12.0} {:>9.1}% {:>9.1}% {:>13.2} ms {:>9.1}% {:>11.2}x {:>16.0}",
            p.name,
            reads,
            100.0 * reads / target(args),
            100.0 * cpu,
            1000.0 * p.rackd_cpu / (reads * p.wall.as_secs_f64() / 1000.0),
            100.0 * p.sim_cpu / p.wall.as_secs_f64(),
            p.rackd_cpu / p.sim_cpu.max(0.01),
            p.changes as f64 / p.changes_wall.as_secs_f64(),
        );
    }
    println!(
        "changing vs static: rackd CPU x{:.2}; changes seen by rackd {:.0}/s of {expected_changes:.0}/s \
         written; tags not good at the end: {} static, {} changing",
        busy.rackd_cpu / idle.rackd_cpu.max(0.01),
        busy.changes as f64 / busy.changes_wall.as_secs_f64(),
        idle.not_good,
        busy.not_good,
    );
}
