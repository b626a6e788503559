//! Modbus exception codes: what a device answers instead of data when it refuses a request.

use crate::protocols::parse_number;
use crate::protocols::{BadDeviceCode, DeviceCode, PlcError};

/// A Modbus exception code, as carried by an exception reply (function | 0x80, one code byte).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Exception(pub u8);

impl Exception {
    /// 01: the function code is not supported by the device.
    pub const ILLEGAL_FUNCTION: Exception = Exception(0x01);
    /// 02: the address (or address + count) is outside the device's memory.
    pub const ILLEGAL_DATA_ADDRESS: Exception = Exception(0x02);
    /// 03: a value in the request is not allowed (count out of limits, bad coil value).
    pub const ILLEGAL_DATA_VALUE: Exception = Exception(0x03);
    /// 04: the device failed while performing the request.
    pub const SERVER_DEVICE_FAILURE: Exception = Exception(0x04);
    /// 06: the device is busy with a long command.
    pub const SERVER_DEVICE_BUSY: Exception = Exception(0x06);
    /// 0B: a gateway got no answer from the target device.
    pub const GATEWAY_TARGET_FAILED: Exception = Exception(0x0B);

    /// What the code means, in the words of the Modbus specification.
    pub fn meaning(self) -> &'static str {
        match self.0 {
            0x01 => "illegal function",
            0x02 => "illegal data address",
            0x03 => "illegal data value",
            0x04 => "server device failure",
            0x05 => "acknowledge",
            0x06 => "server device busy",
            0x08 => "memory parity error",
            0x0A => "gateway path unavailable",
            0x0B => "gateway target device failed to respond",
            _ => "unknown exception code",
        }
    }
}

impl std::fmt::Display for Exception {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "exception {:02X} \"{}\"", self.0, self.meaning())
    }
}

impl From<Exception> for PlcError {
    fn from(e: Exception) -> Self {
        PlcError::Device(DeviceCode::Modbus(e))
    }
}

impl std::str::FromStr for Exception {
    type Err = BadDeviceCode;

    /// A code in decimal or `0x` hexadecimal, 1..=255 (`2`, `0x0B`).
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match parse_number(text) {
            Some(code @ 1..=255) => Ok(Exception(code as u8)),
            _ => Err(BadDeviceCode {
                protocol: "modbus",
                text: text.to_owned(),
                expected: "an exception code 1..=255, decimal or 0x hexadecimal",
            }),
        }
    }
}
