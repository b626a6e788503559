//! `rackd sim modbus`: a standalone Modbus server whose bank covers all four tables
//! (addresses 0..65535), for commissioning tools and manual tests, optionally prepared
//! with a preset and driven through a control surface ([`PresetArgs`]).

use std::sync::Arc;

use anyhow::Context;

use super::sim_bench::PresetArgs;
use super::sim_control::ControlServer;
use super::sim_faults::FaultArgs;
use crate::protocols::Protocol;
use crate::protocols::modbus::Exception;
use crate::protocols::modbus::server::{ModbusServer, ServerHandle, ServerOptions};
use crate::protocols::serial::SerialSettings;
use crate::sim::memory::ModbusMemory;

/// The transports the simulator can listen on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SimTransport {
    /// Modbus UDP.
    Udp,
    /// Modbus TCP.
    Tcp,
    /// RTU frames over raw TCP.
    RtuOverTcp,
    /// RTU on a serial port (`--listen /dev/ttyX`).
    Rtu,
}

/// Device quirks the simulator can imitate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SimQuirk {
    /// Reply with MBAP length 0, like the shelf PLC.
    Length0,
    /// Reply with transaction id 0 instead of echoing it.
    ZeroTid,
}

/// Arguments of `rackd sim modbus`.
#[derive(Debug, clap::Args)]
pub struct SimModbusArgs {
    /// HOST:PORT to listen on, or a serial device for `--transport rtu`.
    #[arg(long)]
    pub listen: String,
    /// Transport.
    #[arg(long, value_enum, default_value = "udp")]
    pub transport: SimTransport,
    /// Unit id answered. Over TCP and UDP any of 0..=255, and units 0 and 255 are answered
    /// too (they address the device itself); over RTU a station 1..=247.
    #[arg(long, default_value_t = 1)]
    pub unit: u8,
    /// Device quirks to imitate (repeatable).
    #[arg(long, value_enum)]
    pub quirk: Vec<SimQuirk>,
    /// Serial settings for `--transport rtu`.
    #[arg(long, default_value = "9600,8E1")]
    pub serial: SerialSettings,
    /// Link faults.
    #[command(flatten)]
    pub faults: FaultArgs,
    /// Preset and control surface.
    #[command(flatten)]
    pub bench: PresetArgs,
}

/// A running simulator and its control surface, if asked for.
pub struct Running {
    /// The Modbus server.
    pub server: ServerHandle,
    /// The control surface.
    pub control: Option<ControlServer>,
}

/// Loads the preset and starts serving.
pub async fn start(args: &SimModbusArgs) -> anyhow::Result<Running> {
    let rtu = matches!(args.transport, SimTransport::Rtu | SimTransport::RtuOverTcp);
    if rtu && !(1..=247).contains(&args.unit) {
        anyhow::bail!("--unit {}: an RTU station is 1..=247 (0 is the broadcast address)", args.unit);
    }
    let memory = ModbusMemory::default();
    let read_only = args.bench.load(Protocol::ModbusTcp, &memory)?;
    let faults = args.faults.faults::<Exception>()?;
    let options = ServerOptions {
        unit: args.unit,
        length0: args.quirk.contains(&SimQuirk::Length0),
        zero_transaction_id: args.quirk.contains(&SimQuirk::ZeroTid),
        faults,
        ..ServerOptions::default()
    };
    let options = match args.bench.identity()?.map(|i| i.modbus()).transpose()?.flatten() {
        Some(objects) => ServerOptions { identification: Some(objects), ..options },
        None => options,
    };
    let server = ModbusServer::new(Arc::new(memory.clone()), options);
    let listen = args.listen.as_str();
    let handle = match args.transport {
        SimTransport::Udp => server.serve_udp(listen).await,
        SimTransport::Tcp => server.serve_tcp(listen).await,
        SimTransport::RtuOverTcp => server.serve_rtu_over_tcp(listen).await,
        SimTransport::Rtu => {
            args.serial.open(listen).map(|port| server.serve_rtu_stream(port, args.serial.baud))
        }
    }
    .with_context(|| format!("cannot listen on {listen}"))?;
    let control =
        args.bench.start_control(Protocol::ModbusTcp, Arc::new(memory), handle.faults(), read_only).await?;
    Ok(Running { server: handle, control })
}

/// Runs the simulator until Ctrl-C.
pub async fn run(args: SimModbusArgs) -> anyhow::Result<()> {
    let Running { server, control } = start(&args).await?;
    let at = server.local_addr().map_or(args.listen.clone(), |a| a.to_string());
    eprintln!("modbus simulator ({:?}) serving unit {} on {at}; Ctrl-C to stop", args.transport, args.unit);
    tokio::signal::ctrl_c().await.context("waiting for Ctrl-C")?;
    drop(control);
    server.shutdown().await;
    Ok(())
}
