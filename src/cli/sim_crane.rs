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
//! > put 1 4 2 1       a load into row 1, bay 4, level 2, near (starts tracking the inventory)
//! > take 1 4 2 1      the load out of that cell
//! > inventory         the occupied cells
//! > stats             cycles, busy time, distances, business alarms
//! ```
//!
//! `--motion` (or any of its figures, e.g. `--travel-speed 4`) times the action states by
//! the motion model instead of `--step-ms`; `--time-scale 100` runs it 100 times faster
//! than real time; `--inventory FILE` (a JSON array of `[row, bay, level, side]`) gives the
//! crane an inventory, so it raises 7069/7070 and 7091..7098 when asked the impossible.

use std::time::Duration;

use tokio::io::{AsyncBufReadExt, BufReader};

use super::sim_faults::FaultArgs;
use super::sim_mc3e::SimTransport;
use crate::protocols::mc3e::{EndCode, TransportKind};
use crate::sim::crane::inventory::Cell;
use crate::sim::crane::{CraneSim, CraneSimOptions};
use crate::wire::motion::Motion;

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
    /// Simulated seconds per real second (100: a 60 s cycle in 0.6 s).
    #[arg(long, default_value_t = 1.0)]
    pub time_scale: f64,
    /// The crane's inventory at start: a JSON array of [row, bay, level, side].
    #[arg(long, value_name = "FILE")]
    pub inventory: Option<std::path::PathBuf>,
    /// The motion model.
    #[command(flatten)]
    pub motion: MotionArgs,
    /// Link faults.
    #[command(flatten)]
    pub faults: FaultArgs,
}

/// The motion model's options: `--motion` takes the defaults, each figure overrides one
/// (and implies `--motion`).
#[derive(clap::Args, Clone, Debug, Default)]
pub struct MotionArgs {
    /// Time the action states by the motion model (travel, lift, forks) instead of --step-ms.
    #[arg(long)]
    pub motion: bool,
    /// Travel top speed, m/s (default 3).
    #[arg(long)]
    pub travel_speed: Option<f64>,
    /// Travel acceleration, m/s² (default 0.5).
    #[arg(long)]
    pub travel_accel: Option<f64>,
    /// Lift top speed, m/s (default 1).
    #[arg(long)]
    pub lift_speed: Option<f64>,
    /// Lift acceleration, m/s² (default 0.5).
    #[arg(long)]
    pub lift_accel: Option<f64>,
    /// Bay width, m (default 1.4).
    #[arg(long)]
    pub bay_width: Option<f64>,
    /// Level height, m (default 1.5).
    #[arg(long)]
    pub level_height: Option<f64>,
    /// Seconds of a fork cycle at a near position or a station (default 6).
    #[arg(long)]
    pub fork_near: Option<f64>,
    /// Seconds of a fork cycle at a far position (default 9).
    #[arg(long)]
    pub fork_far: Option<f64>,
}

impl MotionArgs {
    /// The model asked for, if any.
    pub fn model(&self) -> Option<Motion> {
        let mut m = Motion::default();
        let figures = [
            (self.travel_speed, &mut m.travel.speed),
            (self.travel_accel, &mut m.travel.accel),
            (self.lift_speed, &mut m.lift.speed),
            (self.lift_accel, &mut m.lift.accel),
            (self.bay_width, &mut m.bay_width),
            (self.level_height, &mut m.level_height),
            (self.fork_near, &mut m.fork_near),
            (self.fork_far, &mut m.fork_far),
        ];
        let mut any = self.motion;
        for (given, figure) in figures {
            if let Some(v) = given {
                *figure = v;
                any = true;
            }
        }
        any.then_some(m)
    }
}

/// Reads an inventory file: a JSON array of [row, bay, level, side].
fn read_inventory(path: &std::path::Path) -> anyhow::Result<Vec<Cell>> {
    use anyhow::Context;
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text)
        .with_context(|| format!("{}: expected a JSON array of [row, bay, level, side]", path.display()))
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
    let inventory = args.inventory.as_deref().map(read_inventory).transpose()?;
    let options = CraneSimOptions {
        transport,
        step: Duration::from_millis(args.step_ms),
        wcs_timeout,
        motion: args.motion.model(),
        time_scale: args.time_scale,
        inventory,
    };
    let sim = std::sync::Arc::new(CraneSim::start(&args.listen, options).await?);
    sim.set_faults(faults);
    println!("crane simulator on {:?} {} (commands on stdin)", args.transport, sim.local_addr());
    if let Some(m) = args.motion.model() {
        println!("motion model {m:?}, time scale {}", args.time_scale);
    }
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
