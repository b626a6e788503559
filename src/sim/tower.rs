//! A simulated light tower and conveyor station on a Modbus TCP register bank, for the demo
//! and for trying a tags device by hand.
//!
//! Coils 0..=3 are the red, amber and green lamps and the buzzer; discrete input 0 is a
//! box-present sensor that a simulated box sets and clears every `box_period`; holding
//! registers 100..=101 hold the conveyor speed (f32, high word first) and bit 0 of register
//! 102 its running flag. [`TAGS`] maps them to tag names.

use std::net::SocketAddr;
use std::time::Duration;

use tokio::task::JoinHandle;

use crate::protocols::modbus::server::{Bank, ModbusServer, ServerHandle, ServerOptions};

/// The `[devices.tags]` table of a tags device on this tower.
pub const TAGS: &str = r#"
"tower.red" = "0x0"
"tower.amber" = "0x1"
"tower.green" = "0x2"
"tower.buzzer" = "0x3"
"station1.box_present" = "1x0"
"conveyor.speed" = { address = "4x100", type = "f32", min = 0, max = 2.5 }
"conveyor.running" = "4x102.0"
"#;

/// A running light tower.
pub struct TowerSim {
    bank: Bank,
    server: ServerHandle,
    boxes: Option<JoinHandle<()>>,
}

impl TowerSim {
    /// Serves Modbus TCP (unit 1) on `address`; with `box_period`, a box arrives at and
    /// leaves the station sensor at that period.
    pub async fn start(address: &str, box_period: Option<Duration>) -> std::io::Result<TowerSim> {
        let bank = Bank::new();
        let server = ModbusServer::new(std::sync::Arc::new(bank.clone()), ServerOptions::default())
            .serve_tcp(address)
            .await?;
        let boxes = box_period.map(|period| {
            let bank = bank.clone();
            tokio::spawn(async move {
                let mut tick = tokio::time::interval(period);
                tick.tick().await;
                loop {
                    tick.tick().await;
                    let mut b = bank.lock();
                    b.discrete_inputs[0] = !b.discrete_inputs[0];
                }
            })
        });
        Ok(TowerSim { bank, server, boxes })
    }

    /// The address served.
    pub fn local_addr(&self) -> SocketAddr {
        self.server.local_addr().expect("a TCP server has an address")
    }

    /// The register bank, to look at or change what rackd sees.
    pub fn bank(&self) -> &Bank {
        &self.bank
    }
}

impl Drop for TowerSim {
    fn drop(&mut self) {
        if let Some(task) = &self.boxes {
            task.abort();
        }
    }
}
