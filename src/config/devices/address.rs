//! What a `[[devices]]` entry's `address`, `unit` and `serial` may be for its protocol,
//! checked without a connection so that `rackd check-config` finds a typo before a site
//! starts.
//!
//! Decisions where the protocol documents leave room:
//! - **Addresses**: a network protocol takes `HOST:PORT`, the host a name (letters, digits,
//!   `-`, dots) or an IP address, IPv6 in brackets (`[fe80::1]:502`), the port 1..=65535.
//!   A host of only digits and dots must be an IPv4 address, so `192.168.1.300:502` is
//!   refused instead of being looked up as a name. A serial protocol takes a device path
//!   (`/dev/ttyUSB0`, or `COM3` on Windows); `HOST:PORT` there is refused with a pointer to
//!   the protocol's `-tcp` form, the usual mix-up with a serial-to-Ethernet gateway.
//! - **Units** follow the protocol documents: Modbus RTU (also over TCP, where a gateway
//!   puts the frame on an RS-485 bus) 1..=247, as 0 is the broadcast that no station
//!   answers; Modbus TCP and UDP 0..=255, since there the unit id addresses the TCP device
//!   itself (Modbus Messaging on TCP/IP Implementation Guide: 0xFF, or 0) or a station
//!   behind a gateway, rather than a bus, and unit 0 is answered; MEWTOCOL
//!   stations 1..=99 (two decimal digits), or the global station `EE` (written `unit = "EE"`,
//!   or 238 = 0xEE, as rackd keeps it),
//!   which the one PLC on a point-to-point line answers whatever its number; PPI addresses 1..=126 (0 is rackd, the master;
//!   127 is the broadcast). An MC 3E frame addresses the PLC by network 0, PC FF, station
//!   0 and carries no unit, so an MC entry's `unit` must stay at its default 1 (a value
//!   that would be silently ignored is refused).
//! - **`serial`** applies where a baud rate matters: the serial protocols, and
//!   `modbus-rtu-tcp`, whose frame gaps follow the gateway's line speed.

use std::net::{Ipv4Addr, SocketAddr};

use crate::protocols::Protocol;
use crate::protocols::mewtocol::frame::GLOBAL_STATION;
use crate::protocols::protocol::Family;

/// An address, unit or serial setting the protocol cannot use.
#[derive(Debug, PartialEq, Eq, thiserror::Error)]
pub enum AddressError {
    /// A network address that is not `HOST:PORT`.
    #[error("address {address:?} is not HOST:PORT ({why})")]
    NotHostPort {
        /// The address as written.
        address: String,
        /// What is wrong with it.
        why: &'static str,
    },
    /// `HOST:PORT` on a serial protocol.
    #[error(
        "address {address:?}: {protocol} is a serial protocol and takes a serial device such as \
         /dev/ttyUSB0 (for a serial-to-Ethernet gateway use {protocol}-tcp)"
    )]
    NotSerialDevice {
        /// The address as written.
        address: String,
        /// The link's protocol.
        protocol: Protocol,
    },
    /// A unit outside the protocol's range.
    #[error("unit {unit} is not a {protocol} station: {range}")]
    Unit {
        /// The unit as written.
        unit: i64,
        /// The link's protocol.
        protocol: Protocol,
        /// The valid range, in words.
        range: &'static str,
    },
    /// `unit = "EE"` on a protocol other than MEWTOCOL.
    #[error("unit \"EE\" is MEWTOCOL's global station; {0} takes a number")]
    GlobalStation(Protocol),
    /// `serial` on a protocol without a serial line.
    #[error("serial settings apply to serial protocols and modbus-rtu-tcp, not to {0}")]
    SerialUnused(Protocol),
}

/// Checks `address` for `protocol`.
pub fn check_address(protocol: Protocol, address: &str) -> Result<(), AddressError> {
    if protocol.is_serial() {
        let com_port = address.strip_prefix("COM").is_some_and(|n| n.parse::<u16>().is_ok());
        if address.starts_with('/') || com_port {
            return Ok(());
        }
        return Err(AddressError::NotSerialDevice { address: address.to_owned(), protocol });
    }
    let bad = |why| Err(AddressError::NotHostPort { address: address.to_owned(), why });
    if address.starts_with('[') {
        return match address.parse::<SocketAddr>() {
            Ok(a) if a.port() != 0 => Ok(()),
            Ok(_) => bad("the port must be 1..=65535"),
            Err(_) => bad("an IPv6 address is written [ADDRESS]:PORT"),
        };
    }
    let Some((host, port)) = address.rsplit_once(':') else {
        return bad("no port");
    };
    if host.contains(':') {
        return bad("an IPv6 address is written in brackets, [ADDRESS]:PORT");
    }
    if !matches!(port.parse::<u16>(), Ok(p) if p != 0) {
        return bad("the port must be 1..=65535");
    }
    if host.chars().all(|c| c.is_ascii_digit() || c == '.') {
        return match host.parse::<Ipv4Addr>() {
            Ok(_) => Ok(()),
            Err(_) => bad("not an IPv4 address: four numbers 0..=255"),
        };
    }
    let label = |l: &str| {
        !l.is_empty()
            && l.len() <= 63
            && !l.starts_with('-')
            && !l.ends_with('-')
            && l.chars().all(|c| c.is_ascii_alphanumeric() || c == '-')
    };
    if host.len() > 253 || !host.split('.').all(label) {
        return bad("the host is neither an IP address nor a host name");
    }
    Ok(())
}

/// Checks `unit` for `protocol` (see the module documentation for the ranges).
pub fn check_unit(protocol: Protocol, unit: i64) -> Result<u8, AddressError> {
    let range: (i64, i64, &'static str) = match (protocol.family(), protocol) {
        (Family::Modbus, Protocol::ModbusTcp | Protocol::ModbusUdp) => {
            (0, 255, "0..=255 (255 or 0 address the TCP device itself)")
        }
        (Family::Modbus, _) => (1, 247, "1..=247 (0 is the broadcast, which no station answers)"),
        (Family::Mewtocol, _) => (1, 99, "1..=99, or 238 for EE, the global station"),
        (Family::Ppi, _) => (1, 126, "1..=126 (0 is rackd's own address, 127 the broadcast)"),
        (Family::Mc3e, _) => (1, 1, "the 3E frame carries no unit; leave `unit` out"),
    };
    let global = protocol.family() == Family::Mewtocol && unit == i64::from(GLOBAL_STATION);
    match u8::try_from(unit) {
        Ok(u) if (range.0..=range.1).contains(&unit) || global => Ok(u),
        _ => Err(AddressError::Unit { unit, protocol, range: range.2 }),
    }
}

/// Checks that `serial` settings are only given where a line speed matters.
pub fn check_serial(protocol: Protocol, has_serial: bool) -> Result<(), AddressError> {
    if has_serial && !(protocol.is_serial() || protocol == Protocol::ModbusRtuTcp) {
        return Err(AddressError::SerialUnused(protocol));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn network_addresses_are_host_and_port() {
        let ok = |a| check_address(Protocol::ModbusTcp, a);
        for good in ["192.168.1.10:502", "plc-1.site.local:502", "[fe80::1]:502", "localhost:1"] {
            assert_eq!(ok(good), Ok(()), "{good}");
        }
        for bad in ["192.168.1.300:502", "192.168.1.10", "plc:0", "plc:70000", "fe80::1:502", "a b:1", ":502"]
        {
            assert!(matches!(ok(bad), Err(AddressError::NotHostPort { .. })), "{bad}");
        }
        let err = ok("192.168.1.300:502").unwrap_err().to_string();
        assert!(err.contains("IPv4"), "{err}");
    }

    #[test]
    fn serial_protocols_take_a_device_path() {
        assert_eq!(check_address(Protocol::ModbusRtu, "/dev/ttyUSB0"), Ok(()));
        assert_eq!(check_address(Protocol::Ppi, "COM3"), Ok(()));
        let err = check_address(Protocol::Mewtocol, "10.0.0.1:9094").unwrap_err().to_string();
        assert!(err.contains("mewtocol-tcp"), "{err}");
    }

    #[test]
    fn units_follow_each_protocol() {
        assert_eq!(check_unit(Protocol::ModbusRtu, 247), Ok(247));
        assert!(check_unit(Protocol::ModbusRtu, 0).unwrap_err().to_string().contains("broadcast"));
        assert_eq!(check_unit(Protocol::ModbusTcp, 0), Ok(0));
        assert_eq!(check_unit(Protocol::ModbusTcp, 255), Ok(255));
        assert!(check_unit(Protocol::ModbusRtuTcp, 248).is_err());
        let err = check_unit(Protocol::ModbusUdp, 300).unwrap_err().to_string();
        assert_eq!(
            err,
            "unit 300 is not a modbus-udp station: 0..=255 (255 or 0 address the TCP device itself)"
        );
        assert!(check_unit(Protocol::Mewtocol, 100).is_err() && check_unit(Protocol::Mewtocol, 99).is_ok());
        assert_eq!(check_unit(Protocol::MewtocolTcp, 238), Ok(238));
        assert!(check_unit(Protocol::Ppi, 238).is_err() && check_unit(Protocol::Mewtocol, 237).is_err());
        assert!(check_unit(Protocol::Ppi, 0).is_err() && check_unit(Protocol::PpiTcp, 126).is_ok());
        assert!(check_unit(Protocol::Ppi, 127).is_err() && check_unit(Protocol::Ppi, -1).is_err());
        assert_eq!(check_unit(Protocol::Mc3e, 1), Ok(1));
        assert!(check_unit(Protocol::Mc3eUdp, 5).unwrap_err().to_string().contains("no unit"));
    }

    #[test]
    fn serial_settings_only_where_a_line_speed_matters() {
        assert!(
            check_serial(Protocol::ModbusRtuTcp, true).is_ok() && check_serial(Protocol::Ppi, true).is_ok()
        );
        assert!(check_serial(Protocol::ModbusUdp, false).is_ok());
        assert_eq!(
            check_serial(Protocol::ModbusUdp, true),
            Err(AddressError::SerialUnused(Protocol::ModbusUdp))
        );
    }
}
