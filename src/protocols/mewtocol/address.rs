//! Panasonic address notation for [`PlcMemory`](crate::protocols::PlcMemory).
//!
//! | text | area | index | access |
//! |---|---|---|---|
//! | `DT100` | `DT` | register number (0..=99999) | words (RD/WD) |
//! | `WX0`, `WY2`, `WR10`, `WL3` | `WX` ... | word number (0..=999) | words (RCC/WCC) |
//! | `X0`, `Y1A`, `R0010`, `R1F`, `L5`, `T3`, `C7` | `X` ... | word x 16 + bit | bits (RCS/RCP/RCC, WCS/WCP) |
//!
//! A contact is a decimal word number followed by one hex digit for the bit, so `R1F` is
//! word 1 bit 15 and `R0010` is word 1 bit 0 (index 16); consecutive bits run on into the
//! next word (`Y0F` is followed by `Y10`).

use super::command::{ContactArea, MAX_CONTACT_WORD, MAX_DT};
use crate::protocols::{Address, Area, PlcError};

/// What an [`Address`] refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    /// Data register DT n.
    Data(u32),
    /// Contact word n of an area (WX, WY, WR, WL).
    Words(ContactArea, u16),
    /// Contact number (word x 16 + bit) of an area.
    Bits(ContactArea, u32),
}

fn bad(text: &str, reason: &'static str) -> PlcError {
    PlcError::BadAddress { text: text.to_owned(), reason }
}

/// Parses `DT100`, `WR10`, `Y1A`, ... into an [`Address`].
pub fn parse(text: &str) -> Result<Address, PlcError> {
    let upper = text.trim().to_ascii_uppercase();
    let number = |digits: &str, max: u32| -> Result<u32, PlcError> {
        if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
            return Err(bad(text, "expected a decimal number after the area"));
        }
        digits.parse::<u32>().ok().filter(|&n| n <= max).ok_or_else(|| bad(text, "number out of range"))
    };
    if let Some(rest) = upper.strip_prefix("DT") {
        return Ok(Address { area: Area::new("DT"), index: number(rest, MAX_DT)? });
    }
    let bytes = upper.as_bytes();
    if bytes.len() >= 2
        && bytes[0] == b'W'
        && ContactArea::from_letter(bytes[1]).is_some()
        && bytes[1] != b'T'
        && bytes[1] != b'C'
    {
        let index = number(&upper[2..], MAX_CONTACT_WORD as u32)?;
        return Ok(Address { area: Area::new(&upper[..2]), index });
    }
    let Some(&letter) = bytes.first() else { return Err(bad(text, "empty address")) };
    if ContactArea::from_letter(letter).is_none() {
        return Err(bad(text, "unknown area (DT, WX, WY, WR, WL, X, Y, R, L, T, C)"));
    }
    let rest = &upper[1..];
    let Some(last) = rest.chars().last() else { return Err(bad(text, "missing contact number")) };
    let bit = last.to_digit(16).ok_or_else(|| bad(text, "the last digit of a contact is its bit (0-F)"))?;
    let word_digits = &rest[..rest.len() - 1];
    let word = if word_digits.is_empty() { 0 } else { number(word_digits, MAX_CONTACT_WORD as u32)? };
    Ok(Address { area: Area::new(&upper[..1]), index: word * 16 + bit })
}

/// What `address` refers to, checking that `count` items fit the area.
pub fn resolve(address: &Address, count: usize) -> Result<Target, PlcError> {
    let last = address.index as u64 + count.saturating_sub(1) as u64;
    let name = address.area.name();
    let out = || PlcError::OutOfRange("past the end of the MEWTOCOL area");
    if name == "DT" {
        return if last <= MAX_DT as u64 { Ok(Target::Data(address.index)) } else { Err(out()) };
    }
    let area_of = |letter: &str| {
        letter
            .bytes()
            .next()
            .and_then(ContactArea::from_letter)
            .ok_or(PlcError::BadAddress { text: address.area.to_string(), reason: "not a MEWTOCOL area" })
    };
    if let Some(letter) = name.strip_prefix('W').filter(|l| l.len() == 1) {
        let area = area_of(letter)?;
        return if last <= MAX_CONTACT_WORD as u64 {
            Ok(Target::Words(area, address.index as u16))
        } else {
            Err(out())
        };
    }
    if name.len() != 1 {
        return Err(PlcError::BadAddress { text: name.to_owned(), reason: "not a MEWTOCOL area" });
    }
    let area = area_of(name)?;
    if last < (MAX_CONTACT_WORD as u64 + 1) * 16 { Ok(Target::Bits(area, address.index)) } else { Err(out()) }
}

/// Whether the area holds bits (contacts) rather than words.
pub fn is_bit_area(address: &Address) -> bool {
    matches!(resolve(address, 1), Ok(Target::Bits(..)))
}

/// Formats an address back in Panasonic notation (`DT100`, `WR1`, `Y1A`).
pub fn format(address: &Address) -> String {
    match resolve(address, 1) {
        Ok(Target::Bits(_, n)) if n >= 16 => format!("{}{}{:X}", address.area, n / 16, n % 16),
        Ok(Target::Bits(_, n)) => format!("{}{:X}", address.area, n),
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
    fn parses_panasonic_notation() {
        assert_eq!(parse("DT100").unwrap(), at("DT", 100));
        assert_eq!(parse("dt99999").unwrap(), at("DT", 99_999));
        assert_eq!(parse("WR10").unwrap(), at("WR", 10));
        assert_eq!(parse("R0010").unwrap(), at("R", 16));
        assert_eq!(parse("R1F").unwrap(), at("R", 31));
        assert_eq!(parse("X0").unwrap(), at("X", 0));
        assert_eq!(parse("Y1A").unwrap(), at("Y", 26));
        assert_eq!(parse("Y001A").unwrap(), at("Y", 26));
        assert_eq!(parse("C7").unwrap(), at("C", 7));
        assert!(parse("T9999F").unwrap_err().to_string().contains("out of range"));
        for bad in ["", "DT", "DT1A", "Q1", "RG", "WZ1", "DT100000", "WR1000", "R"] {
            assert!(parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn resolves_and_formats() {
        assert_eq!(resolve(&at("DT", 5), 2).unwrap(), Target::Data(5));
        assert_eq!(resolve(&at("WY", 2), 1).unwrap(), Target::Words(ContactArea::Y, 2));
        assert_eq!(resolve(&at("Y", 26), 1).unwrap(), Target::Bits(ContactArea::Y, 26));
        assert!(resolve(&at("DT", 99_999), 2).is_err());
        assert!(resolve(&at("WR", 999), 2).is_err());
        assert!(resolve(&at("R", 15_999), 2).is_err());
        assert!(resolve(&at("ZZ", 0), 1).is_err());
        assert!(is_bit_area(&at("R", 0)) && !is_bit_area(&at("WR", 0)));
        for text in ["DT100", "WR1", "Y1A", "R1F", "X0", "R10"] {
            assert_eq!(format(&parse(text).unwrap()), text);
        }
    }
}
