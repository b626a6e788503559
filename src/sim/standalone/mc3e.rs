//! `rackd sim mc3e`: a simulated MC PLC answering 3E and 4E frames on one port, serving
//! every device (D, W, R, ZR, M, X, Y, B, L, SM, SD, F, V, SB, SW and the timers and
//! counters at a Q-series CPU's default sizes), with optional faults, a configurable answer
//! to "read CPU model name", a preset and a control surface ([`Bench`]).

use std::net::SocketAddr;
use std::sync::Arc;

use super::{Bench, Running};
use crate::protocols::Protocol;
use crate::protocols::faults::{Faults, SharedFaults};
use crate::protocols::mc3e::{Bank, Mc3eServer, ServerState, TransportKind, TypeName};
use crate::sim::memory::Mc3eMemory;

/// What the simulated PLC is and where it listens.
#[derive(Clone, Debug)]
pub struct Mc3eOptions {
    /// Address to listen on.
    pub listen: SocketAddr,
    /// TCP or UDP.
    pub transport: TransportKind,
    /// Link faults.
    pub faults: Faults,
    /// The answer to "read CPU model name" (command 0101), unless the preset's `identity`
    /// says otherwise.
    pub type_name: TypeName,
    /// Preset and control surface.
    pub bench: Bench,
}

/// Loads the preset, starts the simulated PLC and returns it running.
pub async fn start(options: &Mc3eOptions) -> anyhow::Result<Running<Mc3eServer>> {
    let bank = Bank::default().shared();
    let memory = Mc3eMemory::new(bank.clone());
    let read_only = options.bench.load(Protocol::Mc3e, &memory)?;
    let faults = SharedFaults::new(options.faults.clone());
    let type_name = match options.bench.identity()? {
        Some(identity) => identity.mc3e(options.type_name.clone())?,
        None => options.type_name.clone(),
    };
    let state = ServerState::new(bank).with_faults(faults.clone()).with_type_name(type_name);
    let server = match options.transport {
        TransportKind::Tcp => Mc3eServer::bind_tcp(options.listen, state).await?,
        TransportKind::Udp => Mc3eServer::bind_udp(options.listen, state).await?,
    };
    let control = options.bench.start_control(Protocol::Mc3e, Arc::new(memory), faults, read_only).await?;
    Ok(Running { server, control })
}

/// Runs the simulated PLC until Ctrl-C.
pub async fn run(options: Mc3eOptions) -> anyhow::Result<()> {
    let Running { server, control } = start(&options).await?;
    tracing::info!(address = %server.local_addr(), transport = ?options.transport, "MC 3E simulator listening");
    eprintln!("MC 3E simulator ({:?}) on {}; Ctrl-C to stop", options.transport, server.local_addr());
    tokio::signal::ctrl_c().await?;
    drop(control);
    server.shutdown().await;
    Ok(())
}
