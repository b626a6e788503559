//! rackd: a warehouse control system.

pub mod cli;
pub mod protocols;
