//! How rackd talks to PLCs.
//!
//! Every protocol (Modbus, MC 3E, MEWTOCOL-COM, PPI) implements one small,
//! protocol-neutral trait, [`PlcMemory`]: read and write words or bits of a named memory
//! area. Device adapters (shelf task slots, crane handshakes, tag I/O) use only this trait,
//! so any machine can run over whichever protocol its site uses.
//!
//! Addresses are written in the protocol's own notation (`4x4000` for Modbus, `D200` for
//! MC, `DT100` for MEWTOCOL, `VW100` for PPI); each protocol parses its notation into an
//! [`Address`] with [`PlcMemory::parse_address`].
//!
//! Under the protocols lies one [`transport`] layer (endpoints, connections and their
//! reconnect, the one retry policy, the defences against late replies); a device's own
//! refusal is a [`DeviceCode`] typed by protocol; and every simulated server injects the
//! same [`faults`].

pub mod error;
pub mod faults;
pub mod link;
pub mod mc3e;
pub mod mewtocol;
pub mod modbus;
pub mod notation;
pub mod ppi;
pub mod protocol;
pub mod read_only;
pub mod serial;
pub mod transport;

use async_trait::async_trait;

pub use error::{BadDeviceCode, DeviceCode, DropReason, Dropped, PlcError};
pub use protocol::{Protocol, Quirk};

/// A named memory area of a PLC in the protocol's own notation, upper-cased
/// (`"4X"` holding registers, `"D"` data registers, `"DT"`, `"V"`, ...).
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Area(String);

impl Area {
    /// An area by name; the name is upper-cased so `4x` and `4X` are the same area.
    pub fn new(name: &str) -> Self {
        Area(name.to_ascii_uppercase())
    }

    /// The area's name as the protocol writes it.
    pub fn name(&self) -> &str {
        &self.0
    }
}

impl std::fmt::Display for Area {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// A place in a PLC's memory: an area and an index in it (a word number for word areas,
/// a bit number for bit areas).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Address {
    /// The memory area.
    pub area: Area,
    /// The word or bit number inside the area.
    pub index: u32,
}

impl Address {
    /// The address `offset` items further on in the same area.
    pub fn offset(&self, offset: u32) -> Address {
        Address { area: self.area.clone(), index: self.index + offset }
    }
}

/// A PLC's memory, whatever the protocol: the one interface device adapters use.
///
/// Implementations run every request over the shared [`transport`] layer, under its one
/// retry policy and reconnect; a call either completes or returns a typed [`PlcError`] once
/// the configured retries are spent. Requests
/// larger than one frame allows are split by the implementation.
#[async_trait]
pub trait PlcMemory: Send + Sync {
    /// Parses an address in this protocol's notation (`4x4000`, `D200`, ...).
    fn parse_address(&self, text: &str) -> Result<Address, PlcError>;

    /// The address `words` 16-bit words after `start`. Most protocols number words one
    /// apart; PPI numbers bytes, so `VW100` is followed by `VW102`. Adapters that lay out
    /// blocks of words (task slots) step with this, never with [`Address::offset`].
    fn word_address(&self, start: &Address, words: u32) -> Address {
        start.offset(words)
    }

    /// Reads `count` consecutive 16-bit words starting at `start`.
    async fn read_words(&self, start: &Address, count: u16) -> Result<Vec<u16>, PlcError>;

    /// Writes consecutive 16-bit words starting at `start`.
    async fn write_words(&self, start: &Address, values: &[u16]) -> Result<(), PlcError>;

    /// Reads `count` consecutive bits starting at `start`.
    async fn read_bits(&self, start: &Address, count: u16) -> Result<Vec<bool>, PlcError>;

    /// Writes consecutive bits starting at `start`.
    async fn write_bits(&self, start: &Address, values: &[bool]) -> Result<(), PlcError>;

    /// The link's health: adaptive timeout, degraded flag and counters. Every client of
    /// rackd's protocols keeps one; the default (all zeros, never degraded) is for memories
    /// without a link.
    fn link_stats(&self) -> transport::LinkStats {
        transport::LinkStats::default()
    }
}
