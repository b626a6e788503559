//! `rackd sim mewtocol` and `rackd sim ppi`: a simulated Panasonic or S7-200 PLC on TCP
//! (as behind a serial-to-Ethernet gateway) or on a serial port, with optional faults.

use std::time::Duration;

use crate::protocols::line::{Faults, LineServer, SharedFaults};
use crate::protocols::serial::SerialSettings;
use crate::protocols::{mewtocol, ppi};

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
    /// Station number (MEWTOCOL, default 1) or PPI address (default 2).
    #[arg(long)]
    pub station: Option<u8>,
    /// Fraction (0..1) of requests left unanswered.
    #[arg(long, default_value_t = 0.0)]
    pub drop: f64,
    /// Milliseconds before each reply.
    #[arg(long, default_value_t = 0)]
    pub delay_ms: u64,
    /// Fraction (0..1) of replies preceded by random bytes.
    #[arg(long, default_value_t = 0.0)]
    pub garbage: f64,
    /// Answer every request with this error code (MEWTOCOL: decimal, e.g. 63; PPI: an item
    /// return code below 256 or class x 256 + code, e.g. 34048 for 85 00).
    #[arg(long)]
    pub error: Option<u16>,
}

impl SimLineArgs {
    fn faults(&self) -> anyhow::Result<SharedFaults> {
        for (name, p) in [("--drop", self.drop), ("--garbage", self.garbage)] {
            anyhow::ensure!((0.0..=1.0).contains(&p), "{name} must be between 0 and 1, got {p}");
        }
        Ok(Faults {
            drop_ratio: self.drop,
            garbage_ratio: self.garbage,
            delay: Duration::from_millis(self.delay_ms),
            error: self.error,
            ..Faults::default()
        }
        .shared())
    }

    fn is_tcp(&self) -> bool {
        !self.listen.starts_with('/') && self.listen.contains(':')
    }
}

/// Starts the MEWTOCOL simulator.
pub async fn start_mewtocol(args: &SimLineArgs) -> anyhow::Result<LineServer> {
    let mut state = mewtocol::ServerState::new(mewtocol::Bank::default().shared());
    state.faults = args.faults()?;
    state.station = args.station.unwrap_or(1);
    anyhow::ensure!((1..=99).contains(&state.station), "--station must be 1..=99");
    if args.is_tcp() {
        return Ok(mewtocol::server::serve_tcp(&args.listen, state).await?);
    }
    let default = mewtocol::MewtocolConfig::new(mewtocol::MewtocolTransport::Serial, "").serial;
    let port = args.serial.unwrap_or(default).open(&args.listen)?;
    Ok(mewtocol::server::serve_stream(port, state))
}

/// Starts the PPI simulator.
pub async fn start_ppi(args: &SimLineArgs) -> anyhow::Result<LineServer> {
    let mut state = ppi::ServerState::new(ppi::Bank::default().shared());
    state.faults = args.faults()?;
    state.address = args.station.unwrap_or(2);
    anyhow::ensure!((1..=126).contains(&state.address), "--station must be 1..=126");
    if args.is_tcp() {
        return Ok(ppi::server::serve_tcp(&args.listen, state).await?);
    }
    let port = args.serial.unwrap_or_default().open(&args.listen)?;
    Ok(ppi::server::serve_stream(port, state))
}

/// Runs a simulator until Ctrl-C.
pub async fn run(server: LineServer, name: &str, args: &SimLineArgs) -> anyhow::Result<()> {
    let at = server.local_addr().map_or_else(|| args.listen.clone(), |a| a.to_string());
    eprintln!("{name} simulator on {at}; Ctrl-C to stop");
    tokio::signal::ctrl_c().await?;
    server.shutdown().await;
    Ok(())
}
