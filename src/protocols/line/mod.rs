//! Helpers shared by the half-duplex serial protocols' servers (MEWTOCOL-COM and PPI):
//! server-side fault injection, and a TCP accept loop for simulators. The client side of a
//! line is the shared [`transport`](crate::protocols::transport)'s stream link.

pub mod faults;
mod server;

pub use faults::{Fault, Faults, Plan, SharedFaults};
pub use server::LineServer;
pub(crate) use server::spawn_tcp;
