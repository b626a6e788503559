//! Siemens S7-200 address notation for [`PlcMemory`](crate::protocols::PlcMemory).
//!
//! | text | area name | `Address.index` | access |
//! |---|---|---|---|
//! | `V10.3`, `I0.0`, `Q0.1`, `M2.7`, `SM0.1`, `S1.0` | `V` ... | byte x 8 + bit | bits |
//! | `VB0`, `IB0`, `QB0`, `MB4`, `SMB0`, `SB0` | `VB` ... | byte offset | words, one byte each (0..=255) |
//! | `VW100`, `IW0`, `QW0`, `MW4`, `SMW22`, `SW0`, `AIW0`, `AQW0` | `VW` ... | byte offset | words |
//! | `VD4`, `ID0`, `QD0`, `MD0`, `SMD0`, `SD0` | `VD` ... | byte offset | words, two per double word (high first) |
//! | `T37`, `C5` | `T`, `C` | timer / counter number | words (current value) |
//!
//! A word address is a *byte* offset, as in Siemens notation: `VW100` covers VB100 and
//! VB101, so `read_words(VW100, 3)` reads VW100, VW102 and VW104 (bytes 100..=105), and
//! the i-th word is at byte `index + 2 * i`.

use super::pdu::{MemArea, Size};
use crate::protocols::{Address, Area, PlcError};

/// Largest byte offset accepted.
pub const MAX_BYTE: u32 = 0xFFFF;

/// What an [`Address`] refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Target {
    /// The memory area.
    pub area: MemArea,
    /// Access size: [`Size::Bit`], [`Size::Byte`], [`Size::Word`], [`Size::DWord`], or
    /// [`Size::Timer`] / [`Size::Counter`].
    pub size: Size,
    /// Bit index (bits), byte offset (bytes, words, double words) or number (T, C).
    pub index: u32,
}

const PREFIXES: [(&str, MemArea); 10] = [
    ("SM", MemArea::SM),
    ("AI", MemArea::AI),
    ("AQ", MemArea::AQ),
    ("V", MemArea::V),
    ("I", MemArea::I),
    ("Q", MemArea::Q),
    ("M", MemArea::M),
    ("S", MemArea::S),
    ("T", MemArea::T),
    ("C", MemArea::C),
];

fn bad(text: &str, reason: &'static str) -> PlcError {
    PlcError::BadAddress { text: text.to_owned(), reason }
}

fn split_area(name: &str) -> Option<(MemArea, &str)> {
    PREFIXES.iter().find_map(|(p, a)| name.strip_prefix(p).map(|rest| (*a, rest)))
}

fn size_of(letter: &str) -> Option<Size> {
    match letter {
        "B" => Some(Size::Byte),
        "W" => Some(Size::Word),
        "D" => Some(Size::DWord),
        _ => None,
    }
}

/// Parses `VW100`, `V10.3`, `SMB0`, `T37`, ... into an [`Address`].
pub fn parse(text: &str) -> Result<Address, PlcError> {
    let upper = text.trim().to_ascii_uppercase();
    let (area, rest) =
        split_area(&upper).ok_or_else(|| bad(text, "unknown area (V, I, Q, M, SM, S, AI, AQ, T, C)"))?;
    let number = |digits: &str, max: u32| -> Result<u32, PlcError> {
        if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
            return Err(bad(text, "expected a decimal number"));
        }
        digits.parse::<u32>().ok().filter(|&n| n <= max).ok_or_else(|| bad(text, "number out of range"))
    };
    let prefix = &upper[..upper.len() - rest.len()];
    if matches!(area, MemArea::T | MemArea::C) {
        return Ok(Address { area: Area::new(prefix), index: number(rest, MAX_BYTE)? });
    }
    if let Some(size) = rest.get(..1).and_then(size_of) {
        if matches!(area, MemArea::AI | MemArea::AQ) && size != Size::Word {
            return Err(bad(text, "analog areas are addressed by word (AIW, AQW)"));
        }
        let index = number(&rest[1..], MAX_BYTE)?;
        return Ok(Address { area: Area::new(&upper[..prefix.len() + 1]), index });
    }
    if matches!(area, MemArea::AI | MemArea::AQ) {
        return Err(bad(text, "analog areas are addressed by word (AIW, AQW)"));
    }
    let (byte, bit) = rest.split_once('.').ok_or_else(|| bad(text, "expected B, W, D or byte.bit"))?;
    let bit = number(bit, 7)?;
    Ok(Address { area: Area::new(prefix), index: number(byte, MAX_BYTE)? * 8 + bit })
}

/// What `address` refers to.
pub fn resolve(address: &Address) -> Result<Target, PlcError> {
    let name = address.area.name();
    let not_ppi = || PlcError::BadAddress { text: name.to_owned(), reason: "not a PPI area" };
    let (area, rest) = split_area(name).ok_or_else(not_ppi)?;
    let size = match (area, rest) {
        (MemArea::T, "") => Size::Timer,
        (MemArea::C, "") => Size::Counter,
        (MemArea::T | MemArea::C, _) => return Err(not_ppi()),
        (MemArea::AI | MemArea::AQ, "W") => Size::Word,
        (MemArea::AI | MemArea::AQ, _) => return Err(not_ppi()),
        (_, "") => Size::Bit,
        (_, letter) => size_of(letter).ok_or_else(not_ppi)?,
    };
    Ok(Target { area, size, index: address.index })
}

/// Whether the address names single bits.
pub fn is_bit_area(address: &Address) -> bool {
    resolve(address).is_ok_and(|t| t.size == Size::Bit)
}

/// How far apart consecutive items of the area are in `Address.index` (2 for words, as
/// `VW100` is followed by `VW102`).
pub fn step(address: &Address) -> u32 {
    match resolve(address).map(|t| t.size) {
        Ok(Size::Word | Size::DWord) => 2,
        _ => 1,
    }
}

/// Formats an address back in Siemens notation.
pub fn format(address: &Address) -> String {
    match resolve(address) {
        Ok(Target { size: Size::Bit, index, .. }) => format!("{}{}.{}", address.area, index / 8, index % 8),
        _ => format!("{}{}", address.area, address.index),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(area: &str, index: u32) -> Address {
        Address { area: Area::new(area), index }
    }

    #[test]
    fn parses_siemens_notation() {
        for (text, area, index) in [
            ("VW100", "VW", 100),
            ("VB0", "VB", 0),
            ("V10.3", "V", 83),
            ("VD4", "VD", 4),
            ("QB0", "QB", 0),
            ("Q0.1", "Q", 1),
            ("I0.0", "I", 0),
            ("MW4", "MW", 4),
            ("SMB0", "SMB", 0),
            ("SM0.1", "SM", 1),
            ("SB2", "SB", 2),
            ("S1.2", "S", 10),
            ("AIW2", "AIW", 2),
            ("aqw0", "AQW", 0),
            ("T37", "T", 37),
            ("C5", "C", 5),
        ] {
            assert_eq!(parse(text).unwrap(), at(area, index), "{text}");
            assert_eq!(format(&parse(text).unwrap()), text.to_ascii_uppercase(), "{text}");
        }
        for bad in ["", "X0", "V10", "V10.8", "VX1", "AIB0", "AI0.1", "VW", "VW70000", "TW1", "V.1"] {
            assert!(parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn resolves_sizes_and_steps() {
        assert_eq!(
            resolve(&at("VW", 100)).unwrap(),
            Target { area: MemArea::V, size: Size::Word, index: 100 }
        );
        assert_eq!(resolve(&at("SMB", 0)).unwrap().size, Size::Byte);
        assert_eq!(resolve(&at("T", 3)).unwrap().size, Size::Timer);
        assert_eq!(resolve(&at("C", 3)).unwrap().size, Size::Counter);
        assert!(
            resolve(&at("TW", 3)).is_err()
                && resolve(&at("AIB", 0)).is_err()
                && resolve(&at("VX", 0)).is_err()
        );
        assert!(is_bit_area(&at("Q", 1)) && !is_bit_area(&at("QB", 1)));
        assert_eq!((step(&at("VW", 0)), step(&at("VB", 0)), step(&at("T", 0))), (2, 1, 1));
    }
}
