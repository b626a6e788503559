//! MELSEC communication protocol (MC protocol), 3E frame, binary code: the client rackd
//! uses to talk to Mitsubishi Q/L-series PLCs through their Ethernet modules, and a server
//! for simulators and tests.
//!
//! # The protocol
//! A 3E binary request is a 9-byte header (subheader `50 00`, network, PC, module I/O,
//! station, data length) followed by a monitoring timer, a command, a subcommand and the
//! command's data; the response (`D0 00`) echoes the route and carries an end code, then
//! the data (end code 0) or optional 9 bytes of error information. All fields are
//! little-endian. rackd uses the four batch commands: read (0401) and write (1401), in word
//! units (subcommand 0000) and bit units (0001). See `/work/shared/spec/crane-mc3e.md`.
//!
//! # Layers
//! [`frame`], [`request`], [`response`] are the pure codec (no I/O); [`device`] parses
//! addresses in each device's native radix (`X1A` hexadecimal, `D200` decimal);
//! [`end_code`] names end codes; [`link`] sends frames over the shared
//! [`transport`](crate::protocols::transport) layer (timeouts, retries, reconnection) with
//! the stale-reply defences; [`client`] implements [`PlcMemory`](super::PlcMemory); [`bank`],
//! [`handler`] and [`server`] make the simulated PLC (faults from
//! [`crate::protocols::faults`]).
//!
//! # Choices
//! - The codec is written here rather than taken from a crate: the Rust MC crates found are
//!   clients only (and tied to their own I/O), while rackd needs the same frames on both
//!   sides, a server for the crane simulator, and decoders that never panic.
//! - Limits, from the Q-series MC protocol manual for 3E binary: 960 points per word-unit
//!   batch read/write, 7168 points per bit-unit batch read/write; device numbers fit 3
//!   bytes (up to 0xFFFFFF). The client splits larger requests; the server answers C051.
//! - Word devices are read and written in words only; bit devices in bits, or in words of
//!   16 points (bit 0 of each word is the lowest-numbered device).
//! - End codes become `PlcError::Device(DeviceCode::Mc3e(EndCode))` and are never
//!   retried (the PLC answered). Error replies are accepted with or without error info.
//! - Over UDP plain 3E has no serial number; see [`link`] for how stale replies are
//!   kept out and the one case where they cannot be (a fixed local UDP port).
//! - Only binary code, the 3E frame and the Q/L device specification (subcommands 0000
//!   and 0001) are supported; not ASCII, 4E (which has serial numbers), random or block
//!   reads, or the iQ-R 4-byte device numbers (subcommands 0002/0003).

pub mod bank;
pub mod client;
pub mod client_reads;
pub mod command;
pub mod device;
pub mod end_code;
pub mod frame;
pub mod handler;
pub mod link;
pub mod request;
pub mod response;
pub mod scattered;
pub mod server;
pub mod type_name;

#[cfg(test)]
mod proptests;

pub use bank::{Bank, SharedBank};
pub use client::{Mc3eClient, Mc3eConfig};
pub use device::Device;
pub use end_code::EndCode;
pub use frame::{FrameKind, Route};
pub use handler::{WriteEvent, WriteHook};
pub use link::{LinkConfig, TransportKind};
pub use scattered::Block;
pub use server::{Mc3eServer, ServerState};
pub use type_name::TypeName;
