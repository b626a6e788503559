//! MC addresses in text: each device's native radix (`X1A` hexadecimal, `D200` decimal) and
//! GX Works' `K4` digit notation for a bit device read as 16-bit words (`K4M100`), the
//! decisions about which are in [`super::device`]'s documentation.

use super::device::{Device, MAX_DEVICE_NUMBER};
use crate::protocols::{Address, Area, PlcError};

/// The prefix of an area that reads a bit device as words (`K4M`).
const WORD_VIEW: &str = "K4";

/// The bit device a `K4` area reads as 16-bit words (`K4M` -> M), if it is one.
pub fn word_view(area: &Area) -> Option<Device> {
    let name = area.name().strip_prefix(WORD_VIEW)?;
    Device::from_name(name).filter(|d| d.is_bit())
}

/// How far apart consecutive words are in `Address.index`: 16 points for a `K4` area, 1
/// otherwise.
pub fn step(address: &Address) -> u32 {
    if word_view(&address.area).is_some() { 16 } else { 1 }
}

/// The address text in the device's notation: `K4M116`, `X1A`, `D200`.
pub fn format_address(address: &Address) -> String {
    match (word_view(&address.area), Device::of_area(&address.area)) {
        (Some(d), _) => format!("{WORD_VIEW}{}", d.format(address.index)),
        (None, Ok(d)) => d.format(address.index),
        (None, Err(_)) => format!("{}{}", address.area, address.index),
    }
}

/// Parses `D200`, `x1a`, `ZR100000`, `TN5`, `K4M100` into an [`Address`] (area = device
/// name, or `K4` + bit device name; index = device number).
pub fn parse_address(text: &str) -> Result<Address, PlcError> {
    let bad = |reason| PlcError::BadAddress { text: text.to_owned(), reason };
    let t = text.trim();
    let (words, t) = match t.get(..1).map(|k| k.eq_ignore_ascii_case("K")) {
        Some(true) => match t.get(1..2) {
            Some("4") => (true, &t[2..]),
            _ => {
                return Err(bad(
                    "K digits: only K4 (16 bits as one word) is accepted; for 32 bits read K4 with a count of 2",
                ));
            }
        },
        _ => (false, t),
    };
    // Longest names first: STN before ST.., SM before M, ZR before R.
    let split = (1..=3).rev().find_map(|n| Some((Device::from_name(t.get(..n)?)?, &t[n..])));
    let Some((device, digits)) = split else {
        return Err(bad(
            "unknown device (expected D, W, R, ZR, M, X, Y, B, L, TN, CN, ... see `rackd plc --help`)",
        ));
    };
    if words && !device.is_bit() {
        return Err(bad("K4 reads a bit device as words (K4M100); a word device is already words"));
    }
    if digits.is_empty() {
        return Err(bad("missing device number"));
    }
    if !digits.chars().all(|c| c.is_digit(device.radix())) {
        return Err(bad(if device.radix() == 16 {
            "device number must be hexadecimal for X, Y, B, W, SB, SW"
        } else {
            "device number must be decimal for D, R, ZR, M, L, SM, SD, F, V and the timers and counters"
        }));
    }
    let number = u32::from_str_radix(digits, device.radix()).map_err(|_| bad("device number too large"))?;
    if number > MAX_DEVICE_NUMBER {
        return Err(bad("device number above 0xFFFFFF"));
    }
    let area =
        if words { Area::new(&format!("{WORD_VIEW}{}", device.name())) } else { Area::new(device.name()) };
    Ok(Address { area, index: number })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timers_counters_and_k4() {
        assert_eq!(parse_address("TN5").unwrap(), Address { area: Area::new("TN"), index: 5 });
        assert_eq!(parse_address("STN12").unwrap().area, Area::new("STN"));
        assert_eq!(parse_address("SN12").unwrap().area, Area::new("STN"));
        assert_eq!(parse_address("CS3").unwrap().area, Area::new("CS"));
        assert_eq!(parse_address("SM400").unwrap().area, Area::new("SM"));
        assert_eq!(parse_address("SB1F").unwrap().index, 0x1F);
        assert!(Device::TS.is_bit() && !Device::TN.is_bit() && !Device::CN.is_bit() && Device::CC.is_bit());
        assert!(!Device::TS.is_writable() && Device::TN.is_writable() && Device::TC.is_writable());
        let k4 = parse_address("K4M100").unwrap();
        assert_eq!(k4, Address { area: Area::new("K4M"), index: 100 });
        assert_eq!(word_view(&k4.area), Some(Device::M));
        assert_eq!(step(&k4), 16);
        assert_eq!(format_address(&k4.offset(16)), "K4M116");
        assert_eq!(format_address(&parse_address("k4x10").unwrap()), "K4X10");
        assert_eq!(format_address(&parse_address("x1a").unwrap()), "X1A");
        assert_eq!(word_view(&Area::new("M")), None);
        for bad in ["K4D100", "K8M0", "K1M0", "K", "K4", "K4Q1"] {
            assert!(matches!(parse_address(bad), Err(PlcError::BadAddress { .. })), "{bad}");
        }
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
        for bad in ["", "D", "D1A", "Q5", "M-1", "D16777216", "XFFFFFFF", "ZR", "D 1", "TN1A", "T5"] {
            assert!(matches!(parse_address(bad), Err(PlcError::BadAddress { .. })), "{bad}");
        }
        assert_eq!(parse_address("XFFFFFF").unwrap().index, MAX_DEVICE_NUMBER);
    }
}
