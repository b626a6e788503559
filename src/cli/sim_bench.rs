//! `--preset FILE` and `--control HOST:PORT`, the options every memory simulator takes
//! (`rackd sim modbus|mc3e|mewtocol|ppi`): load the preset before serving, then serve the
//! control surface beside the protocol server.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use anyhow::Context;

use super::sim_control::{Control, ControlServer};
use super::sim_identity::Identity;
use super::sim_preset::{Preset, ReadOnlyRange};
use crate::protocols::Protocol;
use crate::protocols::faults::SharedFaults;
use crate::sim::memory::SimMemory;

/// `--preset` and `--control`, taken by every memory simulator.
#[derive(clap::Args, Clone, Debug, Default, PartialEq)]
pub struct PresetArgs {
    /// Load initial values and read-only ranges from FILE before serving (JSON, or TOML when
    /// it ends in .toml), addresses in the simulator's notation; for Modbus: {"values": [{"address": "4x100", "type": "f32", "word_order":
    /// "cdab", "value": 3.5}, ...], "read_only": [{"address": "1x0", "count": 16}]}. See
    /// docs/commissioning/simulators.md and config/sim/.
    #[arg(long, value_name = "FILE")]
    pub preset: Option<PathBuf>,
    /// Serve a control surface on HOST:PORT (HTTP/JSON): GET /values?address=4x100&type=f32,
    /// PUT /values with a preset entry (writes pass by read-only ranges), GET /read-only,
    /// GET /counters.
    #[arg(long, value_name = "HOST:PORT")]
    pub control: Option<SocketAddr>,
}

impl PresetArgs {
    /// Loads the preset, if any, into `memory`; returns the read-only ranges it set.
    pub fn load(&self, protocol: Protocol, memory: &dyn SimMemory) -> anyhow::Result<Vec<ReadOnlyRange>> {
        match &self.preset {
            Some(path) => Preset::read(path)?.apply(path, protocol, memory),
            None => Ok(Vec::new()),
        }
    }

    /// The preset's `identity` section, if it has one (see [`super::sim_identity`]).
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
