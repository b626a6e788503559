//! How the simulated shelf PLC is set up: which protocol it speaks and where its task slots
//! sit in that protocol's memory, with per-protocol defaults.
//!
//! | protocol | slot 1 (`base`) | `stride` | unit | why |
//! |---|---|---|---|---|
//! | `modbus-udp`, `modbus-tcp` | `4x4000` | 100 | 1 | the seed's PLC: slot k at MW 4000 + 100(k-1) |
//! | `modbus-rtu`, `modbus-rtu-tcp` | `4x0` | 100 | 1 | an S7-1200 Modbus_Slave: MB_HOLD_REG (a DB of slots) answers from PDU address 0 |
//! | `ppi`, `ppi-tcp` | `VW1000` | 50 | 2 | an S7-200: slot k at VW 1000 + 100(k-1), 60 slots end at VB6999, inside a CPU 224's 8 KB of V memory |
//! | `mewtocol`, `mewtocol-tcp` | `DT4000` | 100 | 1 | a Panasonic FP: slot k at DT 4000 + 100(k-1) |
//!
//! `stride` always counts 16-bit words; on PPI a word is two byte addresses, so a stride of
//! 50 puts slots 100 byte addresses apart (a slot's 50 words, none to spare, as the spec
//! lays a slot out). Sites with other layouts set `base` and `stride` to match.

use std::str::FromStr;
use std::time::Duration;

use crate::protocols::Protocol;
use crate::protocols::faults::Faults;
use crate::protocols::serial::SerialSettings;

/// The transports the shelf simulator serves, named as a device's `protocol`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum ShelfProtocol {
    /// Modbus over UDP, answering with MBAP length 0 like the seed's PLC.
    #[default]
    ModbusUdp,
    /// Modbus TCP (standard MBAP lengths).
    ModbusTcp,
    /// Modbus RTU on a serial line, as an S7-1200 Modbus_Slave.
    ModbusRtu,
    /// Modbus RTU frames over raw TCP (a serial-to-Ethernet gateway before the S7-1200).
    ModbusRtuTcp,
    /// S7-200 PPI on a serial line.
    Ppi,
    /// S7-200 PPI over raw TCP (through a gateway).
    PpiTcp,
    /// Panasonic MEWTOCOL-COM on a serial line.
    Mewtocol,
    /// MEWTOCOL-COM over raw TCP (through a gateway).
    MewtocolTcp,
}

/// The protocol families, each with its own server and bank.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Family {
    Modbus,
    Ppi,
    Mewtocol,
}

/// A protocol name the simulator does not serve.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown shelf protocol {0:?} (known: modbus-udp, modbus-tcp, modbus-rtu, modbus-rtu-tcp, ppi, ppi-tcp, mewtocol, mewtocol-tcp)"
)]
pub struct UnknownProtocol(pub String);

impl ShelfProtocol {
    /// Every protocol.
    pub const ALL: [ShelfProtocol; 8] = [
        ShelfProtocol::ModbusUdp,
        ShelfProtocol::ModbusTcp,
        ShelfProtocol::ModbusRtu,
        ShelfProtocol::ModbusRtuTcp,
        ShelfProtocol::Ppi,
        ShelfProtocol::PpiTcp,
        ShelfProtocol::Mewtocol,
        ShelfProtocol::MewtocolTcp,
    ];

    /// The name a device's `protocol` uses.
    pub fn name(self) -> &'static str {
        match self {
            ShelfProtocol::ModbusUdp => "modbus-udp",
            ShelfProtocol::ModbusTcp => "modbus-tcp",
            ShelfProtocol::ModbusRtu => "modbus-rtu",
            ShelfProtocol::ModbusRtuTcp => "modbus-rtu-tcp",
            ShelfProtocol::Ppi => "ppi",
            ShelfProtocol::PpiTcp => "ppi-tcp",
            ShelfProtocol::Mewtocol => "mewtocol",
            ShelfProtocol::MewtocolTcp => "mewtocol-tcp",
        }
    }

    /// The device protocol of the same name.
    pub fn protocol(self) -> Protocol {
        match self {
            ShelfProtocol::ModbusUdp => Protocol::ModbusUdp,
            ShelfProtocol::ModbusTcp => Protocol::ModbusTcp,
            ShelfProtocol::ModbusRtu => Protocol::ModbusRtu,
            ShelfProtocol::ModbusRtuTcp => Protocol::ModbusRtuTcp,
            ShelfProtocol::Ppi => Protocol::Ppi,
            ShelfProtocol::PpiTcp => Protocol::PpiTcp,
            ShelfProtocol::Mewtocol => Protocol::Mewtocol,
            ShelfProtocol::MewtocolTcp => Protocol::MewtocolTcp,
        }
    }

    /// True when the simulator serves a serial device (a path or an open stream) rather
    /// than a network address.
    pub fn is_serial(self) -> bool {
        matches!(self, ShelfProtocol::ModbusRtu | ShelfProtocol::Ppi | ShelfProtocol::Mewtocol)
    }

    pub(super) fn family(self) -> Family {
        match self {
            ShelfProtocol::ModbusUdp
            | ShelfProtocol::ModbusTcp
            | ShelfProtocol::ModbusRtu
            | ShelfProtocol::ModbusRtuTcp => Family::Modbus,
            ShelfProtocol::Ppi | ShelfProtocol::PpiTcp => Family::Ppi,
            ShelfProtocol::Mewtocol | ShelfProtocol::MewtocolTcp => Family::Mewtocol,
        }
    }

    /// True for the RTU transports, which answer like an S7-1200 Modbus_Slave.
    pub fn is_s7_1200(self) -> bool {
        matches!(self, ShelfProtocol::ModbusRtu | ShelfProtocol::ModbusRtuTcp)
    }

    /// Where slot 1's task id sits by default, in the protocol's notation (see the table
    /// in the module documentation).
    /// (The same defaults as a shelf device's: [`crate::wire::slot::default_layout`].)
    pub fn default_base(self) -> &'static str {
        crate::wire::slot::default_layout(self.protocol()).0
    }

    /// Words from one slot to the next by default.
    pub fn default_stride(self) -> u16 {
        crate::wire::slot::default_layout(self.protocol()).1
    }

    /// The unit (Modbus unit, PPI address, MEWTOCOL station) answered by default: 2 is
    /// the S7-200's factory PPI address ([`Protocol::default_unit`]).
    pub fn default_unit(self) -> u8 {
        self.protocol().default_unit()
    }

    /// Serial settings by default: 9600,8E1 (Modbus RTU and PPI), 9600,8O1 (MEWTOCOL).
    pub fn default_serial(self) -> SerialSettings {
        match self.family() {
            Family::Mewtocol => {
                SerialSettings { parity: tokio_serial::Parity::Odd, ..SerialSettings::default() }
            }
            _ => SerialSettings::default(),
        }
    }
}

impl std::fmt::Display for ShelfProtocol {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl TryFrom<Protocol> for ShelfProtocol {
    type Error = UnknownProtocol;

    fn try_from(protocol: Protocol) -> Result<Self, Self::Error> {
        ShelfProtocol::ALL
            .into_iter()
            .find(|p| p.protocol() == protocol)
            .ok_or_else(|| UnknownProtocol(protocol.name().to_owned()))
    }
}

impl FromStr for ShelfProtocol {
    type Err = UnknownProtocol;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let text = text.trim();
        ShelfProtocol::ALL
            .into_iter()
            .find(|p| p.name().eq_ignore_ascii_case(text))
            .ok_or_else(|| UnknownProtocol(text.to_owned()))
    }
}

/// How the simulated PLC is set up. `None` fields take the protocol's default (see the
/// module documentation).
#[derive(Clone, Debug)]
pub struct ShelfSimOptions {
    /// The protocol served.
    pub protocol: ShelfProtocol,
    /// Number of task slots.
    pub slots: u16,
    /// Slot 1's task id in the protocol's notation (`4x4000`, `VW1000`, `DT4000`); for
    /// Modbus a bare number is a holding register.
    pub base: Option<String>,
    /// Words from one slot to the next.
    pub stride: Option<u16>,
    /// Modbus unit, PPI address or MEWTOCOL station.
    pub unit: Option<u8>,
    /// Serial settings when the simulator opens a serial device.
    pub serial: Option<SerialSettings>,
    /// Time each task takes (0 = at once).
    pub task_time: Duration,
    /// Fraction of tasks that fail with kind 1 (PLC fault).
    pub fail_rate: f64,
    /// Link faults (loss, delay, noise, ...), as every simulator takes them.
    pub faults: Faults,
    /// Modbus UDP and TCP: answer with transaction id 0 whatever the request carried, as
    /// the seed's PLC does (its replies name no request).
    pub no_transaction_id: bool,
}

impl Default for ShelfSimOptions {
    fn default() -> Self {
        ShelfSimOptions {
            protocol: ShelfProtocol::default(),
            slots: 60,
            base: None,
            stride: None,
            unit: None,
            serial: None,
            task_time: Duration::from_millis(500),
            fail_rate: 0.0,
            faults: Faults::default(),
            no_transaction_id: false,
        }
    }
}

impl ShelfSimOptions {
    /// Options for `protocol` with every other setting at its default.
    pub fn for_protocol(protocol: ShelfProtocol) -> Self {
        ShelfSimOptions { protocol, ..ShelfSimOptions::default() }
    }

    /// Slot 1's address as configured or by default, in the protocol's notation.
    pub fn base_text(&self) -> String {
        match self.base.as_deref().map(str::trim) {
            Some(n) if self.protocol.family() == Family::Modbus && n.bytes().all(|b| b.is_ascii_digit()) => {
                format!("4x{n}")
            }
            Some(text) => text.to_owned(),
            None => self.protocol.default_base().to_owned(),
        }
    }

    /// The stride as configured or by default.
    pub fn stride_or_default(&self) -> u16 {
        self.stride.unwrap_or(self.protocol.default_stride())
    }

    /// The unit as configured or by default.
    pub fn unit_or_default(&self) -> u8 {
        self.unit.unwrap_or(self.protocol.default_unit())
    }

    /// The serial settings as configured or by default.
    pub fn serial_or_default(&self) -> SerialSettings {
        self.serial.unwrap_or(self.protocol.default_serial())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_unknown_ones_are_refused() {
        for p in ShelfProtocol::ALL {
            assert_eq!(p.name().parse::<ShelfProtocol>(), Ok(p));
            assert_eq!(p.protocol().name(), p.name(), "{p} is a device protocol");
            assert_eq!(ShelfProtocol::try_from(p.protocol()), Ok(p));
        }
        assert_eq!(" PPI-tcp ".parse::<ShelfProtocol>(), Ok(ShelfProtocol::PpiTcp));
        assert_eq!("mc3e".parse::<ShelfProtocol>(), Err(UnknownProtocol("mc3e".into())));
        assert!(ShelfProtocol::try_from(Protocol::Mc3eUdp).is_err());
    }

    #[test]
    fn defaults_follow_the_protocol() {
        let ppi = ShelfSimOptions::for_protocol(ShelfProtocol::Ppi);
        assert_eq!(
            (ppi.base_text(), ppi.stride_or_default(), ppi.unit_or_default()),
            ("VW1000".into(), 50, 2)
        );
        let rtu = ShelfSimOptions::for_protocol(ShelfProtocol::ModbusRtu);
        assert_eq!((rtu.base_text(), rtu.stride_or_default()), ("4x0".into(), 100));
        let mew = ShelfSimOptions::for_protocol(ShelfProtocol::Mewtocol);
        assert_eq!(mew.serial_or_default().parity, tokio_serial::Parity::Odd);
        let udp = ShelfSimOptions { base: Some("4100".into()), ..ShelfSimOptions::default() };
        assert_eq!(udp.base_text(), "4x4100", "a bare Modbus number is a holding register");
        let dt = ShelfSimOptions { base: Some("DT200".into()), ..mew };
        assert_eq!(dt.base_text(), "DT200");
    }
}
