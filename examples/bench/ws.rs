//! `bench ws`: fan-out of live events to many WebSocket subscribers.
//!
//! Starts rackd as a child process (so its CPU time can be read apart from the load
//! generator's, see `child.rs`) on a temporary database with no devices, then
//! submits single jobs at a steady rate while subscribers follow `GET /api/v1/ws?topics=jobs`.
//! A job's event latency runs from the moment its POST is sent until a subscriber has the
//! `job.updated` event (so it includes the commit, whose own latency is printed as the
//! POST's). Two phases with the same load: one subscriber (the baseline), then N; figures
//! as rates and as ratios to the baseline measured in the same run.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use futures::StreamExt;
use hdrhistogram::Histogram;
use tokio_tungstenite::tungstenite::Message;

use crate::child::Server;

/// What one phase measured.
struct Phase {
    subscribers: usize,
    delivered: u64,
    latency_us: Histogram<u64>,
    post_us: Histogram<u64>,
    cpu_secs: f64,
    wall: Duration,
}

/// Runs the benchmark and prints its figures.
pub async fn run(subscribers: usize, events: usize, rate: u32) -> anyhow::Result<()> {
    let dir = tempfile::tempdir()?;
    let config = dir.path().join("bench.toml");
    std::fs::write(&config, "# bench ws: no devices\n")?;
    let server = Server::start(&config, dir.path()).await?;
    println!(
        "bench ws: {subscribers} subscribers, {events} events per phase at {rate}/s, {} cores",
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    let origin = Instant::now();
    let baseline = phase(&server, 1, 0, events, rate, origin).await?;
    let many = phase(&server, subscribers, events, events, rate, origin).await?;
    print(&baseline, &many);
    server.stop().await;
    Ok(())
}

/// One phase: `subscribers` follow while `events` jobs numbered from `first` are posted.
async fn phase(
    server: &Server,
    subscribers: usize,
    first: usize,
    events: usize,
    rate: u32,
    origin: Instant,
) -> anyhow::Result<Phase> {
    let base = server.addr.as_str();
    let sent: Arc<Vec<AtomicU64>> = Arc::new((0..events).map(|_| AtomicU64::new(0)).collect());
    let seq = last_seq(base).await?;
    let mut streams = Vec::with_capacity(subscribers);
    for _ in 0..subscribers {
        let url = format!("ws://{base}/api/v1/ws?topics=jobs&since={seq}");
        let (stream, _) = tokio_tungstenite::connect_async(url).await.context("connecting a subscriber")?;
        streams.push(stream);
    }
    let readers: Vec<_> = streams
        .into_iter()
        .map(|mut stream| {
            let sent = sent.clone();
            tokio::spawn(async move {
                let mut hist = Histogram::<u64>::new(3).expect("valid histogram");
                while (hist.len() as usize) < events {
                    let Ok(Some(Ok(message))) =
                        tokio::time::timeout(Duration::from_secs(30), stream.next()).await
                    else {
                        break;
                    };
                    let Message::Text(text) = message else { continue };
                    let Some(n) = job_number(&text).and_then(|n| n.checked_sub(first)) else { continue };
                    let Some(at) = sent.get(n).map(|a| a.load(Ordering::Acquire)) else { continue };
                    let now = origin.elapsed().as_micros() as u64;
                    hist.record(now.saturating_sub(at)).ok();
                }
                hist
            })
        })
        .collect();
    let client = reqwest::Client::new();
    let url = format!("http://{base}/api/v1/jobs");
    let mut post_us = Histogram::<u64>::new(3)?;
    let cpu_before = server.cpu_secs()?;
    let started = Instant::now();
    let mut tick = tokio::time::interval(Duration::from_secs(1) / rate.max(1));
    for (n, slot) in sent.iter().enumerate() {
        tick.tick().await;
        let body = format!(
            r#"{{"kind":"light","reference":"ws-{}","location":{{"aisle":1,"row":1,"bay":1,"level":1,"position":1}},"color":"green","on":true}}"#,
            first + n
        );
        let t = Instant::now();
        slot.store(origin.elapsed().as_micros() as u64, Ordering::Release);
        let response = client.post(&url).header("content-type", "application/json").body(body).send().await?;
        if !response.status().is_success() {
            bail!("POST answered {}", response.status());
        }
        post_us.record(t.elapsed().as_micros() as u64)?;
    }
    let mut latency_us = Histogram::<u64>::new(3)?;
    for r in readers {
        latency_us.add(r.await?)?;
    }
    let wall = started.elapsed();
    let cpu_secs = server.cpu_secs()? - cpu_before;
    Ok(Phase { subscribers, delivered: latency_us.len(), latency_us, post_us, cpu_secs, wall })
}

/// The event log's last sequence number now (from a small snapshot), so that subscribers
/// start there with `since` instead of each taking a snapshot.
async fn last_seq(base: &str) -> anyhow::Result<i64> {
    let url = format!("ws://{base}/api/v1/ws?topics=devices");
    let (mut stream, _) = tokio_tungstenite::connect_async(url).await?;
    while let Some(message) = stream.next().await {
        if let Message::Text(text) = message? {
            let v: serde_json::Value = serde_json::from_str(&text)?;
            return Ok(v["seq"].as_i64().unwrap_or(0));
        }
    }
    bail!("no snapshot")
}

/// The number in a job event's `"reference":"ws-N"`, found without parsing the whole event.
fn job_number(text: &str) -> Option<usize> {
    let start = text.find(r#""reference":"ws-"#)? + r#""reference":"ws-"#.len();
    let digits: &str = &text[start..];
    let end = digits.find('"')?;
    digits[..end].parse().ok()
}

fn print(baseline: &Phase, many: &Phase) {
    let ms = |h: &Histogram<u64>, q: f64| h.value_at_quantile(q) as f64 / 1000.0;
    println!(
        "{:<18} {:>10} {:>12} {:>8} {:>8} {:>8} {:>10} {:>11}",
        "phase", "delivered", "POST p50 ms", "p50 ms", "p99 ms", "max ms", "server CPU", "CPU/msg µs"
    );
    for p in [baseline, many] {
        println!(
            "{:<18} {:>10} {:>12.2} {:>8.2} {:>8.2} {:>8.2} {:>9.0}% {:>11.1}",
            format!("{} subscriber{}", p.subscribers, if p.subscribers == 1 { "" } else { "s" }),
            p.delivered,
            ms(&p.post_us, 0.5),
            ms(&p.latency_us, 0.5),
            ms(&p.latency_us, 0.99),
            p.latency_us.max() as f64 / 1000.0,
            100.0 * p.cpu_secs / p.wall.as_secs_f64(),
            1e6 * p.cpu_secs / p.delivered.max(1) as f64,
        );
    }
    println!(
        "{} subscribers vs 1: p99 x{:.1}, server CPU x{:.1}; every subscriber got {} of {} events",
        many.subscribers,
        many.latency_us.value_at_quantile(0.99) as f64
            / baseline.latency_us.value_at_quantile(0.99).max(1) as f64,
        many.cpu_secs / baseline.cpu_secs.max(0.01),
        if many.delivered == (many.subscribers as u64) * (baseline.delivered) { "all" } else { "NOT all" },
        baseline.delivered
    );
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_job_number_is_found_in_an_event() {
        let text = r#"{"seq":3,"type":"job.updated","data":{"id":3,"reference":"ws-42","kind":"light"}}"#;
        assert_eq!(super::job_number(text), Some(42));
        assert_eq!(super::job_number(r#"{"reference":"other"}"#), None);
    }
}
