//! `bench intake`: job intake throughput and latency against a trivial route.
//!
//! Starts a real server on a temporary database, then drives it over loopback HTTP with
//! N concurrent keep-alive clients in three phases of equal length: `GET /healthz` (the
//! ceiling: what this machine's HTTP stack does with no work), single-job POSTs, and batch
//! POSTs of 1000 jobs. Figures are printed as rates and as ratios to the ceiling measured
//! in the same run, since absolute numbers swing on a shared machine, and as the process's
//! CPU time per job (server and clients together, from `/proc/self/stat`), which swings
//! less: another tenant of the machine takes turns from rackd, not work from each job.
//!
//! With `--tls`, the same phases run again right after, over HTTPS (`[server.tls]` with a
//! certificate made for the run by a CA of its own, which the clients trust), against a
//! fresh database, and the figures over TLS are printed as ratios to the same over HTTP:
//! what TLS costs, measured in one run, so that the machine's mood shows in both.

use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use hdrhistogram::Histogram;

use rackd::config::Config;

use crate::served::Served;

mod tls {
    //! The run's own CA and a server certificate it signs, in the run's temporary folder.

    use rackd::config::TlsConfig;
    use rcgen::{BasicConstraints, CertificateParams, DnType, IsCa, Issuer, KeyPair, KeyUsagePurpose};

    /// What the server serves and the clients trust.
    pub struct Site {
        /// `[server.tls]` on the files written.
        pub tls: TlsConfig,
        /// The CA's certificate.
        pub ca_pem: String,
    }

    impl Site {
        /// Makes the CA and the server's certificate (for 127.0.0.1), written into `dir`.
        pub fn new(dir: &std::path::Path) -> anyhow::Result<Site> {
            let ca_key = KeyPair::generate()?;
            let mut ca = CertificateParams::new(Vec::<String>::new())?;
            ca.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
            ca.distinguished_name.push(DnType::CommonName, "bench CA");
            ca.key_usages = vec![KeyUsagePurpose::KeyCertSign];
            let ca_pem = ca.self_signed(&ca_key)?.pem();
            let issuer = Issuer::new(ca, ca_key);
            let key = KeyPair::generate()?;
            let cert = CertificateParams::new(vec!["127.0.0.1".to_owned()])?.signed_by(&key, &issuer)?;
            let (cert_file, key_file) = (dir.join("server.crt"), dir.join("server.key"));
            std::fs::write(&cert_file, cert.pem())?;
            std::fs::write(&key_file, key.serialize_pem())?;
            Ok(Site { tls: TlsConfig::new(cert_file, key_file), ca_pem })
        }
    }
}

/// What one phase measured.
pub struct Phase {
    /// The phase, as printed.
    pub name: &'static str,
    requests: u64,
    jobs_per_request: u64,
    elapsed: Duration,
    /// Each request's latency, in µs.
    pub latency_us: Histogram<u64>,
    /// The process's CPU time over the phase, if the system tells it.
    cpu: Option<Duration>,
}

impl Phase {
    /// Requests answered per second.
    pub fn requests_per_sec(&self) -> f64 {
        self.requests as f64 / self.elapsed.as_secs_f64()
    }

    /// CPU microseconds per job, if the system tells the CPU time.
    pub fn cpu_us_per_job(&self) -> Option<f64> {
        let cpu = self.cpu?;
        Some(cpu.as_secs_f64() * 1e6 / (self.requests * self.jobs_per_request) as f64)
    }

    /// CPU microseconds per job, as printed.
    fn cpu_per_job(&self) -> String {
        self.cpu_us_per_job().map_or("-".into(), |us| format!("{us:.1}"))
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

/// What `bench intake` is asked to do.
pub struct Options {
    /// Concurrent clients.
    pub clients: usize,
    /// Seconds per phase.
    pub seconds: u64,
    /// Jobs per batch request.
    pub batch: usize,
    /// `sqlite`, `postgres` or a `postgres://` URL.
    pub database: String,
    /// Also over HTTPS.
    pub tls: bool,
}

/// Runs the intake benchmark and prints its figures.
pub async fn run(options: Options) -> anyhow::Result<()> {
    let dir = tempfile::tempdir()?;
    let Options { clients, seconds, batch, .. } = options;
    let mut config = Config::demo();
    config.server.listen = "127.0.0.1:0".parse()?;
    let engine = if options.database == "sqlite" { "sqlite" } else { "postgres" };
    if options.database == "postgres" {
        crate::postgres::DURABLE.store(true, std::sync::atomic::Ordering::Relaxed);
    }
    println!(
        "bench intake: {clients} clients, {seconds} s per phase, batches of {batch}, {} cores, {engine}{}",
        num_cpus(),
        if options.tls { ", HTTP then HTTPS" } else { "" }
    );
    let client = reqwest::Client::builder().pool_max_idle_per_host(clients);
    use_database(&mut config, &options.database, &dir.path().join("bench.db")).await;
    let plain = measure(&config, client, &options, "").await?;
    print(&plain);
    if !options.tls {
        return Ok(());
    }
    let ca = tls::Site::new(dir.path())?;
    config.server.tls = Some(ca.tls.clone());
    use_database(&mut config, &options.database, &dir.path().join("bench-tls.db")).await;
    let client = reqwest::Client::builder()
        .pool_max_idle_per_host(clients)
        .tls_built_in_root_certs(false)
        .add_root_certificate(reqwest::Certificate::from_pem(ca.ca_pem.as_bytes())?);
    // Other references, should `--database` be one URL for both runs.
    let over_tls = measure(&config, client, &options, "tls-").await?;
    println!("\nover HTTPS:");
    print(&over_tls);
    println!("\nHTTPS / HTTP, same run:");
    println!("{:<26} {:>12} {:>10} {:>10} {:>11}", "phase", "requests/s", "p50", "p99", "CPU µs/job");
    for (p, t) in plain.iter().zip(&over_tls) {
        let ratio = |over: f64, under: f64| format!("{:.2}", over / under);
        let p50 = |p: &Phase| p.latency_us.value_at_quantile(0.5) as f64;
        let p99 = |p: &Phase| p.latency_us.value_at_quantile(0.99) as f64;
        let cpu = match (t.cpu_us_per_job(), p.cpu_us_per_job()) {
            (Some(t), Some(p)) => ratio(t, p),
            _ => "-".into(),
        };
        println!(
            "{:<26} {:>12} {:>10} {:>10} {:>11}",
            p.name,
            ratio(t.requests_per_sec(), p.requests_per_sec()),
            ratio(p50(t), p50(p)),
            ratio(p99(t), p99(p)),
            cpu
        );
    }
    Ok(())
}

/// Puts the store `database` names into `config`: a fresh SQLite file at `path`, a fresh
/// database of the throwaway cluster, or the URL given.
async fn use_database(config: &mut Config, database: &str, path: &std::path::Path) {
    config.database.path = path.to_owned();
    config.database.url = match database {
        "sqlite" => None,
        "postgres" => Some(crate::postgres::database().await),
        url => Some(url.to_owned()),
    };
}

/// Serves `config` and runs the three phases against it (`bench webhooks --neighbours`
/// runs them with and without a subscription in `config`).
pub async fn measure(
    config: &Config,
    client: reqwest::ClientBuilder,
    options: &Options,
    prefix: &'static str,
) -> anyhow::Result<Vec<Phase>> {
    let (clients, batch) = (options.clients, options.batch);
    let served = Served::start(config).await?;
    let base = served.base.clone();
    let duration = Duration::from_secs(options.seconds);
    let client = client.build()?;
    let trivial = phase("GET /healthz (ceiling)", &client, clients, duration, 1, {
        let url = reqwest::Url::parse(&format!("{base}/healthz"))?;
        move |c, _| c.get(url.clone())
    })
    .await?;
    let single = phase("POST /api/v1/jobs", &client, clients, duration, 1, {
        let url = reqwest::Url::parse(&format!("{base}/api/v1/jobs"))?;
        move |c, n| c.post(url.clone()).header("content-type", "application/json").body(job(prefix, n))
    })
    .await?;
    let batch_phase = phase("POST /api/v1/jobs/batch", &client, clients, duration, batch as u64, {
        let url = reqwest::Url::parse(&format!("{base}/api/v1/jobs/batch"))?;
        move |c, n| {
            let jobs: Vec<String> =
                (0..batch as u64).map(|i| job(prefix, n * batch as u64 + i + (1 << 40))).collect();
            let body = format!(r#"{{"jobs":[{}]}}"#, jobs.join(","));
            c.post(url.clone()).header("content-type", "application/json").body(body)
        }
    })
    .await?;
    served.stop().await?;
    Ok(vec![trivial, single, batch_phase])
}

/// Prints the phases' figures, as ratios to the first (the ceiling).
fn print(phases: &[Phase]) {
    println!(
        "{:<26} {:>12} {:>12} {:>10} {:>10} {:>10} {:>11}",
        "phase", "requests/s", "jobs/s", "p50 ms", "p99 ms", "vs ceiling", "CPU µs/job"
    );
    let ceiling = phases[0].requests_per_sec();
    for p in phases {
        println!(
            "{:<26} {:>12.0} {:>12.0} {:>10.2} {:>10.2} {:>9.0}% {:>11}",
            p.name,
            p.requests_per_sec(),
            p.requests_per_sec() * p.jobs_per_request as f64,
            p.latency_us.value_at_quantile(0.5) as f64 / 1000.0,
            p.latency_us.value_at_quantile(0.99) as f64 / 1000.0,
            100.0 * p.requests_per_sec() / ceiling,
            p.cpu_per_job(),
        );
    }
}

fn num_cpus() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// A valid store job for the demo site, unique by reference (`bench-PREFIXn`), as JSON
/// text (built with `format!` so the client spends little of the shared CPU on it).
fn job(prefix: &str, n: u64) -> String {
    format!(
        r#"{{"kind":"store","reference":"bench-{prefix}{n}","barcode":"B{:08}","to":{{"aisle":1,"row":{},"bay":{},"level":{},"position":{}}}}}"#,
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
