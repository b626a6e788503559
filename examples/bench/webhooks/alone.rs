//! The baseline of `bench webhooks`: one signed POST at a time to the receiver with nothing
//! else running, from a client built as the deliverer's (`service::webhooks::client`), in a
//! process of its own as rackd's deliverer is (this executable run as `bench
//! webhooks-round-trips URL N BODY_FILE`), on one thread: the fastest sequential client
//! tried (on a multi-thread runtime, as rackd's, 7,800-8,400 round trips a second at 74-86
//! µs of client CPU each, against 11,300-13,600 at 34-39 µs on one thread, same session).
//!
//! It is not a hard bound on this machine (a shared VM). A ping-pong alone lets the cores
//! idle between its steps, and waking an idle core there is slow: the same baseline ran at
//! 11,300-13,600 round trips a second (32-39 µs of client CPU each) in some runs and at
//! 25,000-46,000 (11-19 µs) in others, at times both in one run; an earlier version of it
//! (in the benchmark's process) ran at 23,000-29,000 with a busy loop at the lowest
//! priority keeping the cores awake and at 10,400-17,300 without, minutes apart. rackd
//! keeps a core busy while it delivers (its SQLite thread, writer and sync thread).

use std::ffi::OsString;
use std::path::Path;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{Context, ensure};
use axum::body::Bytes;
use rackd::service::webhooks::sign;

use super::ms;
use super::receiver::{Receiver, SECRET};

/// The first argument that makes this executable run the baseline's client.
pub const ARG: &str = "webhooks-round-trips";

/// What the baseline measured.
pub struct Alone {
    /// Each round trip, in ms, sorted.
    pub latency_ms: Vec<f64>,
    /// All of them, one after another.
    pub elapsed: Duration,
    /// CPU seconds of the client's process over them.
    pub client_cpu: f64,
    /// CPU seconds of the benchmark's process (the receiver's) meanwhile.
    pub receiver_cpu: f64,
}

impl Alone {
    /// Round trips per second.
    pub fn rate(&self) -> f64 {
        self.latency_ms.len() as f64 / self.elapsed.as_secs_f64()
    }
}

/// `n` round trips of `body` to `receiver`, from a child process; `dir` holds the body's file.
pub async fn measure(receiver: &Receiver, body: &Bytes, n: usize, dir: &Path) -> anyhow::Result<Alone> {
    let file = dir.join("body.json");
    std::fs::write(&file, body)?;
    let from = receiver.count();
    let cpu = crate::child::cpu_secs(std::process::id())?;
    let output = tokio::process::Command::new(std::env::current_exe()?)
        .arg(ARG)
        .arg(receiver.url())
        .arg(n.to_string())
        .arg(&file)
        .output()
        .await
        .context("running the baseline's client")?;
    let receiver_cpu = crate::child::cpu_secs(std::process::id())? - cpu;
    ensure!(output.status.success(), "the baseline's client: {}", String::from_utf8_lossy(&output.stderr));
    let answer: serde_json::Value = serde_json::from_slice(&output.stdout)?;
    let mut latency_ms: Vec<f64> = serde_json::from_value(answer["latency_ms"].clone())?;
    latency_ms.sort_by(f64::total_cmp);
    ensure!(receiver.count() == from + n, "the receiver did not count every round trip");
    Ok(Alone {
        latency_ms,
        elapsed: Duration::from_secs_f64(answer["elapsed_s"].as_f64().context("elapsed_s")?),
        client_cpu: answer["cpu_s"].as_f64().context("cpu_s")?,
        receiver_cpu,
    })
}

/// The child's side: `args` are URL, N and the body's file; prints the figures as JSON.
pub fn run_child(args: &[OsString]) -> ExitCode {
    let runtime =
        tokio::runtime::Builder::new_current_thread().enable_all().build().expect("a tokio runtime");
    match runtime.block_on(client(args)) {
        Ok(figures) => {
            println!("{figures}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("bench {ARG}: {e:#}");
            ExitCode::FAILURE
        }
    }
}

async fn client(args: &[OsString]) -> anyhow::Result<serde_json::Value> {
    let [url, n, file] = args else { anyhow::bail!("usage: bench {ARG} URL N BODY_FILE") };
    let url = url.to_str().context("the URL")?;
    let n: usize = n.to_str().and_then(|n| n.parse().ok()).context("N")?;
    let body = Bytes::from(std::fs::read(file)?);
    let key = rackd::config::webhooks::decode_secret(SECRET).map_err(anyhow::Error::msg)?;
    // As `service::webhooks::client` builds it: one idle connection kept, no proxy.
    let client = reqwest::Client::builder()
        .no_proxy()
        .redirect(reqwest::redirect::Policy::none())
        .timeout(Duration::from_secs(5))
        .pool_max_idle_per_host(1)
        .build()?;
    let mut latency_ms = Vec::with_capacity(n);
    let cpu = crate::child::cpu_secs(std::process::id())?;
    let started = Instant::now();
    for i in 0..n {
        let t = Instant::now();
        let id = format!("alone-{i}");
        let timestamp = rackd::domain::time::now_ms() / 1000;
        let signed = sign::sign(&key, &id, timestamp, &body);
        let answer = client
            .post(url)
            .header("content-type", "application/json")
            .header("webhook-id", &signed.id)
            .header("webhook-timestamp", signed.timestamp.to_string())
            .header("webhook-signature", &signed.signature)
            .body(body.clone())
            .send()
            .await?;
        ensure!(answer.status().is_success(), "the receiver answered {}", answer.status());
        answer.bytes().await?;
        latency_ms.push(ms(t.elapsed()));
    }
    let elapsed = started.elapsed().as_secs_f64();
    let cpu_s = crate::child::cpu_secs(std::process::id())? - cpu;
    Ok(serde_json::json!({ "elapsed_s": elapsed, "cpu_s": cpu_s, "latency_ms": latency_ms }))
}
