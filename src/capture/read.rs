//! Reading a capture back: the pcapng files [`super::write()`] makes, and plain Wireshark
//! captures of the same link types, as the [`Link`] and its [`Frame`]s.
//!
//! # Decisions
//! - Blocks: one Section Header Block (either byte order), one Interface Description Block
//!   and Enhanced Packet Blocks; other blocks (name resolution, statistics, decryption
//!   secrets, custom) are skipped. The obsolete Packet Block and the Simple Packet Block
//!   carry packets this reader would have to guess the interface or time of: refused, as
//!   are a second section or a second interface (filter the file to one conversation).
//! - Times: `if_tsresol` is honoured (a power of 10 or, with the high bit, of 2); 6 when
//!   absent, as the specification says. Frames keep microseconds.
//! - Ethernet (link type 1): IPv4 or IPv6 (an 802.1Q tag is skipped), then UDP or TCP; the
//!   frame is the payload, cut by the IP length (a short frame's Ethernet padding is not
//!   payload). TCP segments without payload (handshake, bare ACKs) are skipped; the file's
//!   TCP is not analysed further (a retransmission would be read as a frame of its own).
//! - Who is rackd: on rackd's own files, the sender whose MAC is `02:00:00:00:00:01`. On
//!   other files, the sender of the first SYN without ACK, or failing that of the first
//!   packet with payload: a master speaks first, and rackd is the master. A packet between
//!   two other endpoints is refused (filter the file to one conversation).
//! - Exported PDUs (link type 252): the dissector's name gives the [`SerialProtocol`], tag
//!   35 the direction; the port is the interface's name without the protocol's.

use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr};

use super::frame::{Direction, Frame};
use super::link::{LINKTYPE_ETHERNET, LINKTYPE_UPPER_PDU, Link, SerialProtocol, Transport};
use super::packet::{LOCAL_MAC, TAG_END, TAG_P2P_DIRECTION, TAG_PROTO_NAME};
use super::pcapng::{BYTE_ORDER_MAGIC, EPB, IDB, IF_NAME, IF_TSRESOL, OPT_COMMENT, OPT_END, SHB};

/// A capture read back.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Capture {
    /// The link its frames travelled on.
    pub link: Link,
    /// The frames, in file order.
    pub frames: Vec<Frame>,
}

/// Why a file is not a capture this reader takes.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The file could not be read.
    #[error("cannot read the capture: {0}")]
    Io(#[from] std::io::Error),
    /// The file does not start with a Section Header Block.
    #[error("not a pcapng file (first block type {0:#010x})")]
    NotPcapng(u32),
    /// The section's byte-order magic is neither order of 0x1A2B3C4D.
    #[error("unknown byte-order magic {0:#010x}")]
    ByteOrder(u32),
    /// A block runs past the end of the file or its length is not a multiple of 4.
    #[error("block at byte {at}: length {length} is impossible")]
    BlockLength {
        /// Offset of the block.
        at: usize,
        /// Its stated total length.
        length: u32,
    },
    /// A block's trailing length differs from its leading one.
    #[error("block at byte {at}: trailing length differs")]
    Trailer {
        /// Offset of the block.
        at: usize,
    },
    /// A block's body is shorter than its fixed fields or its options say.
    #[error("block at byte {at}: {what} cut short")]
    Short {
        /// Offset of the block.
        at: usize,
        /// What was cut.
        what: &'static str,
    },
    /// A second section, a second interface, or a packet block without packets' interface.
    #[error("{0}: one section with one interface is read")]
    Layout(&'static str),
    /// A packet block of a kind that is not read (2: obsolete Packet Block, 3: Simple).
    #[error("block type {0} is not read (only Enhanced Packet Blocks)")]
    PacketBlock(u32),
    /// The interface's link type is neither Ethernet nor exported PDUs.
    #[error("link type {0} is not read (1 Ethernet or 252 exported PDU)")]
    LinkType(u16),
    /// A packet is not what the link type promised.
    #[error("packet {packet}: {what}")]
    Packet {
        /// The packet's number, from 1 as Wireshark counts.
        packet: usize,
        /// What was wrong.
        what: &'static str,
    },
    /// A packet of another conversation than the first one's.
    #[error("packet {packet}: {from} -> {to} is another conversation; filter the file to one")]
    Conversation {
        /// The packet's number, from 1.
        packet: usize,
        /// Its source.
        from: SocketAddr,
        /// Its destination.
        to: SocketAddr,
    },
    /// An exported PDU names a dissector that is not one of rackd's serial protocols.
    #[error("exported PDU for dissector {0:?}: not a serial protocol rackd speaks")]
    Dissector(String),
    /// No packet: nothing tells the link's endpoints.
    #[error("no packets")]
    Empty,
}

/// Reads a capture from a file.
pub fn read_file(path: &std::path::Path) -> Result<Capture, ReadError> {
    read(&std::fs::read(path)?)
}

/// Reads a capture from its bytes.
pub fn read(bytes: &[u8]) -> Result<Capture, ReadError> {
    let mut reader = Blocks { bytes, at: 0, big: false };
    let mut interface: Option<Interface> = None;
    let mut packets: Vec<(u64, Vec<u8>, String)> = Vec::new();
    let mut sections = 0;
    while let Some(block) = reader.next()? {
        match block.kind {
            SHB => {
                sections += 1;
                if sections > 1 {
                    return Err(ReadError::Layout("a second section"));
                }
            }
            _ if sections == 0 => return Err(ReadError::NotPcapng(block.kind)),
            IDB => {
                if interface.is_some() {
                    return Err(ReadError::Layout("a second interface"));
                }
                interface = Some(reader.interface(&block)?);
            }
            EPB => {
                let Some(i) = &interface else {
                    return Err(ReadError::Layout("a packet before the interface"));
                };
                packets.push(reader.packet(&block, i)?);
            }
            2 | 3 => return Err(ReadError::PacketBlock(block.kind)),
            _ => {}
        }
    }
    let interface = interface.ok_or(ReadError::Empty)?;
    match interface.link_type {
        LINKTYPE_ETHERNET => ethernet_capture(&packets),
        LINKTYPE_UPPER_PDU => serial_capture(&interface.name, &packets),
        other => Err(ReadError::LinkType(other)),
    }
}

/// One block: its type and where its body lies.
struct Block {
    kind: u32,
    at: usize,
    body: std::ops::Range<usize>,
}

/// What the one interface says.
struct Interface {
    link_type: u16,
    name: String,
    /// Time units per second.
    units: u128,
}

/// Walks a file's blocks in the section's byte order.
struct Blocks<'a> {
    bytes: &'a [u8],
    at: usize,
    big: bool,
}

impl Blocks<'_> {
    fn u16(&self, at: usize) -> u16 {
        let b = [self.bytes[at], self.bytes[at + 1]];
        if self.big { u16::from_be_bytes(b) } else { u16::from_le_bytes(b) }
    }

    fn u32(&self, at: usize) -> u32 {
        let b = [self.bytes[at], self.bytes[at + 1], self.bytes[at + 2], self.bytes[at + 3]];
        if self.big { u32::from_be_bytes(b) } else { u32::from_le_bytes(b) }
    }

    /// The next block, checked for its lengths; a section header sets the byte order.
    fn next(&mut self) -> Result<Option<Block>, ReadError> {
        let at = self.at;
        if at == self.bytes.len() {
            return Ok(None);
        }
        if self.bytes.len() - at < 12 {
            return Err(ReadError::BlockLength { at, length: (self.bytes.len() - at) as u32 });
        }
        let raw_kind = u32::from_le_bytes(self.bytes[at..at + 4].try_into().unwrap_or_default());
        if raw_kind == SHB {
            let magic = u32::from_le_bytes(self.bytes[at + 8..at + 12].try_into().unwrap_or_default());
            self.big = match magic {
                BYTE_ORDER_MAGIC => false,
                m if m == BYTE_ORDER_MAGIC.swap_bytes() => true,
                m => return Err(ReadError::ByteOrder(m)),
            };
        }
        let kind = self.u32(at);
        let length = self.u32(at + 4);
        let len = length as usize;
        if len < 12 || !len.is_multiple_of(4) || len > self.bytes.len() - at {
            return Err(ReadError::BlockLength { at, length });
        }
        if self.u32(at + len - 4) != length {
            return Err(ReadError::Trailer { at });
        }
        self.at = at + len;
        Ok(Some(Block { kind, at, body: at + 8..at + len - 4 }))
    }

    /// The options of a block from `from` to the end of its body: (code, value range).
    fn options(&self, block: &Block, from: usize) -> Result<Vec<(u16, std::ops::Range<usize>)>, ReadError> {
        let mut out = Vec::new();
        let mut at = from;
        while at + 4 <= block.body.end {
            let (code, len) = (self.u16(at), self.u16(at + 2) as usize);
            if code == OPT_END {
                break;
            }
            let value = at + 4..at + 4 + len;
            if value.end > block.body.end {
                return Err(ReadError::Short { at: block.at, what: "an option" });
            }
            out.push((code, value));
            at += 4 + len.div_ceil(4) * 4;
        }
        Ok(out)
    }

    fn interface(&self, block: &Block) -> Result<Interface, ReadError> {
        if block.body.len() < 8 {
            return Err(ReadError::Short { at: block.at, what: "an interface description" });
        }
        let link_type = self.u16(block.body.start);
        let mut interface = Interface { link_type, name: String::new(), units: 1_000_000 };
        for (code, value) in self.options(block, block.body.start + 8)? {
            match code {
                IF_NAME => interface.name = String::from_utf8_lossy(&self.bytes[value]).into_owned(),
                IF_TSRESOL if !value.is_empty() => {
                    let v = self.bytes[value.start];
                    let exp = u32::from(v & 0x7F);
                    let units = if v & 0x80 == 0 { 10u128.checked_pow(exp) } else { 2u128.checked_pow(exp) };
                    interface.units =
                        units.ok_or(ReadError::Short { at: block.at, what: "a usable if_tsresol" })?;
                }
                _ => {}
            }
        }
        Ok(interface)
    }

    /// An Enhanced Packet Block: time in microseconds, captured bytes, comment.
    fn packet(&self, block: &Block, interface: &Interface) -> Result<(u64, Vec<u8>, String), ReadError> {
        let b = block.body.start;
        if block.body.len() < 20 {
            return Err(ReadError::Short { at: block.at, what: "a packet block" });
        }
        if self.u32(b) != 0 {
            return Err(ReadError::Layout("a packet on a second interface"));
        }
        let ticks = (u64::from(self.u32(b + 4)) << 32) | u64::from(self.u32(b + 8));
        let time_us = (u128::from(ticks) * 1_000_000 / interface.units) as u64;
        let captured = self.u32(b + 12) as usize;
        let data = b + 20..(b + 20).saturating_add(captured);
        if data.end > block.body.end {
            return Err(ReadError::Short { at: block.at, what: "a packet's data" });
        }
        let options_at = b + 20 + captured.div_ceil(4) * 4;
        let mut comment = String::new();
        if options_at < block.body.end {
            for (code, value) in self.options(block, options_at)? {
                if code == OPT_COMMENT && comment.is_empty() {
                    comment = String::from_utf8_lossy(&self.bytes[value]).into_owned();
                }
            }
        }
        Ok((time_us, self.bytes[data].to_vec(), comment))
    }
}

/// One IP packet's endpoints and payload, and whether it came from rackd's made-up MAC.
struct IpPacket {
    transport: Transport,
    src: SocketAddr,
    dst: SocketAddr,
    from_rackd_mac: bool,
    /// A TCP SYN without ACK.
    syn: bool,
    payload: Vec<u8>,
}

fn ethernet_capture(packets: &[(u64, Vec<u8>, String)]) -> Result<Capture, ReadError> {
    let mut parsed = Vec::with_capacity(packets.len());
    for (n, (time, data, comment)) in packets.iter().enumerate() {
        let p = ip_packet(data).map_err(|what| ReadError::Packet { packet: n + 1, what })?;
        parsed.push((n + 1, *time, p, comment));
    }
    let rackd = parsed
        .iter()
        .find(|(_, _, p, _)| p.from_rackd_mac)
        .or_else(|| parsed.iter().find(|(_, _, p, _)| p.syn))
        .or_else(|| parsed.iter().find(|(_, _, p, _)| !p.payload.is_empty()))
        .ok_or(ReadError::Empty)?;
    let (transport, local, remote) = (rackd.2.transport, rackd.2.src, rackd.2.dst);
    let mut frames = Vec::new();
    for (packet, time_us, p, comment) in &parsed {
        let direction = if (p.src, p.dst) == (local, remote) {
            Direction::Sent
        } else if (p.src, p.dst) == (remote, local) {
            Direction::Received
        } else {
            return Err(ReadError::Conversation { packet: *packet, from: p.src, to: p.dst });
        };
        if p.transport != transport {
            return Err(ReadError::Packet { packet: *packet, what: "UDP and TCP in one capture" });
        }
        if p.payload.is_empty() && transport == Transport::Tcp {
            continue;
        }
        frames.push(frame(direction, *time_us, p.payload.clone(), comment));
    }
    Ok(Capture { link: Link::Ip { transport, local, remote }, frames })
}

fn frame(direction: Direction, time_us: u64, bytes: Vec<u8>, comment: &str) -> Frame {
    let mut f = Frame::new(direction, time_us, bytes);
    f.annotations = super::frame::Annotations::parse(comment);
    f
}

/// Ethernet II (with at most one 802.1Q tag), IPv4 or IPv6, UDP or TCP.
fn ip_packet(data: &[u8]) -> Result<IpPacket, &'static str> {
    let short = "cut short";
    let from_rackd_mac = data.get(6..12).ok_or(short)? == LOCAL_MAC;
    let mut at = 12;
    let mut ethertype = u16::from_be_bytes([*data.get(at).ok_or(short)?, *data.get(at + 1).ok_or(short)?]);
    if ethertype == 0x8100 {
        at += 4;
        ethertype = u16::from_be_bytes([*data.get(at).ok_or(short)?, *data.get(at + 1).ok_or(short)?]);
    }
    let ip = data.get(at + 2..).ok_or(short)?;
    let (src, dst, proto, segment) = match ethertype {
        0x0800 => {
            let ihl = usize::from(ip.first().ok_or(short)? & 0x0F) * 4;
            let total = usize::from(u16::from_be_bytes([*ip.get(2).ok_or(short)?, *ip.get(3).ok_or(short)?]));
            if ihl < 20 || total < ihl || total > ip.len() {
                return Err("IPv4 lengths do not fit");
            }
            let a = |o: usize| IpAddr::V4(Ipv4Addr::new(ip[o], ip[o + 1], ip[o + 2], ip[o + 3]));
            (a(12), a(16), ip[9], &ip[ihl..total])
        }
        0x86DD => {
            let payload =
                usize::from(u16::from_be_bytes([*ip.get(4).ok_or(short)?, *ip.get(5).ok_or(short)?]));
            if ip.len() < 40 + payload {
                return Err("IPv6 length does not fit");
            }
            let a = |o: usize| {
                let octets: [u8; 16] = ip[o..o + 16].try_into().unwrap_or_default();
                IpAddr::V6(Ipv6Addr::from(octets))
            };
            (a(8), a(24), ip[6], &ip[40..40 + payload])
        }
        _ => return Err("not IPv4 or IPv6"),
    };
    let port = |o: usize| segment.get(o..o + 2).map(|b| u16::from_be_bytes([b[0], b[1]])).ok_or(short);
    let (src, dst) = (SocketAddr::new(src, port(0)?), SocketAddr::new(dst, port(2)?));
    match proto {
        17 => {
            let payload = segment.get(8..).ok_or(short)?.to_vec();
            Ok(IpPacket { transport: Transport::Udp, src, dst, from_rackd_mac, syn: false, payload })
        }
        6 => {
            let offset = usize::from(segment.get(12).ok_or(short)? >> 4) * 4;
            let flags = *segment.get(13).ok_or(short)?;
            if offset < 20 || offset > segment.len() {
                return Err("TCP header length does not fit");
            }
            let syn = flags & 0x12 == 0x02;
            let payload = segment[offset..].to_vec();
            Ok(IpPacket { transport: Transport::Tcp, src, dst, from_rackd_mac, syn, payload })
        }
        _ => Err("not UDP or TCP"),
    }
}

fn serial_capture(name: &str, packets: &[(u64, Vec<u8>, String)]) -> Result<Capture, ReadError> {
    let mut protocol = None;
    let mut frames = Vec::with_capacity(packets.len());
    for (n, (time, data, comment)) in packets.iter().enumerate() {
        let bad = |what| ReadError::Packet { packet: n + 1, what };
        let (dissector, direction, at) = exported_pdu(data).map_err(bad)?;
        let p = match dissector.as_str() {
            "mbrtu" => SerialProtocol::ModbusRtu,
            "mewtocol" => SerialProtocol::Mewtocol,
            "s7ppi" => SerialProtocol::Ppi,
            _ => return Err(ReadError::Dissector(dissector)),
        };
        if protocol.is_some_and(|q| q != p) {
            return Err(bad("a second protocol on the line"));
        }
        protocol = Some(p);
        let direction = direction.ok_or_else(|| bad("no direction (tag 35)"))?;
        frames.push(frame(direction, *time, data[at..].to_vec(), comment));
    }
    let protocol = protocol.ok_or(ReadError::Empty)?;
    let suffix = format!(" {}", protocol.dissector());
    let port = name.strip_suffix(&suffix).unwrap_or(name).to_owned();
    Ok(Capture { link: Link::Serial { protocol, port }, frames })
}

/// An exported PDU's dissector name, direction and where its payload starts.
fn exported_pdu(data: &[u8]) -> Result<(String, Option<Direction>, usize), &'static str> {
    let (mut name, mut direction, mut at) = (None, None, 0);
    loop {
        let head = data.get(at..at + 4).ok_or("exported-PDU tags cut short")?;
        let tag = u16::from_be_bytes([head[0], head[1]]);
        let len = usize::from(u16::from_be_bytes([head[2], head[3]]));
        let value = data.get(at + 4..at + 4 + len).ok_or("an exported-PDU tag cut short")?;
        at += 4 + len;
        match tag {
            TAG_END => break,
            TAG_PROTO_NAME => {
                let end = value.iter().position(|&b| b == 0).unwrap_or(value.len());
                name = Some(String::from_utf8_lossy(&value[..end]).into_owned());
            }
            TAG_P2P_DIRECTION if len == 4 => {
                let v = u32::from_be_bytes([value[0], value[1], value[2], value[3]]);
                direction = Some(if v == 0 { Direction::Sent } else { Direction::Received });
            }
            _ => {}
        }
    }
    Ok((name.ok_or("no dissector name (tag 12)")?, direction, at))
}

#[cfg(test)]
#[path = "read_tests.rs"]
mod tests;
