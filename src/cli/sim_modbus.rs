//! `rackd sim modbus`: a standalone Modbus server whose bank covers all four tables
//! (addresses 0..65535), for commissioning tools and manual tests.

use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;

use crate::protocols::modbus::Exception;
use crate::protocols::modbus::server::{Bank, Faults, ModbusServer, ServerOptions};
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
    /// Unit id answered.
    #[arg(long, default_value_t = 1)]
    pub unit: u8,
    /// Device quirks to imitate (repeatable).
    #[arg(long, value_enum)]
    pub quirk: Vec<SimQuirk>,
    /// Fraction of requests to ignore (0..1).
    #[arg(long, default_value_t = 0.0)]
    pub drop: f64,
    /// Delay before each reply, in milliseconds.
    #[arg(long, default_value_t = 0)]
    pub delay_ms: u64,
    /// Answer every request with this exception code.
    #[arg(long)]
    pub exception: Option<u8>,
    /// Fraction of replies preceded by garbage bytes (0..1).
    #[arg(long, default_value_t = 0.0)]
    pub garbage: f64,
    /// Serial settings for `--transport rtu`.
    #[arg(long, default_value = "9600,8E1")]
    pub serial: SerialSettings,
}

/// Runs the simulator until Ctrl-C.
pub async fn run(args: SimModbusArgs) -> anyhow::Result<()> {
    if !(0.0..=1.0).contains(&args.drop) || !(0.0..=1.0).contains(&args.garbage) {
        anyhow::bail!("--drop and --garbage are fractions between 0 and 1");
    }
    let faults = Faults {
        drop_rate: args.drop,
        delay: Duration::from_millis(args.delay_ms),
        exception: args.exception.map(Exception),
        garbage_rate: args.garbage,
        ..Faults::default()
    };
    let options = ServerOptions {
        unit: args.unit,
        length0: args.quirk.contains(&SimQuirk::Length0),
        zero_transaction_id: args.quirk.contains(&SimQuirk::ZeroTid),
        faults,
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
