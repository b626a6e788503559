//! `rackd sim mc3e`: a standalone simulated MC PLC answering 3E and 4E frames on one port,
//! serving every device (D, W, R, ZR, M, X, Y, B, L, SM, SD, F, V, SB, SW and the timers and
//! counters at a Q-series CPU's default sizes), with optional faults, a configurable answer
//! to "read CPU model name", a preset and a control surface ([`PresetArgs`]).

use std::net::SocketAddr;
use std::sync::Arc;

use super::sim_bench::PresetArgs;
use super::sim_control::ControlServer;
use super::sim_faults::FaultArgs;
use crate::protocols::Protocol;
use crate::protocols::faults::SharedFaults;
use crate::protocols::mc3e::{Bank, EndCode, Mc3eServer, ServerState, TypeName};
use crate::sim::memory::Mc3eMemory;

/// Transport of the simulated PLC.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum SimTransport {
    /// TCP.
    Tcp,
    /// UDP.
    Udp,
}

/// `rackd sim mc3e` options.
#[derive(clap::Args, Clone, Debug)]
pub struct SimMc3eArgs {
    /// Address to listen on.
    #[arg(long, default_value = "127.0.0.1:5000")]
    pub listen: SocketAddr,
    /// TCP or UDP.
    #[arg(long, value_enum, default_value_t = SimTransport::Tcp)]
    pub transport: SimTransport,
    /// Link faults.
    #[command(flatten)]
    pub faults: FaultArgs,
    /// The answer to "read CPU model name" (command 0101).
    #[command(flatten)]
    pub cpu: CpuArgs,
    /// Preset and control surface.
    #[command(flatten)]
    pub bench: PresetArgs,
}

/// What the simulated CPU says it is.
#[derive(clap::Args, Clone, Debug, PartialEq)]
pub struct CpuArgs {
    /// Model name answered to "read CPU model name" (up to 16 ASCII characters).
    #[arg(long = "cpu-model", default_value = "Q03UDVCPU")]
    pub model: String,
    /// Model code answered with it, in hexadecimal as the manual writes it (0366 = Q03UDVCPU).
    #[arg(long = "cpu-code", default_value = "0366", value_parser = parse_code)]
    pub code: u16,
}

impl Default for CpuArgs {
    /// A Q03UDVCPU, model code 0366.
    fn default() -> Self {
        let TypeName { model, code } = TypeName::default();
        CpuArgs { model, code }
    }
}

fn parse_code(text: &str) -> Result<u16, String> {
    let hex = text.trim().trim_start_matches("0x").trim_start_matches("0X");
    u16::from_str_radix(hex, 16)
        .map_err(|_| format!("bad model code {text:?}: expected 4 hex digits such as 0366"))
}

/// A running simulated PLC and its control surface, if asked for.
pub struct Running {
    /// The MC server.
    pub server: Mc3eServer,
    /// The control surface.
    pub control: Option<ControlServer>,
}

/// Loads the preset, starts the simulated PLC described by `args` and returns it running.
pub async fn start(args: &SimMc3eArgs) -> anyhow::Result<Running> {
    let bank = Bank::default().shared();
    let memory = Mc3eMemory::new(bank.clone());
    let read_only = args.bench.load(Protocol::Mc3e, &memory)?;
    let faults = SharedFaults::new(args.faults.faults::<EndCode>()?);
    let Some(type_name) = TypeName::new(&args.cpu.model, args.cpu.code) else {
        anyhow::bail!("bad --cpu-model {:?}: up to 16 printable ASCII characters", args.cpu.model);
    };
    let type_name = match args.bench.identity()? {
        Some(identity) => identity.mc3e(type_name)?,
        None => type_name,
    };
    let state = ServerState::new(bank).with_faults(faults.clone()).with_type_name(type_name);
    let server = match args.transport {
        SimTransport::Tcp => Mc3eServer::bind_tcp(args.listen, state).await?,
        SimTransport::Udp => Mc3eServer::bind_udp(args.listen, state).await?,
    };
    let control = args.bench.start_control(Protocol::Mc3e, Arc::new(memory), faults, read_only).await?;
    Ok(Running { server, control })
}

/// Runs the simulated PLC until Ctrl-C.
pub async fn run(args: SimMc3eArgs) -> anyhow::Result<()> {
    let Running { server, control } = start(&args).await?;
    tracing::info!(address = %server.local_addr(), transport = ?args.transport, "MC 3E simulator listening");
    eprintln!("MC 3E simulator ({:?}) on {}; Ctrl-C to stop", args.transport, server.local_addr());
    tokio::signal::ctrl_c().await?;
    drop(control);
    server.shutdown().await;
    Ok(())
}
