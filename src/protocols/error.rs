//! The typed errors every protocol reports through [`PlcMemory`](super::PlcMemory).
//!
//! A device's own refusal ([`PlcError::Device`]) keeps which protocol's code it is
//! ([`DeviceCode`]), so a caller that cares (the CLI, which words a failure as the device's
//! manual does) matches every protocol exhaustively instead of comparing protocol names.
//! [`DeviceCode`] names every protocol's code type, so it lives in the parent module, which
//! knows the protocols; this module names none of them, and they all report through it.

use std::time::Duration;

use super::DeviceCode;

/// Why a PLC request failed.
#[derive(Debug, thiserror::Error)]
pub enum PlcError {
    /// No valid reply arrived within the timeout, after every retry. When replies did
    /// arrive but were dropped (another transaction id, another unit, late replies to
    /// earlier requests), `dropped` says how many and why, and the message names the quirk
    /// that would take them, if one would.
    #[error("no reply after {attempts} attempt(s) of {timeout:?} each{}", note(.dropped))]
    Timeout {
        /// How many times the request was sent.
        attempts: u32,
        /// The timeout of the last attempt (adaptive timeouts make them differ).
        timeout: Duration,
        /// Replies that arrived during the request but were dropped, if any.
        dropped: Option<Dropped>,
    },
    /// The connection could not be made or was lost.
    #[error("connection lost: {0}")]
    Connection(#[from] std::io::Error),
    /// The device answered with its own error code. Never retried: the device answered.
    #[error("{0}")]
    Device(DeviceCode),
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

/// Why a reply that arrived was not taken as the answer.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DropReason {
    /// It carried another transaction id (Modbus TCP/UDP).
    TransactionId,
    /// It carried the PDU reference of an earlier request (PPI).
    PduReference,
    /// It came from another unit or station.
    Unit,
    /// Its MBAP length field was 0 (Modbus TCP/UDP without the `length0` quirk).
    LengthZero,
    /// A late reply to an earlier request, or one that does not match this request
    /// (another function, command or size).
    Stale,
    /// It could not be decoded at all.
    Malformed,
}

impl DropReason {
    /// The quirk that would take such replies, if one would.
    pub fn quirk(self) -> Option<super::Quirk> {
        match self {
            DropReason::TransactionId => Some(super::Quirk::NoTransactionId),
            DropReason::LengthZero => Some(super::Quirk::Length0),
            DropReason::PduReference => Some(super::Quirk::NoPduRef),
            DropReason::Unit | DropReason::Stale | DropReason::Malformed => None,
        }
    }

    fn words(self) -> &'static str {
        match self {
            DropReason::TransactionId => "with another transaction id",
            DropReason::PduReference => "with another PDU reference",
            DropReason::Unit => "from another unit",
            DropReason::LengthZero => "with MBAP length 0",
            DropReason::Stale => "that answer another request",
            DropReason::Malformed => "that could not be decoded",
        }
    }
}

/// Replies dropped during one request: how many, and the commonest reason.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Dropped {
    /// Replies dropped for `reason`.
    pub count: u32,
    /// Why they were dropped.
    pub reason: DropReason,
}

impl std::fmt::Display for Dropped {
    /// `4 replies arrived with another transaction id: the `no-transaction-id` quirk would
    /// take them`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let Dropped { count, reason } = *self;
        let replies = if count == 1 { "reply" } else { "replies" };
        write!(f, "{count} {replies} arrived {}", reason.words())?;
        match reason.quirk() {
            Some(q) => write!(f, ": the `{q}` quirk would take them"),
            None => Ok(()),
        }
    }
}

fn note(dropped: &Option<Dropped>) -> String {
    dropped.map_or_else(String::new, |d| format!(" ({d})"))
}

impl From<DeviceCode> for PlcError {
    fn from(code: DeviceCode) -> Self {
        PlcError::Device(code)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocols::{mc3e, mewtocol, modbus, ppi};

    #[test]
    fn device_errors_read_the_same_for_every_protocol() {
        let cases = [
            (DeviceCode::Modbus(modbus::Exception(2)), "modbus device error 0x0002: illegal data address"),
            (
                DeviceCode::Mc3e(mc3e::EndCode(0xC059)),
                "mc3e device error 0xC059: wrong command or subcommand, or a command the target cannot execute",
            ),
            (DeviceCode::Mewtocol(mewtocol::ErrorCode(63)), "mewtocol device error 0x003F: PLC mode error"),
            (DeviceCode::Ppi(ppi::ReturnCode::Item(0x0A)), "ppi device error 0x000A: object does not exist"),
        ];
        for (code, text) in cases {
            assert_eq!(PlcError::Device(code).to_string(), text);
        }
    }

    #[test]
    fn a_timeout_says_which_replies_were_dropped_and_which_quirk_takes_them() {
        let timeout = Duration::from_millis(300);
        let plain = PlcError::Timeout { attempts: 3, timeout, dropped: None };
        assert_eq!(plain.to_string(), "no reply after 3 attempt(s) of 300ms each");
        let dropped = Some(Dropped { count: 4, reason: DropReason::TransactionId });
        assert_eq!(
            PlcError::Timeout { attempts: 3, timeout, dropped }.to_string(),
            "no reply after 3 attempt(s) of 300ms each (4 replies arrived with another transaction id: \
             the `no-transaction-id` quirk would take them)"
        );
        let dropped = Some(Dropped { count: 1, reason: DropReason::Unit });
        assert!(
            PlcError::Timeout { attempts: 1, timeout, dropped }
                .to_string()
                .ends_with("(1 reply arrived from another unit)")
        );
    }

    #[test]
    fn codes_parse_in_each_manuals_notation() {
        assert_eq!("2".parse(), Ok(modbus::Exception(2)));
        assert_eq!("0x0B".parse(), Ok(modbus::Exception(0x0B)));
        assert!("0".parse::<modbus::Exception>().is_err() && "256".parse::<modbus::Exception>().is_err());
        assert_eq!("C051".parse(), Ok(mc3e::EndCode(0xC051)));
        assert_eq!("0xc059".parse(), Ok(mc3e::EndCode(0xC059)));
        assert!("0".parse::<mc3e::EndCode>().is_err() && "G1".parse::<mc3e::EndCode>().is_err());
        assert_eq!("63".parse(), Ok(mewtocol::ErrorCode(63)));
        assert!("100".parse::<mewtocol::ErrorCode>().is_err());
        assert_eq!("0x0A".parse(), Ok(ppi::ReturnCode::Item(0x0A)));
        assert_eq!("34048".parse(), Ok(ppi::ReturnCode::Refused { class: 0x85, code: 0 }));
        assert!("0xFF".parse::<ppi::ReturnCode>().is_err(), "FF is success");
        let e = "x".parse::<mc3e::EndCode>().unwrap_err();
        assert_eq!(
            e.to_string(),
            "bad mc3e device error code \"x\": a nonzero hexadecimal end code such as C051"
        );
    }
}
