//! Siemens S7-200 PPI: the master/slave protocol of the S7-200's RS-485 port, over a serial
//! line or raw TCP through a serial-to-Ethernet gateway. Client, and a server for
//! simulators.

pub mod frame;
pub mod pdu;
pub mod return_code;
