//! rackd's benchmarks, kept out of the service binary and its dependencies.
//!
//! ```text
//! cargo run --release --example bench -- intake [--clients 64] [--seconds 5] [--batch 1000] [--database sqlite|postgres|URL] [--tls]
//! cargo run --release --example bench -- shelf  [--latency-jobs 1000] [--batch-jobs 20000] [--poll-ms 10]
//!                                               [--drop 0.2 [--lossy-jobs 1000] [--fixed-timeout]
//!                                                [--min-timeout-ms 20] [--no-transaction-id]]
//! cargo run --release --example bench -- ws     [--subscribers 1000] [--events 500] [--rate 50]
//! cargo run --release --example bench -- fleet  [--devices 500] [--tags 30] [--poll-ms 500] [--seconds 20] [--changing 0.1]
//!                                               [--capture on|off|both [--rounds 3]]
//! cargo run --release --example bench -- crane  [--jobs 200] [--backlog 30] [--fill 0.5] [--time-scale 200] [--seed 7]
//! cargo run --release --example bench -- site   [--aisles 1,10,40] [--jobs 30] [--backlog 8] [--time-scale 20] [--seed 7]
//!                                               [--slack 40] [--tight 0.2] [--deadlines 0.4] [--sequenced 0.5] [--poll-ms 200]
//! cargo run --release --example bench -- history [--jobs 10000000] [--days 365] [--database sqlite|postgres|URL]
//! cargo run --release --example bench -- webhooks [--rate 200] [--seconds 5] [--backlog 20000] [--round-trips 10000]
//! cargo run --release --example bench -- capture [--downloads 50] [--ring-mib 64]
//! cargo run --release --example bench -- webhooks --neighbours [--rounds 3] [--intake-seconds 2]
//!                                               [--shelf-latency-jobs 500] [--shelf-batch-jobs 5000]
//! ```
//!
//! An example rather than a `rackd bench` subcommand, so that `cargo build --release` of
//! the service neither compiles nor links the load generators' crates (hdrhistogram,
//! tokio-tungstenite, tempfile are dev-dependencies), while `cargo test` and clippy still
//! build and check it. Figures and what they mean: docs/development/benchmarks.md.
//!
//! `ws`, `fleet` and `webhooks` measure the server's CPU apart from the load generator's, so they run
//! rackd as a child process. The child is this same executable started as `bench rackd
//! serve ...`, which hands the rest of its arguments to rackd's own command line exactly as
//! the `rackd` binary does: `cargo run --example` does not rebuild the `rackd` binary, and
//! a stale one beside it would silently measure old code.

mod capture;
mod child;
mod crane;
mod fleet;
mod fleet_capture;
mod history;
mod intake;
// The tests' PostgreSQL; its TLS-only cluster (and the certificates it needs, `tls`) is the
// tests' alone (the tests' own build still reports what nobody uses).
#[allow(dead_code)]
#[path = "../../tests/it/support/postgres.rs"]
mod postgres;
mod retention;
mod served;
mod shelf;
mod site;
#[allow(dead_code)]
#[path = "../../tests/it/support/tls.rs"]
mod tls;
mod webhooks;
mod ws;

use std::process::ExitCode;

use clap::Parser;

/// The allocator the `rackd` binary uses (see `src/main.rs`), so the server it starts in
/// this process runs as it does in production.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// The benchmarks.
#[derive(Parser, Debug)]
#[command(name = "bench", about = "rackd's benchmarks (see docs/development/benchmarks.md)")]
enum Bench {
    /// Intake: single POSTs, batch POSTs and a trivial route, at N concurrent clients.
    Intake {
        /// Concurrent clients.
        #[arg(long, default_value_t = 64)]
        clients: usize,
        /// Seconds per phase.
        #[arg(long, default_value_t = 5)]
        seconds: u64,
        /// Jobs per batch request.
        #[arg(long, default_value_t = 1000)]
        batch: usize,
        /// The store: `sqlite` (a temporary file), `postgres` (a throwaway local cluster
        /// with PostgreSQL's durable defaults, from /usr/lib/postgresql) or a `postgres://` URL.
        #[arg(long, default_value = "sqlite")]
        database: String,
        /// Then the same phases again over HTTPS (a certificate made for the run, on a
        /// fresh database), and the ratio of each figure over TLS to the same over HTTP.
        #[arg(long)]
        tls: bool,
    },
    /// Shelf PLC: POST-to-slot latency and completed jobs/s against the simulator.
    Shelf {
        /// Jobs sent one at a time for the latency figures.
        #[arg(long, default_value_t = 1000)]
        latency_jobs: usize,
        /// Jobs sent in batches for the throughput figure.
        #[arg(long, default_value_t = 20000)]
        batch_jobs: usize,
        /// The device's poll period in milliseconds (default 10; with `--drop`, the shelf's
        /// configured default, 200).
        #[arg(long)]
        poll_ms: Option<u64>,
        /// Also run `lossy_jobs` jobs with this share of datagrams lost (the simulator
        /// drops requests), next to as many on the clean link, and print both rates.
        #[arg(long)]
        drop: Option<f64>,
        /// Jobs in each of the clean and the lossy runs of `--drop`.
        #[arg(long, default_value_t = 500)]
        lossy_jobs: usize,
        /// Keep the reply timeout fixed at `timeout_ms` (no adaptive timer), as before
        /// issue 12, for comparison.
        #[arg(long)]
        fixed_timeout: bool,
        /// The adaptive timeout's floor for the device (`min_timeout_ms`; default 2 on Modbus
        /// UDP with transaction ids, 20 without).
        #[arg(long)]
        min_timeout_ms: Option<u64>,
        /// The simulator answers with transaction id 0, as the seed's PLC does, and the
        /// device has the `no-transaction-id` quirk (issue 50: its replies name no request).
        #[arg(long)]
        no_transaction_id: bool,
        /// The device's `timeout_ms` (default 300): the reply lifetime the rule against late
        /// replies and writes waits out after a lost request.
        #[arg(long)]
        timeout_ms: Option<u64>,
    },
    /// Live events: fan-out latency and the server's CPU with 1 and with N WebSocket subscribers.
    Ws {
        /// Concurrent subscribers in the second phase.
        #[arg(long, default_value_t = 1000)]
        subscribers: usize,
        /// Jobs (events) per phase.
        #[arg(long, default_value_t = 500)]
        events: usize,
        /// Jobs posted per second.
        #[arg(long, default_value_t = 50)]
        rate: u32,
    },
    /// Tag devices: tag reads/s and rackd's CPU per 1000 reads, values static and changing.
    Fleet(fleet::FleetArgs),
    /// The crane planner: fifo against travel on one workload, against the simulated crane.
    Crane(crane::CraneArgs),
    /// A site: N crane aisles, sequences to stations and deadlines; throughput, inversions,
    /// missed deadlines, travel, rackd's CPU and dispatch latency.
    Site(site::SiteArgs),
    /// A year of history: the reads, start-up, memory and size on N ended jobs against an
    /// empty store.
    History(history::HistoryArgs),
    /// A simulated year with `[retention]`: the store's size, and every job in the store or
    /// the archive.
    Retention(retention::RetentionArgs),
    /// Webhooks: delivery lag and events/s to one receiver; with `--neighbours`, what a
    /// slow or dead receiver costs `intake` and `shelf`.
    Webhooks(webhooks::WebhooksArgs),
    /// Capture downloads: rackd's memory and the device's link while N clients download
    /// the capture of a device with a full ring at once.
    Capture(capture::CaptureArgs),
}

fn main() -> ExitCode {
    let args: Vec<std::ffi::OsString> = std::env::args_os().collect();
    if args.get(1).is_some_and(|a| a == child::RACKD) {
        return child::run_rackd(&args[1..]);
    }
    if args.get(1).is_some_and(|a| a == webhooks::alone::ARG) {
        return webhooks::alone::run_child(&args[2..]);
    }
    let bench = Bench::parse();
    let runtime = tokio::runtime::Runtime::new().expect("a tokio runtime");
    let result = runtime.block_on(async {
        match bench {
            Bench::Intake { clients, seconds, batch, database, tls } => {
                intake::run(intake::Options { clients, seconds, batch, database, tls }).await
            }
            Bench::Shelf {
                latency_jobs,
                batch_jobs,
                poll_ms,
                drop,
                lossy_jobs,
                fixed_timeout,
                min_timeout_ms,
                no_transaction_id,
                timeout_ms,
            } => {
                let lossy = drop.map(|rate| shelf::Lossy {
                    rate,
                    jobs: lossy_jobs,
                    fixed_timeout,
                    min_timeout_ms,
                    no_transaction_id,
                    timeout_ms,
                });
                let poll_ms = poll_ms.unwrap_or(if lossy.is_some() { 200 } else { 10 });
                shelf::run(latency_jobs, batch_jobs, poll_ms, lossy).await
            }
            Bench::Ws { subscribers, events, rate } => ws::run(subscribers, events, rate).await,
            Bench::Fleet(args) => fleet::run(args).await,
            Bench::Crane(args) => crane::run(args).await,
            Bench::Site(args) => site::run(args).await,
            Bench::History(args) => history::run(args).await,
            Bench::Retention(args) => retention::run(args).await,
            Bench::Webhooks(args) => webhooks::run(args).await,
            Bench::Capture(args) => capture::run(args).await,
        }
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("bench: {e:#}");
            ExitCode::FAILURE
        }
    }
}
