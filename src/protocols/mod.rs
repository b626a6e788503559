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
pub mod simwire;
pub mod transport;

use async_trait::async_trait;

use protocol::Family;

pub use error::{DropReason, Dropped, PlcError};
pub use protocol::{Protocol, Quirk, Replies};

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

    /// The link's flight recorder: every frame sent and read lately (see
    /// [`crate::capture::Recorder`]). None for memories without a link, or when capture is
    /// off for the device.
    fn recorder(&self) -> Option<std::sync::Arc<crate::capture::Recorder>> {
        None
    }

    /// The job and task the next requests serve (a hand-over), or `None` once it is done;
    /// frames recorded meanwhile carry them.
    fn serving(&self, job: Option<(i64, u16)>) {
        if let Some(recorder) = self.recorder() {
            recorder.set_serving(job);
        }
    }
}

/// A device's own error code, typed by the protocol that carried it.
///
/// It lives here, beside the list of protocols, rather than in [`error`]: it names every
/// protocol's code type, and every protocol reports through [`error`], which so names none.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DeviceCode {
    /// A Modbus exception reply.
    Modbus(modbus::Exception),
    /// A nonzero MC 3E end code.
    Mc3e(mc3e::EndCode),
    /// A MEWTOCOL-COM `!` error code.
    Mewtocol(mewtocol::ErrorCode),
    /// A PPI item return code or a refused request's error class and code.
    Ppi(ppi::ReturnCode),
}

impl DeviceCode {
    /// Reads a device error code of `protocol` (for a simulator to answer with), as the
    /// protocol's manual writes it.
    pub fn parse(protocol: Protocol, text: &str) -> Result<DeviceCode, BadDeviceCode> {
        match protocol.family() {
            Family::Modbus => text.parse::<modbus::Exception>().map(DeviceCode::from),
            Family::Mc3e => text.parse::<mc3e::EndCode>().map(DeviceCode::from),
            Family::Mewtocol => text.parse::<mewtocol::ErrorCode>().map(DeviceCode::from),
            Family::Ppi => text.parse::<ppi::ReturnCode>().map(DeviceCode::from),
        }
    }

    /// The protocol's name as rackd spells it in logs (`modbus`, `mc3e`, `mewtocol`, `ppi`).
    pub fn protocol(&self) -> &'static str {
        match self {
            DeviceCode::Modbus(_) => "modbus",
            DeviceCode::Mc3e(_) => "mc3e",
            DeviceCode::Mewtocol(_) => "mewtocol",
            DeviceCode::Ppi(_) => "ppi",
        }
    }

    /// The code as a number (for a PPI refusal: error class x 256 + code).
    pub fn number(&self) -> u32 {
        match self {
            DeviceCode::Modbus(e) => u32::from(e.0),
            DeviceCode::Mc3e(c) => u32::from(c.0),
            DeviceCode::Mewtocol(c) => u32::from(c.0),
            DeviceCode::Ppi(c) => c.number(),
        }
    }

    /// What the code means, from the protocol's documentation.
    pub fn meaning(&self) -> &'static str {
        match self {
            DeviceCode::Modbus(e) => e.meaning(),
            DeviceCode::Mc3e(c) => c.meaning(),
            DeviceCode::Mewtocol(c) => c.meaning(),
            DeviceCode::Ppi(c) => c.meaning(),
        }
    }
}

impl From<modbus::Exception> for DeviceCode {
    fn from(e: modbus::Exception) -> Self {
        DeviceCode::Modbus(e)
    }
}

impl From<mc3e::EndCode> for DeviceCode {
    fn from(c: mc3e::EndCode) -> Self {
        DeviceCode::Mc3e(c)
    }
}

impl From<mewtocol::ErrorCode> for DeviceCode {
    fn from(c: mewtocol::ErrorCode) -> Self {
        DeviceCode::Mewtocol(c)
    }
}

impl From<ppi::ReturnCode> for DeviceCode {
    fn from(c: ppi::ReturnCode) -> Self {
        DeviceCode::Ppi(c)
    }
}

impl std::fmt::Display for DeviceCode {
    /// `modbus device error 0x0002: illegal data address`: one shape for logs and alarms.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} device error {:#06X}: {}", self.protocol(), self.number(), self.meaning())
    }
}

/// Why a device error code given as text (a simulator's `--device-error`) was refused.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("bad {protocol} device error code {text:?}: {expected}")]
pub struct BadDeviceCode {
    /// The protocol whose code was asked for.
    pub protocol: &'static str,
    /// The text as given.
    pub text: String,
    /// What a valid code looks like.
    pub expected: &'static str,
}

/// A number in decimal, or in hexadecimal after `0x`.
pub(crate) fn parse_number(text: &str) -> Option<u32> {
    let text = text.trim();
    match text.strip_prefix("0x").or_else(|| text.strip_prefix("0X")) {
        Some(hex) => u32::from_str_radix(hex, 16).ok(),
        None => text.parse().ok(),
    }
}
