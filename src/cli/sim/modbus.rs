//! `rackd sim modbus`: the arguments of the Modbus simulator
//! ([`crate::sim::standalone::modbus`]).

use super::bench::PresetArgs;
use super::faults::FaultArgs;
use crate::protocols::modbus::Exception;
use crate::protocols::modbus::server::{ServerHandle, ServerOptions};
use crate::protocols::serial::SerialSettings;
use crate::sim::standalone::Running;
use crate::sim::standalone::modbus::{self as sim, ModbusOptions, Transport};

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

impl SimModbusArgs {
    /// The simulator options these arguments select.
    pub fn options(&self) -> anyhow::Result<ModbusOptions> {
        let rtu = matches!(self.transport, SimTransport::Rtu | SimTransport::RtuOverTcp);
        if rtu && !(1..=247).contains(&self.unit) {
            anyhow::bail!("--unit {}: an RTU station is 1..=247 (0 is the broadcast address)", self.unit);
        }
        let server = ServerOptions {
            unit: self.unit,
            length0: self.quirk.contains(&SimQuirk::Length0),
            zero_transaction_id: self.quirk.contains(&SimQuirk::ZeroTid),
            faults: self.faults.faults::<Exception>()?,
            ..ServerOptions::default()
        };
        let transport = match self.transport {
            SimTransport::Udp => Transport::Udp,
            SimTransport::Tcp => Transport::Tcp,
            SimTransport::RtuOverTcp => Transport::RtuOverTcp,
            SimTransport::Rtu => Transport::Rtu,
        };
        Ok(ModbusOptions {
            listen: self.listen.clone(),
            transport,
            serial: self.serial,
            server,
            bench: self.bench.bench(),
        })
    }
}

/// Loads the preset and starts serving.
pub async fn start(args: &SimModbusArgs) -> anyhow::Result<Running<ServerHandle>> {
    sim::start(&args.options()?).await
}
