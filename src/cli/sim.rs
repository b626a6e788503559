//! `rackd sim <machine>`: one simulator alone, for commissioning and tests.

use std::time::Duration;

use anyhow::Context;

use crate::protocols::Protocol;
use crate::protocols::serial::SerialSettings;
use crate::sim::shelf::{LinkFaults, ShelfProtocol, ShelfSim, ShelfSimOptions};

/// The simulators.
#[derive(clap::Subcommand, Debug)]
pub enum SimCommand {
    /// A Modbus server with a full register bank (all four tables, 0..65535).
    Modbus(super::sim_modbus::SimModbusArgs),
    /// The shelf storage PLC: task slots over Modbus UDP (answering with MBAP length 0),
    /// Modbus TCP, Modbus RTU as an S7-1200 (serial or over TCP), PPI or MEWTOCOL.
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
    /// Protocol served: modbus-udp, modbus-tcp, modbus-rtu, modbus-rtu-tcp, ppi, ppi-tcp,
    /// mewtocol or mewtocol-tcp.
    #[arg(long, value_enum, default_value_t = Protocol::ModbusUdp)]
    pub protocol: Protocol,
    /// Address to answer on (UDP / TCP), or the serial device to open (modbus-rtu, ppi,
    /// mewtocol) [default: 127.0.0.1:1502 for network protocols].
    #[arg(long)]
    pub listen: Option<String>,
    /// Number of task slots.
    #[arg(long, default_value_t = 60)]
    pub slots: u16,
    /// Slot 1's task id in the protocol's notation (a bare number is a Modbus holding
    /// register) [default: 4x4000 Modbus UDP/TCP, 4x0 Modbus RTU (S7-1200), VW1000 PPI,
    /// DT4000 MEWTOCOL].
    #[arg(long)]
    pub base: Option<String>,
    /// Words from one slot to the next [default: 50 for PPI, else 100].
    #[arg(long)]
    pub stride: Option<u16>,
    /// Modbus unit, PPI address or MEWTOCOL station [default: 2 for PPI, else 1].
    #[arg(long)]
    pub unit: Option<u8>,
    /// Serial settings when opening a serial device [default: 9600,8E1; 9600,8O1 for
    /// MEWTOCOL].
    #[arg(long)]
    pub serial: Option<SerialSettings>,
    /// Milliseconds each task takes.
    #[arg(long, default_value_t = 500)]
    pub task_ms: u64,
    /// Fraction (0..1) of requests left unanswered.
    #[arg(long, default_value_t = 0.0)]
    pub drop: f64,
    /// Milliseconds before each reply.
    #[arg(long, default_value_t = 0)]
    pub delay_ms: u64,
    /// Fraction (0..1) of replies preceded by random bytes.
    #[arg(long, default_value_t = 0.0)]
    pub garbage: f64,
    /// Fraction (0..1) of tasks failing with kind 1 (PLC fault).
    #[arg(long, default_value_t = 0.0)]
    pub fail: f64,
}

impl SimShelfArgs {
    /// The simulator options these arguments select.
    pub fn options(&self) -> anyhow::Result<ShelfSimOptions> {
        for (name, p) in [("--drop", self.drop), ("--garbage", self.garbage), ("--fail", self.fail)] {
            anyhow::ensure!((0.0..=1.0).contains(&p), "{name} must be between 0 and 1, got {p}");
        }
        Ok(ShelfSimOptions {
            protocol: ShelfProtocol::try_from(self.protocol)?,
            slots: self.slots,
            base: self.base.clone(),
            stride: self.stride,
            unit: self.unit,
            serial: self.serial,
            task_time: Duration::from_millis(self.task_ms),
            fail_rate: self.fail,
            faults: LinkFaults {
                drop_rate: self.drop,
                delay: Duration::from_millis(self.delay_ms),
                garbage_rate: self.garbage,
            },
        })
    }

    /// Where to serve: `--listen`, or for network protocols 127.0.0.1:1502.
    pub fn listen(&self) -> anyhow::Result<String> {
        match (&self.listen, self.protocol.is_serial()) {
            (Some(at), _) => Ok(at.clone()),
            (None, false) => Ok("127.0.0.1:1502".into()),
            (None, true) => {
                anyhow::bail!("{} needs --listen with a serial device, e.g. /dev/ttyUSB0", self.protocol)
            }
        }
    }
}

/// Runs the shelf simulator until Ctrl-C.
async fn run_shelf(args: SimShelfArgs) -> anyhow::Result<()> {
    let listen = args.listen()?;
    let sim = ShelfSim::start(&listen, args.options()?)
        .await
        .with_context(|| format!("starting the {} shelf simulator on {listen}", args.protocol))?;
    let at = sim.local_addr().map_or(listen, |a| a.to_string());
    println!(
        "shelf PLC simulator ({}) on {at}: {} slots from {}, {} words apart, unit {}",
        sim.protocol(),
        args.slots,
        sim.base(),
        sim.stride(),
        sim.unit()
    );
    tokio::signal::ctrl_c().await?;
    let (done, failed) = sim.finished();
    println!("tasks finished {done}, failed {failed}; busy-slot violations {}", sim.violations());
    sim.shutdown().await;
    Ok(())
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
        SimCommand::Shelf(args) => run_shelf(args).await,
    }
}
