//! Simulated machines, faithful to their specs and able to inject faults: engineers use
//! them to commission a site, and the tests run rackd against them over real sockets.

pub mod crane;
pub mod memory;
pub mod shelf;
pub mod tower;
