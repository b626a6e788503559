//! `rackd sim modbus`: a standalone Modbus server whose bank covers all four tables
//! (addresses 0..65535), for commissioning tools and manual tests.

use std::sync::Arc;

use anyhow::Context;

use super::sim_faults::FaultArgs;
use crate::protocols::modbus::Exception;
use crate::protocols::modbus::server::{Bank, ModbusServer, ServerOptions};
use crate::protocols::serial::SerialSettings;

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
}

/// Runs the simulator until Ctrl-C.
pub async fn run(args: SimModbusArgs) -> anyhow::Result<()> {
    let rtu = matches!(args.transport, SimTransport::Rtu | SimTransport::RtuOverTcp);
    if rtu && !(1..=247).contains(&args.unit) {
        anyhow::bail!("--unit {}: an RTU station is 1..=247 (0 is the broadcast address)", args.unit);
    }
    let faults = args.faults.faults::<Exception>()?;
    let options = ServerOptions {
        unit: args.unit,
        length0: args.quirk.contains(&SimQuirk::Length0),
        zero_transaction_id: args.quirk.contains(&SimQuirk::ZeroTid),
        faults,
        ..ServerOptions::default()
    };
    let server = ModbusServer::new(Arc::new(Bank::new()), options);
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
    let at = handle.local_addr().map_or(listen.to_string(), |a| a.to_string());
    eprintln!("modbus simulator ({:?}) serving unit {} on {at}; Ctrl-C to stop", args.transport, args.unit);
    tokio::signal::ctrl_c().await.context("waiting for Ctrl-C")?;
    handle.shutdown().await;
    Ok(())
}
