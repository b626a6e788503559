//! Siemens S7-200 PPI: the master/slave protocol of the S7-200's RS-485 port, over a serial
//! line or raw TCP through a serial-to-Ethernet gateway. Client (master), and a server
//! (slave) for simulators. See `/work/shared/spec/ppi.md`.
//!
//! # Layers
//! [`frame`] (long and short frames, `E5`, FCS, scanning a byte stream) and [`pdu`] (the S7
//! read, write, RUN and STOP PDUs) are the pure codec; [`return_code`] names item return
//! codes and error classes; [`address`] parses Siemens notation; [`PpiClient`] owns the
//! line, the two-step exchange, timeouts and retries, and implements
//! [`PlcMemory`](super::PlcMemory); [`bank`] and [`server`] make the simulated PLC.
//!
//! ```no_run
//! # async fn demo() -> Result<(), rackd::protocols::PlcError> {
//! use rackd::protocols::PlcMemory;
//! use rackd::protocols::ppi::{PpiClient, PpiConfig, PpiTransport};
//! let mut config = PpiConfig::new(PpiTransport::Serial, "/dev/ttyUSB0");
//! config.serial = "19200,8E1".parse().unwrap();
//! let plc = PpiClient::new(config)?;
//! let words = plc.read_words(&plc.parse_address("VW100")?, 2).await?; // VW100, VW102
//! plc.stop().await?;
//! # Ok(()) }
//! ```
//!
//! # Choices where the spec is silent
//! - Each attempt is one whole exchange (request, `E5`, poll, response) within the timeout;
//!   a lost `E5` or response makes the attempt time out, and the retry resends the request.
//!   A poll answered with `E5` ("nothing yet") is not re-polled: the attempt waits for the
//!   response until its deadline.
//! - Late replies: input waiting before a request is flushed, whole frames seen while
//!   waiting for the `E5` are skipped, and a response is taken only if it carries the PDU
//!   reference of one of this request's attempts (each attempt gets a new one). The seed's
//!   frames use reference 0; `match_pdu_ref = false` accepts any reference.
//! - Requests use the seed's function codes (6C read, 7C write); the FCB is not toggled.
//! - One item per request; at most 200 data bytes (LE must fit one byte). Bit access reads
//!   or writes one bit per item.
//! - Errors: an item return code becomes [`ReturnCode::Item`] (05, 0A, ...) and a refused
//!   request (`32 02 ... 85 00`) [`ReturnCode::Refused`] (numbered `class << 8 | code`,
//!   0x8500), both as `PlcError::Device(DeviceCode::Ppi(..))`. Neither is retried.
//! - Timers and counters (T, C) are read with transport size 1F / 1E, offset = number, two
//!   bytes per value. This follows the S7 convention; it is not checked against a CPU.

pub mod address;
pub mod area;
pub mod bank;
mod client;
pub mod frame;
mod memory;
pub mod pdu;
pub mod return_code;
pub mod server;
pub mod setup;

pub use bank::{Bank, SharedBank};
pub use client::{PpiClient, PpiConfig, PpiTransport};
pub use pdu::{Item, MemArea, Reply, Request, Size};
pub use return_code::ReturnCode;
pub use server::ServerState;
