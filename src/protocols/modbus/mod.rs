//! Modbus TCP, UDP and RTU: codec, client (master) and server (slave, for simulators).
//!
//! # Layers
//!
//! - [`pdu`], [`decode`], [`exception`], [`device_id`]: PDUs as Rust values, encoded and
//!   decoded without I/O.
//! - [`frame`] (MBAP, for TCP and UDP) and [`rtu`] (CRC-16, frame scanning): framings.
//! - `link`: one request/reply attempt per framing (MBAP over TCP or UDP, RTU over a byte
//!   stream), over the shared [`transport`](crate::protocols::transport) layer;
//!   [`ModbusClient`] runs attempts under the one retry policy, splits requests and
//!   implements the [`PlcMemory`](crate::protocols::PlcMemory) trait.
//! - [`server`]: a slave over TCP, UDP, RTU over TCP or a serial stream, backed by a shared
//!   register bank, with the shelf PLC's quirk and fault injection for tests.
//!
//! # Why our own codec
//!
//! tokio-modbus has no UDP transport and keeps its codec private, so it cannot carry the
//! shelf PLC's Modbus UDP. rmodbus (0.13) parses TCP/UDP and RTU frames and tolerates a
//! length of 0, but does not fit the rest: it has no function 08 (our link check), folds a
//! wrong transaction id, a wrong unit and a wrong function into one `FrameBroken` error
//! (the client must drop stale datagrams but report a wrong function), reads a function
//! mismatch as an exception code, does not check write echoes, and works on whole frames,
//! with no way to find frame boundaries in an RTU byte stream after line noise. The Modbus
//! PDU is small (eleven functions here), so the codec is written out in full, with typed
//! errors and property tests that no input panics it.
//!
//! # Quirks ([`Quirks`])
//!
//! - `length0`: the shelf PLC answers with an MBAP length of 0 (spec/shelf-plc.md). The
//!   client still sends standard frames; it takes the reply's PDU length from the datagram
//!   (UDP) or from the PDU's function code and byte count (TCP). The server can answer the
//!   same way ([`server::ServerOptions::length0`]). The server also takes request lengths
//!   from the datagram or PDU, so the seed's short length field for function 16 is accepted.
//! - `ignore_transaction_id`: for devices that do not echo the transaction id; replies are
//!   matched by unit, function and write echo, and stale input is flushed before each request.
//!
//! # Matching and retries
//!
//! Each attempt gets a new transaction id; a reply with the id of any attempt of the current
//! request is taken, any other is dropped, so a late reply after a timeout is never taken for
//! a newer request's answer. Exceptions are returned at once (not retried); timeouts, lost
//! connections and malformed replies are retried `retries` times. A frame from the wrong unit
//! is dropped, and if no right one follows, the attempt reports "reply from the wrong unit"
//! rather than a bare timeout.

pub mod address;
mod client;
pub mod config;
pub mod decode;
pub mod device_id;
pub mod exception;
pub mod frame;
mod link;
mod memory;
pub mod pdu;
pub mod rtu;
pub mod server;

pub use crate::protocols::transport::ByteStream;
pub use client::{ClientStats, ModbusClient};
pub use config::{ModbusConfig, Quirks, Transport};
pub use device_id::{DeviceIdPage, DeviceIdentification, DeviceObject, ObjectId, ReadDeviceIdCode};
pub use exception::Exception;
pub use pdu::{Request, Response};
