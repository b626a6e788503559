//! MELSEC communication protocol (MC protocol), 3E and 4E frames, binary code: the client
//! rackd uses to talk to Mitsubishi Q/L-series PLCs through their Ethernet modules, and a
//! server for simulators and tests.
//!
//! # The protocol
//! A 3E binary request is a 9-byte header (subheader `50 00`, network, PC, module I/O,
//! station, data length) followed by a monitoring timer, a command, a subcommand and the
//! command's data; the response (`D0 00`) echoes the route and carries an end code, then
//! the data (end code 0) or, usually, 9 bytes of error information. A 4E frame (`54 00` /
//! `D4 00`) adds a serial number the reply echoes. All fields are little-endian. rackd
//! speaks the batch commands read (0401) and write (1401) in word units (subcommand 0000)
//! and bit units (0001), read CPU model name (0101), random read in word units (0403) and
//! multiple-block batch read (0406). See `/work/shared/spec/crane-mc3e.md`.
//!
//! # Layers
//! [`frame`], [`bits`], [`command`], [`scattered`], [`type_name`], [`request`], [`response`]
//! are the pure codec (no I/O); [`device`] names the devices and their codes, [`address`]
//! parses addresses in each device's native radix (`X1A` hexadecimal, `D200` decimal,
//! `K4M100` a bit device in words); [`end_code`] names end
//! codes; [`link`] sends frames over the shared [`transport`](crate::protocols::transport)
//! layer (timeouts, retries, reconnection) with the stale-reply defences; [`client`]
//! implements [`PlcMemory`](super::PlcMemory) and [`client_reads`] adds the type name,
//! random and block reads; [`bank`], [`handler`] and [`server`] make the simulated PLC
//! (faults from [`crate::protocols::faults`]).
//!
//! # Choices
//! - The codec is written here rather than taken from a crate: the Rust MC crates found are
//!   clients only (and tied to their own I/O), while rackd needs the same frames on both
//!   sides, a server for the crane simulator, and decoders that never panic.
//! - Limits, from the Q-series MC protocol manual for 3E binary: 960 points per word-unit
//!   batch read/write, 7168 points per bit-unit batch read/write, 192 points per random
//!   read, 120 blocks and 960 words per block read; device numbers fit 3 bytes (up to
//!   0xFFFFFF). The client splits larger batch requests and refuses larger random and block
//!   reads before sending (the caller decides how to split those); the server answers C051.
//! - Word devices are read and written in words only; bit devices in bits, or in words of
//!   16 points (bit 0 of each word is the lowest-numbered device), written `K4M100`.
//! - Timer and counter devices: contacts and coils are bit devices, current values word
//!   devices (see [`device`]); the simulator stores them and does not run timers.
//! - End codes become `PlcError::Device(DeviceCode::Mc3e(EndCode))` and are never
//!   retried (the PLC answered). An error reply's end code surfaces whatever follows it
//!   (nothing, 9 bytes of error information, anything else) as long as the length field
//!   matches the frame (issue 15: a peer server sent other data there).
//! - 4E is chosen by protocol name: `mc4e` (TCP, alias `mc4e-tcp`) and `mc4e-udp`; the
//!   client numbers requests 1, 2, ... (wrapping) and drops a reply with another serial,
//!   counted as a stale reply. The simulator answers 3E and 4E on one port, each in its
//!   own frame.
//! - Over UDP plain 3E has no serial number; see [`link`] for how stale replies are
//!   kept out and the one case where they cannot be (a fixed local UDP port).
//! - Only binary code and the Q/L device specification (subcommands 0000 and 0001) are
//!   supported; not ASCII, random or block writes, monitor registration, or the iQ-R
//!   4-byte device numbers (subcommands 0002/0003).

pub mod address;
pub mod bank;
pub mod bits;
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
