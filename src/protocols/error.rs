//! The typed errors every protocol reports through [`PlcMemory`](super::PlcMemory).

use std::time::Duration;

/// Why a PLC request failed.
#[derive(Debug, thiserror::Error)]
pub enum PlcError {
    /// No valid reply arrived within the timeout, after every retry.
    #[error("no reply after {attempts} attempt(s) of {timeout:?} each")]
    Timeout {
        /// How many times the request was sent.
        attempts: u32,
        /// The timeout of each attempt.
        timeout: Duration,
    },
    /// The connection could not be made or was lost.
    #[error("connection lost: {0}")]
    Connection(#[from] std::io::Error),
    /// The device answered with its own error code (Modbus exception, MC end code,
    /// MEWTOCOL error code, PPI item return code).
    #[error("{protocol} device error {code:#06X}: {meaning}")]
    Device {
        /// The protocol that carried the code ("modbus", "mc3e", ...).
        protocol: &'static str,
        /// The device's own code.
        code: u32,
        /// What the code means, from the protocol's documentation.
        meaning: &'static str,
    },
    /// The reply could not be decoded or did not match the request.
    #[error("malformed reply: {0}")]
    Malformed(&'static str),
    /// The address or count is outside what the protocol or area allows.
    #[error("address out of range: {0}")]
    OutOfRange(&'static str),
    /// The address text is not valid in this protocol's notation.
    #[error("bad address {text:?}: {reason}")]
    BadAddress {
        /// The text as given.
        text: String,
        /// What is wrong with it.
        reason: &'static str,
    },
}
