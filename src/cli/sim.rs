//! `rackd sim <machine>`: one simulator alone, for commissioning and tests.

use std::time::Duration;

use crate::protocols::modbus::server::Faults;
use crate::sim::shelf::{ShelfSim, ShelfSimOptions};

/// The simulators.
#[derive(clap::Subcommand, Debug)]
pub enum SimCommand {
    /// A Modbus server with a full register bank (all four tables, 0..65535).
    Modbus(super::sim_modbus::SimModbusArgs),
    /// The shelf storage PLC: task slots over Modbus UDP, answering with MBAP length 0.
    Shelf(SimShelfArgs),
    /// A Mitsubishi MC protocol 3E (binary) server over the whole device range.
    Mc3e(super::sim_mc3e::SimMc3eArgs),
    /// A stacker crane with the MC 3E register interface (D0..D39 / D200..D239). Reads
    /// commands on stdin: `alarm CODE`, `clear`, `heartbeat on|off`, `handshake on|off`, `force`, `drop`,
    /// `link on|off`, `status`.
    Crane(super::sim_crane::SimCraneArgs),
    /// A Panasonic PLC answering MEWTOCOL-COM (DT, X, Y, R, L, T, C) on TCP or a serial port.
    Mewtocol(super::sim_line::SimLineArgs),
    /// A Siemens S7-200 answering PPI (V, I, Q, M, SM, S, AI, AQ, T, C) on TCP or a serial port.
    Ppi(super::sim_line::SimLineArgs),
}

/// Options of `rackd sim shelf`.
#[derive(clap::Args, Debug)]
pub struct SimShelfArgs {
    /// UDP address to answer on.
    #[arg(long, default_value = "127.0.0.1:1502")]
    pub listen: String,
    /// Number of task slots.
    #[arg(long, default_value_t = 60)]
    pub slots: u16,
    /// Holding register of slot 1's task id.
    #[arg(long, default_value_t = 4000)]
    pub base: u16,
    /// Registers from one slot to the next.
    #[arg(long, default_value_t = 100)]
    pub stride: u16,
    /// Modbus unit id.
    #[arg(long, default_value_t = 1)]
    pub unit: u8,
    /// Milliseconds each task takes.
    #[arg(long, default_value_t = 500)]
    pub task_ms: u64,
    /// Fraction (0..1) of datagrams ignored.
    #[arg(long, default_value_t = 0.0)]
    pub drop: f64,
    /// Milliseconds before each reply.
    #[arg(long, default_value_t = 0)]
    pub delay_ms: u64,
    /// Fraction (0..1) of tasks failing with kind 1 (PLC fault).
    #[arg(long, default_value_t = 0.0)]
    pub fail: f64,
}

impl SimShelfArgs {
    /// The simulator options these arguments select.
    pub fn options(&self) -> anyhow::Result<ShelfSimOptions> {
        for (name, p) in [("--drop", self.drop), ("--fail", self.fail)] {
            anyhow::ensure!((0.0..=1.0).contains(&p), "{name} must be between 0 and 1, got {p}");
        }
        Ok(ShelfSimOptions {
            slots: self.slots,
            base: self.base,
            stride: self.stride,
            unit: self.unit,
            task_time: Duration::from_millis(self.task_ms),
            fail_rate: self.fail,
            faults: Faults {
                drop_rate: self.drop,
                delay: Duration::from_millis(self.delay_ms),
                ..Faults::default()
            },
        })
    }
}

/// Runs a simulator until Ctrl-C.
pub async fn run(cmd: SimCommand) -> anyhow::Result<()> {
    match cmd {
        SimCommand::Modbus(args) => super::sim_modbus::run(args).await,
        SimCommand::Mc3e(args) => super::sim_mc3e::run(args).await,
        SimCommand::Crane(args) => super::sim_crane::run(args).await,
        SimCommand::Mewtocol(args) => {
            let server = super::sim_line::start_mewtocol(&args).await?;
            super::sim_line::run(server, "MEWTOCOL", &args).await
        }
        SimCommand::Ppi(args) => {
            let server = super::sim_line::start_ppi(&args).await?;
            super::sim_line::run(server, "PPI", &args).await
        }
        SimCommand::Shelf(args) => {
            let sim = ShelfSim::start(&args.listen, args.options()?).await?;
            println!(
                "shelf PLC simulator on udp://{} ({} slots from MW{})",
                sim.local_addr(),
                args.slots,
                args.base
            );
            tokio::signal::ctrl_c().await?;
            let (done, failed) = sim.finished();
            println!("tasks finished {done}, failed {failed}; busy-slot violations {}", sim.violations());
            sim.shutdown().await;
            Ok(())
        }
    }
}
