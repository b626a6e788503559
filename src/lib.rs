//! rackd: a warehouse control system.

pub mod protocols;
