//! `--preset FILE` and `--control HOST:PORT`, the options every memory simulator takes
//! (`rackd sim modbus|mc3e|mewtocol|ppi`): the simulator loads the preset before serving,
//! then serves the control surface beside the protocol server ([`Bench`]).

use std::net::SocketAddr;
use std::path::PathBuf;

use crate::sim::standalone::Bench;

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
    /// The preset and control surface these arguments ask for.
    pub fn bench(&self) -> Bench {
        Bench { preset: self.preset.clone(), control: self.control }
    }
}
