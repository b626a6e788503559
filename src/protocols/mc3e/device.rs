//! MC device kinds, their binary device codes, and addresses in each device's native radix.
//!
//! Device codes (binary, one byte) from the MELSEC Q/L MC protocol reference manual's device
//! table (the same values as pymcprotocol's `mcprotocolconst.py`): D `A8`, W `B4`, R `AF`,
//! ZR `B0`, SD `A9`, SW `B5`, M `90`, X `9C`, Y `9D`, B `A0`, L `92`, SM `91`, F `93`, V `94`,
//! SB `A1`; timers TS (contact) `C1`, TC (coil) `C0`, TN (current value) `C2`; retentive
//! timers STS `C7`, STC `C6`, STN `C8`; counters CS `C4`, CC `C3`, CN `C5`. X, Y, B, W, SB
//! and SW are numbered in hexadecimal (`X1A` is 0x1A), the others in decimal (`D200` is 200).
//!
//! Decisions where the manual leaves a choice:
//! - Retentive timers are written `STS`/`STC`/`STN` as GX Works does; the MC manual's
//!   `SS`/`SC`/`SN` are accepted too and mean the same devices.
//! - Contacts and coils (TS, TC, STS, STC, CS, CC) are bit devices, current values (TN, STN,
//!   CN) word devices; counters' current values are 16-bit (Q/L; the 32-bit long counters of
//!   iQ-R need 4-byte device numbers, which rackd does not send).
//! - `K4M100` (GX Works' digit notation) names 16 bits from M100 as one word; only K4 is
//!   accepted, because the MC protocol moves bit devices in words of exactly 16 points: K1..K3
//!   have no word access, and K8 (32 bits) is two K4 words (`read K4M100 2`). The start need
//!   not be a multiple of 16: the manual's own word-unit example reads M100..M131. A PLC that
//!   refuses a start answers with an end code, which rackd surfaces.

use crate::protocols::{Area, PlcError};

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
    /// Special register (word, decimal).
    SD,
    /// Link special register (word, hexadecimal).
    SW,
    /// Timer current value (word, decimal).
    TN,
    /// Retentive timer current value (word, decimal).
    STN,
    /// Counter current value (word, decimal).
    CN,
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
    /// Special relay (bit, decimal).
    SM,
    /// Annunciator (bit, decimal).
    F,
    /// Edge relay (bit, decimal).
    V,
    /// Link special relay (bit, hexadecimal).
    SB,
    /// Timer contact (bit, decimal).
    TS,
    /// Timer coil (bit, decimal).
    TC,
    /// Retentive timer contact (bit, decimal).
    STS,
    /// Retentive timer coil (bit, decimal).
    STC,
    /// Counter contact (bit, decimal).
    CS,
    /// Counter coil (bit, decimal).
    CC,
}

impl Device {
    /// Every supported device, word devices first.
    pub const ALL: [Device; 24] = [
        Device::D,
        Device::W,
        Device::R,
        Device::ZR,
        Device::SD,
        Device::SW,
        Device::TN,
        Device::STN,
        Device::CN,
        Device::M,
        Device::X,
        Device::Y,
        Device::B,
        Device::L,
        Device::SM,
        Device::F,
        Device::V,
        Device::SB,
        Device::TS,
        Device::TC,
        Device::STS,
        Device::STC,
        Device::CS,
        Device::CC,
    ];

    /// The binary device code.
    pub fn code(self) -> u8 {
        match self {
            Device::D => 0xA8,
            Device::W => 0xB4,
            Device::R => 0xAF,
            Device::ZR => 0xB0,
            Device::SD => 0xA9,
            Device::SW => 0xB5,
            Device::TN => 0xC2,
            Device::STN => 0xC8,
            Device::CN => 0xC5,
            Device::M => 0x90,
            Device::X => 0x9C,
            Device::Y => 0x9D,
            Device::B => 0xA0,
            Device::L => 0x92,
            Device::SM => 0x91,
            Device::F => 0x93,
            Device::V => 0x94,
            Device::SB => 0xA1,
            Device::TS => 0xC1,
            Device::TC => 0xC0,
            Device::STS => 0xC7,
            Device::STC => 0xC6,
            Device::CS => 0xC4,
            Device::CC => 0xC3,
        }
    }

    /// The device with this binary code, if supported.
    pub fn from_code(code: u8) -> Option<Device> {
        Device::ALL.into_iter().find(|d| d.code() == code)
    }

    /// The device's name as written in addresses (`"D"`, `"ZR"`, `"STN"`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Device::D => "D",
            Device::W => "W",
            Device::R => "R",
            Device::ZR => "ZR",
            Device::SD => "SD",
            Device::SW => "SW",
            Device::TN => "TN",
            Device::STN => "STN",
            Device::CN => "CN",
            Device::M => "M",
            Device::X => "X",
            Device::Y => "Y",
            Device::B => "B",
            Device::L => "L",
            Device::SM => "SM",
            Device::F => "F",
            Device::V => "V",
            Device::SB => "SB",
            Device::TS => "TS",
            Device::TC => "TC",
            Device::STS => "STS",
            Device::STC => "STC",
            Device::CS => "CS",
            Device::CC => "CC",
        }
    }

    /// The device with this name (case-insensitive), if supported; the MC manual's `SS`,
    /// `SC`, `SN` name the retentive timer's STS, STC, STN.
    pub fn from_name(name: &str) -> Option<Device> {
        let alias = match name.to_ascii_uppercase().as_str() {
            "SS" => Some(Device::STS),
            "SC" => Some(Device::STC),
            "SN" => Some(Device::STN),
            _ => None,
        };
        alias.or_else(|| Device::ALL.into_iter().find(|d| d.name().eq_ignore_ascii_case(name)))
    }

    /// Whether this is a bit device (relays, inputs, outputs, timer/counter contacts and coils).
    pub fn is_bit(self) -> bool {
        !matches!(
            self,
            Device::D
                | Device::W
                | Device::R
                | Device::ZR
                | Device::SD
                | Device::SW
                | Device::TN
                | Device::STN
                | Device::CN
        )
    }

    /// Whether a master may write it: not X (the PLC refreshes inputs from the field) nor the
    /// timer and counter contacts (the timer or counter itself sets them).
    pub fn is_writable(self) -> bool {
        !matches!(self, Device::X | Device::TS | Device::STS | Device::CS)
    }

    /// The radix device numbers are written in: 16 for X, Y, B, W, SB, SW; 10 otherwise.
    pub fn radix(self) -> u32 {
        match self {
            Device::X | Device::Y | Device::B | Device::W | Device::SB | Device::SW => 16,
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

    /// The device an [`Address`](crate::protocols::Address)'s area names (not a `K4` word
    /// view: see [`word_view`](super::address::word_view)).
    pub fn of_area(area: &Area) -> Result<Device, PlcError> {
        Device::from_name(area.name()).ok_or(PlcError::OutOfRange(UNKNOWN))
    }
}

const UNKNOWN: &str = "not an MC device (D, W, R, ZR, SD, SW, TN, STN, CN, M, X, Y, B, L, SM, F, V, SB, \
                       TS, TC, STS, STC, CS, CC, or K4 + a bit device)";

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
        // Timer/counter and special devices, as pymcprotocol's mcprotocolconst.py lists them.
        let more = [
            (Device::TS, 0xC1),
            (Device::TC, 0xC0),
            (Device::TN, 0xC2),
            (Device::STS, 0xC7),
            (Device::STC, 0xC6),
            (Device::STN, 0xC8),
            (Device::CS, 0xC4),
            (Device::CC, 0xC3),
            (Device::CN, 0xC5),
            (Device::SM, 0x91),
            (Device::SD, 0xA9),
            (Device::F, 0x93),
            (Device::V, 0x94),
            (Device::SB, 0xA1),
            (Device::SW, 0xB5),
        ];
        for (d, c) in more {
            assert_eq!(d.code(), c, "{d:?}");
        }
        assert_eq!(Device::from_name("sn"), Some(Device::STN));
        assert_eq!(Device::from_name("SS"), Some(Device::STS));
    }
}
