//! `rackd sim crane`: one simulated stacker crane on MC 3E, driven from stdin.
//!
//! ```text
//! rackd sim crane --listen 127.0.0.1:8000 --transport udp --step-ms 300 --alarm 7069@12
//! > alarm 7002        raise an alarm (any code)
//! > clear             clear the alarm
//! > heartbeat off     stop answering the heartbeat (on: answer again)
//! > handshake off     ignore the hand-over strobe (on: answer again)
//! > force             force-complete the task under way (state 30)
//! > drop              close the connection once (UDP: lose one request)
//! > link off          ignore every request (on: answer again)
//! > status            action state, task, alarm, load, positions
//! ```

use std::time::Duration;

use tokio::io::{AsyncBufReadExt, BufReader};

use super::sim_faults::FaultArgs;
use super::sim_mc3e::SimTransport;
use crate::protocols::mc3e::{EndCode, TransportKind};
use crate::sim::crane::{CraneSim, CraneSimOptions};

/// `rackd sim crane` options.
#[derive(clap::Args, Clone, Debug)]
pub struct SimCraneArgs {
    /// Address to listen on.
    #[arg(long, default_value = "127.0.0.1:8000")]
    pub listen: String,
    /// TCP or UDP.
    #[arg(long, value_enum, default_value_t = SimTransport::Tcp)]
    pub transport: SimTransport,
    /// Milliseconds per action state.
    #[arg(long, default_value_t = 500)]
    pub step_ms: u64,
    /// Raise alarm 7020 when rackd's heartbeat (D0) stalls this many seconds (0 = never).
    #[arg(long, default_value_t = 10)]
    pub watchdog_secs: u64,
    /// Raise alarm CODE SECONDS after start (repeatable), e.g. `7069@10`.
    #[arg(long, value_parser = scheduled_alarm)]
    pub alarm: Vec<(u16, u64)>,
    /// Link faults.
    #[command(flatten)]
    pub faults: FaultArgs,
}

/// Why a `--alarm` value was refused.
#[derive(Debug, thiserror::Error)]
#[error("expected CODE@SECONDS, e.g. 7069@10: {0}")]
pub struct BadScheduledAlarm(&'static str);

fn scheduled_alarm(text: &str) -> Result<(u16, u64), BadScheduledAlarm> {
    let (code, secs) = text.split_once('@').ok_or(BadScheduledAlarm("no '@'"))?;
    let code = code.parse().map_err(|_| BadScheduledAlarm("the code is not a number"))?;
    let secs = secs.parse().map_err(|_| BadScheduledAlarm("the seconds are not a number"))?;
    Ok((code, secs))
}

/// Runs the crane until Ctrl-C or the end of stdin.
pub async fn run(args: SimCraneArgs) -> anyhow::Result<()> {
    let transport = match args.transport {
        SimTransport::Tcp => TransportKind::Tcp,
        SimTransport::Udp => TransportKind::Udp,
    };
    let faults = args.faults.faults::<EndCode>()?;
    let wcs_timeout = (args.watchdog_secs > 0).then(|| Duration::from_secs(args.watchdog_secs));
    let options = CraneSimOptions { transport, step: Duration::from_millis(args.step_ms), wcs_timeout };
    let sim = std::sync::Arc::new(CraneSim::start(&args.listen, options).await?);
    sim.set_faults(faults);
    println!("crane simulator on {:?} {} (commands on stdin)", args.transport, sim.local_addr());
    for (code, secs) in args.alarm.clone() {
        let sim = sim.clone();
        tokio::spawn(async move {
            tokio::time::sleep(Duration::from_secs(secs)).await;
            println!("scheduled alarm {code}");
            sim.raise_alarm(code);
        });
    }
    let mut lines = BufReader::new(tokio::io::stdin()).lines();
    loop {
        tokio::select! {
            _ = tokio::signal::ctrl_c() => break,
            line = lines.next_line() => match line? {
                Some(line) if line.trim().is_empty() => {}
                Some(line) => match sim.command(&line) {
                    Ok(out) => println!("{out}"),
                    Err(e) => println!("error: {e}"),
                },
                // stdin closed (run in the background): keep serving until Ctrl-C.
                None => {
                    tokio::signal::ctrl_c().await?;
                    break;
                }
            },
        }
    }
    Ok(())
}
