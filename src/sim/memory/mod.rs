//! A simulated PLC's memory seen from the field: read and write words and bits by
//! [`Address`] straight in the server's bank, and mark ranges read-only to masters.
//!
//! [`SimMemory`] is the synchronous twin of [`crate::protocols::PlcMemory`]: the same
//! addresses and the same word and bit semantics (PPI words step two bytes, `VB` items
//! carry one byte each, `VD` items are read as pairs of words, high word first), without a
//! link. Preset loading and the control surface of `rackd sim` use it; their writes are the
//! field's, so they pass by the read-only ranges that refuse a master's writes.
//!
//! Each protocol keeps read-only ranges where its server carries out a request: a Modbus
//! [`Handler`](crate::protocols::modbus::server::Handler) wrapping the bank, a PPI or
//! MEWTOCOL server handler, and the MC bank itself (the MC server has no handler seam).
//! The refusal is each protocol's own:
//!
//! | protocol | refusal | why this one |
//! |----------|---------|--------------|
//! | Modbus   | exception 02, illegal data address | Modbus Application Protocol v1.1b3, section 7: "not an allowable address for the server"; 04 is an unrecoverable failure while acting, which would send a master looking for a fault |
//! | MC 3E    | end code C05B | Q-series MC protocol manual's end code table: the target cannot read or write the specified device |
//! | MEWTOCOL | error 65, protect error | the MEWTOCOL-COM error table (FP2-CCU manual, 6.3): a write into protected memory |
//! | PPI      | item return code 0x03 | S7 data item return codes: access to the object not allowed |
//!
//! A master write touching any read-only item is refused whole: nothing of it is written.

mod mc3e;
mod mewtocol;
mod modbus;
mod ppi;

use std::ops::Range;

pub use mc3e::Mc3eMemory;
pub use mewtocol::MewtocolMemory;
pub use modbus::ModbusMemory;
pub use ppi::PpiMemory;

use crate::protocols::read_only::Overlap;
use crate::protocols::{Address, PlcError};

/// Items of one area, in the unit the memory keeps the area in (items of a Modbus table,
/// points of an MC device, DT words, bits of a MEWTOCOL contact area or an S7 area).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Span {
    /// The area, as the memory names it (`4x`, `D`, `DT`, `X`, `V`).
    pub area: String,
    /// The items.
    pub items: Range<u64>,
}

impl Span {
    /// Whether two spans share an item.
    pub fn overlaps(&self, other: &Span) -> bool {
        self.area == other.area && self.items.start < other.items.end && other.items.start < self.items.end
    }
}

/// A simulated PLC's memory, from the field's side.
pub trait SimMemory: Send + Sync {
    /// Reads `count` consecutive words from `start`.
    fn read_words(&self, start: &Address, count: u16) -> Result<Vec<u16>, PlcError>;

    /// Writes consecutive words from `start`, read-only or not.
    fn write_words(&self, start: &Address, values: &[u16]) -> Result<(), PlcError>;

    /// Reads `count` consecutive bits from `start`.
    fn read_bits(&self, start: &Address, count: u16) -> Result<Vec<bool>, PlcError>;

    /// Writes consecutive bits from `start`, read-only or not.
    fn write_bits(&self, start: &Address, values: &[bool]) -> Result<(), PlcError>;

    /// The items `count` words (word addresses) or bits (bit addresses) from `start` cover.
    fn span(&self, start: &Address, count: u32) -> Result<Span, PlcError>;

    /// Makes `count` words or bits from `start` read-only to masters; refused if they
    /// overlap an earlier read-only range.
    fn protect(&self, start: &Address, count: u32) -> Result<(), ProtectError>;

    /// Master writes refused by the read-only ranges so far.
    fn refused(&self) -> u64;
}

/// Why a range cannot be made read-only.
#[derive(Debug, thiserror::Error)]
pub enum ProtectError {
    /// The address or count does not fit the memory.
    #[error(transparent)]
    Address(#[from] PlcError),
    /// The range overlaps one already read-only.
    #[error(transparent)]
    Overlap(#[from] Overlap),
}

/// `count` items from `start`, checked against a 64-bit overflow.
fn items(start: u64, count: u64) -> Range<u64> {
    start..start.saturating_add(count)
}

#[cfg(test)]
mod tests;
