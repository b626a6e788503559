//! Modbus addresses in the `0x`/`1x`/`3x`/`4x` notation: `4x4000` is holding register 4000
//! (PDU address 4000 = 0x0FA0, the PLC's MW4000; no -1 offset as in "40001" notation).

use crate::protocols::{Address, Area, PlcError};

/// The four Modbus data tables.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Table {
    /// `0x`: coils, read/write bits.
    Coils,
    /// `1x`: discrete inputs, read-only bits.
    DiscreteInputs,
    /// `3x`: input registers, read-only words.
    InputRegisters,
    /// `4x`: holding registers, read/write words.
    HoldingRegisters,
}

impl Table {
    /// The area name used in [`Address`] (`0X`, `1X`, `3X`, `4X`).
    pub fn area_name(self) -> &'static str {
        match self {
            Table::Coils => "0X",
            Table::DiscreteInputs => "1X",
            Table::InputRegisters => "3X",
            Table::HoldingRegisters => "4X",
        }
    }

    /// The table an [`Area`] names, if it is a Modbus one.
    pub fn from_area(area: &Area) -> Option<Table> {
        match area.name() {
            "0X" => Some(Table::Coils),
            "1X" => Some(Table::DiscreteInputs),
            "3X" => Some(Table::InputRegisters),
            "4X" => Some(Table::HoldingRegisters),
            _ => None,
        }
    }

    /// True for the word tables (3x, 4x).
    pub fn holds_words(self) -> bool {
        matches!(self, Table::InputRegisters | Table::HoldingRegisters)
    }

    /// True for the tables a master may write (0x, 4x).
    pub fn writable(self) -> bool {
        matches!(self, Table::Coils | Table::HoldingRegisters)
    }
}

/// Parses `4x4000`-style text (case-insensitive prefix, decimal PDU address 0..65535).
pub fn parse(text: &str) -> Result<Address, PlcError> {
    let bad = |reason| PlcError::BadAddress { text: text.to_string(), reason };
    let t = text.trim();
    let (prefix, number) =
        t.split_at_checked(2).ok_or_else(|| bad("expected 0x, 1x, 3x or 4x and a number"))?;
    let area = Area::new(prefix);
    Table::from_area(&area).ok_or_else(|| bad("the area must be 0x, 1x, 3x or 4x"))?;
    if number.is_empty() || !number.bytes().all(|b| b.is_ascii_digit()) {
        return Err(bad("the address must be a decimal number"));
    }
    let index: u32 = number.parse().map_err(|_| bad("the address must be 0..65535"))?;
    if index > 0xFFFF {
        return Err(bad("the address must be 0..65535"));
    }
    Ok(Address { area, index })
}

/// Formats an address back to its text (`4x4000`).
pub fn format(address: &Address) -> String {
    format!("{}{}", address.area.name().to_ascii_lowercase(), address.index)
}

/// Checks that `count` items from `start` fit in the 16-bit address space; returns the
/// table and the first PDU address.
pub fn resolve(start: &Address, count: usize) -> Result<(Table, u16), PlcError> {
    let table =
        Table::from_area(&start.area).ok_or(PlcError::OutOfRange("not a Modbus area (0x, 1x, 3x, 4x)"))?;
    if count == 0 {
        return Err(PlcError::OutOfRange("count must be at least 1"));
    }
    if start.index as usize + count > 0x1_0000 {
        return Err(PlcError::OutOfRange("address + count beyond 65535"));
    }
    Ok((table, start.index as u16))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_four_tables() {
        let a = parse("4x4000").unwrap();
        assert_eq!((a.area.name(), a.index), ("4X", 4000));
        assert_eq!(parse("0X1").unwrap().area, Area::new("0x"));
        assert_eq!(parse("1x65535").unwrap().index, 65535);
        assert_eq!(parse("3x0").unwrap().area.name(), "3X");
        assert_eq!(format(&parse("4X4700").unwrap()), "4x4700");
    }

    #[test]
    fn rejects_bad_text() {
        for text in ["", "4", "4x", "2x10", "4x65536", "4x-1", "4x0x10", "D200", "4x99999999999"] {
            assert!(matches!(parse(text), Err(PlcError::BadAddress { .. })), "{text}");
        }
    }

    #[test]
    fn resolve_checks_range() {
        let a = parse("4x65535").unwrap();
        assert!(resolve(&a, 1).is_ok());
        assert!(matches!(resolve(&a, 2), Err(PlcError::OutOfRange(_))));
        assert!(matches!(resolve(&a, 0), Err(PlcError::OutOfRange(_))));
        let d = Address { area: Area::new("D"), index: 0 };
        assert!(matches!(resolve(&d, 1), Err(PlcError::OutOfRange(_))));
    }
}
