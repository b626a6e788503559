//! `bench capture`: what many capture downloads at once cost rackd (issue 51).
//!
//! rackd runs as a child process (its memory and CPU apart from the clients') with one
//! tags device on Modbus TCP against a simulator in this process, polled as fast as it
//! answers (`poll_ms = 1`, ten reads of 120 registers a poll), its flight recorder bounded
//! by `--ring-mib` (64) and a day. Once the ring is full (counted at the simulator: every
//! exchange is a 12-byte request and a 249-byte reply, 297 bytes of records), `--downloads`
//! (50) clients ask for `GET /api/v1/devices/{id}/capture` at once; each that is answered
//! 429 waits its `Retry-After` and asks again, until every one has read a whole file.
//!
//! Figures: rackd's resident memory (sampled every 10 ms, and its peak, `VmHWM`), before
//! and during the downloads; the files and the 429s; and the device's link over the
//! downloads (its requests a second against before, its timeouts and retries), with the
//! device's default timeouts (300 ms, a 2 ms floor on Modbus TCP).

use std::fmt::Write as _;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, bail, ensure};
use rackd::protocols::modbus::server::{Bank, ModbusServer, ServerOptions};

use crate::child::Server;

/// The benchmark's settings.
#[derive(Clone, Copy, Debug, clap::Args)]
pub struct CaptureArgs {
    /// Downloads asked for at once.
    #[arg(long, default_value_t = 50)]
    pub downloads: usize,
    /// The device's flight recorder, MiB (`capture_bytes`).
    #[arg(long, default_value_t = 64)]
    pub ring_mib: usize,
    /// `server.capture_downloads`: captures built at once.
    #[arg(long, default_value_t = 2)]
    pub builds: usize,
    /// The device's `min_timeout_ms` (its protocol's default, 2 ms on Modbus TCP, if not given).
    #[arg(long)]
    pub min_timeout_ms: Option<u64>,
}

/// Registers a poll reads (ten reads of 120).
const TAGS: u16 = 1200;
/// Bytes of records one exchange leaves in the ring: (18 + 12) + (18 + 249).
const PER_EXCHANGE: u64 = 297;
const DEVICE: &str = "capture1";

/// Runs the benchmark and prints its figures.
pub async fn run(args: CaptureArgs) -> anyhow::Result<()> {
    ensure!(
        args.downloads >= 1 && (1..=256).contains(&args.ring_mib),
        "--downloads at least 1, --ring-mib 1..=256"
    );
    // The simulator on a thread and runtime of its own: the PLC is another machine, and
    // must not wait behind the clients' tasks.
    let (tx, rx) = tokio::sync::oneshot::channel();
    std::thread::spawn(move || {
        let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().expect("a runtime");
        runtime.block_on(async move {
            let bank = Bank::new();
            bank.set_holding(0, &(0..TAGS).collect::<Vec<u16>>());
            let server =
                ModbusServer::new(Arc::new(bank), ServerOptions::default()).serve_tcp("127.0.0.1:0").await;
            let _ = tx.send(server);
            std::future::pending::<()>().await
        })
    });
    let sim = rx.await?.context("starting the simulator")?;
    let plc = sim.local_addr().context("the simulator's address")?;
    let ring = args.ring_mib * 1024 * 1024;
    let mut text = format!(
        "[[devices]]\nid = \"{DEVICE}\"\nkind = \"tags\"\nprotocol = \"modbus-tcp\"\naddress = \"{plc}\"\n\
         poll_ms = 1\ncapture_bytes = {ring}\ncapture_seconds = 86400\n[devices.tags]\n"
    );
    text.insert_str(0, &format!("[server]\ncapture_downloads = {}\n\n", args.builds));
    if let Some(ms) = args.min_timeout_ms {
        text = text.replace("poll_ms = 1\n", &format!("poll_ms = 1\nmin_timeout_ms = {ms}\n"));
    }
    for t in 0..TAGS {
        let _ = writeln!(text, "\"t{t:04}\" = \"4x{t}\"");
    }
    let dir = tempfile::tempdir()?;
    let config = dir.path().join("capture.toml");
    std::fs::write(&config, text)?;
    let rackd = Server::start(&config, dir.path()).await?;
    let client = reqwest::Client::new();
    let device_url = format!("http://{}/api/v1/devices/{DEVICE}", rackd.addr);
    println!(
        "bench capture: {} downloads at once of a device with a {} MiB ring, {} built at once, {} cores, \
         rackd process {}",
        args.downloads,
        args.ring_mib,
        args.builds,
        std::thread::available_parallelism().map_or(1, |n| n.get()),
        rackd.pid
    );

    // Fill the ring, and a tenth more so that it is full.
    let needed = ring as u64 * 11 / 10 / PER_EXCHANGE;
    let started = Instant::now();
    while sim.stats().requests < needed {
        ensure!(started.elapsed() < Duration::from_secs(600), "the ring did not fill in 10 minutes");
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    let fill = started.elapsed();
    println!("ring filled in {:.1} s ({} exchanges)", fill.as_secs_f64(), sim.stats().requests);
    // The pace of polls before the downloads, over 5 s.
    let (before, requests0, t0) = (link(&client, &device_url).await?, sim.stats().requests, Instant::now());
    tokio::time::sleep(Duration::from_secs(5)).await;
    let pace_before = (sim.stats().requests - requests0) as f64 / t0.elapsed().as_secs_f64();
    let rss_before = memory(rackd.pid, "VmRSS")?;

    let peak = Arc::new(AtomicU64::new(0));
    let done = Arc::new(AtomicBool::new(false));
    let sampler = {
        let (peak, done, pid) = (peak.clone(), done.clone(), rackd.pid);
        tokio::spawn(async move {
            while !done.load(Ordering::Relaxed) {
                if let Ok(rss) = memory(pid, "VmRSS") {
                    peak.fetch_max(rss, Ordering::Relaxed);
                }
                tokio::time::sleep(Duration::from_millis(10)).await;
            }
        })
    };
    let link_before = link(&client, &device_url).await?;
    let requests1 = sim.stats().requests;
    let t1 = Instant::now();
    let url = format!("{device_url}/capture");
    let clients: Vec<_> =
        (0..args.downloads).map(|_| tokio::spawn(download(client.clone(), url.clone()))).collect();
    let mut files = Vec::new();
    for c in clients {
        files.push(c.await??);
    }
    let wall = t1.elapsed();
    let pace_during = (sim.stats().requests - requests1) as f64 / wall.as_secs_f64();
    done.store(true, Ordering::Relaxed);
    sampler.await?;
    let after = link(&client, &device_url).await?;
    let hwm = memory(rackd.pid, "VmHWM")?;

    let mib = |kib: u64| kib as f64 / 1024.0;
    let refused: u64 = files.iter().map(|f| f.1).sum();
    let sizes: Vec<u64> = files.iter().map(|f| f.0).collect();
    let total: u64 = sizes.iter().sum();
    println!(
        "{} downloads in {:.1} s: files of {:.1} to {:.1} MB ({:.0} MB/s in all), {refused} answers 429 before them",
        files.len(),
        wall.as_secs_f64(),
        *sizes.iter().min().unwrap_or(&0) as f64 / 1e6,
        *sizes.iter().max().unwrap_or(&0) as f64 / 1e6,
        total as f64 / 1e6 / wall.as_secs_f64()
    );
    println!(
        "rackd resident memory: {:.0} MiB before, {:.0} MiB at most during the downloads (sampled every \
         10 ms), peak of the process {:.0} MiB (VmHWM)",
        mib(rss_before),
        mib(peak.load(Ordering::Relaxed)),
        mib(hwm)
    );
    let delta = |key: &str| after[key].as_u64().unwrap_or(0) - link_before[key].as_u64().unwrap_or(0);
    println!(
        "the device's link: {:.0} requests/s before, {:.0} during; during the downloads {} timeouts, {} retries \
         (since its start: {} timeouts); adaptive timeout {} ms, degraded {}",
        pace_before,
        pace_during,
        delta("timeouts"),
        delta("retries"),
        after["timeouts"],
        after["timeout_ms"],
        after["degraded"]
    );
    let _ = before;
    rackd.stop().await;
    Ok(())
}

/// Downloads the capture, asking again after each 429's `Retry-After`: the file's bytes
/// and the 429s before it.
async fn download(client: reqwest::Client, url: String) -> anyhow::Result<(u64, u64)> {
    let mut refused = 0;
    loop {
        let mut response = client.get(&url).send().await?;
        match response.status().as_u16() {
            200 => {
                let mut bytes = 0;
                while let Some(chunk) = response.chunk().await? {
                    bytes += chunk.len() as u64;
                }
                return Ok((bytes, refused));
            }
            429 => {
                refused += 1;
                let wait = response.headers().get("retry-after").and_then(|v| v.to_str().ok()?.parse().ok());
                tokio::time::sleep(Duration::from_secs(wait.unwrap_or(1))).await;
            }
            other => bail!("GET {url}: {other}"),
        }
    }
}

/// The device's link as rackd shows it.
async fn link(client: &reqwest::Client, url: &str) -> anyhow::Result<serde_json::Value> {
    let device: serde_json::Value = client.get(url).send().await?.error_for_status()?.json().await?;
    Ok(device["link"].clone())
}

/// A line of `/proc/PID/status` in KiB (`VmRSS`, `VmHWM`).
fn memory(pid: u32, key: &str) -> anyhow::Result<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))?;
    let line = status.lines().find(|l| l.starts_with(key)).with_context(|| format!("no {key}"))?;
    let kib = line.split_whitespace().nth(1).context("a number")?.parse()?;
    Ok(kib)
}
