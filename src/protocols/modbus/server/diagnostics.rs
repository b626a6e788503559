//! The counters a server answers diagnostics (function 08) from, Modbus Application
//! Protocol Specification V1.1b3, section 6.8.
//!
//! Decisions where the specification leaves room:
//! - **Bus message count** (000B): every request frame the server decoded the unit of,
//!   for any unit; **server message count** (000E): those addressed to this server (its
//!   unit, a broadcast, or 0 / 255 over TCP and UDP).
//! - **Bus communication error count** (000C): the specification counts CRC errors, but a
//!   frame with a bad CRC never reaches the server (the RTU scanner skips it as noise), so
//!   this counts requests to this server that were cut short or too long (truncated,
//!   trailing bytes, a byte count that does not match): frames damaged on the way.
//! - **Bus exception error count** (000D): exception replies sent; **server no response
//!   count** (000F): requests to this server left unanswered (broadcasts, drop faults).
//! - **Diagnostic register** (0002): always 0, as the simulated device has no condition to
//!   report. 000A clears the counters (after counting itself) and echoes.
//! - The counters are 16 bits on the wire and wrap.

use std::sync::atomic::{AtomicU64, Ordering};

use crate::protocols::modbus::decode::DecodeError;
use crate::protocols::modbus::pdu::{self, Response};

/// A server's diagnostic counters.
#[derive(Debug, Default)]
pub(crate) struct Counters {
    bus_messages: AtomicU64,
    comm_errors: AtomicU64,
    exceptions: AtomicU64,
    server_messages: AtomicU64,
    no_responses: AtomicU64,
}

fn bump(counter: &AtomicU64) {
    counter.fetch_add(1, Ordering::Relaxed);
}

impl Counters {
    /// A request frame for any unit.
    pub fn bus_message(&self) {
        bump(&self.bus_messages);
    }

    /// A request addressed to this server.
    pub fn server_message(&self) {
        bump(&self.server_messages);
    }

    /// A request to this server that did not decode for `error`.
    pub fn undecoded(&self, error: DecodeError) {
        if matches!(
            error,
            DecodeError::Empty
                | DecodeError::Truncated
                | DecodeError::TrailingBytes
                | DecodeError::ByteCountMismatch
        ) {
            bump(&self.comm_errors);
        }
    }

    /// An exception reply sent.
    pub fn exception(&self) {
        bump(&self.exceptions);
    }

    /// A request to this server left unanswered.
    pub fn no_response(&self) {
        bump(&self.no_responses);
    }

    /// The reply to diagnostics `sub_function` with `data`, if it is one the counters
    /// answer (0002, 000A, 000B..=000F); `None` for the others (0000), which the handler
    /// answers.
    pub fn answer(&self, sub_function: u16, data: u16) -> Option<Response> {
        let counter = |c: &AtomicU64| c.load(Ordering::Relaxed) as u16;
        let value = match sub_function {
            pdu::DIAG_DIAGNOSTIC_REGISTER => 0,
            pdu::DIAG_CLEAR_COUNTERS => {
                for c in [&self.bus_messages, &self.comm_errors, &self.exceptions, &self.server_messages] {
                    c.store(0, Ordering::Relaxed);
                }
                self.no_responses.store(0, Ordering::Relaxed);
                data
            }
            pdu::DIAG_BUS_MESSAGES => counter(&self.bus_messages),
            pdu::DIAG_BUS_COMM_ERRORS => counter(&self.comm_errors),
            pdu::DIAG_BUS_EXCEPTIONS => counter(&self.exceptions),
            pdu::DIAG_SERVER_MESSAGES => counter(&self.server_messages),
            pdu::DIAG_SERVER_NO_RESPONSES => counter(&self.no_responses),
            _ => return None,
        };
        Some(Response::Diagnostics { sub_function, data: value })
    }
}
