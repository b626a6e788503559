//! `bench fleet --capture both`: what the flight recorders cost the polling path.
//!
//! The same fleet against the same simulator, rackd started afresh for each setting, in
//! alternating rounds (off, on; then on, off; ...), so drift of a shared, noisy machine
//! falls on both settings alike. Each round measures the static phase only: the recorder's
//! cost is per frame, and a changing value adds work after the frames, not to them.
//!
//! Figures: rackd's CPU per 1000 tag reads with recording off and on, their ratio per
//! round, and the ratio of the sums over every round (the figure the 3 % bound is
//! read against).

use std::time::Duration;

use anyhow::ensure;
use rackd::protocols::modbus::server::ServerHandle;

use crate::child::Server;
use crate::fleet::{FleetArgs, Phase, config_text, phase, target, wait_all_good};

/// Runs alternating rounds with recording off and on; prints CPU per 1000 tag reads.
pub async fn compare(args: FleetArgs, server: &ServerHandle, plc: &str) -> anyhow::Result<()> {
    let FleetArgs { devices, tags, poll_ms, seconds, rounds, .. } = args;
    ensure!(rounds >= 1, "--rounds at least 1");
    println!(
        "bench fleet --capture both: {devices} tag devices x {tags} u16 tags every {poll_ms} ms over Modbus \
         TCP (target {:.0} tag reads/s), {rounds} rounds of {seconds} s per setting, {} cores",
        target(args),
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    println!(
        "{:<6} {:>8} {:>12} {:>10} {:>16}",
        "round", "capture", "tag reads/s", "rackd CPU", "CPU/1000 reads"
    );
    let mut sums = [(0.0, 0.0); 2];
    let mut ratios = Vec::new();
    for round in 0..rounds {
        let order = if round % 2 == 0 { [false, true] } else { [true, false] };
        let mut per = [0.0; 2];
        for on in order {
            let p = measure(args, server, plc, on).await?;
            let reads = p.requests as f64 * tags as f64;
            let ms_per_1000 = 1000.0 * p.rackd_cpu / (reads / 1000.0);
            println!(
                "{:<6} {:>8} {:>12.0} {:>9.1}% {:>13.3} ms",
                round + 1,
                if on { "on" } else { "off" },
                reads / p.wall.as_secs_f64(),
                100.0 * p.rackd_cpu / p.wall.as_secs_f64(),
                ms_per_1000
            );
            ensure!(p.not_good == 0, "{} tags not good at the end of the round", p.not_good);
            per[usize::from(on)] = ms_per_1000;
            sums[usize::from(on)].0 += p.rackd_cpu;
            sums[usize::from(on)].1 += reads;
        }
        ratios.push(per[1] / per[0]);
    }
    let cost = |(cpu, reads): (f64, f64)| 1000.0 * cpu / (reads / 1000.0);
    let words: Vec<String> = ratios.iter().map(|r| format!("{r:.3}")).collect();
    println!(
        "CPU per 1000 tag reads: off {:.3} ms, on {:.3} ms; on/off {:.3} over every round (per round: {})",
        cost(sums[0]),
        cost(sums[1]),
        cost(sums[1]) / cost(sums[0]),
        words.join(", ")
    );
    Ok(())
}

/// One static phase of a fresh rackd with recording `on` or off.
async fn measure(args: FleetArgs, server: &ServerHandle, plc: &str, on: bool) -> anyhow::Result<Phase> {
    let dir = tempfile::tempdir()?;
    let config = dir.path().join("fleet.toml");
    let capture = on.then_some(args.capture_seconds);
    std::fs::write(&config, config_text(args.devices, args.tags, args.poll_ms, plc, capture))?;
    let rackd = Server::start(&config, dir.path()).await?;
    let client = reqwest::Client::new();
    let url = format!("http://{}/api/v1/devices", rackd.addr);
    wait_all_good(&client, &url, args.devices * args.tags as usize).await?;
    // Settle after the start-up burst, as the single run does.
    tokio::time::sleep(Duration::from_secs(5)).await;
    let name = if on { "on" } else { "off" };
    let measured = phase(name.into(), &client, &url, server, &rackd, args.seconds).await;
    rackd.stop().await;
    measured
}
