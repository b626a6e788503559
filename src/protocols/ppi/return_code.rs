//! PPI / S7 return codes: the per-item code of a data item, and the error class of a
//! refused request, with their meanings.

use crate::protocols::parse_number;
use crate::protocols::{BadDeviceCode, DeviceCode, PlcError};

/// What an S7-200 answered instead of doing a request.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ReturnCode {
    /// The data item's own return code (anything but [`SUCCESS`]).
    Item(u8),
    /// The whole request was refused with an error class and code (`32 02 ... 85 00`).
    Refused {
        /// The error class (0x81..0x87).
        class: u8,
        /// The code within the class.
        code: u8,
    },
}

impl ReturnCode {
    /// The code as one number: an item code below 0x100, a refusal as class x 256 + code.
    pub fn number(self) -> u32 {
        match self {
            ReturnCode::Item(code) => u32::from(code),
            ReturnCode::Refused { class, code } => u32::from(class) << 8 | u32::from(code),
        }
    }

    /// What the code means: the item code's meaning, or the refusal's error class's.
    pub fn meaning(self) -> &'static str {
        match self {
            ReturnCode::Item(code) => item_meaning(code),
            ReturnCode::Refused { class, .. } => class_meaning(class),
        }
    }
}

/// Item return code for success.
pub const SUCCESS: u8 = 0xFF;
/// Item return code: hardware fault.
pub const HARDWARE_FAULT: u8 = 0x01;
/// Item return code: access to the object not allowed.
pub const ACCESS_DENIED: u8 = 0x03;
/// Item return code: address out of range.
pub const OUT_OF_RANGE: u8 = 0x05;
/// Item return code: data type not supported.
pub const TYPE_NOT_SUPPORTED: u8 = 0x06;
/// Item return code: data type or size mismatch.
pub const SIZE_MISMATCH: u8 = 0x07;
/// Item return code: object does not exist.
pub const NO_OBJECT: u8 = 0x0A;

impl std::str::FromStr for ReturnCode {
    type Err = BadDeviceCode;

    /// An item return code below 0x100 (not FF, success), or a refusal as error class x 256
    /// + code (`0x8500`, or 34048), in decimal or `0x` hexadecimal.
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match parse_number(text) {
            Some(code) if code < 0x100 && code != u32::from(SUCCESS) => Ok(ReturnCode::Item(code as u8)),
            Some(code @ 0x100..=0xFFFF) => {
                Ok(ReturnCode::Refused { class: (code >> 8) as u8, code: code as u8 })
            }
            _ => Err(BadDeviceCode {
                protocol: "ppi",
                text: text.to_owned(),
                expected: "an item return code below 0x100 (not 0xFF) or class x 256 + code, e.g. 0x8500",
            }),
        }
    }
}

/// What an item return code means.
pub fn item_meaning(code: u8) -> &'static str {
    match code {
        SUCCESS => "success",
        HARDWARE_FAULT => "hardware fault",
        ACCESS_DENIED => "accessing the object not allowed",
        OUT_OF_RANGE => "address out of range",
        TYPE_NOT_SUPPORTED => "data type not supported",
        SIZE_MISMATCH => "data type or size mismatch",
        NO_OBJECT => "object does not exist",
        _ => "unknown item return code",
    }
}

/// What a header error class means (S7 protocol error classes).
pub fn class_meaning(class: u8) -> &'static str {
    match class {
        0x81 => "application relationship error",
        0x82 => "object definition error",
        0x83 => "no resources available",
        0x84 => "error on service processing",
        0x85 => "error on supplies (request refused)",
        0x87 => "access error",
        _ => "unknown error class",
    }
}

/// The error for a failed item: `code` is the item's return code (below 0x100).
pub fn item_error(code: u8) -> PlcError {
    PlcError::Device(DeviceCode::Ppi(ReturnCode::Item(code)))
}

/// The error for a refused request: `code` is class x 256 + code (0x8500 and up).
pub fn refused(class: u8, code: u8) -> PlcError {
    PlcError::Device(DeviceCode::Ppi(ReturnCode::Refused { class, code }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_keep_their_number_and_meaning() {
        for (code, text) in [
            (0x01, "hardware fault"),
            (0x03, "accessing the object not allowed"),
            (0x05, "address out of range"),
            (0x06, "data type not supported"),
            (0x07, "data type or size mismatch"),
            (0x0A, "object does not exist"),
            (0x42, "unknown item return code"),
        ] {
            assert!(matches!(item_error(code), PlcError::Device(DeviceCode::Ppi(c))
                if c == ReturnCode::Item(code) && c.number() == u32::from(code) && c.meaning() == text));
        }
        assert!(matches!(refused(0x85, 0), PlcError::Device(DeviceCode::Ppi(c))
            if c.number() == 0x8500 && c.meaning().starts_with("error on supplies")));
        assert_eq!(class_meaning(0x10), "unknown error class");
    }
}
