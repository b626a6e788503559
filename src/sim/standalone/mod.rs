//! The simulators `rackd sim` runs alone, for commissioning and tests, each started from
//! plain options and run until Ctrl-C: a Modbus server over a whole register bank
//! ([`modbus`]), an MC 3E/4E PLC ([`mc3e`]), a MEWTOCOL or PPI PLC on TCP or a serial port
//! ([`line`](mod@line)), the shelf PLC ([`shelf`]), the stacker crane driven from stdin
//! ([`crane`]) and the replay of a capture ([`replay`]).
//!
//! The memory simulators (Modbus, MC, MEWTOCOL, PPI) also take a [`Bench`]: a preset to
//! start from ([`crate::sim::preset`]) and a control surface to serve beside the protocol
//! server ([`crate::sim::control`]).

pub mod crane;
pub mod line;
pub mod mc3e;
pub mod modbus;
pub mod replay;
pub mod shelf;

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use anyhow::Context;

use super::control::{Control, ControlServer};
use super::memory::SimMemory;
use super::preset::identity::Identity;
use super::preset::{Preset, ReadOnlyRange};
use crate::protocols::Protocol;
use crate::protocols::faults::SharedFaults;

/// What every memory simulator takes besides its own options: a preset and a control
/// surface.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Bench {
    /// The preset to load before serving (JSON, or TOML when the name ends in `.toml`).
    pub preset: Option<PathBuf>,
    /// Where to serve the control surface, if anywhere.
    pub control: Option<SocketAddr>,
}

impl Bench {
    /// Loads the preset, if any, into `memory`; returns the read-only ranges it set.
    pub fn load(&self, protocol: Protocol, memory: &dyn SimMemory) -> anyhow::Result<Vec<ReadOnlyRange>> {
        match &self.preset {
            Some(path) => Preset::read(path)?.apply(path, protocol, memory),
            None => Ok(Vec::new()),
        }
    }

    /// The preset's `identity` section, if it has one (see [`crate::sim::preset::identity`]).
    pub fn identity(&self) -> anyhow::Result<Option<Identity>> {
        match &self.preset {
            Some(path) => Ok(Preset::read(path)?.identity),
            None => Ok(None),
        }
    }

    /// Refuses an `identity` section where the protocol has no request that asks for it.
    pub fn no_identity(&self, protocol: Protocol) -> anyhow::Result<()> {
        if self.identity()?.is_some() {
            anyhow::bail!(
                "the preset's `identity` section is for Modbus and MC; {protocol} has no such request"
            );
        }
        Ok(())
    }

    /// Starts the control surface, if asked for.
    pub async fn start_control(
        &self,
        protocol: Protocol,
        memory: Arc<dyn SimMemory>,
        faults: SharedFaults,
        read_only: Vec<ReadOnlyRange>,
    ) -> anyhow::Result<Option<ControlServer>> {
        let Some(listen) = self.control else { return Ok(None) };
        let control = Control { protocol, memory, faults, read_only: Mutex::new(read_only) };
        let server = ControlServer::start(listen, control)
            .await
            .with_context(|| format!("cannot serve the control surface on {listen}"))?;
        eprintln!("control surface on http://{}", server.local_addr());
        Ok(Some(server))
    }
}

/// A running memory simulator and its control surface, if asked for.
pub struct Running<S> {
    /// The protocol server.
    pub server: S,
    /// The control surface.
    pub control: Option<ControlServer>,
}
