//! Wrapping a frame's bytes as the link type wants them.
//!
//! - IP links: an Ethernet II frame around an IPv4 packet (an IPv6 one when either address
//!   is IPv6; an IPv4 address is then written IPv4-mapped) around a UDP datagram or a TCP
//!   segment, with the link's real addresses and ports. The MAC addresses are made up,
//!   locally administered: `02:00:00:00:00:01` for rackd, `02:00:00:00:00:02` for the device.
//!   Checksums (IPv4 header, UDP, TCP) are computed, so Wireshark's checks pass when turned on.
//! - TCP: no handshake is invented; each direction's sequence number starts at 1 and
//!   advances by each segment's length, every segment acknowledges what the other side sent
//!   so far and carries ACK and PSH, so Wireshark's analysis and reassembly see one clean
//!   stream per direction.
//! - Serial links: an exported-PDU header (Wireshark's `exported_pdu`, link type 252) with two
//!   tags, the dissector's name (tag 12) and the direction (tag 35: 0 sent, 1 received, which
//!   `mbrtu` needs to tell a request from a response), closed by tag 0.

use std::net::{IpAddr, Ipv6Addr, SocketAddr};

use super::frame::{Direction, Frame};
use super::link::{Link, SerialProtocol, Transport};

/// rackd's made-up MAC address.
pub const LOCAL_MAC: [u8; 6] = [0x02, 0, 0, 0, 0, 0x01];
/// The device's made-up MAC address.
pub const REMOTE_MAC: [u8; 6] = [0x02, 0, 0, 0, 0, 0x02];
/// Exported-PDU tag: the name of the dissector for the PDU.
pub const TAG_PROTO_NAME: u16 = 12;
/// Exported-PDU tag: the direction on a point-to-point link.
pub const TAG_P2P_DIRECTION: u16 = 35;
/// Exported-PDU tag: end of the tags.
pub const TAG_END: u16 = 0;

const ETHERTYPE_IPV4: u16 = 0x0800;
const ETHERTYPE_IPV6: u16 = 0x86DD;
const PROTO_TCP: u8 = 6;
const PROTO_UDP: u8 = 17;
/// TCP flags ACK and PSH.
const ACK_PSH: u8 = 0x18;

/// Wraps the frames of one link in order; keeps what runs on from frame to frame (TCP
/// sequence numbers, IPv4 identification).
pub struct Wrapper {
    link: Link,
    /// Next sequence number of rackd's side and of the device's side.
    seq: [u32; 2],
    /// Next IPv4 identification.
    ip_id: u16,
}

impl Wrapper {
    /// A wrapper for frames on `link`.
    pub fn new(link: &Link) -> Wrapper {
        Wrapper { link: link.clone(), seq: [1, 1], ip_id: 1 }
    }

    /// The packet bytes for `frame`.
    pub fn wrap(&mut self, frame: &Frame) -> Vec<u8> {
        match self.link.clone() {
            Link::Ip { transport, local, remote } => {
                let (src, dst) = match frame.direction {
                    Direction::Sent => (local, remote),
                    Direction::Received => (remote, local),
                };
                let segment = match transport {
                    Transport::Udp => udp(src, dst, &frame.bytes),
                    Transport::Tcp => self.tcp(frame.direction, src, dst, &frame.bytes),
                };
                let proto = if transport == Transport::Tcp { PROTO_TCP } else { PROTO_UDP };
                self.ethernet(frame.direction, src.ip(), dst.ip(), proto, &segment)
            }
            Link::Serial { protocol, .. } => exported_pdu(protocol, frame.direction, &frame.bytes),
        }
    }

    fn tcp(&mut self, direction: Direction, src: SocketAddr, dst: SocketAddr, payload: &[u8]) -> Vec<u8> {
        let (me, other) = match direction {
            Direction::Sent => (0, 1),
            Direction::Received => (1, 0),
        };
        let seq = self.seq[me];
        self.seq[me] = seq.wrapping_add(payload.len() as u32);
        let mut out = Vec::with_capacity(20 + payload.len());
        out.extend_from_slice(&src.port().to_be_bytes());
        out.extend_from_slice(&dst.port().to_be_bytes());
        out.extend_from_slice(&seq.to_be_bytes());
        out.extend_from_slice(&self.seq[other].to_be_bytes());
        out.extend_from_slice(&[5 << 4, ACK_PSH]);
        out.extend_from_slice(&u16::MAX.to_be_bytes());
        out.extend_from_slice(&[0, 0, 0, 0]);
        out.extend_from_slice(payload);
        let sum = transport_checksum(src.ip(), dst.ip(), PROTO_TCP, &out);
        out[16..18].copy_from_slice(&sum.to_be_bytes());
        out
    }

    fn ethernet(
        &mut self,
        direction: Direction,
        src: IpAddr,
        dst: IpAddr,
        proto: u8,
        segment: &[u8],
    ) -> Vec<u8> {
        let (src_mac, dst_mac) = match direction {
            Direction::Sent => (LOCAL_MAC, REMOTE_MAC),
            Direction::Received => (REMOTE_MAC, LOCAL_MAC),
        };
        let mut out = Vec::with_capacity(14 + 40 + segment.len());
        out.extend_from_slice(&dst_mac);
        out.extend_from_slice(&src_mac);
        match (src, dst) {
            (IpAddr::V4(s), IpAddr::V4(d)) => {
                out.extend_from_slice(&ETHERTYPE_IPV4.to_be_bytes());
                let id = self.ip_id;
                self.ip_id = id.wrapping_add(1);
                out.extend_from_slice(&ipv4_header(s.octets(), d.octets(), proto, id, segment.len()));
            }
            (s, d) => {
                out.extend_from_slice(&ETHERTYPE_IPV6.to_be_bytes());
                out.extend_from_slice(&ipv6_header(v6(s), v6(d), proto, segment.len()));
            }
        }
        out.extend_from_slice(segment);
        out
    }
}

fn v6(ip: IpAddr) -> Ipv6Addr {
    match ip {
        IpAddr::V4(v4) => v4.to_ipv6_mapped(),
        IpAddr::V6(v6) => v6,
    }
}

/// A UDP datagram: ports, length, checksum, payload.
fn udp(src: SocketAddr, dst: SocketAddr, payload: &[u8]) -> Vec<u8> {
    let len = 8 + payload.len();
    let mut out = Vec::with_capacity(len);
    out.extend_from_slice(&src.port().to_be_bytes());
    out.extend_from_slice(&dst.port().to_be_bytes());
    out.extend_from_slice(&(u16::try_from(len).unwrap_or(u16::MAX)).to_be_bytes());
    out.extend_from_slice(&[0, 0]);
    out.extend_from_slice(payload);
    // A computed 0 is sent as FFFF: 0 means "no checksum" (and is not allowed over IPv6).
    let sum = match transport_checksum(src.ip(), dst.ip(), PROTO_UDP, &out) {
        0 => 0xFFFF,
        s => s,
    };
    out[6..8].copy_from_slice(&sum.to_be_bytes());
    out
}

/// An IPv4 header without options: don't fragment, TTL 64, its checksum computed.
fn ipv4_header(src: [u8; 4], dst: [u8; 4], proto: u8, id: u16, payload: usize) -> [u8; 20] {
    let total = u16::try_from(20 + payload).unwrap_or(u16::MAX).to_be_bytes();
    let id = id.to_be_bytes();
    let mut h = [
        0x45, 0, total[0], total[1], id[0], id[1], 0x40, 0, 64, proto, 0, 0, src[0], src[1], src[2], src[3],
        dst[0], dst[1], dst[2], dst[3],
    ];
    let sum = checksum(&[&h]).to_be_bytes();
    h[10..12].copy_from_slice(&sum);
    h
}

/// An IPv6 header: no flow label, hop limit 64.
fn ipv6_header(src: Ipv6Addr, dst: Ipv6Addr, proto: u8, payload: usize) -> Vec<u8> {
    let mut h = Vec::with_capacity(40);
    h.extend_from_slice(&[0x60, 0, 0, 0]);
    h.extend_from_slice(&(u16::try_from(payload).unwrap_or(u16::MAX)).to_be_bytes());
    h.extend_from_slice(&[proto, 64]);
    h.extend_from_slice(&src.octets());
    h.extend_from_slice(&dst.octets());
    h
}

/// The UDP or TCP checksum of `segment` (its checksum field zero) under the pseudo-header.
fn transport_checksum(src: IpAddr, dst: IpAddr, proto: u8, segment: &[u8]) -> u16 {
    let len = segment.len() as u32;
    match (src, dst) {
        (IpAddr::V4(s), IpAddr::V4(d)) => {
            let pseudo = [&s.octets()[..], &d.octets(), &[0, proto], &(len as u16).to_be_bytes()].concat();
            checksum(&[&pseudo, segment])
        }
        (s, d) => {
            let pseudo =
                [&v6(s).octets()[..], &v6(d).octets(), &len.to_be_bytes(), &[0, 0, 0, proto]].concat();
            checksum(&[&pseudo, segment])
        }
    }
}

/// The Internet checksum (RFC 1071) of the parts, read as one run of bytes.
fn checksum(parts: &[&[u8]]) -> u16 {
    let mut sum = 0u32;
    let mut odd: Option<u8> = None;
    for byte in parts.iter().flat_map(|p| p.iter().copied()) {
        match odd.take() {
            Some(high) => sum += u32::from(u16::from_be_bytes([high, byte])),
            None => odd = Some(byte),
        }
        sum = (sum & 0xFFFF) + (sum >> 16);
    }
    if let Some(high) = odd {
        sum += u32::from(high) << 8;
    }
    while sum > 0xFFFF {
        sum = (sum & 0xFFFF) + (sum >> 16);
    }
    !(sum as u16)
}

/// An exported PDU: the dissector's name (padded to 32 bits), the direction, the end tag,
/// then the frame's bytes.
fn exported_pdu(protocol: SerialProtocol, direction: Direction, bytes: &[u8]) -> Vec<u8> {
    let name = protocol.dissector().as_bytes();
    let padded = name.len().div_ceil(4) * 4;
    let mut out = Vec::with_capacity(16 + padded + bytes.len());
    out.extend_from_slice(&TAG_PROTO_NAME.to_be_bytes());
    out.extend_from_slice(&(padded as u16).to_be_bytes());
    out.extend_from_slice(name);
    out.resize(out.len() + padded - name.len(), 0);
    let p2p: u32 = match direction {
        Direction::Sent => 0,
        Direction::Received => 1,
    };
    out.extend_from_slice(&TAG_P2P_DIRECTION.to_be_bytes());
    out.extend_from_slice(&4u16.to_be_bytes());
    out.extend_from_slice(&p2p.to_be_bytes());
    out.extend_from_slice(&TAG_END.to_be_bytes());
    out.extend_from_slice(&0u16.to_be_bytes());
    out.extend_from_slice(bytes);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tcp_link() -> Link {
        Link::Ip {
            transport: Transport::Tcp,
            local: "10.0.0.1:40000".parse().unwrap(),
            remote: "10.0.0.9:8000".parse().unwrap(),
        }
    }

    #[test]
    fn the_ipv4_checksum_of_a_worked_example() {
        // Wikipedia's "IPv4 header checksum" example: 4500 0073 0000 4000 4011 B861
        // C0A8 0001 C0A8 00C7.
        let h = ipv4_header([0xC0, 0xA8, 0x00, 0x01], [0xC0, 0xA8, 0x00, 0xC7], 17, 0, 0x73 - 20);
        assert_eq!(&h[..12], [0x45, 0, 0, 0x73, 0, 0, 0x40, 0, 0x40, 0x11, 0xB8, 0x61]);
    }

    #[test]
    fn a_sent_udp_frame_goes_from_rackd_to_the_device() {
        let link = Link::Ip {
            transport: Transport::Udp,
            local: "192.168.1.10:50000".parse().unwrap(),
            remote: "192.168.1.20:502".parse().unwrap(),
        };
        let p = Wrapper::new(&link).wrap(&Frame::new(Direction::Sent, 0, vec![1, 2, 3]));
        assert_eq!(&p[..12], [REMOTE_MAC, LOCAL_MAC].concat());
        assert_eq!(&p[12..14], [0x08, 0x00]);
        assert_eq!(&p[14 + 2..14 + 4], [0, 20 + 8 + 3]);
        assert_eq!(&p[14 + 12..14 + 20], [192, 168, 1, 10, 192, 168, 1, 20]);
        assert_eq!(checksum(&[&p[14..34]]), 0, "a header with its checksum sums to 0");
        assert_eq!(&p[34..40], [0xC3, 0x50, 0x01, 0xF6, 0, 11]);
        assert_eq!(&p[42..], [1, 2, 3]);
        let received = Wrapper::new(&link).wrap(&Frame::new(Direction::Received, 0, vec![9]));
        assert_eq!(&received[14 + 12..14 + 20], [192, 168, 1, 20, 192, 168, 1, 10]);
        assert_eq!(&received[34..38], [0x01, 0xF6, 0xC3, 0x50]);
    }

    #[test]
    fn tcp_sequence_numbers_advance_per_direction() {
        let mut w = Wrapper::new(&tcp_link());
        let seq_ack = |p: &[u8]| {
            let t = &p[34..];
            (
                u32::from_be_bytes(t[4..8].try_into().unwrap()),
                u32::from_be_bytes(t[8..12].try_into().unwrap()),
            )
        };
        let a = w.wrap(&Frame::new(Direction::Sent, 0, vec![0; 21]));
        let b = w.wrap(&Frame::new(Direction::Received, 0, vec![0; 15]));
        let c = w.wrap(&Frame::new(Direction::Sent, 0, vec![0; 21]));
        assert_eq!(seq_ack(&a), (1, 1));
        assert_eq!(seq_ack(&b), (1, 22));
        assert_eq!(seq_ack(&c), (22, 16));
        assert_eq!(&a[34 + 12..34 + 14], [0x50, 0x18], "header length 20, ACK and PSH");
    }

    #[test]
    fn ipv6_addresses_make_an_ipv6_packet() {
        let link = Link::Ip {
            transport: Transport::Udp,
            local: "[::1]:50000".parse().unwrap(),
            remote: "[::1]:502".parse().unwrap(),
        };
        let p = Wrapper::new(&link).wrap(&Frame::new(Direction::Sent, 0, vec![7; 5]));
        assert_eq!(&p[12..14], [0x86, 0xDD]);
        assert_eq!(p[14] >> 4, 6);
        assert_eq!(&p[18..22], [0, 13, 17, 64]);
        assert_eq!(p.len(), 14 + 40 + 8 + 5);
    }

    #[test]
    fn the_exported_pdu_header_names_the_dissector_and_direction() {
        let link = Link::Serial { protocol: SerialProtocol::ModbusRtu, port: "ttyS0".into() };
        let p = Wrapper::new(&link).wrap(&Frame::new(Direction::Received, 0, vec![0xAA]));
        assert_eq!(&p[..4], [0, 12, 0, 8]);
        assert_eq!(&p[4..12], b"mbrtu\0\0\0");
        assert_eq!(&p[12..20], [0, 35, 0, 4, 0, 0, 0, 1]);
        assert_eq!(&p[20..], [0, 0, 0, 0, 0xAA]);
    }
}
