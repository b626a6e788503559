//! Simulated machines, faithful to their specs and able to inject faults: engineers use
//! them to commission a site, and the tests run rackd against them over real sockets.
//!
//! The machines: the shelf PLC ([`shelf`]), the stacker crane ([`crane`]), the demo's light
//! tower ([`tower`]). The memory simulators (a whole Modbus, MC, MEWTOCOL or PPI memory)
//! are the protocol servers seen through [`memory`], prepared by a [`preset`] and played
//! through a [`control`] surface; [`standalone`] runs any of them alone, as `rackd sim`
//! does. [`replay`] plays a recorded device (a capture) back to a live rackd.

pub mod control;
pub mod crane;
pub mod memory;
pub mod preset;
pub mod replay;
pub mod shelf;
pub mod standalone;
pub mod tower;
