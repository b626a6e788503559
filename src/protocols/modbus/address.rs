//! Modbus addresses. Three notations name the same [`Address`]:
//!
//! | text | names | PDU address |
//! |---|---|---|
//! | `4x4000`, `3x0`, `1x7`, `0x10` | area notation: table and PDU address, decimal | 4000, 0, 7, 10 |
//! | `40001`, `400001`, `30001`, `10001`, `00001` | Modicon reference: table digit, then a 1-based number (4 or 5 digits) | reference - 1 |
//! | `%MW100`, `MW100`; `%M100` | Schneider: holding register 100; coil 100 | 100 |
//!
//! The area notation is rackd's own and what it prints: `4x4000` is holding register 4000
//! (PDU address 4000 = 0x0FA0, the PLC's MW4000). `0x10` is coil ten (the Modicon "0x"
//! area), never hex sixteen: the number is always decimal. A Modicon reference counts from
//! 1, so `40001` is `4x0`; the five-digit form reaches `49999` (4x9998), the six-digit
//! form `465536` (4x65535). Schneider numbers `%MW` from 0 as the PDU does (`%MW0` is
//! 400001 in Unity/EcoStruxure), so `%MW100` is `4x100`; `MW100` without `%` is the same.

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

/// Parses any of the module's notations (case-insensitive): `4x4000`, `40001`, `%MW100`.
pub fn parse(text: &str) -> Result<Address, PlcError> {
    let bad = |reason| PlcError::BadAddress { text: text.to_string(), reason };
    let t = text.trim();
    let upper = t.to_ascii_uppercase();
    if let Some(number) = upper.strip_prefix("%MW").or_else(|| upper.strip_prefix("MW")) {
        return schneider(Table::HoldingRegisters, number).ok_or_else(|| bad("%MW takes 0..65535"));
    }
    if let Some(number) = upper.strip_prefix("%M") {
        return schneider(Table::Coils, number).ok_or_else(|| bad("%M takes 0..65535"));
    }
    if !t.is_empty() && t.bytes().all(|b| b.is_ascii_digit()) {
        return modicon(t).map_err(bad);
    }
    let (prefix, number) = t.split_at_checked(2).ok_or_else(|| bad("expected 4x100, 40101 or %MW100"))?;
    let area = Area::new(prefix);
    Table::from_area(&area)
        .ok_or_else(|| bad("expected 4x100 (area notation), 40101 (Modicon reference) or %MW100"))?;
    if number.is_empty() || !number.bytes().all(|b| b.is_ascii_digit()) {
        return Err(bad("in the area notation the number is decimal: 0x10 is coil 10 (Modicon area 0x), \
                        not hex 16; registers are 4x"));
    }
    let index: u32 = number.parse().map_err(|_| bad("the address must be 0..65535"))?;
    if index > 0xFFFF {
        return Err(bad("the address must be 0..65535"));
    }
    Ok(Address { area, index })
}

fn schneider(table: Table, number: &str) -> Option<Address> {
    let index =
        number.parse::<u32>().ok().filter(|&i| i <= 0xFFFF && number.bytes().all(|b| b.is_ascii_digit()))?;
    Some(Address { area: Area::new(table.area_name()), index })
}

/// A 1-based Modicon reference: the table digit and 4 or 5 more digits.
fn modicon(digits: &str) -> Result<Address, &'static str> {
    let table = match digits.as_bytes()[0] {
        b'0' => Table::Coils,
        b'1' => Table::DiscreteInputs,
        b'3' => Table::InputRegisters,
        b'4' => Table::HoldingRegisters,
        _ => return Err("a Modicon reference starts with 0, 1, 3 or 4 (40001 is holding register 4x0)"),
    };
    if !matches!(digits.len(), 5 | 6) {
        return Err("a Modicon reference has 5 or 6 digits (40001 or 400001 = 4x0); \
                    the area notation is 4x0");
    }
    match digits[1..].parse::<u32>() {
        Ok(n @ 1..=0x1_0000) => Ok(Address { area: Area::new(table.area_name()), index: n - 1 }),
        _ => Err("a Modicon reference counts from 1 (40001 = 4x0) up to 465536 (4x65535)"),
    }
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
        for text in [
            "",
            "4",
            "4x",
            "2x10",
            "4x65536",
            "4x-1",
            "4x0x10",
            "D200",
            "4x99999999999",
            "0x1A",
            "4000",
            "20001",
            "40000",
            "465537",
            "4000001",
            "%MW65536",
            "%MWx",
            "%IW0",
        ] {
            assert!(matches!(parse(text), Err(PlcError::BadAddress { .. })), "{text}");
        }
    }

    #[test]
    fn modicon_references_count_from_one() {
        // Modicon reference notation (Modicon Modbus Protocol Reference Guide PI-MBUS-300,
        // "4xxxx" references): 40001 is the first holding register, PDU address 0.
        for (text, area, index) in [
            ("40001", "4X", 0),
            ("400001", "4X", 0),
            ("44001", "4X", 4000),
            ("465536", "4X", 65535),
            ("30001", "3X", 0),
            ("10002", "1X", 1),
            ("00001", "0X", 0),
            ("000011", "0X", 10),
            ("%MW100", "4X", 100),
            ("mw100", "4X", 100),
            ("%MW0", "4X", 0),
            ("%M10", "0X", 10),
        ] {
            assert_eq!(parse(text).unwrap(), Address { area: Area::new(area), index }, "{text}");
        }
    }

    #[test]
    fn an_error_on_a_hex_looking_coil_says_the_number_is_decimal() {
        let Err(PlcError::BadAddress { reason, .. }) = parse("0x1A") else { panic!() };
        assert!(reason.contains("coil 10") && reason.contains("not hex"), "{reason}");
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
