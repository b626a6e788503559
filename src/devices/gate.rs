//! A PLC link that only talks while this node may drive the machines: in a cluster, the
//! active node's device links pass every request through [`Gated`], which asks the
//! leadership's gate first and refuses the request (as a lost connection) the instant the
//! lease runs out, whatever the device task is in the middle of. The check is synchronous
//! and costs a lock and a clock read per request.

use std::sync::Arc;

use async_trait::async_trait;

use crate::protocols::transport::LinkStats;
use crate::protocols::{Address, PlcError, PlcMemory};

/// Whether this node may talk to the machines now.
pub type MayDrive = Arc<dyn Fn() -> bool + Send + Sync>;

/// `plc`, talking only while `may` says so.
pub struct Gated {
    plc: Arc<dyn PlcMemory>,
    may: MayDrive,
}

impl Gated {
    /// Wraps `plc`.
    pub fn new(plc: Arc<dyn PlcMemory>, may: MayDrive) -> Gated {
        Gated { plc, may }
    }

    fn check(&self) -> Result<(), PlcError> {
        match (self.may)() {
            true => Ok(()),
            false => Err(PlcError::Connection(std::io::Error::new(
                std::io::ErrorKind::PermissionDenied,
                "this node does not hold the cluster's lease: it does not talk to the machines",
            ))),
        }
    }
}

#[async_trait]
impl PlcMemory for Gated {
    fn parse_address(&self, text: &str) -> Result<Address, PlcError> {
        self.plc.parse_address(text)
    }

    fn word_address(&self, start: &Address, words: u32) -> Address {
        self.plc.word_address(start, words)
    }

    async fn read_words(&self, start: &Address, count: u16) -> Result<Vec<u16>, PlcError> {
        self.check()?;
        self.plc.read_words(start, count).await
    }

    async fn write_words(&self, start: &Address, values: &[u16]) -> Result<(), PlcError> {
        self.check()?;
        self.plc.write_words(start, values).await
    }

    async fn read_bits(&self, start: &Address, count: u16) -> Result<Vec<bool>, PlcError> {
        self.check()?;
        self.plc.read_bits(start, count).await
    }

    async fn write_bits(&self, start: &Address, values: &[bool]) -> Result<(), PlcError> {
        self.check()?;
        self.plc.write_bits(start, values).await
    }

    fn link_stats(&self) -> LinkStats {
        self.plc.link_stats()
    }

    fn recorder(&self) -> Option<std::sync::Arc<crate::capture::Recorder>> {
        self.plc.recorder()
    }

    fn serving(&self, job: Option<(i64, u16)>) {
        self.plc.serving(job)
    }
}
