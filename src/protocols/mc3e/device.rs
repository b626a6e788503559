//! MC device kinds, their binary device codes, and addresses in each device's native radix.
//!
//! Device codes (binary, one byte) from the MELSEC Q/L MC protocol reference manual's device
//! table: D `A8`, W `B4`, R `AF`, ZR `B0`, M `90`, X `9C`, Y `9D`, B `A0`, L `92`. X, Y, B and
//! W are numbered in hexadecimal (`X1A` is 0x1A), the others in decimal (`D200` is 200).

use crate::protocols::{Address, Area, PlcError};

/// The largest device number a 3E binary request can carry (3 bytes).
pub const MAX_DEVICE_NUMBER: u32 = 0xFF_FFFF;

/// A device (memory area) kind this implementation supports.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Device {
    /// Data register (word, decimal).
    D,
    /// Link register (word, hexadecimal).
    W,
    /// File register, block-switched (word, decimal).
    R,
    /// File register, serial numbers (word, decimal).
    ZR,
    /// Internal relay (bit, decimal).
    M,
    /// Input (bit, hexadecimal).
    X,
    /// Output (bit, hexadecimal).
    Y,
    /// Link relay (bit, hexadecimal).
    B,
    /// Latch relay (bit, decimal).
    L,
}

impl Device {
    /// Every supported device, word devices first.
    pub const ALL: [Device; 9] =
        [Device::D, Device::W, Device::R, Device::ZR, Device::M, Device::X, Device::Y, Device::B, Device::L];

    /// The binary device code.
    pub fn code(self) -> u8 {
        match self {
            Device::D => 0xA8,
            Device::W => 0xB4,
            Device::R => 0xAF,
            Device::ZR => 0xB0,
            Device::M => 0x90,
            Device::X => 0x9C,
            Device::Y => 0x9D,
            Device::B => 0xA0,
            Device::L => 0x92,
        }
    }

    /// The device with this binary code, if supported.
    pub fn from_code(code: u8) -> Option<Device> {
        Device::ALL.into_iter().find(|d| d.code() == code)
    }

    /// The device's name as written in addresses (`"D"`, `"ZR"`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Device::D => "D",
            Device::W => "W",
            Device::R => "R",
            Device::ZR => "ZR",
            Device::M => "M",
            Device::X => "X",
            Device::Y => "Y",
            Device::B => "B",
            Device::L => "L",
        }
    }

    /// The device with this name (case-insensitive), if supported.
    pub fn from_name(name: &str) -> Option<Device> {
        Device::ALL.into_iter().find(|d| d.name().eq_ignore_ascii_case(name))
    }

    /// Whether this is a bit device (M, X, Y, B, L).
    pub fn is_bit(self) -> bool {
        matches!(self, Device::M | Device::X | Device::Y | Device::B | Device::L)
    }

    /// The radix device numbers are written in: 16 for X, Y, B, W; 10 otherwise.
    pub fn radix(self) -> u32 {
        match self {
            Device::X | Device::Y | Device::B | Device::W => 16,
            _ => 10,
        }
    }

    /// The address text for device number `number` (`X1A`, `D200`).
    pub fn format(self, number: u32) -> String {
        if self.radix() == 16 {
            format!("{}{:X}", self.name(), number)
        } else {
            format!("{}{}", self.name(), number)
        }
    }

    /// The device an [`Address`]'s area names.
    pub fn of_area(area: &Area) -> Result<Device, PlcError> {
        Device::from_name(area.name())
            .ok_or(PlcError::OutOfRange("not an MC 3E device (D, W, R, ZR, M, X, Y, B, L)"))
    }
}

/// Parses `D200`, `x1a`, `ZR100000` into an [`Address`] (area = device name, index = number).
pub fn parse_address(text: &str) -> Result<Address, PlcError> {
    let bad = |reason| PlcError::BadAddress { text: text.to_owned(), reason };
    let t = text.trim();
    // ZR is the only two-letter device; try it before the one-letter ones.
    let (device, digits) = match t.get(..2).and_then(Device::from_name) {
        Some(d) => (d, &t[2..]),
        None => match t.get(..1).and_then(Device::from_name) {
            Some(d) => (d, &t[1..]),
            None => return Err(bad("unknown device (expected D, W, R, ZR, M, X, Y, B or L)")),
        },
    };
    if digits.is_empty() {
        return Err(bad("missing device number"));
    }
    if !digits.chars().all(|c| c.is_digit(device.radix())) {
        return Err(bad(if device.radix() == 16 {
            "device number must be hexadecimal for X, Y, B, W"
        } else {
            "device number must be decimal for D, R, ZR, M, L"
        }));
    }
    let number = u32::from_str_radix(digits, device.radix()).map_err(|_| bad("device number too large"))?;
    if number > MAX_DEVICE_NUMBER {
        return Err(bad("device number above 0xFFFFFF"));
    }
    Ok(Address { area: Area::new(device.name()), index: number })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_and_match_the_manual() {
        let expect = [(Device::D, 0xA8), (Device::W, 0xB4), (Device::R, 0xAF), (Device::ZR, 0xB0)];
        for (d, c) in expect {
            assert_eq!(d.code(), c);
        }
        for d in Device::ALL {
            assert_eq!(Device::from_code(d.code()), Some(d));
            assert_eq!(Device::from_name(d.name()), Some(d));
        }
        assert_eq!(Device::X.code(), 0x9C);
        assert_eq!(Device::Y.code(), 0x9D);
        assert_eq!(Device::M.code(), 0x90);
        assert_eq!(Device::B.code(), 0xA0);
        assert_eq!(Device::L.code(), 0x92);
        assert_eq!(Device::from_code(0x00), None);
    }

    #[test]
    fn native_radix() {
        assert_eq!(parse_address("X1A").unwrap(), Address { area: Area::new("X"), index: 0x1A });
        assert_eq!(parse_address("d200").unwrap(), Address { area: Area::new("D"), index: 200 });
        assert_eq!(parse_address("W1F").unwrap().index, 0x1F);
        assert_eq!(parse_address("BFF").unwrap(), Address { area: Area::new("B"), index: 0xFF });
        assert_eq!(parse_address("ZR100000").unwrap(), Address { area: Area::new("ZR"), index: 100_000 });
        assert_eq!(parse_address("R10").unwrap().area, Area::new("R"));
        assert_eq!(Device::X.format(0x1A), "X1A");
        assert_eq!(Device::D.format(200), "D200");
    }

    #[test]
    fn rejects_bad_text() {
        for bad in ["", "D", "D1A", "Q5", "M-1", "D16777216", "XFFFFFFF", "ZR", "D 1"] {
            assert!(matches!(parse_address(bad), Err(PlcError::BadAddress { .. })), "{bad}");
        }
        assert_eq!(parse_address("XFFFFFF").unwrap().index, MAX_DEVICE_NUMBER);
    }
}
