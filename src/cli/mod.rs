//! Command-line subcommands; `src/main.rs` only parses and dispatches.

pub mod plc;
pub mod sim_modbus;
