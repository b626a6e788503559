//! Flag values of `rackd plc` that need more than clap's parsers: the unit (with
//! MEWTOCOL's global station `EE`) and the default port of each protocol.
//!
//! Decisions:
//! - `--unit` takes 0..=255 here and the protocol's own range is checked with the link
//!   (`protocols::link`), so one place says which units a protocol has. `EE` is 238
//!   (0xEE), MEWTOCOL's global station that every PLC answers whatever its number.
//! - **Default ports**: Modbus TCP and UDP use 502, the port IANA registered for Modbus
//!   (`mbap`). MC protocol has no standard port: each Ethernet module or built-in port is
//!   given one in its open settings (5000..5010 are common but not fixed), and a guess
//!   that is wrong only costs a timeout, so rackd asks for it. The serial gateways
//!   (`modbus-rtu-tcp`, `mewtocol-tcp`, `ppi-tcp`) have whatever port the gateway was set
//!   to, so rackd asks for those too.

use anyhow::bail;

use crate::protocols::Protocol;
use crate::protocols::protocol::Family;

/// MEWTOCOL's global station, as a unit number.
pub const GLOBAL_STATION: u8 = 0xEE;

/// `--unit`: 0..=255, or `EE`.
pub fn unit(text: &str) -> Result<u8, String> {
    if text.eq_ignore_ascii_case("EE") {
        return Ok(GLOBAL_STATION);
    }
    text.parse::<u8>().map_err(|_| {
        "expected a unit number 0..255, or EE (MEWTOCOL's global station, which every PLC answers)".to_owned()
    })
}

/// The protocol's standard port, if it has one.
pub fn default_port(protocol: Protocol) -> Option<u16> {
    match protocol {
        Protocol::ModbusTcp | Protocol::ModbusUdp => Some(502),
        _ => None,
    }
}

/// Whether a network address names a port (`host:502`, `[::1]:502`).
fn has_port(address: &str) -> bool {
    match address.rsplit_once(':') {
        Some((host, port)) => !port.is_empty() && (!host.contains(':') || host.ends_with(']')),
        None => false,
    }
}

/// `--address` with the protocol's default port added when it names none.
pub fn address(protocol: Protocol, address: &str) -> anyhow::Result<String> {
    if protocol.is_serial() || has_port(address) {
        return Ok(address.to_owned());
    }
    let host = if address.contains(':') && !address.starts_with('[') {
        format!("[{address}]")
    } else {
        address.to_owned()
    };
    match default_port(protocol) {
        Some(port) => Ok(format!("{host}:{port}")),
        None if protocol.family() == Family::Mc3e => bail!(
            "--address {address} names no port, and MC protocol has none of its own: give the port set in \
             the module's open settings, e.g. {host}:5000"
        ),
        None => bail!(
            "--address {address} names no port: give the port the serial gateway listens on, e.g. {host}:4001"
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_take_ee_for_mewtocols_global_station() {
        assert_eq!((unit("ee"), unit("EE"), unit("255"), unit("0")), (Ok(238), Ok(238), Ok(255), Ok(0)));
        assert!(unit("256").unwrap_err().contains("EE"));
    }

    #[test]
    fn modbus_gets_502_and_the_others_ask_for_their_port() {
        let with = |p, a| address(p, a).map_err(|e| e.to_string());
        assert_eq!(with(Protocol::ModbusTcp, "10.0.0.5").unwrap(), "10.0.0.5:502");
        assert_eq!(with(Protocol::ModbusUdp, "plc.local").unwrap(), "plc.local:502");
        assert_eq!(with(Protocol::ModbusTcp, "::1").unwrap(), "[::1]:502");
        assert_eq!(with(Protocol::ModbusTcp, "[::1]").unwrap(), "[::1]:502");
        assert_eq!(with(Protocol::ModbusTcp, "[::1]:1502").unwrap(), "[::1]:1502");
        assert_eq!(with(Protocol::ModbusTcp, "10.0.0.5:1502").unwrap(), "10.0.0.5:1502");
        assert_eq!(with(Protocol::ModbusRtu, "/dev/ttyUSB0").unwrap(), "/dev/ttyUSB0");
        assert!(with(Protocol::Mc3e, "10.0.0.1").unwrap_err().contains("open settings"));
        assert!(with(Protocol::PpiTcp, "10.0.0.1").unwrap_err().contains("gateway"));
    }
}
