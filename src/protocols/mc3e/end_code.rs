//! The end code catalogue: what a nonzero end code in a 3E response means.
//!
//! Meanings are paraphrased from the end code tables of the MELSEC Q-series Ethernet module
//! and MC protocol reference manuals (codes C050..C0xx are raised by the Ethernet interface
//! or CPU while checking the request). Codes outside this table are still surfaced with
//! their number and a generic meaning.

use crate::protocols::{BadDeviceCode, DeviceCode, PlcError};

/// A nonzero end code in a 3E response: the PLC's refusal of a request.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct EndCode(pub u16);

impl EndCode {
    /// What the code means (see [`meaning`]).
    pub fn meaning(self) -> &'static str {
        meaning(self.0)
    }
}

/// ASCII data that cannot be converted to binary was received.
pub const ASCII_NOT_CONVERTIBLE: u16 = 0xC050;
/// The number of read/write points is outside the allowed range (this server's answer to
/// any batch count of 0 or above the limit, as the seed's crane PLC answers a long read).
pub const POINTS_OUT_OF_RANGE: u16 = 0xC051;
/// The start device plus the point count exceeds the device's range.
pub const DEVICE_OUT_OF_RANGE: u16 = 0xC056;
/// Wrong command or subcommand, or a command the target cannot execute.
pub const UNKNOWN_COMMAND: u16 = 0xC059;
/// The specified device cannot be read or written (unknown device code).
pub const DEVICE_NOT_ACCESSIBLE: u16 = 0xC05B;
/// Error in the request contents (bit-unit access to a word device, ...).
pub const BAD_REQUEST_CONTENTS: u16 = 0xC05C;
/// Error in the request data (a bit value other than 0 or 1, ...).
pub const BAD_REQUEST_DATA: u16 = 0xC060;
/// The request data length does not match the number of data bytes.
pub const LENGTH_MISMATCH: u16 = 0xC061;

impl std::str::FromStr for EndCode {
    type Err = BadDeviceCode;

    /// A nonzero code in hexadecimal as the manuals write it (`C051`, or `0xC051`).
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let hex = text.trim().trim_start_matches("0x").trim_start_matches("0X");
        match u16::from_str_radix(hex, 16) {
            Ok(code) if code != 0 => Ok(EndCode(code)),
            _ => Err(BadDeviceCode {
                protocol: "mc3e",
                text: text.to_owned(),
                expected: "a nonzero hexadecimal end code such as C051",
            }),
        }
    }
}

/// What an end code means; never fails (unknown codes get a generic meaning).
pub fn meaning(code: u16) -> &'static str {
    match code {
        0x0000 => "normal completion",
        0xC050 => "ASCII code data that cannot be converted to binary was received",
        0xC051..=0xC054 => "the number of read/write points is outside the allowed range",
        0xC055 => "the number of file data read/write points is outside the allowed range",
        0xC056 => "the read/write request exceeds the largest device number",
        0xC057 => "the request data length does not match the data in the request (file data)",
        0xC058 => "the request data length after ASCII-to-binary conversion does not match the data",
        0xC059 => "wrong command or subcommand, or a command the target cannot execute",
        0xC05A | 0xC05B => "the target cannot read or write the specified device",
        0xC05C => "error in the request contents (e.g. bit-unit access to a word device)",
        0xC05D => "monitor registration has not been made",
        0xC05E => "the communication time with the CPU exceeded the monitoring timer",
        0xC05F => "the request cannot be executed by the target CPU module",
        0xC060 => "error in the request data (e.g. bit data other than 0 or 1)",
        0xC061 => "the request data length does not match the number of data",
        0xC06F => "communication data code mismatch (ASCII request to a binary port or vice versa)",
        0xC070 => "device memory extension cannot be specified for the target station",
        0xC072 => "error in the request contents for the target (e.g. unsupported word-unit access)",
        0xC074 => "the target CPU cannot execute the request (e.g. wrong network number)",
        0x4000..=0x4FFF => "error detected by the CPU module (see the CPU's error code list)",
        _ => "unknown end code (see the PLC's or Ethernet module's manual)",
    }
}

/// The typed error for a nonzero end code.
pub fn to_error(code: u16) -> PlcError {
    PlcError::Device(DeviceCode::Mc3e(EndCode(code)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn brief_codes_have_specific_meanings() {
        for code in
            [0xC050, 0xC051, 0xC052, 0xC055, 0xC056, 0xC058, 0xC059, 0xC05B, 0xC05C, 0xC05F, 0xC060, 0xC061]
        {
            assert!(!meaning(code).starts_with("unknown"), "{code:#06X}");
        }
        assert!(meaning(0xC0FF).starts_with("unknown"));
    }

    #[test]
    fn error_carries_code_and_meaning() {
        match to_error(0xC051) {
            PlcError::Device(DeviceCode::Mc3e(code)) => {
                assert_eq!(code, EndCode(0xC051));
                assert!(code.meaning().contains("points"));
            }
            other => panic!("{other:?}"),
        }
        assert!(to_error(0xC059).to_string().contains("0xC059"));
    }
}
