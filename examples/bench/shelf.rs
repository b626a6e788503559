//! `bench shelf`: how fast jobs reach and run on a shelf PLC.
//!
//! Starts the shelf simulator (zero-duration tasks) and a real server driving it over
//! loopback UDP, then measures:
//! - hand-over latency: from sending `POST /api/v1/jobs` to the task id landing in a slot
//!   at the simulator, one job at a time (p50/p99);
//! - sustained throughput: completed jobs per second for a large batch of light jobs.
//!
//! The baseline, measured in the same run, is one Modbus UDP read round trip to the same
//! simulator: a hand-over needs at least three (read the slot, write the body, write the
//! id), so `latency / (3 x round trip)` says how close dispatch is to the wire's floor.
//!
//! With `--drop P` (issue 12), the latency and sustained phases are skipped: the same
//! number of jobs runs on the clean link and then with the simulator dropping a share P of
//! requests, and both completed-jobs rates are printed with their ratio (the goal: at least
//! half the clean rate under 20% loss), with the device's link health after the lossy run.
//! `--fixed-timeout` pins the reply timeout at `timeout_ms` (the floor raised to the
//! ceiling), which is how rackd behaved before the adaptive timer. `--no-transaction-id`
//! runs both on the seed's PLC's habit (replies without transaction ids): what the rule
//! for such links costs under loss (issue 50).

use std::time::{Duration, Instant};

use anyhow::Context;
use hdrhistogram::Histogram;

use rackd::cli::demo::shelf_device;
use rackd::config::{Config, WebhookConfig};
use rackd::protocols::PlcMemory;
use rackd::protocols::faults::Faults;
use rackd::protocols::modbus::{ModbusClient, ModbusConfig};
use rackd::sim::shelf::{ShelfSim, ShelfSimOptions};
use rackd::wire::task_id_for;

use crate::served::Served;

/// The lossy comparison of `--drop`.
pub struct Lossy {
    /// Share of requests the simulator drops.
    pub rate: f64,
    /// Jobs in each run.
    pub jobs: usize,
    /// No adaptive timer (as before issue 12).
    pub fixed_timeout: bool,
    /// The adaptive timer's floor, if not the default.
    pub min_timeout_ms: Option<u64>,
    /// The PLC answers without transaction ids (the seed's), and the device knows it.
    pub no_transaction_id: bool,
    /// The device's `timeout_ms`, if not the default.
    pub timeout_ms: Option<u64>,
}

/// Runs the shelf benchmark: `latency_jobs` single jobs, then `batch_jobs` in batches; or,
/// with `lossy`, the clean and lossy runs.
pub async fn run(
    latency_jobs: usize,
    batch_jobs: usize,
    poll_ms: u64,
    lossy: Option<Lossy>,
) -> anyhow::Result<()> {
    let Some(lossy) = lossy else {
        let figures = measure(latency_jobs, batch_jobs, poll_ms, Vec::new()).await?;
        println!("bench shelf: simulator with zero-duration tasks, poll every {poll_ms} ms");
        figures.print();
        return Ok(());
    };
    let (sim, served, _dir) = start(poll_ms, Some(&lossy), Vec::new()).await?;
    let base = served.base.clone();
    let client = reqwest::Client::new();
    let clean = rate(batch(&client, &base, &sim, 0, lossy.jobs).await?);
    sim.set_faults(Faults { drop_rate: lossy.rate, ..Faults::default() });
    let dropped = rate(batch(&client, &base, &sim, lossy.jobs, lossy.jobs).await?);
    let device: serde_json::Value =
        client.get(format!("{base}/api/v1/devices/shelf1")).send().await?.json().await?;
    let timer = match (lossy.fixed_timeout, lossy.min_timeout_ms) {
        (true, _) => "fixed timeout".to_owned(),
        (false, Some(ms)) => format!("adaptive timeout, floor {ms} ms"),
        (false, None) => "adaptive timeout, default floor".to_owned(),
    };
    let ids = if lossy.no_transaction_id { "replies without transaction ids" } else { "transaction ids" };
    let ids = format!("{ids}, timeout_ms {}", lossy.timeout_ms.unwrap_or(300));
    println!(
        "bench shelf --drop {}: {} jobs per run, poll every {poll_ms} ms, {timer}, {ids}",
        lossy.rate, lossy.jobs
    );
    println!("clean link:          {clean:.1} completed jobs/s");
    println!("{:>3.0}% requests lost:  {dropped:.1} completed jobs/s", lossy.rate * 100.0);
    println!("ratio lossy / clean: {:.1}%", 100.0 * dropped / clean);
    println!("device link after the lossy run: {}", device["link"]);
    served.stop().await?;
    sim.shutdown().await;
    Ok(())
}

/// The simulator, and rackd driving it (with `webhooks` subscribed) on a database in the
/// temporary folder returned.
async fn start(
    poll_ms: u64,
    lossy: Option<&Lossy>,
    webhooks: Vec<WebhookConfig>,
) -> anyhow::Result<(ShelfSim, Served, tempfile::TempDir)> {
    let no_transaction_id = lossy.is_some_and(|l| l.no_transaction_id);
    let options = ShelfSimOptions { task_time: Duration::ZERO, no_transaction_id, ..Default::default() };
    let sim = ShelfSim::start("127.0.0.1:0", options).await?;
    let dir = tempfile::tempdir()?;
    let mut config = Config::demo();
    config.server.listen = "127.0.0.1:0".parse()?;
    config.database.path = dir.path().join("bench.db");
    config.webhooks = webhooks;
    let plc_addr = sim.local_addr().context("a UDP simulator has an address")?.to_string();
    let mut device = shelf_device(&sim, "shelf1", &plc_addr, vec![1]);
    device.poll_ms = poll_ms;
    if let Some(ms) = lossy.and_then(|l| l.timeout_ms) {
        device.link.timeout = Duration::from_millis(ms);
    }
    if let Some(ms) = lossy.and_then(|l| l.min_timeout_ms) {
        device.link.tuning.min_timeout = Duration::from_millis(ms);
    }
    if lossy.is_some_and(|l| l.fixed_timeout) {
        device.link.tuning.min_timeout = device.link.timeout;
    }
    config.devices = vec![device.into()];
    let served = Served::start(&config).await?;
    Ok((sim, served, dir))
}

/// What the clean run of `bench shelf` measures.
pub struct Figures {
    /// One Modbus UDP read round trip to the simulator, in µs.
    pub rtt: Histogram<u64>,
    /// From sending a job's POST to its task id in a slot, in µs.
    pub handover: Histogram<u64>,
    /// Jobs completed in the sustained run.
    pub done: u64,
    /// How long they took.
    pub elapsed: Duration,
}

impl Figures {
    /// Completed jobs per second in the sustained run.
    pub fn sustained(&self) -> f64 {
        rate((self.done, self.elapsed))
    }

    fn print(&self) {
        let ms = |h: &Histogram<u64>, q: f64| h.value_at_quantile(q) as f64 / 1000.0;
        let (rtt, handover) = (&self.rtt, &self.handover);
        let jobs = handover.len();
        println!(
            "Modbus UDP round trip (baseline)   p50 {:.3} ms  p99 {:.3} ms",
            ms(rtt, 0.5),
            ms(rtt, 0.99)
        );
        println!(
            "POST -> task in slot ({jobs} jobs)    p50 {:.3} ms  p99 {:.3} ms  = {:.1}x / {:.1}x three round trips",
            ms(handover, 0.5),
            ms(handover, 0.99),
            ms(handover, 0.5) / (3.0 * ms(rtt, 0.5)),
            ms(handover, 0.99) / (3.0 * ms(rtt, 0.5)),
        );
        println!(
            "sustained: {} jobs completed in {:.2} s = {:.0} jobs/s ({} slots)",
            self.done,
            self.elapsed.as_secs_f64(),
            self.sustained(),
            60
        );
    }
}

/// The clean run: the round trips, `latency_jobs` hand-overs one at a time, then
/// `batch_jobs` in batches, against a fresh simulator and rackd with `webhooks` subscribed
/// (`bench webhooks --neighbours` runs it with and without a subscription).
pub async fn measure(
    latency_jobs: usize,
    batch_jobs: usize,
    poll_ms: u64,
    webhooks: Vec<WebhookConfig>,
) -> anyhow::Result<Figures> {
    let (sim, served, _dir) = start(poll_ms, None, webhooks).await?;
    let base = served.base.clone();
    let client = reqwest::Client::new();
    let plc_addr = sim.local_addr().context("a UDP simulator has an address")?.to_string();
    let plc = ModbusClient::connect(ModbusConfig::shelf_plc(plc_addr)).await?;
    let at = plc.parse_address("4x4000")?;
    let mut rtt = Histogram::<u64>::new(3)?;
    for _ in 0..2000 {
        let t = Instant::now();
        plc.read_words(&at, 35).await?;
        rtt.record(t.elapsed().as_micros() as u64)?;
    }

    let mut handover = Histogram::<u64>::new(3)?;
    for n in 0..latency_jobs {
        let body = light(n);
        let t = Instant::now();
        let r = client.post(format!("{base}/api/v1/jobs")).json(&body).send().await?;
        anyhow::ensure!(r.status() == 201, "POST: {}", r.status());
        let id = r.json::<serde_json::Value>().await?["id"].as_i64().context("job id")?;
        let deadline = Instant::now() + Duration::from_secs(5);
        let landed = loop {
            if let Some(at) = sim.received_at(task_id_for(id)).filter(|&at| at >= t) {
                break at;
            }
            anyhow::ensure!(Instant::now() < deadline, "job {id} never reached the PLC");
            tokio::task::yield_now().await;
        };
        handover.record((landed - t).as_micros() as u64)?;
    }

    let (done, elapsed) = batch(&client, &base, &sim, latency_jobs, batch_jobs).await?;
    served.stop().await?;
    sim.shutdown().await;
    Ok(Figures { rtt, handover, done, elapsed })
}

/// Posts `count` light jobs (numbered from `first`) in batches and waits until every one
/// has completed; returns how many the simulator completed and how long it took.
async fn batch(
    client: &reqwest::Client,
    base: &str,
    sim: &ShelfSim,
    first: usize,
    count: usize,
) -> anyhow::Result<(u64, Duration)> {
    let jobs: Vec<_> = (0..count).map(|n| light(n + first)).collect();
    let (done_before, _) = sim.finished();
    let t = Instant::now();
    for chunk in jobs.chunks(1000) {
        let r = client
            .post(format!("{base}/api/v1/jobs/batch"))
            .json(&serde_json::json!({ "jobs": chunk }))
            .send()
            .await?;
        anyhow::ensure!(r.status() == 201, "batch: {}", r.status());
    }
    let deadline = Instant::now() + Duration::from_secs(1800);
    loop {
        let r: serde_json::Value =
            client.get(format!("{base}/api/v1/jobs?state=queued&limit=1")).send().await?.json().await?;
        let running: serde_json::Value =
            client.get(format!("{base}/api/v1/devices/shelf1")).send().await?.json().await?;
        if r["jobs"].as_array().is_some_and(|a| a.is_empty()) && running["slots_in_use"] == 0 {
            break;
        }
        anyhow::ensure!(Instant::now() < deadline, "the batch did not finish");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    let (done_after, _) = sim.finished();
    Ok((done_after - done_before, t.elapsed()))
}

/// Completed jobs per second of a [`batch`].
fn rate((done, elapsed): (u64, Duration)) -> f64 {
    done as f64 / elapsed.as_secs_f64()
}

/// A light job on the demo site; consecutive jobs use different locations.
fn light(n: usize) -> serde_json::Value {
    let n = n as u64;
    serde_json::json!({
        "kind": "light", "color": if n.is_multiple_of(2) { "green" } else { "red" }, "on": !n.is_multiple_of(3),
        "location": {"aisle": 1, "row": 1 + n % 2, "bay": 1 + (n / 2) % 10, "level": 1 + (n / 20) % 6, "position": 1 + (n / 120) % 4},
    })
}
