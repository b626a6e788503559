use super::*;
use crate::capture::frame::{Annotations, Verdict};
use crate::capture::{pcapng, write};

fn written(link: &Link, frames: &[Frame]) -> Vec<u8> {
    let mut out = Vec::new();
    write(&mut out, link, frames).unwrap();
    out
}

fn frames() -> Vec<Frame> {
    vec![
        Frame::new(Direction::Sent, 1_760_000_000_000_001, vec![0x50, 0, 1, 2, 3]),
        Frame::new(Direction::Received, 1_760_000_000_250_000, vec![0xD0, 0, 9]).with(Annotations {
            job: Some(3),
            verdict: Some(Verdict::Ok),
            ..Annotations::default()
        }),
        Frame::new(Direction::Sent, 1_760_000_000_300_000, vec![7; 61]),
        Frame::new(Direction::Received, 1_760_000_000_400_000, vec![])
            .with(Annotations { note: "nothing, then more".into(), ..Annotations::default() }),
    ]
}

#[test]
fn what_write_writes_reads_back_on_every_link() {
    let ip = |transport, local: &str, remote: &str| Link::Ip {
        transport,
        local: local.parse().unwrap(),
        remote: remote.parse().unwrap(),
    };
    let links = [
        ip(Transport::Udp, "192.168.1.10:50000", "192.168.1.20:502"),
        ip(Transport::Udp, "[::1]:50000", "[::1]:502"),
        ip(Transport::Tcp, "10.0.0.1:40000", "10.0.0.9:8000"),
        Link::Serial { protocol: SerialProtocol::Mewtocol, port: "/dev/ttyUSB0".into() },
        Link::Serial { protocol: SerialProtocol::ModbusRtu, port: "COM3".into() },
        Link::Serial { protocol: SerialProtocol::Ppi, port: "ttyS0".into() },
    ];
    for link in links {
        let mut frames = frames();
        if matches!(link, Link::Ip { transport: Transport::Tcp, .. }) {
            // A TCP segment without payload is no frame: the reader skips it.
            frames.pop();
        }
        let back = read(&written(&link, &frames)).unwrap_or_else(|e| panic!("{link:?}: {e}"));
        assert_eq!(back, Capture { link: link.clone(), frames }, "{link:?}");
    }
}

/// A foreign file: big-endian, nanosecond times, a name resolution block to skip, a TCP
/// handshake, padded Ethernet frames, the device's packet first.
#[test]
fn a_foreign_big_endian_file_with_a_handshake_and_padding() {
    let client: SocketAddr = "10.1.1.5:49152".parse().unwrap();
    let server: SocketAddr = "10.1.1.9:5020".parse().unwrap();
    let link = Link::Ip { transport: Transport::Tcp, local: client, remote: server };
    // Take our own packets and change their MACs, flags and padding.
    let mut wrapper = crate::capture::packet::Wrapper::new(&link);
    let mut packet = |d, bytes: &[u8], flags: u8, pad: usize| {
        let mut p = wrapper.wrap(&Frame::new(d, 0, bytes.to_vec()));
        p[0..12].copy_from_slice(&[0xAA; 12]);
        p[14 + 20 + 13] = flags;
        p.resize(p.len() + pad, 0);
        p
    };
    let server_syn_ack = packet(Direction::Received, b"", 0x12, 6);
    let syn = packet(Direction::Sent, b"", 0x02, 6);
    let request = packet(Direction::Sent, &[1, 2, 3], 0x18, 3);
    let reply = packet(Direction::Received, &[4, 5], 0x18, 4);
    let mut file = Vec::new();
    file.extend(be_block(SHB, &[&BYTE_ORDER_MAGIC.to_be_bytes()[..], &[0, 1, 0, 0], &[0xFF; 8]].concat()));
    file.extend(be_block(4, &[0; 4]));
    let idb = [
        &1u16.to_be_bytes()[..],
        &[0, 0, 0, 0, 0, 0],
        &9u16.to_be_bytes(),
        &1u16.to_be_bytes(),
        &[9, 0, 0, 0],
        &[0, 0, 0, 0],
    ]
    .concat();
    file.extend(be_block(IDB, &idb));
    for (ns, p) in [(1_000u64, &syn), (2_000, &server_syn_ack), (5_000_000, &request), (7_500_000, &reply)] {
        let mut body = Vec::new();
        for v in [0, (ns >> 32) as u32, ns as u32, p.len() as u32, p.len() as u32] {
            body.extend(v.to_be_bytes());
        }
        body.extend(p.iter());
        body.resize(body.len().div_ceil(4) * 4, 0);
        file.extend(be_block(EPB, &body));
    }
    let back = read(&file).unwrap();
    assert_eq!(back.link, link, "the SYN's sender is rackd");
    let got: Vec<(Direction, u64, Vec<u8>)> =
        back.frames.iter().map(|f| (f.direction, f.time_us, f.bytes.to_vec())).collect();
    assert_eq!(got, [(Direction::Sent, 5_000, vec![1, 2, 3]), (Direction::Received, 7_500, vec![4, 5])]);
}

fn be_block(kind: u32, body: &[u8]) -> Vec<u8> {
    let len = (12 + body.len()) as u32;
    [&kind.to_be_bytes()[..], &len.to_be_bytes(), body, &len.to_be_bytes()].concat()
}

#[test]
fn without_our_macs_or_a_syn_the_first_speaker_is_rackd() {
    let link = Link::Ip {
        transport: Transport::Udp,
        local: "10.0.0.1:1000".parse().unwrap(),
        remote: "10.0.0.2:502".parse().unwrap(),
    };
    let mut file = written(&link, &frames());
    // Blank every MAC address: the made-up ones no longer tell who is who.
    let mut at = 0;
    while at < file.len() {
        let len = u32::from_le_bytes(file[at + 4..at + 8].try_into().unwrap()) as usize;
        if u32::from_le_bytes(file[at..at + 4].try_into().unwrap()) == EPB {
            file[at + 28..at + 40].fill(0);
        }
        at += len;
    }
    assert_eq!(read(&file).unwrap().link, link);
}

#[test]
fn malformed_files_are_refused_with_what_was_wrong() {
    let link = Link::Ip {
        transport: Transport::Udp,
        local: "10.0.0.1:1000".parse().unwrap(),
        remote: "10.0.0.2:502".parse().unwrap(),
    };
    let good = written(&link, &frames());
    assert!(matches!(read(&good[28..]), Err(ReadError::NotPcapng(IDB))));
    assert!(matches!(read(&good[..good.len() - 2]), Err(ReadError::BlockLength { .. })));
    let mut trailer = good.clone();
    let last = trailer.len() - 1;
    trailer[last] ^= 1;
    assert!(matches!(read(&trailer), Err(ReadError::Trailer { .. })));
    let mut magic = good.clone();
    magic[8] = 0;
    assert!(matches!(read(&magic), Err(ReadError::ByteOrder(_))));
    assert!(matches!(read(&pcapng::section_header()), Err(ReadError::Empty)));
    let two = [&good[..], &pcapng::interface(1, "again")].concat();
    assert!(matches!(read(&two), Err(ReadError::Layout(_))));
    let wrong_link =
        [pcapng::section_header(), pcapng::interface(147, "x"), pcapng::packet(0, &[1], "")].concat();
    assert!(matches!(read(&wrong_link), Err(ReadError::LinkType(147))));
    let not_ip =
        [pcapng::section_header(), pcapng::interface(1, "x"), pcapng::packet(0, &[0; 20], "")].concat();
    assert!(matches!(read(&not_ip), Err(ReadError::Packet { packet: 1, .. })));
    let other = Link::Ip {
        transport: Transport::Udp,
        local: "10.0.0.3:1000".parse().unwrap(),
        remote: "10.0.0.2:502".parse().unwrap(),
    };
    let mut w = crate::capture::packet::Wrapper::new(&other);
    let stray = pcapng::packet(9, &w.wrap(&Frame::new(Direction::Sent, 0, vec![1])), "");
    assert!(matches!(read(&[&good[..], &stray].concat()), Err(ReadError::Conversation { packet: 5, .. })));
    let unknown_pdu = [
        pcapng::section_header(),
        pcapng::interface(252, "x"),
        pcapng::packet(0, &[0, 12, 0, 4, b'a', b'b', 0, 0, 0, 0, 0, 0, 1], ""),
    ]
    .concat();
    assert!(matches!(read(&unknown_pdu), Err(ReadError::Dissector(name)) if name == "ab"));
}

#[test]
fn cut_or_random_bytes_never_panic() {
    let link = Link::Ip {
        transport: Transport::Tcp,
        local: "10.0.0.1:1000".parse().unwrap(),
        remote: "10.0.0.2:502".parse().unwrap(),
    };
    let good = written(&link, &frames()[..3]);
    for end in 0..good.len() {
        let _ = read(&good[..end]);
    }
    let mut state = 0x2545_F491_u32;
    for i in 0..good.len() {
        let mut bad = good.clone();
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        bad[i] = state as u8;
        let _ = read(&bad);
    }
}
