//! `rackd sim crane`: the arguments of the stacker crane simulator
//! ([`crate::sim::standalone::crane`], which lists the commands it reads on stdin).
//!
//! ```text
//! rackd sim crane --listen 127.0.0.1:8000 --transport udp --step-ms 300 --alarm 7069@12
//! ```
//!
//! `--motion` (or any of its figures, e.g. `--travel-speed 4`) times the action states by
//! the motion model instead of `--step-ms`; `--time-scale 100` runs it 100 times faster
//! than real time; `--inventory FILE` (a JSON array of `[row, bay, level, side]`) gives the
//! crane an inventory, so it raises 7069/7070 and 7091..7098 when asked the impossible.

use std::time::Duration;

use super::faults::FaultArgs;
use super::mc3e::SimTransport;
use crate::protocols::mc3e::EndCode;
use crate::sim::crane::CraneSimOptions;
use crate::sim::crane::inventory::read_cells;
use crate::sim::standalone::crane::CraneOptions;
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

impl SimCraneArgs {
    /// The simulator options these arguments select.
    pub fn options(&self) -> anyhow::Result<CraneOptions> {
        let faults = self.faults.faults::<EndCode>()?;
        let wcs_timeout = (self.watchdog_secs > 0).then(|| Duration::from_secs(self.watchdog_secs));
        let inventory = self.inventory.as_deref().map(read_cells).transpose()?;
        let sim = CraneSimOptions {
            transport: self.transport.kind(),
            step: Duration::from_millis(self.step_ms),
            wcs_timeout,
            motion: self.motion.model(),
            time_scale: self.time_scale,
            inventory,
        };
        let alarms = self.alarm.iter().map(|&(code, secs)| (code, Duration::from_secs(secs))).collect();
        Ok(CraneOptions { listen: self.listen.clone(), sim, faults, alarms })
    }
}
