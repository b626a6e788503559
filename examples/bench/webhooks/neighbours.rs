//! `bench webhooks --neighbours`: what a receiver that is slow or down costs the rest of
//! rackd. `bench intake` and `bench shelf` run, through their own measuring code, with
//! (a) no subscription, (b) one to a receiver that answers every request after 2 s (within
//! the default `timeout_ms` of 5 s: each delivery succeeds, slowly) and (c) one to a port
//! nothing listens on (every try refused, retried with the default backoff), each with
//! `job.*`. A round runs the three in turn, starting one later each round (abc, bca, cab),
//! so that a drift of the machine's load falls on each alike. Figures of (b) and (c) are
//! printed as ratios to (a) of the same round, and their mean over the rounds; beside
//! intake's rates and CPU per job, the process's peak resident memory over each intake run
//! (a subscriber that stops reading the hub can hold commits in memory).

use std::time::Duration;

use rackd::config::{Config, WebhookConfig};

use super::WebhooksArgs;
use super::receiver::{Receiver, SECRET, refusing_url};
use crate::{intake, shelf};

/// The receiver of a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Variant {
    /// No subscription.
    None,
    /// A receiver that answers after 2 s.
    Slow,
    /// A receiver that is down.
    Down,
}

impl Variant {
    const ALL: [Variant; 3] = [Variant::None, Variant::Slow, Variant::Down];

    fn name(self) -> &'static str {
        match self {
            Variant::None => "(a) none",
            Variant::Slow => "(b) slow",
            Variant::Down => "(c) down",
        }
    }
}

/// The figures of one run, higher is better for each but the latencies.
#[derive(Clone, Debug, Default)]
struct Run {
    /// Intake: `/healthz` requests/s, single POSTs/s, batched jobs/s.
    healthz: f64,
    singles: f64,
    batched: f64,
    /// Intake: single POSTs' p99 in ms, CPU µs per single job and per batched job.
    single_p99: f64,
    single_cpu: f64,
    batch_cpu: f64,
    /// Intake: the process's peak resident memory over the run, in MiB (NaN if unknown).
    intake_peak_mib: f64,
    /// Shelf: POST to task in slot p50 and p99 in ms, completed jobs/s.
    handover_p50: f64,
    handover_p99: f64,
    sustained: f64,
}

impl Run {
    /// Each figure with its name.
    fn figures(&self) -> [(&'static str, f64); 10] {
        [
            ("intake GET /healthz req/s", self.healthz),
            ("intake POST /api/v1/jobs req/s", self.singles),
            ("intake POST p99 ms", self.single_p99),
            ("intake CPU µs per single job", self.single_cpu),
            ("intake batched jobs/s", self.batched),
            ("intake CPU µs per batched job", self.batch_cpu),
            ("intake peak resident MiB", self.intake_peak_mib),
            ("shelf POST -> slot p50 ms", self.handover_p50),
            ("shelf POST -> slot p99 ms", self.handover_p99),
            ("shelf completed jobs/s", self.sustained),
        ]
    }
}

/// Runs the rounds and prints each run and the ratios.
pub async fn run(args: &WebhooksArgs) -> anyhow::Result<()> {
    let slow = Receiver::start(Duration::from_secs(2)).await?;
    let down = refusing_url()?;
    println!(
        "bench webhooks --neighbours: {} rounds; intake 64 clients, {} s per phase; shelf {} + {} jobs, 10 ms poll",
        args.rounds, args.intake_seconds, args.shelf_latency_jobs, args.shelf_batch_jobs
    );
    let subscription = |variant| {
        let url = match variant {
            Variant::None => return Vec::new(),
            Variant::Slow => slow.url().to_owned(),
            Variant::Down => down.clone(),
        };
        vec![WebhookConfig::new("wms", &url, &["job.*"], SECRET)]
    };
    let mut rounds: Vec<[Run; 3]> = Vec::new();
    for round in 0..args.rounds {
        let mut runs: [Run; 3] = Default::default();
        for k in 0..3 {
            let variant = Variant::ALL[(round + k) % 3];
            let run = measure(args, subscription(variant)).await?;
            println!(
                "round {} {}: intake {:.0} POST/s, {:.0} batched jobs/s, {:.1} / {:.1} CPU µs per job, \
                 peak {:.0} MiB; shelf slot p99 {:.2} ms, {:.0} jobs/s",
                round + 1,
                variant.name(),
                run.singles,
                run.batched,
                run.single_cpu,
                run.batch_cpu,
                run.intake_peak_mib,
                run.handover_p99,
                run.sustained
            );
            runs[variant as usize] = run;
        }
        rounds.push(runs);
    }
    println!("\nslow receiver (b) and receiver down (c) against no subscription (a), same round:");
    println!(
        "{:<32} {:>12} {:>8} {:>16} {:>8} {:>16}",
        "figure", "(a) mean", "(b)/(a)", "rounds", "(c)/(a)", "rounds"
    );
    let names = Run::default().figures().map(|(name, _)| name);
    for (i, name) in names.iter().enumerate() {
        let figure = |r: &Run| r.figures()[i].1;
        let mean_a = rounds.iter().map(|r| figure(&r[0])).sum::<f64>() / rounds.len() as f64;
        let ratios =
            |v: usize| -> Vec<f64> { rounds.iter().map(|r| figure(&r[v]) / figure(&r[0])).collect() };
        let (slow, down) = (ratios(1), ratios(2));
        println!(
            "{name:<32} {mean_a:>12.2} {:>8.3} {:>16} {:>8.3} {:>16}",
            mean(&slow),
            spread(&slow),
            mean(&down),
            spread(&down)
        );
    }
    Ok(())
}

/// One run of intake and then shelf, each on a fresh rackd subscribed to `webhooks`.
async fn measure(args: &WebhooksArgs, webhooks: Vec<WebhookConfig>) -> anyhow::Result<Run> {
    let dir = tempfile::tempdir()?;
    let mut config = Config::demo();
    config.server.listen = "127.0.0.1:0".parse()?;
    config.database.path = dir.path().join("bench.db");
    config.webhooks = webhooks.clone();
    let options = intake::Options {
        clients: 64,
        seconds: args.intake_seconds,
        batch: 1000,
        database: "sqlite".into(),
        tls: false,
    };
    let client = reqwest::Client::builder().pool_max_idle_per_host(options.clients);
    reset_peak_rss();
    let phases = intake::measure(&config, client, &options, "").await?;
    let intake_peak_mib = peak_rss_mib().unwrap_or(f64::NAN);
    let [healthz, single, batch] = &phases[..] else {
        anyhow::bail!("intake measured {} phases", phases.len())
    };
    let shelf = shelf::measure(args.shelf_latency_jobs, args.shelf_batch_jobs, 10, webhooks).await?;
    let ms = |h: &hdrhistogram::Histogram<u64>, q: f64| h.value_at_quantile(q) as f64 / 1000.0;
    Ok(Run {
        healthz: healthz.requests_per_sec(),
        singles: single.requests_per_sec(),
        batched: batch.requests_per_sec() * options.batch as f64,
        single_p99: ms(&single.latency_us, 0.99),
        single_cpu: single.cpu_us_per_job().unwrap_or(f64::NAN),
        batch_cpu: batch.cpu_us_per_job().unwrap_or(f64::NAN),
        intake_peak_mib,
        handover_p50: ms(&shelf.handover, 0.5),
        handover_p99: ms(&shelf.handover, 0.99),
        sustained: shelf.sustained(),
    })
}

/// Starts this process's peak resident memory afresh (Linux: `/proc/self/clear_refs`).
fn reset_peak_rss() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

/// This process's peak resident memory since [`reset_peak_rss`], in MiB (Linux).
fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// The lowest and highest of `v`, as printed.
fn spread(v: &[f64]) -> String {
    let low = v.iter().copied().fold(f64::INFINITY, f64::min);
    let high = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    format!("{low:.3}-{high:.3}")
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_spread_is_the_lowest_and_the_highest() {
        assert_eq!(super::spread(&[1.02, 0.97, 1.0]), "0.970-1.020");
        assert_eq!(super::mean(&[1.0, 2.0, 3.0]), 2.0);
    }
}
