//! `rackd sim mewtocol` and `rackd sim ppi`: a simulated Panasonic or S7-200 PLC on TCP
//! (as behind a serial-to-Ethernet gateway) or on a serial port, with optional faults, a
//! preset and a control surface ([`PresetArgs`]).

use std::sync::Arc;

use super::sim_bench::PresetArgs;
use super::sim_control::ControlServer;
use super::sim_faults::FaultArgs;
use crate::protocols::faults::SharedFaults;
use crate::protocols::serial::SerialSettings;
use crate::protocols::transport::StreamServer;
use crate::protocols::{Protocol, mewtocol, ppi};
use crate::sim::memory::{MewtocolMemory, PpiMemory};

/// Options shared by both simulators.
#[derive(clap::Args, Clone, Debug)]
pub struct SimLineArgs {
    /// `HOST:PORT` to listen on (TCP), or a serial device such as /dev/ttyUSB0.
    #[arg(long, default_value = "127.0.0.1:9094")]
    pub listen: String,
    /// Serial settings when listening on a serial device [default: 9600,8O1 for MEWTOCOL,
    /// 9600,8E1 for PPI].
    #[arg(long)]
    pub serial: Option<SerialSettings>,
    /// Station number (MEWTOCOL 1..=99, default 1; the global station EE is answered too)
    /// or PPI address (1..=126, default 2).
    #[arg(long)]
    pub station: Option<u8>,
    /// Link faults.
    #[command(flatten)]
    pub faults: FaultArgs,
    /// Preset and control surface.
    #[command(flatten)]
    pub bench: PresetArgs,
}

/// A running simulated PLC and its control surface, if asked for.
pub struct Running {
    /// The server.
    pub server: StreamServer,
    /// The control surface.
    pub control: Option<ControlServer>,
}

impl SimLineArgs {
    fn is_tcp(&self) -> bool {
        !self.listen.starts_with('/') && self.listen.contains(':')
    }
}

/// Loads the preset and starts the MEWTOCOL simulator.
pub async fn start_mewtocol(args: &SimLineArgs) -> anyhow::Result<Running> {
    let bank = mewtocol::Bank::default().shared();
    let memory = MewtocolMemory::new(bank.clone());
    args.bench.no_identity(Protocol::Mewtocol)?;
    let read_only = args.bench.load(Protocol::Mewtocol, &memory)?;
    let mut state = mewtocol::ServerState::new(bank).with_handler(memory.handler());
    state.faults = SharedFaults::new(args.faults.faults::<mewtocol::ErrorCode>()?);
    state.station = args.station.unwrap_or(1);
    anyhow::ensure!((1..=99).contains(&state.station), "--station must be 1..=99");
    let faults = state.faults.clone();
    let server = if args.is_tcp() {
        mewtocol::server::serve_tcp(&args.listen, state).await?
    } else {
        let default = mewtocol::MewtocolConfig::new(mewtocol::MewtocolTransport::Serial, "").serial;
        let port = args.serial.unwrap_or(default).open(&args.listen)?;
        mewtocol::server::serve_stream(port, state)
    };
    let control = args.bench.start_control(Protocol::Mewtocol, Arc::new(memory), faults, read_only).await?;
    Ok(Running { server, control })
}

/// Loads the preset and starts the PPI simulator.
pub async fn start_ppi(args: &SimLineArgs) -> anyhow::Result<Running> {
    let bank = ppi::Bank::default().shared();
    let memory = PpiMemory::new(bank.clone());
    args.bench.no_identity(Protocol::Ppi)?;
    let read_only = args.bench.load(Protocol::Ppi, &memory)?;
    let mut state = ppi::ServerState::new(bank).with_handler(memory.handler());
    state.faults = SharedFaults::new(args.faults.faults::<ppi::ReturnCode>()?);
    state.address = args.station.unwrap_or(2);
    anyhow::ensure!((1..=126).contains(&state.address), "--station must be 1..=126");
    let faults = state.faults.clone();
    let server = if args.is_tcp() {
        ppi::server::serve_tcp(&args.listen, state).await?
    } else {
        let port = args.serial.unwrap_or_default().open(&args.listen)?;
        ppi::server::serve_stream(port, state)
    };
    let control = args.bench.start_control(Protocol::Ppi, Arc::new(memory), faults, read_only).await?;
    Ok(Running { server, control })
}

/// Runs a simulator until Ctrl-C.
pub async fn run(running: Running, name: &str, args: &SimLineArgs) -> anyhow::Result<()> {
    let Running { server, control } = running;
    let at = server.local_addr().map_or_else(|| args.listen.clone(), |a| a.to_string());
    eprintln!("{name} simulator on {at}; Ctrl-C to stop");
    tokio::signal::ctrl_c().await?;
    drop(control);
    server.shutdown().await;
    Ok(())
}
