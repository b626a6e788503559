//! `rackd sim crane`: one simulated stacker crane on MC 3E, driven from stdin.
//!
//! ```text
//! > alarm 7002        raise an alarm (any code)
//! > clear             clear the alarm
//! > heartbeat off     stop answering the heartbeat (on: answer again)
//! > handshake off     ignore the hand-over strobe (on: answer again)
//! > force             force-complete the task under way (state 30)
//! > drop              close the connection once (UDP: lose one request)
//! > link off          ignore every request (on: answer again)
//! > status            action state, task, alarm, load, positions
//! > put 1 4 2 1       a load into row 1, bay 4, level 2, near (starts tracking the inventory)
//! > take 1 4 2 1      the load out of that cell
//! > inventory         the occupied cells
//! > stats             cycles, busy time, distances, business alarms
//! ```
//!
//! The commands are the simulator's own ([`CraneSim::command`]); this reads them and
//! prints the answers, and raises the alarms scheduled at start.

use std::sync::Arc;
use std::time::Duration;

use tokio::io::{AsyncBufReadExt, BufReader};

use crate::protocols::faults::Faults;
use crate::sim::crane::{CraneSim, CraneSimOptions};

/// What the crane is, where it listens, and what happens to it on its own.
#[derive(Clone, Debug)]
pub struct CraneOptions {
    /// Address to listen on.
    pub listen: String,
    /// The simulated crane.
    pub sim: CraneSimOptions,
    /// Link faults.
    pub faults: Faults,
    /// Alarms to raise, each this long after start.
    pub alarms: Vec<(u16, Duration)>,
}

/// Runs the crane until Ctrl-C or the end of stdin.
pub async fn run(options: CraneOptions) -> anyhow::Result<()> {
    let CraneOptions { listen, sim, faults, alarms } = options;
    let (transport, motion, time_scale) = (sim.transport, sim.motion, sim.time_scale);
    let sim = Arc::new(CraneSim::start(&listen, sim).await?);
    sim.set_faults(faults);
    println!("crane simulator on {transport:?} {} (commands on stdin)", sim.local_addr());
    if let Some(m) = motion {
        println!("motion model {m:?}, time scale {time_scale}");
    }
    for (code, after) in alarms {
        let sim = sim.clone();
        tokio::spawn(async move {
            tokio::time::sleep(after).await;
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
