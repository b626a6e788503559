//! Modbus over UDP, TCP (on a port other than 502) and RTU (a serial capture's exported
//! PDUs), decoded by Wireshark's own dissectors.
//!
//! On another port than 502, Modbus/TCP needs its port preference (`-o
//! mbtcp.tcp.port:5020`), not Decode As: with `-d tcp.port==5020,mbtcp` alone, tshark 4.0
//! decodes the function code but cannot tell requests from responses ("Cannot classify
//! packet type"), so it shows no addresses or values; the test checks that too.

use rackd::capture::{Annotations, Link, SerialProtocol, Transport, Verdict};
use rackd::protocols::modbus::frame::{self, LengthField};
use rackd::protocols::modbus::pdu::encode_exception;
use rackd::protocols::modbus::{Request, Response, rtu};

use super::{Frames, assert_clean, assert_comments, decode, job};

fn pdu_of(encode: impl FnOnce(&mut Vec<u8>)) -> Vec<u8> {
    let mut pdu = Vec::new();
    encode(&mut pdu);
    pdu
}

fn mbap(transaction: u16, unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    frame::encode(&mut out, transaction, unit, pdu, LengthField::Standard);
    out
}

fn rtu_frame(unit: u8, pdu: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    rtu::encode(&mut out, unit, pdu);
    out
}

/// A read of two holding registers, its answer, a write of three, its answer, and an
/// exception (illegal data address), with the framing given.
fn exchange(framing: impl Fn(u16, &[u8]) -> Vec<u8>) -> Frames {
    let read = Request::ReadHoldingRegisters { address: 10, count: 2 };
    let write = Request::WriteMultipleRegisters { address: 300, values: vec![1, 0xBEEF, 65535] };
    let mut frames = Frames::default();
    frames
        .sent(framing(1, &pdu_of(|b| read.encode(b))), job(17))
        .received(
            framing(1, &pdu_of(|b| Response::ReadHoldingRegisters(vec![42, 7]).encode(b))),
            Annotations { verdict: Some(Verdict::Ok), ..job(17) },
        )
        .sent(framing(2, &pdu_of(|b| write.encode(b))), Annotations { retry: 1, ..job(17) })
        .received(
            framing(2, &pdu_of(|b| Response::WriteMultipleRegisters { address: 300, count: 3 }.encode(b))),
            Annotations::default(),
        )
        .sent(framing(3, &pdu_of(|b| read.encode(b))), Annotations::default())
        .received(
            framing(3, &pdu_of(|b| encode_exception(3, 2, b))),
            Annotations { verdict: Some(Verdict::StaleReply), note: "late".into(), ..Annotations::default() },
        );
    frames
}

const FIELDS: [&str; 7] = [
    "modbus.func_code",
    "modbus.reference_num",
    "modbus.word_cnt",
    "modbus.regval_uint16",
    "modbus.exception_code",
    "mbtcp.trans_id",
    "mbtcp.unit_id",
];

/// What the six frames of [`exchange`] decode to: function, reference, count, values,
/// exception.
fn assert_exchange(packets: &[super::Packet]) {
    let row = |i: usize| {
        let p = &packets[i];
        [
            p.get("modbus.func_code"),
            p.get("modbus.reference_num"),
            p.get("modbus.word_cnt"),
            &p.all("modbus.regval_uint16").join(","),
            p.get("modbus.exception_code"),
        ]
        .map(str::to_owned)
    };
    assert_eq!(row(0), ["3", "10", "2", "", ""]);
    assert_eq!(row(1), ["3", "", "", "42,7", ""]);
    assert_eq!(row(2), ["16", "300", "3", "1,48879,65535", ""]);
    assert_eq!(row(3), ["16", "300", "3", "", ""]);
    assert_eq!(row(4), ["3", "10", "2", "", ""]);
    // An exception: the function code without its high bit, and the exception code.
    assert_eq!(row(5), ["3", "", "", "", "2"]);
}

#[test]
fn modbus_udp_decodes_in_wiresharks_modbus_udp() {
    let link = Link::Ip {
        transport: Transport::Udp,
        local: "192.168.1.10:50000".parse().unwrap(),
        remote: "192.168.1.20:502".parse().unwrap(),
    };
    let frames = exchange(|t, pdu| mbap(t, 5, pdu));
    let mut fields = FIELDS.to_vec();
    fields.extend(["udp.srcport", "udp.dstport", "ip.src"]);
    let packets = decode(&link, &frames, &[], &fields);
    assert_exchange(&packets);
    assert_eq!(
        packets.iter().map(|p| p.get("mbtcp.trans_id")).collect::<Vec<_>>(),
        ["1", "1", "2", "2", "3", "3"]
    );
    assert_eq!(packets[0].get("mbtcp.unit_id"), "5");
    assert_eq!([packets[0].get("udp.srcport"), packets[0].get("udp.dstport")], ["50000", "502"]);
    assert_eq!([packets[1].get("ip.src"), packets[1].get("udp.srcport")], ["192.168.1.20", "502"]);
    assert_clean(&packets, &[]);
    assert_comments(&packets, &frames);
    assert_eq!(packets[5].get("frame.comment"), "verdict: stale reply, late");
}

#[test]
fn modbus_tcp_on_another_port_decodes_with_the_port_preference() {
    let link = Link::Ip {
        transport: Transport::Tcp,
        local: "[fd00::1]:40000".parse().unwrap(),
        remote: "[fd00::2]:5020".parse().unwrap(),
    };
    let frames = exchange(|t, pdu| mbap(t, 1, pdu));
    let mut fields = FIELDS.to_vec();
    fields.extend(["tcp.analysis.flags", "ipv6.src", "tcp.checksum.status", "mbtcp.cannot_classify"]);
    let options = ["-o", "mbtcp.tcp.port:5020", "-o", "tcp.check_checksum:TRUE"];
    let packets = decode(&link, &frames, &options, &fields);
    assert_exchange(&packets);
    assert_eq!(packets[0].get("ipv6.src"), "fd00::1");
    assert!(packets.iter().all(|p| p.get("tcp.analysis.flags").is_empty()), "TCP analysis is clean");
    assert!(packets.iter().all(|p| p.get("tcp.checksum.status") == "1"), "TCP checksums are good");
    assert_clean(&packets, &[]);
    assert_comments(&packets, &frames);

    let decode_as = decode(&link, &frames, &["-d", "tcp.port==5020,mbtcp"], &fields);
    assert_eq!(decode_as[0].get("modbus.func_code"), "3");
    assert_eq!(decode_as[0].get("mbtcp.cannot_classify"), "1", "Decode As alone cannot classify");
}

#[test]
fn modbus_rtu_decodes_from_a_serial_capture() {
    let link = Link::Serial { protocol: SerialProtocol::ModbusRtu, port: "/dev/ttyUSB0".into() };
    let frames = exchange(|_, pdu| rtu_frame(7, pdu));
    let mut fields = FIELDS.to_vec();
    fields.extend(["mbrtu.unit_id", "mbrtu.crc16.status", "exported_pdu.prot_name"]);
    let packets = decode(&link, &frames, &["-o", "mbrtu.crc_verification:TRUE"], &fields);
    assert_exchange(&packets);
    assert!(packets.iter().all(|p| p.get("mbrtu.unit_id") == "7"));
    assert!(packets.iter().all(|p| p.get("mbrtu.crc16.status") == "1"), "CRCs are good");
    assert_eq!(packets[0].get("exported_pdu.prot_name"), "mbrtu");
    assert_clean(&packets, &[]);
    assert_comments(&packets, &frames);
}
