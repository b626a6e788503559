//! What a capture's frames travelled on: a UDP or TCP socket pair, or a serial line speaking
//! one protocol. It decides the file's link type, the interface name, and how each frame is
//! wrapped ([`super::packet`]).

use std::net::SocketAddr;

/// The IP transport of a link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Transport {
    /// UDP datagrams: one frame, one datagram.
    Udp,
    /// A TCP connection: frames are segments of one stream per direction.
    Tcp,
}

/// The protocol on a serial line (or a byte stream a gateway carries as-is).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SerialProtocol {
    /// Modbus RTU, decoded by Wireshark's own `mbrtu`.
    ModbusRtu,
    /// MEWTOCOL-COM, decoded by `contrib/wireshark/mewtocol.lua`.
    Mewtocol,
    /// S7-200 PPI, decoded by `contrib/wireshark/s7ppi.lua`.
    Ppi,
}

impl SerialProtocol {
    /// The name of the Wireshark dissector the exported-PDU header names.
    pub fn dissector(self) -> &'static str {
        match self {
            SerialProtocol::ModbusRtu => "mbrtu",
            SerialProtocol::Mewtocol => "mewtocol",
            SerialProtocol::Ppi => "s7ppi",
        }
    }
}

/// Where a capture's frames travelled.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Link {
    /// An IP socket pair; frames are wrapped in Ethernet, IP and UDP or TCP headers.
    Ip {
        /// UDP or TCP.
        transport: Transport,
        /// rackd's end.
        local: SocketAddr,
        /// The device's end.
        remote: SocketAddr,
    },
    /// A serial line; frames are exported PDUs naming the protocol's dissector.
    Serial {
        /// The protocol on the line.
        protocol: SerialProtocol,
        /// The port's name (`/dev/ttyUSB0`).
        port: String,
    },
}

/// pcapng link type of Ethernet frames.
pub const LINKTYPE_ETHERNET: u16 = 1;
/// pcapng link type of Wireshark's exported PDUs (`LINKTYPE_WIRESHARK_UPPER_PDU`).
pub const LINKTYPE_UPPER_PDU: u16 = 252;

impl Link {
    /// The pcapng link type of the capture's one interface.
    pub fn link_type(&self) -> u16 {
        match self {
            Link::Ip { .. } => LINKTYPE_ETHERNET,
            Link::Serial { .. } => LINKTYPE_UPPER_PDU,
        }
    }

    /// The interface's name: the socket pair (`tcp 10.0.0.1:40000 - 10.0.0.9:8000`) or the
    /// port and protocol (`/dev/ttyUSB0 mewtocol`).
    pub fn interface_name(&self) -> String {
        match self {
            Link::Ip { transport, local, remote } => {
                let t = match transport {
                    Transport::Udp => "udp",
                    Transport::Tcp => "tcp",
                };
                format!("{t} {local} - {remote}")
            }
            Link::Serial { protocol, port } => format!("{port} {}", protocol.dissector()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_link_types() {
        let ip = Link::Ip {
            transport: Transport::Tcp,
            local: "10.0.0.1:40000".parse().unwrap(),
            remote: "10.0.0.9:8000".parse().unwrap(),
        };
        assert_eq!((ip.link_type(), ip.interface_name().as_str()), (1, "tcp 10.0.0.1:40000 - 10.0.0.9:8000"));
        let serial = Link::Serial { protocol: SerialProtocol::Ppi, port: "/dev/ttyUSB0".into() };
        assert_eq!((serial.link_type(), serial.interface_name().as_str()), (252, "/dev/ttyUSB0 s7ppi"));
        assert_eq!(SerialProtocol::ModbusRtu.dissector(), "mbrtu");
        assert_eq!(SerialProtocol::Mewtocol.dissector(), "mewtocol");
    }
}
