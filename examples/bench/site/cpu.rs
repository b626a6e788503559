//! rackd's CPU time apart from the simulators' and the WMS's, all in this one process.
//!
//! The simulators and the WMS run on runtimes of their own whose threads carry a name
//! ([`SIMS`], [`WMS`]); rackd runs on the benchmark's main runtime and its own threads
//! (the writer, the sync, SQLite's workers). rackd's share is the process's CPU time
//! (its CPU-time clock, every thread, ended ones included) minus what the named threads
//! used, each read from `/proc/self/task/TID/schedstat` (nanoseconds on the CPU). A named
//! thread that ended would leave its time in rackd's share; their runtimes keep idle
//! threads alive for the whole run so none does. The benchmark's main thread only waits
//! on the WMS while it measures, and counts as rackd's.

use std::fs;

use anyhow::Context;

use crate::child::cpu_secs;

/// The prefix of the simulators' threads.
pub const SIMS: &str = "site-sim";
/// The prefix of the WMS's threads.
pub const WMS: &str = "site-wms";

/// CPU seconds used so far, by whom.
#[derive(Clone, Copy, Debug, Default)]
pub struct Cpu {
    /// The whole process.
    pub process: f64,
    /// The crane simulators.
    pub sims: f64,
    /// The WMS.
    pub wms: f64,
}

impl Cpu {
    /// The counts now.
    pub fn now() -> anyhow::Result<Cpu> {
        let (mut sims, mut wms) = (0.0, 0.0);
        for task in fs::read_dir("/proc/self/task").context("/proc/self/task")? {
            let dir = task?.path();
            // A thread may end between the listing and the read: it is simply left out.
            let (Ok(name), Ok(stat)) =
                (fs::read_to_string(dir.join("comm")), fs::read_to_string(dir.join("schedstat")))
            else {
                continue;
            };
            let secs =
                stat.split_whitespace().next().and_then(|ns| ns.parse::<f64>().ok()).unwrap_or(0.0) / 1e9;
            if name.starts_with(SIMS) {
                sims += secs;
            } else if name.starts_with(WMS) {
                wms += secs;
            }
        }
        Ok(Cpu { process: cpu_secs(std::process::id())?, sims, wms })
    }

    /// rackd's share.
    pub fn rackd(&self) -> f64 {
        self.process - self.sims - self.wms
    }

    /// What was used since `before`.
    pub fn since(&self, before: &Cpu) -> Cpu {
        Cpu {
            process: self.process - before.process,
            sims: self.sims - before.sims,
            wms: self.wms - before.wms,
        }
    }
}
