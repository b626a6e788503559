//! MEWTOCOL-COM error codes (the two digits after `!`) and their meanings.

use crate::protocols::{BadDeviceCode, DeviceCode, PlcError};

/// A MEWTOCOL-COM error code: the PLC's refusal of a command (`!` and two digits).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ErrorCode(pub u8);

impl ErrorCode {
    /// What the code means (see [`meaning`]).
    pub fn meaning(self) -> &'static str {
        meaning(self.0)
    }
}

/// BCC error.
pub const BCC_ERROR: u8 = 40;
/// Format error.
pub const FORMAT_ERROR: u8 = 41;
/// Command not supported.
pub const NOT_SUPPORTED: u8 = 42;
/// Procedure error (multi-frame).
pub const PROCEDURE_ERROR: u8 = 43;
/// Parameter error (counts, ranges).
pub const PARAMETER_ERROR: u8 = 60;
/// Data error (contact, area or number out of range, bad data).
pub const DATA_ERROR: u8 = 61;
/// Registration error.
pub const REGISTRATION_ERROR: u8 = 62;
/// PLC mode error (e.g. a write while the PLC forbids it).
pub const MODE_ERROR: u8 = 63;
/// Protect error: a write into memory the PLC protects (the simulators' read-only ranges).
pub const PROTECT_ERROR: u8 = 65;

impl std::str::FromStr for ErrorCode {
    type Err = BadDeviceCode;

    /// Two decimal digits as the `!` reply carries them (`63`), 1..=99.
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match text.trim().parse::<u8>() {
            Ok(code @ 1..=99) => Ok(ErrorCode(code)),
            _ => Err(BadDeviceCode {
                protocol: "mewtocol",
                text: text.to_owned(),
                expected: "a decimal error code 1..=99 such as 63",
            }),
        }
    }
}

/// What an error code means, from the MEWTOCOL-COM documentation (spec/mewtocol.md).
pub fn meaning(code: u8) -> &'static str {
    match code {
        BCC_ERROR => "BCC error",
        FORMAT_ERROR => "format error",
        NOT_SUPPORTED => "command not supported",
        PROCEDURE_ERROR => "procedure error (multi-frame)",
        PARAMETER_ERROR => "parameter error",
        DATA_ERROR => "data error",
        REGISTRATION_ERROR => "registration error",
        MODE_ERROR => "PLC mode error",
        PROTECT_ERROR => "protect error (write-protected memory)",
        _ => "unknown MEWTOCOL error code",
    }
}

/// The [`PlcError`] for an error response.
pub fn device_error(code: u8) -> PlcError {
    PlcError::Device(DeviceCode::Mewtocol(ErrorCode(code)))
}

/// Parses the body of an `!` frame: two decimal digits.
pub fn parse(body: &[u8]) -> Option<u8> {
    match body {
        [a @ b'0'..=b'9', b @ b'0'..=b'9'] => Some((a - b'0') * 10 + (b - b'0')),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_documented_code_has_its_meaning() {
        for (code, text) in [
            (40, "BCC error"),
            (41, "format error"),
            (42, "command not supported"),
            (43, "procedure error (multi-frame)"),
            (60, "parameter error"),
            (61, "data error"),
            (62, "registration error"),
            (63, "PLC mode error"),
            (99, "unknown MEWTOCOL error code"),
        ] {
            match device_error(code) {
                PlcError::Device(DeviceCode::Mewtocol(c)) => assert_eq!((c.0, c.meaning()), (code, text)),
                other => panic!("{other:?}"),
            }
        }
        assert_eq!(parse(b"63"), Some(63));
        assert_eq!(parse(b"6"), None);
        assert_eq!(parse(b"6x"), None);
    }
}
