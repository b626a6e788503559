//! `rackd sim replay`: the arguments of the capture replay
//! ([`crate::sim::standalone::replay`]; the matching is [`crate::sim::replay`]'s).
//!
//! ```text
//! rackd sim replay site-crane1.pcapng --listen 127.0.0.1:8000 --idle-secs 5
//! ```

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use crate::sim::standalone::replay::ReplayOptions;

/// `rackd sim replay` options.
#[derive(clap::Args, Clone, Debug)]
pub struct SimReplayArgs {
    /// The capture to play the device side of (pcapng, UDP or TCP).
    pub file: PathBuf,
    /// Address to serve on [default: 127.0.0.1 and the recorded device's port].
    #[arg(long)]
    pub listen: Option<SocketAddr>,
    /// Stop once the recording has been played out for this many seconds.
    #[arg(long, default_value_t = 5)]
    pub idle_secs: u64,
    /// Writes this many milliseconds apart in the recording may come either way round.
    #[arg(long, default_value_t = 100)]
    pub reorder_ms: u64,
}

impl SimReplayArgs {
    /// The replay these arguments select.
    pub fn options(&self) -> ReplayOptions {
        ReplayOptions {
            file: self.file.clone(),
            listen: self.listen,
            reorder: Duration::from_millis(self.reorder_ms),
            idle: Duration::from_secs(self.idle_secs),
        }
    }
}
