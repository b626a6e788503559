//! What an address in a protocol's notation names, known from its text alone.
//!
//! [`PlcMemory::parse_address`](super::PlcMemory::parse_address) needs a client, and a
//! client needs a link; `rackd check-config` and device adapters that map many addresses
//! (tag I/O) want to know before connecting whether `Q0.1` is a bit, whether `VD4` holds
//! double words and whether `1x7` can be written. [`shape`] answers that for every
//! [`Protocol`] with the same parsers the clients use.

use super::mewtocol::address::{self as mewtocol, Target as MewTarget};
use super::mewtocol::command::ContactArea;
use super::modbus::address::{self as modbus, Table};
use super::ppi::address::{self as ppi, MAX_BYTE};
use super::ppi::pdu::{MemArea, Size};
use super::protocol::{Family, Protocol};
use super::{Address, PlcError, mc3e};

/// The kind of items an area holds, as [`super::PlcMemory`] reads them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Items {
    /// Single bits (`read_bits` / `write_bits`).
    Bits,
    /// 16-bit words.
    Words,
    /// One byte per word value, 0..=255 (S7 `VB`, `QB`, ...).
    Bytes,
    /// Double words, read and written as an even number of words, high word first (S7 `VD`).
    DoubleWords,
}

/// What an address names.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Shape {
    /// The parsed address, as the protocol's client takes it.
    pub address: Address,
    /// What the area holds.
    pub items: Items,
    /// How far apart consecutive words are in `Address.index` (2 for S7 word areas, whose
    /// index is a byte offset; 1 elsewhere).
    pub step: u32,
    /// One past the largest index of the area, so a read of `n` items from here fits when
    /// `index + step * n <= limit`.
    pub limit: u64,
    /// A master may write it: false for inputs (Modbus 1x and 3x, S7 I and AI, MEWTOCOL X,
    /// WX and timer/counter contacts, MC X and TS/STS/CS), which the PLC refreshes from the field.
    pub writable: bool,
}

impl Shape {
    /// Whether `n` consecutive items from this address stay inside the area.
    pub fn fits(&self, n: u32) -> bool {
        self.address.index as u64 + self.step as u64 * n as u64 <= self.limit
    }
}

/// What `text` names in `protocol`'s notation.
pub fn shape(protocol: Protocol, text: &str) -> Result<Shape, PlcError> {
    match protocol.family() {
        Family::Modbus => modbus_shape(text),
        Family::Mc3e => mc3e_shape(text),
        Family::Mewtocol => mewtocol_shape(text),
        Family::Ppi => ppi_shape(text),
    }
}

fn modbus_shape(text: &str) -> Result<Shape, PlcError> {
    let address = modbus::parse(text)?;
    let table = Table::from_area(&address.area).ok_or(PlcError::OutOfRange("not a Modbus area"))?;
    let items = if table.holds_words() { Items::Words } else { Items::Bits };
    Ok(Shape { address, items, step: 1, limit: 0x1_0000, writable: table.writable() })
}

/// MC: bit devices (relays, timer/counter contacts and coils) hold bits, word devices and
/// timer/counter current values words; `K4M100` holds words of 16 points (step 16).
fn mc3e_shape(text: &str) -> Result<Shape, PlcError> {
    let address = mc3e::address::parse_address(text)?;
    let limit = mc3e::device::MAX_DEVICE_NUMBER as u64 + 1;
    if let Some(device) = mc3e::address::word_view(&address.area) {
        return Ok(Shape { address, items: Items::Words, step: 16, limit, writable: device.is_writable() });
    }
    let device = mc3e::Device::of_area(&address.area)?;
    let items = if device.is_bit() { Items::Bits } else { Items::Words };
    Ok(Shape { address, items, step: 1, limit, writable: device.is_writable() })
}

fn mewtocol_shape(text: &str) -> Result<Shape, PlcError> {
    use super::mewtocol::command::{MAX_CONTACT_WORD, MAX_DT};
    let address = mewtocol::parse(text)?;
    let words = MAX_CONTACT_WORD as u64 + 1;
    let (items, limit, writable) = match mewtocol::resolve(&address, 1)? {
        MewTarget::Data(_) => (Items::Words, MAX_DT as u64 + 1, true),
        MewTarget::Words(area, _) => (Items::Words, words, area != ContactArea::X),
        MewTarget::Bits(area, _) => {
            let input = matches!(area, ContactArea::X | ContactArea::T | ContactArea::C);
            (Items::Bits, words * 16, !input)
        }
    };
    Ok(Shape { address, items, step: 1, limit, writable })
}

fn ppi_shape(text: &str) -> Result<Shape, PlcError> {
    let address = ppi::parse(text)?;
    let target = ppi::resolve(&address)?;
    let writable = !matches!(target.area, MemArea::I | MemArea::AI);
    let (items, step) = match target.size {
        Size::Bit => (Items::Bits, 1),
        Size::Byte => (Items::Bytes, 1),
        Size::Word => (Items::Words, 2),
        Size::DWord => (Items::DoubleWords, 2),
        Size::Timer | Size::Counter => (Items::Words, 1),
    };
    let limit = match target.size {
        Size::Bit => (MAX_BYTE as u64 + 1) * 8,
        _ => MAX_BYTE as u64 + 1,
    };
    Ok(Shape { address, items, step, limit, writable })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(protocol: &str, text: &str) -> Result<Shape, PlcError> {
        shape(protocol.parse().unwrap(), text)
    }

    fn of(protocol: &str, text: &str) -> (Items, u32, bool) {
        let s = at(protocol, text).unwrap();
        (s.items, s.step, s.writable)
    }

    #[test]
    fn every_protocol_without_a_connection() {
        assert_eq!(of("modbus-tcp", "4x100"), (Items::Words, 1, true));
        assert_eq!(of("modbus-udp", "3x100"), (Items::Words, 1, false));
        assert_eq!(of("modbus-rtu", "0x1"), (Items::Bits, 1, true));
        assert_eq!(of("modbus-rtu-tcp", "1x1"), (Items::Bits, 1, false));
        assert_eq!(of("mc3e", "D200"), (Items::Words, 1, true));
        assert_eq!(of("mc3e-udp", "X1A"), (Items::Bits, 1, false));
        assert_eq!(of("mc3e", "M10"), (Items::Bits, 1, true));
        assert_eq!(of("mc3e", "K4M100"), (Items::Words, 16, true));
        assert_eq!(of("mc3e", "K4X0"), (Items::Words, 16, false));
        assert_eq!(of("mc3e", "TN5"), (Items::Words, 1, true));
        assert_eq!(of("mc3e", "TS5"), (Items::Bits, 1, false));
        assert_eq!(of("mc3e", "CC2"), (Items::Bits, 1, true));
        assert_eq!(of("mc3e-udp", "STN1"), (Items::Words, 1, true));
        assert_eq!(of("mewtocol", "DT100"), (Items::Words, 1, true));
        assert_eq!(of("mewtocol-tcp", "WX0"), (Items::Words, 1, false));
        assert_eq!(of("mewtocol-tcp", "X0001"), (Items::Bits, 1, false));
        assert_eq!(of("mewtocol-tcp", "Y1A"), (Items::Bits, 1, true));
        assert_eq!(of("ppi", "Q0.1"), (Items::Bits, 1, true));
        assert_eq!(of("ppi-tcp", "I0.0"), (Items::Bits, 1, false));
        assert_eq!(of("ppi-tcp", "VW100"), (Items::Words, 2, true));
        assert_eq!(of("ppi-tcp", "VB3"), (Items::Bytes, 1, true));
        assert_eq!(of("ppi-tcp", "VD4"), (Items::DoubleWords, 2, true));
        assert_eq!(of("ppi-tcp", "AIW0"), (Items::Words, 2, false));
        assert_eq!(of("ppi-tcp", "T37"), (Items::Words, 1, true));
        assert!(at("modbus-tcp", "D200").is_err());
        assert!(at("ppi", "4x1").is_err());
    }

    #[test]
    fn fits_checks_the_end_of_the_area() {
        assert!(at("modbus-tcp", "4x65534").unwrap().fits(2));
        assert!(!at("modbus-tcp", "4x65535").unwrap().fits(2));
        assert!(at("ppi", "VW65534").unwrap().fits(1));
        assert!(!at("ppi", "VW65534").unwrap().fits(2));
        assert!(!at("mewtocol", "DT99999").unwrap().fits(2));
        assert!(at("mewtocol", "DT99998").unwrap().fits(2));
        assert!(!at("mc3e", "D16777215").unwrap().fits(2));
        assert!(at("mc3e", "K4M16777184").unwrap().fits(2));
        assert!(!at("mc3e", "K4M16777185").unwrap().fits(2));
    }
}
