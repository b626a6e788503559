//! S7-200 PPI on a serial line, decoded by `contrib/wireshark/s7ppi.lua` through the
//! exported-PDU header: the two-step exchange (request, `E5`, poll, response) of a read and a
//! write, an item error, a refused request, and a frame whose FCS is wrong.

use rackd::capture::{Annotations, Link, SerialProtocol, Verdict};
use rackd::protocols::ppi::frame::{self, FC_POLL, FC_RESPONSE};
use rackd::protocols::ppi::{Item, MemArea, Reply, Request, Size};

use super::{Frames, assert_clean, assert_comments, decode, job};

const FIELDS: [&str; 17] = [
    "s7ppi.sd",
    "s7ppi.da",
    "s7ppi.sa",
    "s7ppi.fc",
    "s7ppi.fcs_ok",
    "s7ppi.ack",
    "s7ppi.rosctr",
    "s7ppi.pdu_ref",
    "s7ppi.function",
    "s7ppi.transport_size",
    "s7ppi.count",
    "s7ppi.area",
    "s7ppi.byte_address",
    "s7ppi.bit_address",
    "s7ppi.return_code",
    "s7ppi.value",
    "s7ppi.error_class",
];

fn long(da: u8, sa: u8, fc: u8, pdu: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    frame::encode_long(&mut out, da, sa, fc, pdu);
    out
}

fn request(request: &Request, pdu_ref: u16) -> Vec<u8> {
    let mut pdu = Vec::new();
    request.encode(pdu_ref, &mut pdu);
    long(2, 0, request.fc(), &pdu)
}

fn reply(reply: Reply, to: &Request, pdu_ref: u16) -> Vec<u8> {
    let mut pdu = Vec::new();
    reply.encode(to, pdu_ref, &mut pdu);
    long(0, 2, FC_RESPONSE, &pdu)
}

fn poll() -> Vec<u8> {
    let mut out = Vec::new();
    frame::encode_short(&mut out, 2, 0, FC_POLL);
    out
}

#[test]
fn ppi_reads_writes_acknowledgements_and_errors() {
    let link = Link::Serial { protocol: SerialProtocol::Ppi, port: "/dev/ttyS1".into() };
    let read = Request::Read(Item { size: Size::Byte, count: 3, area: MemArea::V, offset: 100 * 8 });
    let write = Request::Write(
        Item { size: Size::Word, count: 1, area: MemArea::V, offset: 100 * 8 },
        vec![0x12, 0x34],
    );
    let bit = Request::Write(Item { size: Size::Bit, count: 1, area: MemArea::Q, offset: 3 }, vec![1]);
    let mut bad = reply(Reply::Written, &write, 2);
    let fcs = bad.len() - 2;
    bad[fcs] = bad[fcs].wrapping_add(1);
    let mut frames = Frames::default();
    frames
        .sent(request(&read, 1), job(8))
        .received(vec![frame::ACK], job(8))
        .sent(poll(), job(8))
        .received(
            reply(Reply::Data(vec![0x99, 0x34, 0x56]), &read, 1),
            Annotations { verdict: Some(Verdict::Ok), ..job(8) },
        )
        .sent(request(&write, 2), Annotations::default())
        .received(reply(Reply::Written, &write, 2), Annotations::default())
        .sent(request(&bit, 3), Annotations::default())
        .received(reply(Reply::ItemError(0x0A), &read, 4), Annotations::default())
        .received(reply(Reply::Refused { class: 0x85, code: 0 }, &write, 5), Annotations::default())
        .received(bad, Annotations { verdict: Some(Verdict::CrcError), ..Annotations::default() });
    let packets = decode(&link, &frames, &[], &FIELDS);
    let row =
        |i: usize, fields: &[&str]| fields.iter().map(|f| packets[i].get(f).to_owned()).collect::<Vec<_>>();

    assert_eq!(row(0, &FIELDS[..5]), ["0x68", "2", "0", "0x6c", "1"]);
    assert_eq!(row(0, &FIELDS[6..14]), ["1", "1", "0x04", "0x02", "3", "0x84", "100", "0"]);
    assert_eq!(row(1, &["s7ppi.sd", "s7ppi.ack"]), ["0xe5", "1"]);
    assert_eq!(
        row(2, &["s7ppi.sd", "s7ppi.da", "s7ppi.sa", "s7ppi.fc", "s7ppi.fcs_ok"]),
        ["0x10", "2", "0", "0x5c", "1"]
    );
    assert_eq!(
        row(
            3,
            &[
                "s7ppi.fc",
                "s7ppi.rosctr",
                "s7ppi.function",
                "s7ppi.return_code",
                "s7ppi.value",
                "s7ppi.error_class"
            ]
        ),
        ["0x08", "3", "0x04", "0xff", "993456", "0x00"]
    );
    assert_eq!(
        row(4, &["s7ppi.fc", "s7ppi.function", "s7ppi.transport_size", "s7ppi.byte_address", "s7ppi.value"]),
        ["0x7c", "0x05", "0x04", "100", "1234"]
    );
    assert_eq!(row(5, &["s7ppi.function", "s7ppi.return_code"]), ["0x05", "0xff"]);
    assert_eq!(
        row(
            6,
            &["s7ppi.transport_size", "s7ppi.area", "s7ppi.byte_address", "s7ppi.bit_address", "s7ppi.value"]
        ),
        ["0x01", "0x82", "0", "3", "01"]
    );
    assert_eq!(row(7, &["s7ppi.return_code"]), ["0x0a"]);
    assert!(packets[7].all("_ws.expert.message").contains(&"The item failed"));
    assert_eq!(row(8, &["s7ppi.rosctr", "s7ppi.error_class"]), ["2", "0x85"]);
    assert_eq!(row(9, &["s7ppi.fcs_ok", "s7ppi.return_code"]), ["0", "0xff"]);

    assert_clean(&packets, &[(9, "FCS does not match")]);
    assert_comments(&packets, &frames);
}
