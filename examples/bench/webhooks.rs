//! `bench webhooks`: how fast events reach a WMS's receiver, and what a receiver that is
//! slow or down costs rackd's other work.
//!
//! Delivery (the default): rackd runs as a child process (its CPU read apart from the
//! receiver's, see `child.rs`) with no devices, so each job posted stays queued and tells
//! of itself in one `job.updated`, and one `[[webhooks]]` subscription (`job.*`) to the
//! benchmark's receiver ([`receiver`]), which verifies every signature and notes when each
//! event arrives. Three phases, one after another:
//! - **lag**: jobs posted one at a time at a steady `--rate` for `--seconds`; per event,
//!   from its `time` (stamped by the writer as its group starts, so before the commit and
//!   its sync; to the millisecond) to its arrival at the receiver, on the wall clock. Beside
//!   it, two bounds on the same events from the benchmark's own monotonic clock: from
//!   sending the job's POST (before the commit) and from its 201 (after the commit).
//! - **the round trip alone** (the baseline, before and after the backlog): a signed POST
//!   of a real event's body, one at a time over one kept-alive connection, straight to the
//!   receiver from a client built like the deliverer's, in a process of its own
//!   ([`alone`], which says why it is not a hard bound on this machine).
//! - **throughput**: the subscription paused, `--backlog` jobs posted in batches of 1000,
//!   then resumed; events per second from the resume to the last event's arrival, checked
//!   in order, once each, signed, over one connection; rackd's CPU per event.
//!
//! Neighbours (`--neighbours`): `bench intake` and `bench shelf` (their own measuring code,
//! shorter), each run with (a) no subscription, (b) a subscription whose receiver answers
//! after 2 s, (c) one whose receiver is down (a port nothing listens on), in rotating order
//! over `--rounds` rounds, rackd in this process as those benchmarks run it; figures of
//! (b) and (c) as ratios to (a) of the same round.

pub mod alone;
mod neighbours;
mod receiver;

use std::collections::{BTreeMap, HashSet};
use std::time::{Duration, Instant};

use anyhow::{Context, ensure};
use serde_json::Value;

use crate::child::Server;
use receiver::{Arrival, Receiver, SECRET};

/// What `bench webhooks` is asked to do.
#[derive(clap::Args, Debug)]
pub struct WebhooksArgs {
    /// Jobs posted per second in the lag phase.
    #[arg(long, default_value_t = 200)]
    rate: u32,
    /// Seconds of the lag phase.
    #[arg(long, default_value_t = 5)]
    seconds: u64,
    /// Events in the throughput phase's backlog.
    #[arg(long, default_value_t = 20_000)]
    backlog: usize,
    /// Requests of the baseline (one round trip at a time, no rackd).
    #[arg(long, default_value_t = 20_000)]
    round_trips: usize,
    /// Instead of the delivery phases: `bench intake` and `bench shelf` with no
    /// subscription, a receiver that answers after 2 s, and one that is down.
    #[arg(long)]
    neighbours: bool,
    /// Rounds of the three runs (`--neighbours`).
    #[arg(long, default_value_t = 3)]
    rounds: usize,
    /// Seconds per phase of each `bench intake` run (`--neighbours`).
    #[arg(long, default_value_t = 2)]
    intake_seconds: u64,
    /// Single jobs of each `bench shelf` run's latency phase (`--neighbours`).
    #[arg(long, default_value_t = 500)]
    shelf_latency_jobs: usize,
    /// Jobs of each `bench shelf` run's sustained phase (`--neighbours`).
    #[arg(long, default_value_t = 5000)]
    shelf_batch_jobs: usize,
}

/// The subscription's name.
const NAME: &str = "bench";

/// Runs the benchmark and prints its figures.
pub async fn run(args: WebhooksArgs) -> anyhow::Result<()> {
    if args.neighbours {
        return neighbours::run(&args).await;
    }
    let receiver = Receiver::start(Duration::ZERO).await?;
    let dir = tempfile::tempdir()?;
    let config = dir.path().join("bench.toml");
    std::fs::write(
        &config,
        format!(
            "# bench webhooks: no devices, one subscription\n[[webhooks]]\nname = \"{NAME}\"\nurl = \"{}\"\n\
             events = [\"job.*\"]\nsecret = \"{SECRET}\"\n",
            receiver.url()
        ),
    )?;
    let server = Server::start(&config, dir.path()).await?;
    let base = format!("http://{}", server.addr);
    println!(
        "bench webhooks: {} jobs/s for {} s, a backlog of {}, {} cores",
        args.rate,
        args.seconds,
        args.backlog,
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    let client = reqwest::Client::new();

    let lag = lag(&client, &base, &receiver, args.rate, args.seconds).await?;
    // The baseline sends the body of a real event (the last one of the lag phase), before
    // and after the backlog, so that a change of the machine's load shows.
    let body = receiver.last_body();
    let before = alone::measure(&receiver, &body, args.round_trips, dir.path()).await?;
    let throughput = throughput(&client, &base, &server, &receiver, args.backlog).await?;
    let after = alone::measure(&receiver, &body, args.round_trips, dir.path()).await?;
    server.stop().await;

    print(&lag, &throughput, [&before, &after]);
    Ok(())
}

fn print(lag: &Lag, t: &Throughput, alone: [&alone::Alone; 2]) {
    let ms = |v: &[f64], q: f64| quantile(v, q);
    println!(
        "\n{:<44} {:>8} {:>8} {:>8}",
        format!("lag of {} events", lag.from_commit.len()),
        "p50 ms",
        "p99 ms",
        "max ms"
    );
    for (name, v) in [
        ("event `time` (commit) -> receiver", &lag.from_commit),
        ("POST sent -> receiver (upper bound)", &lag.from_sent),
        ("201 received -> receiver (lower bound)", &lag.from_answer),
        ("one round trip alone (baseline)", &alone[0].latency_ms),
    ] {
        println!("{name:<44} {:>8.2} {:>8.2} {:>8.2}", ms(v, 0.5), ms(v, 0.99), ms(v, 1.0));
    }
    println!(
        "(POST /api/v1/jobs itself: p50 {:.2} ms, p99 {:.2} ms)",
        ms(&lag.post, 0.5),
        ms(&lag.post, 0.99)
    );

    println!(
        "\n{:<44} {:>10} {:>14} {:>16}",
        "one request at a time, one connection", "per second", "sender µs CPU", "receiver µs CPU"
    );
    let row = |name: &str, n: usize, elapsed: Duration, sender: f64, receiver: f64| {
        let per = |cpu: f64| 1e6 * cpu / n as f64;
        println!(
            "{name:<44} {:>10.0} {:>14.1} {:>16.1}",
            n as f64 / elapsed.as_secs_f64(),
            per(sender),
            per(receiver)
        );
    };
    let [before, after] = alone;
    row(
        "one round trip alone (baseline), before",
        before.latency_ms.len(),
        before.elapsed,
        before.client_cpu,
        before.receiver_cpu,
    );
    row(&format!("rackd: a backlog of {} events", t.events), t.events, t.elapsed, t.rackd_cpu, t.bench_cpu);
    row(
        "one round trip alone (baseline), after",
        after.latency_ms.len(),
        after.elapsed,
        after.client_cpu,
        after.receiver_cpu,
    );
    let rate = t.events as f64 / t.elapsed.as_secs_f64();
    println!(
        "rackd at {:.0}% of the baselines' mean ({:.0}% of a core); in order, each once, every signature valid; \
         connections opened for the backlog: {}",
        200.0 * rate / (before.rate() + after.rate()),
        100.0 * t.rackd_cpu / t.elapsed.as_secs_f64(),
        t.connections,
    );
}

/// What the lag phase measured, in ms.
struct Lag {
    /// Per event: its `time` to its arrival (wall clock).
    from_commit: Vec<f64>,
    /// Per job: sending its POST to its first event's arrival.
    from_sent: Vec<f64>,
    /// Per job: its 201 to its first event's arrival (negative when the event came first).
    from_answer: Vec<f64>,
    /// Per job: its POST's latency.
    post: Vec<f64>,
}

/// Posts single jobs at `rate` for `seconds` and measures each one's events' arrivals.
async fn lag(
    client: &reqwest::Client,
    base: &str,
    receiver: &Receiver,
    rate: u32,
    seconds: u64,
) -> anyhow::Result<Lag> {
    let from = receiver.count();
    let url = format!("{base}/api/v1/jobs");
    let mut posted: BTreeMap<i64, (Instant, Instant)> = BTreeMap::new();
    let mut tick = tokio::time::interval(Duration::from_secs(1) / rate.max(1));
    for n in 0..rate as u64 * seconds {
        tick.tick().await;
        let body = light(&format!("lag-{n}"));
        let sent = Instant::now();
        let response = client.post(&url).header("content-type", "application/json").body(body).send().await?;
        ensure!(response.status() == 201, "POST answered {}", response.status());
        let answered = Instant::now();
        let job: Value = response.json().await?;
        posted.insert(job["id"].as_i64().context("the job's id")?, (sent, answered));
    }
    let jobs: HashSet<i64> = posted.keys().copied().collect();
    let arrivals =
        until_all(receiver, from, &jobs, Duration::from_secs(30)).await.context("the lag phase")?;
    let mut lag =
        Lag { from_commit: Vec::new(), from_sent: Vec::new(), from_answer: Vec::new(), post: Vec::new() };
    let mut seen = HashSet::new();
    for a in &arrivals {
        let time_ms = a.time_ms.context("an event without a time")?;
        lag.from_commit.push(a.wall_ms - time_ms as f64);
        let Some(&(sent, answered)) = a.job.and_then(|id| posted.get(&id)) else { continue };
        if seen.insert(a.job) {
            lag.from_sent.push(ms(a.at.duration_since(sent)));
            lag.from_answer.push(signed_ms(a.at, answered));
            lag.post.push(ms(answered - sent));
        }
    }
    for v in [&mut lag.from_commit, &mut lag.from_sent, &mut lag.from_answer, &mut lag.post] {
        v.sort_by(f64::total_cmp);
    }
    Ok(lag)
}

/// Waits, at most `limit`, until the receiver has had an event of each of `jobs` since its
/// `from`th request; then checks those requests ([`check`]) and returns them.
async fn until_all(
    receiver: &Receiver,
    from: usize,
    jobs: &HashSet<i64>,
    limit: Duration,
) -> anyhow::Result<Vec<Arrival>> {
    let deadline = tokio::time::Instant::now() + limit;
    let mut wanted = from + jobs.len();
    loop {
        let left = deadline.saturating_duration_since(tokio::time::Instant::now());
        receiver.wait_for(wanted, left).await?;
        let arrivals = receiver.arrivals(from);
        let seen: HashSet<i64> = arrivals.iter().filter_map(|a| a.job).collect();
        let missing = jobs.difference(&seen).count();
        if missing == 0 {
            check(&arrivals)?;
            return Ok(arrivals);
        }
        // Other events came too: at least one more per job still missing.
        wanted = from + arrivals.len() + missing;
    }
}

/// What the throughput phase measured.
struct Throughput {
    events: usize,
    elapsed: Duration,
    connections: u64,
    rackd_cpu: f64,
    bench_cpu: f64,
}

/// Pauses the subscription, posts `backlog` jobs in batches, resumes it and times the
/// backlog's delivery.
async fn throughput(
    client: &reqwest::Client,
    base: &str,
    server: &Server,
    receiver: &Receiver,
    backlog: usize,
) -> anyhow::Result<Throughput> {
    let webhook = |action: &'static str| {
        let url = format!("{base}/api/v1/webhooks/{NAME}/{action}");
        async move {
            let answer =
                client.post(url).json(&serde_json::json!({"reason": "bench webhooks"})).send().await?;
            ensure!(answer.status() == 200, "{action}: {}", answer.status());
            anyhow::Ok(())
        }
    };
    webhook("pause").await?;
    let mut ids = HashSet::new();
    for chunk in (0..backlog).collect::<Vec<_>>().chunks(1000) {
        let jobs: Vec<String> = chunk.iter().map(|n| light(&format!("backlog-{n}"))).collect();
        let body = format!(r#"{{"jobs":[{}]}}"#, jobs.join(","));
        let answer = client
            .post(format!("{base}/api/v1/jobs/batch"))
            .header("content-type", "application/json")
            .body(body)
            .send()
            .await?;
        ensure!(answer.status() == 201, "batch: {}", answer.status());
        let created: Value = answer.json().await?;
        ids.extend(
            created["jobs"].as_array().context("the batch's jobs")?.iter().filter_map(|j| j["id"].as_i64()),
        );
    }
    ensure!(ids.len() == backlog, "{} jobs created of {backlog}", ids.len());
    let list: Value = client.get(format!("{base}/api/v1/webhooks")).send().await?.json().await?;
    let behind = list["webhooks"][0]["behind"].as_i64().unwrap_or(0);
    ensure!(behind >= backlog as i64, "the paused subscription is {behind} events behind, not {backlog}");
    let from = receiver.count();
    let connections = receiver.connections();
    let (rackd_cpu, bench_cpu) = (server.cpu_secs()?, crate::child::cpu_secs(std::process::id())?);
    let started = Instant::now();
    webhook("resume").await?;
    let arrivals = until_all(receiver, from, &ids, Duration::from_secs(120)).await.context("the backlog")?;
    let (rackd_cpu, bench_cpu) =
        (server.cpu_secs()? - rackd_cpu, crate::child::cpu_secs(std::process::id())? - bench_cpu);
    let last = arrivals.last().context("no event")?;
    Ok(Throughput {
        events: arrivals.len(),
        elapsed: last.at.duration_since(started),
        connections: receiver.connections() - connections,
        rackd_cpu,
        bench_cpu,
    })
}

/// Every request signed, and each event arriving once, after every event before it.
fn check(arrivals: &[Arrival]) -> anyhow::Result<()> {
    let invalid = arrivals.iter().filter(|a| !a.valid).count();
    ensure!(invalid == 0, "{invalid} requests whose signature or webhook-id did not verify");
    if let Some(w) = arrivals.windows(2).find(|w| w[0].seq >= w[1].seq) {
        anyhow::bail!("event {} arrived after event {}: out of order, or twice", w[1].seq, w[0].seq);
    }
    Ok(())
}

/// A light job on the default site (aisle 1), unique by reference, as JSON text.
fn light(reference: &str) -> String {
    format!(
        r#"{{"kind":"light","reference":"{reference}","location":{{"aisle":1,"row":1,"bay":1,"level":1,"position":1}},"color":"green","on":true}}"#
    )
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// `at - since` in ms, negative when `at` came first.
fn signed_ms(at: Instant, since: Instant) -> f64 {
    match at.checked_duration_since(since) {
        Some(d) => ms(d),
        None => -ms(since - at),
    }
}

/// The `q` quantile of `sorted` (nearest rank; `q` = 1 is the largest), 0 when empty.
fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let rank = (q * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_are_nearest_ranks() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!((quantile(&v, 0.5), quantile(&v, 0.99), quantile(&v, 1.0)), (50.0, 99.0, 100.0));
        assert_eq!(quantile(&v, 0.0), 1.0);
        assert_eq!(quantile(&[], 0.5), 0.0);
    }

    #[test]
    fn an_answer_before_the_event_is_a_negative_lag() {
        let t = Instant::now();
        let later = t + Duration::from_millis(3);
        assert_eq!(signed_ms(later, t), 3.0);
        assert_eq!(signed_ms(t, later), -3.0);
    }
}
