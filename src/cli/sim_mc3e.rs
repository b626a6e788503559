//! `rackd sim mc3e`: a standalone simulated MC 3E PLC serving every device (D, W, R, ZR, M,
//! X, Y, B, L at a Q-series CPU's default sizes), with optional faults.

use std::net::SocketAddr;
use std::time::Duration;

use crate::protocols::mc3e::{Bank, Faults, Mc3eServer, ServerState};

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
    /// Fraction of requests (0.0..=1.0) left unanswered at random.
    #[arg(long, default_value_t = 0.0)]
    pub drop: f64,
    /// Delay before every reply, in milliseconds.
    #[arg(long, default_value_t = 0)]
    pub delay_ms: u64,
    /// Answer every request with this end code (hexadecimal, e.g. C051).
    #[arg(long, value_parser = end_code)]
    pub end_code: Option<u16>,
}

/// Starts the simulated PLC described by `args` and returns it running.
pub async fn start(args: &SimMc3eArgs) -> anyhow::Result<Mc3eServer> {
    anyhow::ensure!((0.0..=1.0).contains(&args.drop), "--drop must be between 0 and 1");
    let faults = Faults {
        drop_ratio: args.drop,
        delay: Duration::from_millis(args.delay_ms),
        end_code: args.end_code,
        ..Faults::default()
    };
    let state = ServerState::new(Bank::default().shared()).with_faults(faults.shared());
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

fn end_code(text: &str) -> Result<u16, String> {
    let code =
        u16::from_str_radix(text.trim_start_matches("0x"), 16).map_err(|e| format!("{text:?}: {e}"))?;
    if code == 0 { Err("end code 0 means success".into()) } else { Ok(code) }
}
