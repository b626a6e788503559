//! `rackd sim mc3e`: a standalone simulated MC 3E PLC serving every device (D, W, R, ZR, M,
//! X, Y, B, L at a Q-series CPU's default sizes), with optional faults.

use std::net::SocketAddr;

use super::sim_faults::FaultArgs;
use crate::protocols::faults::SharedFaults;
use crate::protocols::mc3e::{Bank, EndCode, Mc3eServer, ServerState};

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
}

/// Starts the simulated PLC described by `args` and returns it running.
pub async fn start(args: &SimMc3eArgs) -> anyhow::Result<Mc3eServer> {
    let faults = SharedFaults::new(args.faults.faults::<EndCode>()?);
    let state = ServerState::new(Bank::default().shared()).with_faults(faults);
    let server = match args.transport {
        SimTransport::Tcp => Mc3eServer::bind_tcp(args.listen, state).await?,
        SimTransport::Udp => Mc3eServer::bind_udp(args.listen, state).await?,
    };
    Ok(server)
}

/// Runs the simulated PLC until Ctrl-C.
pub async fn run(args: SimMc3eArgs) -> anyhow::Result<()> {
    let server = start(&args).await?;
    tracing::info!(address = %server.local_addr(), transport = ?args.transport, "MC 3E simulator listening");
    tokio::signal::ctrl_c().await?;
    server.shutdown().await;
    Ok(())
}
