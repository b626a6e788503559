//! `rackd sim mewtocol` and `rackd sim ppi`: a simulated Panasonic or S7-200 PLC on TCP
//! (as behind a serial-to-Ethernet gateway) or on a serial port, with optional faults, a
//! preset and a control surface ([`Bench`]).

use std::sync::Arc;

use super::{Bench, Running};
use crate::protocols::faults::{Faults, SharedFaults};
use crate::protocols::serial::SerialSettings;
use crate::protocols::transport::StreamServer;
use crate::protocols::{Protocol, mewtocol, ppi};
use crate::sim::memory::{MewtocolMemory, PpiMemory};

/// What the simulated PLC is and where it listens.
#[derive(Clone, Debug)]
pub struct LineOptions {
    /// `HOST:PORT` to listen on (TCP), or a serial device such as /dev/ttyUSB0.
    pub listen: String,
    /// Serial settings on a serial device [default: the protocol's].
    pub serial: Option<SerialSettings>,
    /// MEWTOCOL station (1..=99; the global station EE is answered too) or PPI address
    /// (1..=126).
    pub station: u8,
    /// Link faults.
    pub faults: Faults,
    /// Preset and control surface.
    pub bench: Bench,
}

impl LineOptions {
    fn is_tcp(&self) -> bool {
        !self.listen.starts_with('/') && self.listen.contains(':')
    }
}

/// Loads the preset and starts the MEWTOCOL simulator.
pub async fn start_mewtocol(options: &LineOptions) -> anyhow::Result<Running<StreamServer>> {
    let bank = mewtocol::Bank::default().shared();
    let memory = MewtocolMemory::new(bank.clone());
    options.bench.no_identity(Protocol::Mewtocol)?;
    let read_only = options.bench.load(Protocol::Mewtocol, &memory)?;
    let mut state = mewtocol::ServerState::new(bank).with_handler(memory.handler());
    state.faults = SharedFaults::new(options.faults.clone());
    state.station = options.station;
    let faults = state.faults.clone();
    let server = if options.is_tcp() {
        mewtocol::server::serve_tcp(&options.listen, state).await?
    } else {
        let default = mewtocol::MewtocolConfig::new(mewtocol::MewtocolTransport::Serial, "").serial;
        let port = options.serial.unwrap_or(default).open(&options.listen)?;
        mewtocol::server::serve_stream(port, state)
    };
    let control =
        options.bench.start_control(Protocol::Mewtocol, Arc::new(memory), faults, read_only).await?;
    Ok(Running { server, control })
}

/// Loads the preset and starts the PPI simulator.
pub async fn start_ppi(options: &LineOptions) -> anyhow::Result<Running<StreamServer>> {
    let bank = ppi::Bank::default().shared();
    let memory = PpiMemory::new(bank.clone());
    options.bench.no_identity(Protocol::Ppi)?;
    let read_only = options.bench.load(Protocol::Ppi, &memory)?;
    let mut state = ppi::ServerState::new(bank).with_handler(memory.handler());
    state.faults = SharedFaults::new(options.faults.clone());
    state.address = options.station;
    let faults = state.faults.clone();
    let server = if options.is_tcp() {
        ppi::server::serve_tcp(&options.listen, state).await?
    } else {
        let port = options.serial.unwrap_or_default().open(&options.listen)?;
        ppi::server::serve_stream(port, state)
    };
    let control = options.bench.start_control(Protocol::Ppi, Arc::new(memory), faults, read_only).await?;
    Ok(Running { server, control })
}

/// Runs a started simulator (`name`: MEWTOCOL or PPI) until Ctrl-C.
pub async fn run(running: Running<StreamServer>, name: &str, listen: &str) -> anyhow::Result<()> {
    let Running { server, control } = running;
    let at = server.local_addr().map_or_else(|| listen.to_owned(), |a| a.to_string());
    eprintln!("{name} simulator on {at}; Ctrl-C to stop");
    tokio::signal::ctrl_c().await?;
    drop(control);
    server.shutdown().await;
    Ok(())
}
