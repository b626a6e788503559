//! MEWTOCOL-COM on a serial line, decoded by `contrib/wireshark/mewtocol.lua` through the
//! exported-PDU header: reads and writes of data registers and contacts, an error reply, and
//! a reply whose BCC is wrong.

use rackd::capture::{Annotations, Link, SerialProtocol, Verdict};
use rackd::protocols::mewtocol::frame::{self, Kind};
use rackd::protocols::mewtocol::{Contact, ContactArea, Request, Response};

use super::{Frames, assert_clean, assert_comments, decode, job};

const FIELDS: [&str; 13] = [
    "mewtocol.station",
    "mewtocol.type",
    "mewtocol.command",
    "mewtocol.response_code",
    "mewtocol.area",
    "mewtocol.first",
    "mewtocol.last",
    "mewtocol.word",
    "mewtocol.register",
    "mewtocol.contact",
    "mewtocol.contact_value",
    "mewtocol.error_code",
    "mewtocol.bcc_ok",
];

fn framed(kind: Kind, body: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    frame::encode(&mut out, false, 1, kind, body, true);
    out
}

fn command(request: &Request) -> Vec<u8> {
    let mut body = Vec::new();
    request.encode(&mut body);
    framed(Kind::Command, &body)
}

fn answer(request: &Request, response: Response) -> Vec<u8> {
    let mut body = Vec::new();
    response.encode(request, &mut body);
    framed(Kind::Ok, &body)
}

#[test]
fn mewtocol_reads_writes_errors_and_a_bad_bcc() {
    let link = Link::Serial { protocol: SerialProtocol::Mewtocol, port: "/dev/ttyUSB0".into() };
    let read = Request::ReadData { start: 100, end: 102 };
    let write = Request::WriteData { start: 200, values: vec![1, 0x1234] };
    let contact = Request::WriteContact(Contact { area: ContactArea::Y, word: 1, bit: 10 }, true);
    let mut bad = answer(&read, Response::Words(vec![42, 7, 9]));
    let at = bad.len() - 3;
    bad[at..at + 2].copy_from_slice(b"00");
    let mut frames = Frames::default();
    frames
        .sent(command(&read), job(5))
        .received(
            answer(&read, Response::Words(vec![42, 7, 65535])),
            Annotations { verdict: Some(Verdict::Ok), ..job(5) },
        )
        .sent(command(&write), Annotations { retry: 2, ..job(5) })
        .received(answer(&write, Response::Written), Annotations::default())
        .sent(command(&contact), Annotations::default())
        .received(framed(Kind::Error, b"61"), Annotations::default())
        .sent(command(&read), Annotations::default())
        .received(bad, Annotations { verdict: Some(Verdict::CrcError), ..Annotations::default() });
    let packets = decode(&link, &frames, &[], &FIELDS);

    let row =
        |i: usize, fields: &[&str]| fields.iter().map(|f| packets[i].get(f).to_owned()).collect::<Vec<_>>();
    assert_eq!(row(0, &FIELDS[..7]), ["01", "command", "RD", "", "D", "100", "102"]);
    assert_eq!(
        row(1, &["mewtocol.type", "mewtocol.response_code", "mewtocol.bcc_ok"]),
        ["response", "RD", "1"]
    );
    assert_eq!(packets[1].all("mewtocol.word"), ["42", "7", "65535"]);
    assert_eq!(packets[1].all("mewtocol.register"), ["DT100", "DT101", "DT102"]);
    assert_eq!(row(2, &["mewtocol.command", "mewtocol.first", "mewtocol.last"]), ["WD", "200", "201"]);
    assert_eq!(packets[2].all("mewtocol.word"), ["1", "4660"]);
    assert_eq!(row(3, &["mewtocol.response_code", "mewtocol.bcc_ok"]), ["WD", "1"]);
    assert_eq!(
        row(4, &["mewtocol.command", "mewtocol.contact", "mewtocol.contact_value"]),
        ["WCS", "Y001A", "1"]
    );
    assert_eq!(row(5, &["mewtocol.type", "mewtocol.error_code", "mewtocol.bcc_ok"]), ["error", "61", "1"]);
    assert!(packets[5].all("_ws.expert.message").contains(&"The PLC answered with an error code"));
    assert_eq!(row(7, &["mewtocol.response_code", "mewtocol.bcc_ok"]), ["RD", "0"]);
    assert_eq!(packets[7].all("mewtocol.word"), ["42", "7", "9"]);

    assert_clean(&packets, &[(7, "BCC does not match")]);
    assert_comments(&packets, &frames);
}
