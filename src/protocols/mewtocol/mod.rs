//! Panasonic MEWTOCOL-COM: the computer-link protocol of FP-series PLCs, over a serial line
//! or raw TCP through a serial-to-Ethernet gateway. Client, and a server for simulators.
//!
//! # Layers
//! [`frame`] (start, station, BCC, CR; scanning a byte stream) and [`command`] (RCS, RCP,
//! RCC, WCS, WCP, WCC, RD, WD as values) are the pure codec; [`error_code`] names the
//! `!` codes; [`address`] parses Panasonic notation; [`MewtocolClient`] owns the line,
//! timeouts and retries and implements [`PlcMemory`](super::PlcMemory); [`bank`] and
//! [`server`] make the simulated PLC. See `/work/shared/spec/mewtocol.md`.
//!
//! ```no_run
//! # async fn demo() -> Result<(), rackd::protocols::PlcError> {
//! use rackd::protocols::PlcMemory;
//! use rackd::protocols::mewtocol::{MewtocolClient, MewtocolConfig, MewtocolTransport};
//! let mut config = MewtocolConfig::new(MewtocolTransport::Tcp, "10.0.0.9:9094");
//! config.station = 3;
//! let plc = MewtocolClient::new(config)?;
//! let words = plc.read_words(&plc.parse_address("DT100")?, 2).await?;
//! # Ok(()) }
//! ```
//!
//! # Choices where the spec is silent
//! - Replies are matched by station and by the response code and data length the command
//!   expects; MEWTOCOL has no sequence number, so input waiting before a request (a late
//!   reply to a timed-out one) is flushed first. A reply later than the *next* request's
//!   send cannot be told apart when command and length agree: keep the timeout above the
//!   PLC's worst reply time.
//! - With `bcc` on, replies carrying `**` instead of a BCC are refused; with it off they are
//!   accepted, and a BCC that is present is still checked.
//! - Error replies are never retried (the PLC answered); BCC errors, garbled frames and
//!   timeouts are.
//! - The `<` long frame is used for the whole exchange when `long_frames` is set; frame
//!   limits count every character including the CR (118 / 2048).
//! - The simulator refuses out-of-range addresses with 61 (data error) and bad counts with
//!   60 (parameter error).

pub mod address;
pub mod bank;
mod client;
pub mod command;
pub mod contact;
pub mod error_code;
pub mod frame;
mod memory;
pub mod server;

pub use bank::{Bank, SharedBank};
pub use client::{MewtocolClient, MewtocolConfig, MewtocolTransport};
pub use command::{Contact, ContactArea, Request, Response};
pub use error_code::ErrorCode;
pub use server::ServerState;
