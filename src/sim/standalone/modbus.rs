//! `rackd sim modbus`: a Modbus server whose bank covers all four tables (addresses
//! 0..65535), for commissioning tools and manual tests, optionally prepared with a preset
//! and driven through a control surface ([`Bench`]).

use std::sync::Arc;

use anyhow::Context;

use super::{Bench, Running};
use crate::protocols::Protocol;
use crate::protocols::modbus::server::{ModbusServer, ServerHandle, ServerOptions};
use crate::protocols::serial::SerialSettings;
use crate::sim::memory::ModbusMemory;

/// Where the simulator listens.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Transport {
    /// Modbus UDP.
    Udp,
    /// Modbus TCP.
    Tcp,
    /// RTU frames over raw TCP.
    RtuOverTcp,
    /// RTU on a serial port.
    Rtu,
}

/// What the simulator is and where it listens.
#[derive(Clone, Debug)]
pub struct ModbusOptions {
    /// `HOST:PORT`, or a serial device for [`Transport::Rtu`].
    pub listen: String,
    /// The transport.
    pub transport: Transport,
    /// Serial settings for [`Transport::Rtu`].
    pub serial: SerialSettings,
    /// How the server presents itself: unit, quirks, faults (a preset's `identity`
    /// replaces its identification objects).
    pub server: ServerOptions,
    /// Preset and control surface.
    pub bench: Bench,
}

/// Loads the preset and starts serving.
pub async fn start(options: &ModbusOptions) -> anyhow::Result<Running<ServerHandle>> {
    let memory = ModbusMemory::default();
    let read_only = options.bench.load(Protocol::ModbusTcp, &memory)?;
    let server_options = match options.bench.identity()?.map(|i| i.modbus()).transpose()?.flatten() {
        Some(objects) => ServerOptions { identification: Some(objects), ..options.server.clone() },
        None => options.server.clone(),
    };
    let server = ModbusServer::new(Arc::new(memory.clone()), server_options);
    let listen = options.listen.as_str();
    let handle = match options.transport {
        Transport::Udp => server.serve_udp(listen).await,
        Transport::Tcp => server.serve_tcp(listen).await,
        Transport::RtuOverTcp => server.serve_rtu_over_tcp(listen).await,
        Transport::Rtu => {
            options.serial.open(listen).map(|port| server.serve_rtu_stream(port, options.serial.baud))
        }
    }
    .with_context(|| format!("cannot listen on {listen}"))?;
    let control = options
        .bench
        .start_control(Protocol::ModbusTcp, Arc::new(memory), handle.faults(), read_only)
        .await?;
    Ok(Running { server: handle, control })
}

/// Runs the simulator until Ctrl-C.
pub async fn run(options: ModbusOptions) -> anyhow::Result<()> {
    let Running { server, control } = start(&options).await?;
    let at = server.local_addr().map_or(options.listen.clone(), |a| a.to_string());
    eprintln!(
        "modbus simulator ({:?}) serving unit {} on {at}; Ctrl-C to stop",
        options.transport, options.server.unit
    );
    tokio::signal::ctrl_c().await.context("waiting for Ctrl-C")?;
    drop(control);
    server.shutdown().await;
    Ok(())
}
