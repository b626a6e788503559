//! `bench intake`: job intake throughput and latency against a trivial route.
//!
//! Starts a real server on a temporary database, then drives it over loopback HTTP with
//! N concurrent keep-alive clients in three phases of equal length: `GET /healthz` (the
//! ceiling: what this machine's HTTP stack does with no work), single-job POSTs, and batch
//! POSTs of 1000 jobs. Figures are printed as rates and as ratios to the ceiling measured
//! in the same run, since absolute numbers swing on a shared machine, and as the process's
//! CPU time per job (server and clients together, from `/proc/self/stat`), which swings
//! less: another tenant of the machine takes turns from rackd, not work from each job.

use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use hdrhistogram::Histogram;

use rackd::config::Config;

use crate::served::Served;

struct Phase {
    name: &'static str,
    requests: u64,
    jobs_per_request: u64,
    elapsed: Duration,
    latency_us: Histogram<u64>,
    /// The process's CPU time over the phase, if the system tells it.
    cpu: Option<Duration>,
}

impl Phase {
    fn requests_per_sec(&self) -> f64 {
        self.requests as f64 / self.elapsed.as_secs_f64()
    }

    /// CPU microseconds per job, as printed.
    fn cpu_per_job(&self) -> String {
        match self.cpu {
            Some(cpu) => {
                format!("{:.1}", cpu.as_secs_f64() * 1e6 / (self.requests * self.jobs_per_request) as f64)
            }
            None => "-".into(),
        }
    }
}

/// The CPU time this process has used (user and system, all threads), on Linux.
fn cpu_time() -> Option<Duration> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The fields after the command name, which is in parentheses and may hold spaces:
    // utime and stime are the 14th and 15th fields, in ticks of USER_HZ (100 on Linux).
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks: u64 = fields.get(11)?.parse::<u64>().ok()? + fields.get(12)?.parse::<u64>().ok()?;
    Some(Duration::from_millis(ticks * 10))
}

/// Runs the intake benchmark and prints its figures.
pub async fn run(clients: usize, seconds: u64, batch: usize, database: &str) -> anyhow::Result<()> {
    let dir = tempfile::tempdir()?;
    let mut config = Config::demo();
    config.server.listen = "127.0.0.1:0".parse()?;
    config.database.path = dir.path().join("bench.db");
    match database {
        "sqlite" => {}
        "postgres" => {
            crate::postgres::DURABLE.store(true, std::sync::atomic::Ordering::Relaxed);
            config.database.url = Some(crate::postgres::database().await);
        }
        url => config.database.url = Some(url.to_owned()),
    }
    let engine = if config.database.url.is_some() { "postgres" } else { "sqlite" };
    let served = Served::start(&config).await?;
    let base = served.base.clone();
    let duration = Duration::from_secs(seconds);
    let client = reqwest::Client::builder().pool_max_idle_per_host(clients).build()?;
    println!(
        "bench intake: {clients} clients, {seconds} s per phase, batches of {batch}, {} cores, {engine}",
        num_cpus()
    );
    let trivial = phase("GET /healthz (ceiling)", &client, clients, duration, 1, {
        let url = reqwest::Url::parse(&format!("{base}/healthz"))?;
        move |c, _| c.get(url.clone())
    })
    .await?;
    let single = phase("POST /api/v1/jobs", &client, clients, duration, 1, {
        let url = reqwest::Url::parse(&format!("{base}/api/v1/jobs"))?;
        move |c, n| c.post(url.clone()).header("content-type", "application/json").body(job(n))
    })
    .await?;
    let batch_phase = phase("POST /api/v1/jobs/batch", &client, clients, duration, batch as u64, {
        let url = reqwest::Url::parse(&format!("{base}/api/v1/jobs/batch"))?;
        move |c, n| {
            let jobs: Vec<String> =
                (0..batch as u64).map(|i| job(n * batch as u64 + i + (1 << 40))).collect();
            let body = format!(r#"{{"jobs":[{}]}}"#, jobs.join(","));
            c.post(url.clone()).header("content-type", "application/json").body(body)
        }
    })
    .await?;
    println!(
        "{:<26} {:>12} {:>12} {:>10} {:>10} {:>10} {:>11}",
        "phase", "requests/s", "jobs/s", "p50 ms", "p99 ms", "vs ceiling", "CPU µs/job"
    );
    for p in [&trivial, &single, &batch_phase] {
        println!(
            "{:<26} {:>12.0} {:>12.0} {:>10.2} {:>10.2} {:>9.0}% {:>11}",
            p.name,
            p.requests_per_sec(),
            p.requests_per_sec() * p.jobs_per_request as f64,
            p.latency_us.value_at_quantile(0.5) as f64 / 1000.0,
            p.latency_us.value_at_quantile(0.99) as f64 / 1000.0,
            100.0 * p.requests_per_sec() / trivial.requests_per_sec(),
            p.cpu_per_job(),
        );
    }
    served.stop().await?;
    Ok(())
}

fn num_cpus() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// A valid store job for the demo site, unique by reference, as JSON text (built with
/// `format!` so the client spends little of the shared CPU on it).
fn job(n: u64) -> String {
    format!(
        r#"{{"kind":"store","reference":"bench-{n}","barcode":"B{:08}","to":{{"aisle":1,"row":{},"bay":{},"level":{},"position":{}}}}}"#,
        n % 100_000_000,
        1 + n % 2,
        1 + n % 10,
        1 + n % 6,
        1 + n % 4
    )
}

async fn phase<F>(
    name: &'static str,
    client: &reqwest::Client,
    clients: usize,
    duration: Duration,
    jobs_per_request: u64,
    request: F,
) -> anyhow::Result<Phase>
where
    F: Fn(&reqwest::Client, u64) -> reqwest::RequestBuilder + Send + Sync + 'static,
{
    let request = Arc::new(request);
    let cpu_before = cpu_time();
    let started = Instant::now();
    let deadline = started + duration;
    let tasks: Vec<_> = (0..clients as u64)
        .map(|worker| {
            let (client, request) = (client.clone(), request.clone());
            tokio::spawn(async move {
                let mut hist = Histogram::<u64>::new(3).expect("valid histogram");
                let mut n = worker << 32;
                while Instant::now() < deadline {
                    let t = Instant::now();
                    let response = request(&client, n).send().await?;
                    let status = response.status();
                    let body = response.bytes().await?;
                    if !status.is_success() {
                        anyhow::bail!("{name}: status {status}: {}", String::from_utf8_lossy(&body));
                    }
                    hist.record(t.elapsed().as_micros() as u64)?;
                    n += 1;
                }
                Ok::<_, anyhow::Error>(hist)
            })
        })
        .collect();
    let mut latency_us = Histogram::<u64>::new(3)?;
    for t in tasks {
        latency_us.add(t.await.context("bench client")??)?;
    }
    let elapsed = started.elapsed();
    let cpu = cpu_before.zip(cpu_time()).map(|(before, after)| after.saturating_sub(before));
    Ok(Phase { name, requests: latency_us.len(), jobs_per_request, elapsed, latency_us, cpu })
}
