//! The closed sets a link is described with: which [`Protocol`] (and transport) a PLC is
//! reached with, and which [`Quirk`]s of a protocol it needs.
//!
//! This is the one list of protocols: the configuration (serde), `rackd plc` and
//! `rackd sim` (clap), address notation and device defaults all name a protocol with this
//! enum, so adding one is a compile error everywhere a decision depends on it.
//!
//! The names are the configuration's since the first release (`modbus-udp`, ...); `mc3e`
//! is MC 3E over TCP and also answers to `mc3e-tcp`. MC 4E frames are chosen by protocol
//! (`mc4e`, alias `mc4e-tcp`, and `mc4e-udp`) rather than by a separate setting: the frame
//! decides how replies are matched, as the transport does, and a protocol name is what
//! `rackd plc` and the configuration already take.

use std::collections::BTreeSet;
use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// A protocol and its transport.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize, clap::ValueEnum,
)]
pub enum Protocol {
    /// Modbus UDP (MBAP in datagrams): the seed's shelf PLC.
    #[serde(rename = "modbus-udp")]
    #[value(name = "modbus-udp")]
    ModbusUdp,
    /// Modbus TCP (MBAP over TCP).
    #[serde(rename = "modbus-tcp")]
    #[value(name = "modbus-tcp")]
    ModbusTcp,
    /// Modbus RTU on a serial port.
    #[serde(rename = "modbus-rtu")]
    #[value(name = "modbus-rtu")]
    ModbusRtu,
    /// Modbus RTU frames over raw TCP (serial-to-Ethernet gateway).
    #[serde(rename = "modbus-rtu-tcp")]
    #[value(name = "modbus-rtu-tcp")]
    ModbusRtuTcp,
    /// Mitsubishi MC protocol 3E binary over TCP.
    #[serde(rename = "mc3e", alias = "mc3e-tcp")]
    #[value(name = "mc3e", alias = "mc3e-tcp")]
    Mc3e,
    /// Mitsubishi MC protocol 3E binary over UDP.
    #[serde(rename = "mc3e-udp")]
    #[value(name = "mc3e-udp")]
    Mc3eUdp,
    /// Mitsubishi MC protocol 4E binary (3E with serial numbers) over TCP.
    #[serde(rename = "mc4e", alias = "mc4e-tcp")]
    #[value(name = "mc4e", alias = "mc4e-tcp")]
    Mc4e,
    /// Mitsubishi MC protocol 4E binary over UDP: replies are matched by serial number.
    #[serde(rename = "mc4e-udp")]
    #[value(name = "mc4e-udp")]
    Mc4eUdp,
    /// Panasonic MEWTOCOL-COM on a serial port (addresses DT100, WR1, R1F, Y1A).
    #[serde(rename = "mewtocol")]
    #[value(name = "mewtocol")]
    Mewtocol,
    /// Panasonic MEWTOCOL-COM over raw TCP (serial-to-Ethernet gateway).
    #[serde(rename = "mewtocol-tcp")]
    #[value(name = "mewtocol-tcp")]
    MewtocolTcp,
    /// Siemens S7-200 PPI on a serial port (addresses VW100, VB0, V10.3, Q0.1, T37).
    #[serde(rename = "ppi")]
    #[value(name = "ppi")]
    Ppi,
    /// Siemens S7-200 PPI over raw TCP (serial-to-Ethernet gateway).
    #[serde(rename = "ppi-tcp")]
    #[value(name = "ppi-tcp")]
    PpiTcp,
}

/// Whether a link's replies name the request they answer ([`Protocol::replies`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Replies {
    /// Every reply carries an id its request chose (a transaction id, a serial number): a
    /// late reply is told apart by its id, and a retry costs only the request itself.
    Named,
    /// Nothing in a reply names its request: a reply is taken only when the current
    /// request is the only one that could have caused it, which the transport makes sure
    /// of before each send (its module documentation: "Links whose replies name no
    /// request").
    Unnamed,
}

/// The protocol families: one frame format, one address notation, one client each.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Family {
    /// Modbus (UDP, TCP, RTU, RTU over TCP).
    Modbus,
    /// MC protocol 3E and 4E (TCP, UDP).
    Mc3e,
    /// MEWTOCOL-COM (serial, TCP).
    Mewtocol,
    /// S7-200 PPI (serial, TCP).
    Ppi,
}

impl Protocol {
    /// Every protocol, in the order the documentation lists them.
    pub const ALL: [Protocol; 12] = [
        Protocol::ModbusUdp,
        Protocol::ModbusTcp,
        Protocol::ModbusRtu,
        Protocol::ModbusRtuTcp,
        Protocol::Mc3e,
        Protocol::Mc3eUdp,
        Protocol::Mc4e,
        Protocol::Mc4eUdp,
        Protocol::Mewtocol,
        Protocol::MewtocolTcp,
        Protocol::Ppi,
        Protocol::PpiTcp,
    ];

    /// The name the configuration and the command line write.
    pub fn name(self) -> &'static str {
        match self {
            Protocol::ModbusUdp => "modbus-udp",
            Protocol::ModbusTcp => "modbus-tcp",
            Protocol::ModbusRtu => "modbus-rtu",
            Protocol::ModbusRtuTcp => "modbus-rtu-tcp",
            Protocol::Mc3e => "mc3e",
            Protocol::Mc3eUdp => "mc3e-udp",
            Protocol::Mc4e => "mc4e",
            Protocol::Mc4eUdp => "mc4e-udp",
            Protocol::Mewtocol => "mewtocol",
            Protocol::MewtocolTcp => "mewtocol-tcp",
            Protocol::Ppi => "ppi",
            Protocol::PpiTcp => "ppi-tcp",
        }
    }

    /// Whether a link's replies name the request they answer: decided by the protocol
    /// *and* the link's quirks, here and nowhere else. Modbus TCP and UDP name it by the
    /// transaction id unless the PLC does not echo it (`no-transaction-id`); MC 4E by the
    /// serial number. Modbus RTU (on a line or over TCP), MC 3E, MEWTOCOL and PPI cannot:
    /// PPI's PDU reference is checked when the PLC echoes it, but its two-step exchange on
    /// a half-duplex line is held like the other lines' (`ppi.rs`'s module documentation).
    ///
    /// Everything that depends on it asks this: the adaptive timeout's floor
    /// ([`crate::protocols::transport::LinkTuning::for_replies`]), the rule against late
    /// replies (the transport's module documentation), Karn's rule on round trips, and
    /// whether a dropped reply is counted stale or foreign.
    pub fn replies(self, quirks: &BTreeSet<Quirk>) -> Replies {
        let named = match self {
            Protocol::ModbusUdp | Protocol::ModbusTcp => !quirks.contains(&Quirk::NoTransactionId),
            Protocol::Mc4e | Protocol::Mc4eUdp => true,
            Protocol::ModbusRtu
            | Protocol::ModbusRtuTcp
            | Protocol::Mc3e
            | Protocol::Mc3eUdp
            | Protocol::Mewtocol
            | Protocol::MewtocolTcp
            | Protocol::Ppi
            | Protocol::PpiTcp => false,
        };
        if named { Replies::Named } else { Replies::Unnamed }
    }

    /// The family: which frames, notation and client.
    pub fn family(self) -> Family {
        match self {
            Protocol::ModbusUdp | Protocol::ModbusTcp | Protocol::ModbusRtu | Protocol::ModbusRtuTcp => {
                Family::Modbus
            }
            Protocol::Mc3e | Protocol::Mc3eUdp | Protocol::Mc4e | Protocol::Mc4eUdp => Family::Mc3e,
            Protocol::Mewtocol | Protocol::MewtocolTcp => Family::Mewtocol,
            Protocol::Ppi | Protocol::PpiTcp => Family::Ppi,
        }
    }

    /// Whether the address is a serial device (`/dev/ttyUSB0`) rather than `HOST:PORT`.
    pub fn is_serial(self) -> bool {
        matches!(self, Protocol::ModbusRtu | Protocol::Mewtocol | Protocol::Ppi)
    }

    /// The unit / station a PLC of this protocol answers by default: 2 on PPI (an S7-200's
    /// factory address), 1 elsewhere.
    pub fn default_unit(self) -> u8 {
        match self.family() {
            Family::Ppi => 2,
            _ => 1,
        }
    }
}

impl fmt::Display for Protocol {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A protocol name that is not one of [`Protocol::ALL`].
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown protocol {0:?} (known: {known})", known = names(&Protocol::ALL))]
pub struct UnknownProtocol(pub String);

impl FromStr for Protocol {
    type Err = UnknownProtocol;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let wanted = text.trim().to_ascii_lowercase();
        match wanted.as_str() {
            "mc3e-tcp" => Ok(Protocol::Mc3e),
            "mc4e-tcp" => Ok(Protocol::Mc4e),
            name => Protocol::ALL
                .into_iter()
                .find(|p| p.name() == name)
                .ok_or_else(|| UnknownProtocol(text.to_owned())),
        }
    }
}

/// A habit of some PLCs that the client must put up with, named in `quirks = [...]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Quirk {
    /// Modbus UDP/TCP: replies carry MBAP length 0 (the seed's shelf PLC); a standard
    /// length is still accepted.
    Length0,
    /// Modbus UDP/TCP: the PLC does not echo transaction ids.
    NoTransactionId,
    /// MEWTOCOL: the PLC is set up without the BCC check (`**` instead).
    NoBcc,
    /// MEWTOCOL: long `<` frames.
    LongFrames,
    /// PPI: the PLC does not echo the PDU reference.
    NoPduRef,
}

impl Quirk {
    /// Every quirk.
    pub const ALL: [Quirk; 5] =
        [Quirk::Length0, Quirk::NoTransactionId, Quirk::NoBcc, Quirk::LongFrames, Quirk::NoPduRef];

    /// The name the configuration writes.
    pub fn name(self) -> &'static str {
        match self {
            Quirk::Length0 => "length0",
            Quirk::NoTransactionId => "no-transaction-id",
            Quirk::NoBcc => "no-bcc",
            Quirk::LongFrames => "long-frames",
            Quirk::NoPduRef => "no-pdu-ref",
        }
    }

    /// Whether the quirk means anything on `protocol`. The MBAP quirks need an MBAP
    /// header, which Modbus RTU has not.
    pub fn applies_to(self, protocol: Protocol) -> bool {
        match self {
            Quirk::Length0 | Quirk::NoTransactionId => {
                matches!(protocol, Protocol::ModbusUdp | Protocol::ModbusTcp)
            }
            Quirk::NoBcc | Quirk::LongFrames => protocol.family() == Family::Mewtocol,
            Quirk::NoPduRef => protocol.family() == Family::Ppi,
        }
    }

    /// The quirks `protocol` knows.
    pub fn of(protocol: Protocol) -> Vec<Quirk> {
        Quirk::ALL.into_iter().filter(|q| q.applies_to(protocol)).collect()
    }
}

impl fmt::Display for Quirk {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Names joined with ", " for messages.
pub fn names<T: fmt::Display>(items: &[T]) -> String {
    items.iter().map(ToString::to_string).collect::<Vec<_>>().join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_through_text_serde_and_clap() {
        for p in Protocol::ALL {
            assert_eq!(p.name().parse::<Protocol>(), Ok(p));
            assert_eq!(p.to_string(), p.name());
            let toml: Protocol = serde_json::from_value(serde_json::json!(p.name())).unwrap();
            assert_eq!(toml, p);
            assert_eq!(<Protocol as clap::ValueEnum>::from_str(p.name(), false), Ok(p));
        }
        assert_eq!("mc3e-tcp".parse::<Protocol>(), Ok(Protocol::Mc3e));
        assert_eq!(
            serde_json::from_value::<Protocol>(serde_json::json!("mc3e-tcp")).unwrap(),
            Protocol::Mc3e
        );
        assert_eq!(<Protocol as clap::ValueEnum>::from_str("mc3e-tcp", false), Ok(Protocol::Mc3e));
        assert_eq!("mc4e-tcp".parse::<Protocol>(), Ok(Protocol::Mc4e));
        assert_eq!(<Protocol as clap::ValueEnum>::from_str("mc4e-tcp", false), Ok(Protocol::Mc4e));
        assert_eq!(Protocol::Mc4eUdp.family(), Family::Mc3e);
        let err = "mc9".parse::<Protocol>().unwrap_err().to_string();
        assert!(err.contains("mc9") && err.contains("modbus-rtu-tcp"), "{err}");
    }

    #[test]
    fn facts_by_protocol() {
        assert_eq!(Protocol::Ppi.default_unit(), 2);
        assert_eq!(Protocol::PpiTcp.default_unit(), 2);
        assert_eq!(Protocol::Mewtocol.default_unit(), 1);
        let serial: Vec<_> = Protocol::ALL.into_iter().filter(|p| p.is_serial()).collect();
        assert_eq!(serial, [Protocol::ModbusRtu, Protocol::Mewtocol, Protocol::Ppi]);
        assert_eq!(Protocol::ModbusRtuTcp.family(), Family::Modbus);
    }

    #[test]
    fn whether_replies_name_their_request_is_the_protocols_and_the_quirks() {
        let none = BTreeSet::new();
        let no_tid = BTreeSet::from([Quirk::NoTransactionId, Quirk::Length0]);
        let named: Vec<_> =
            Protocol::ALL.into_iter().filter(|p| p.replies(&none) == Replies::Named).collect();
        assert_eq!(named, [Protocol::ModbusUdp, Protocol::ModbusTcp, Protocol::Mc4e, Protocol::Mc4eUdp]);
        assert_eq!(Protocol::ModbusUdp.replies(&no_tid), Replies::Unnamed, "the seed's shelf PLC");
        assert_eq!(Protocol::ModbusTcp.replies(&no_tid), Replies::Unnamed);
        assert_eq!(Protocol::ModbusUdp.replies(&BTreeSet::from([Quirk::Length0])), Replies::Named);
        assert_eq!(Protocol::Ppi.replies(&none), Replies::Unnamed, "a half-duplex line");
    }

    #[test]
    fn quirks_belong_to_their_protocols() {
        assert_eq!(Quirk::of(Protocol::ModbusUdp), [Quirk::Length0, Quirk::NoTransactionId]);
        assert!(Quirk::of(Protocol::ModbusRtu).is_empty());
        assert!(Quirk::of(Protocol::Mc3eUdp).is_empty());
        assert_eq!(Quirk::of(Protocol::MewtocolTcp), [Quirk::NoBcc, Quirk::LongFrames]);
        assert_eq!(Quirk::of(Protocol::Ppi), [Quirk::NoPduRef]);
        for q in Quirk::ALL {
            let parsed: Quirk = serde_json::from_value(serde_json::json!(q.name())).unwrap();
            assert_eq!(parsed, q);
        }
    }
}
