//! Helpers shared by the half-duplex serial protocols (MEWTOCOL-COM and PPI): a client link
//! over a byte stream that flushes stale input before each request, server-side fault
//! injection, and a TCP accept loop for simulators.
//!
//! The carriers (TCP, serial port, a caller's stream) and their reconnection with backoff
//! are Modbus's [`Connection`](crate::protocols::modbus::transport::Connection), reused so
//! reconnection lives in one place.

pub mod faults;
mod link;
mod server;

pub use faults::{Fault, Faults, Plan, SharedFaults};
pub(crate) use link::{LineLink, attempt_error};
pub use server::LineServer;
pub(crate) use server::spawn_tcp;
