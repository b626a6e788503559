//! How to reach one Modbus device: transport, address, unit, timing and quirks.

use std::collections::BTreeSet;
use std::time::Duration;

use crate::capture::Limits;
use crate::protocols::serial::SerialSettings;
use crate::protocols::transport::LinkTuning;
use crate::protocols::{Protocol, Quirk, Replies};

/// The framing and carrier of a Modbus link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Transport {
    /// Modbus TCP: MBAP frames on a TCP connection.
    Tcp,
    /// Modbus UDP: one MBAP frame per datagram.
    Udp,
    /// Modbus RTU on a serial port.
    RtuSerial,
    /// Modbus RTU frames carried in raw TCP (serial-to-Ethernet gateways).
    RtuOverTcp,
}

impl Transport {
    /// True for the MBAP framings (TCP, UDP), where the unit id addresses the device itself
    /// and unit 0 is not a broadcast.
    pub fn is_mbap(self) -> bool {
        matches!(self, Transport::Tcp | Transport::Udp)
    }

    /// Checks a unit id for this transport: RTU stations are 0 (broadcast) and 1..=247
    /// (248..=255 are reserved); TCP and UDP take any unit id.
    pub fn check_unit(self, unit: u8) -> Result<(), &'static str> {
        match self.is_mbap() || unit <= 247 {
            true => Ok(()),
            false => Err("an RTU unit is 1..=247, or 0 to broadcast a write (248..=255 are reserved)"),
        }
    }
}

/// Deviations from the standard that a particular device needs tolerated.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Quirks {
    /// The device answers with an MBAP length field of 0 (the shelf PLC): take the PDU
    /// length from the datagram (UDP) or from the PDU itself (TCP). Requests stay standard.
    pub length0: bool,
    /// The device does not echo the transaction id: its replies name no request
    /// ([`Protocol::replies`]), so they are matched by unit, function and write echo only,
    /// under the transport's rule against late replies (a new UDP port or TCP connection
    /// after an exchange that was not answered).
    pub ignore_transaction_id: bool,
}

/// Everything a [`super::ModbusClient`] needs to talk to one device.
#[derive(Clone, Debug, PartialEq)]
pub struct ModbusConfig {
    /// Framing and carrier.
    pub transport: Transport,
    /// `HOST:PORT` for TCP, UDP and RTU over TCP; the device path (`/dev/ttyUSB0`) for serial.
    pub address: String,
    /// Serial line settings, for [`Transport::RtuSerial`] (also sets the RTU frame gap).
    pub serial: SerialSettings,
    /// Unit id. RTU (serial or over TCP): station 1..=247, 0 broadcasts writes and awaits
    /// no reply. TCP and UDP: any 0..=255, addressing the device itself (or a station
    /// behind a gateway); every request, unit 0 included, awaits a reply.
    pub unit: u8,
    /// How long to wait for each reply.
    pub timeout: Duration,
    /// How many times to resend after a timeout or a bad reply (0 = send once).
    pub retries: u32,
    /// The adaptive timeout's floor and when the link counts as degraded.
    pub tuning: LinkTuning,
    /// Quirks of this device.
    pub quirks: Quirks,
    /// The flight recorder's bounds; `None` records nothing.
    pub capture: Option<Limits>,
}

impl ModbusConfig {
    /// A configuration with the usual defaults: unit 1, 1 s timeout, 2 retries (as the
    /// S7-1200's Modbus_Master), serial 9600,8E1, no quirks, no recorder.
    pub fn new(transport: Transport, address: impl Into<String>) -> Self {
        ModbusConfig {
            transport,
            address: address.into(),
            serial: SerialSettings::default(),
            unit: 1,
            timeout: Duration::from_secs(1),
            retries: 2,
            tuning: LinkTuning::default(),
            quirks: Quirks::default(),
            capture: None,
        }
    }

    /// The shelf PLC of the seed: Modbus UDP, unit 1, length-0 replies with transaction id
    /// 0 whatever was sent.
    pub fn shelf_plc(address: impl Into<String>) -> Self {
        let mut config = ModbusConfig::new(Transport::Udp, address);
        config.quirks = Quirks { length0: true, ignore_transaction_id: true };
        config
    }

    /// The protocol this configuration speaks.
    pub fn protocol(&self) -> Protocol {
        match self.transport {
            Transport::Tcp => Protocol::ModbusTcp,
            Transport::Udp => Protocol::ModbusUdp,
            Transport::RtuSerial => Protocol::ModbusRtu,
            Transport::RtuOverTcp => Protocol::ModbusRtuTcp,
        }
    }

    /// Whether the replies name their request ([`Protocol::replies`]).
    pub fn replies(&self) -> Replies {
        self.protocol().replies(&self.quirks.set())
    }
}

impl Quirks {
    /// The quirks as the configuration names them.
    pub fn set(&self) -> BTreeSet<Quirk> {
        let on = [(self.length0, Quirk::Length0), (self.ignore_transaction_id, Quirk::NoTransactionId)];
        on.into_iter().filter(|(on, _)| *on).map(|(_, q)| q).collect()
    }
}
