//! Byte-exact tests of MBAP framing: the shelf PLC seed's frames and malformed headers.

use super::*;
use crate::protocols::modbus::decode::decode_response;
use crate::protocols::modbus::pdu::{Request, Response};
use proptest::prelude::*;

fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace().map(|b| u8::from_str_radix(b, 16).unwrap()).collect()
}

fn request_frame(tid: u16, unit: u8, req: &Request) -> Vec<u8> {
    let mut pdu = Vec::new();
    req.encode(&mut pdu);
    let mut out = Vec::new();
    encode(&mut out, tid, unit, &pdu, LengthField::Standard);
    out
}

fn response_frame(tid: u16, unit: u8, resp: &Response, length: LengthField) -> Vec<u8> {
    let mut pdu = Vec::new();
    resp.encode(&mut pdu);
    let mut out = Vec::new();
    encode(&mut out, tid, unit, &pdu, length);
    out
}

#[test]
fn seed_read_one_word_at_mw4700() {
    let req = Request::ReadHoldingRegisters { address: 4700, count: 1 };
    assert_eq!(request_frame(0, 1, &req), hex("00 00 00 00 00 06 01 03 12 5C 00 01"));
    let seed_reply = hex("00 00 00 00 00 00 01 03 02 27 10");
    let (header, pdu) = split_datagram(&seed_reply, true).unwrap();
    assert_eq!((header.transaction, header.length, header.unit), (0, 0, 1));
    assert_eq!(decode_response(pdu, &req), Ok(Ok(Response::ReadHoldingRegisters(vec![10000]))));
    assert_eq!(split_datagram(&seed_reply, false), Err(FrameError::BadLength));
    let resp = Response::ReadHoldingRegisters(vec![10000]);
    assert_eq!(response_frame(0, 1, &resp, LengthField::Zero), seed_reply);
}

#[test]
fn seed_write_single_register() {
    let req = Request::WriteSingleRegister { address: 4700, value: 10000 };
    assert_eq!(request_frame(0, 1, &req), hex("00 00 00 00 00 06 01 06 12 5C 27 10"));
    let seed_reply = hex("00 00 00 00 00 00 01 06 12 5C 27 10");
    let (_, pdu) = split_datagram(&seed_reply, true).unwrap();
    assert_eq!(
        decode_response(pdu, &req),
        Ok(Ok(Response::WriteSingleRegister { address: 4700, value: 10000 }))
    );
    let resp = Response::WriteSingleRegister { address: 4700, value: 10000 };
    assert_eq!(response_frame(0, 1, &resp, LengthField::Zero), seed_reply);
}

#[test]
fn seed_write_multiple_registers() {
    let req = Request::WriteMultipleRegisters { address: 4700, values: vec![10000, 10001, 10002] };
    // We send the standard length (13); the seed's own request says 6.
    let seed_request = hex("00 00 00 00 00 06 01 10 12 5C 00 03 06 27 10 27 11 27 12");
    let mut standard = seed_request.clone();
    standard[5] = 0x0D;
    assert_eq!(request_frame(0, 1, &req), standard);
    // A server still understands the seed's request: the PDU is the rest of the datagram.
    let header = decode_header(&seed_request).unwrap();
    assert_eq!(header.length, 6);
    assert_eq!(Request::decode(&seed_request[MBAP_LEN..]), Ok(req.clone()));
    let seed_reply = hex("00 00 00 00 00 00 01 10 12 5C 00 03");
    let (_, pdu) = split_datagram(&seed_reply, true).unwrap();
    assert_eq!(
        decode_response(pdu, &req),
        Ok(Ok(Response::WriteMultipleRegisters { address: 4700, count: 3 }))
    );
    let resp = Response::WriteMultipleRegisters { address: 4700, count: 3 };
    assert_eq!(response_frame(0, 1, &resp, LengthField::Zero), seed_reply);
}

#[test]
fn standard_length_and_transaction_id() {
    let resp = Response::ReadHoldingRegisters(vec![10000]);
    let frame = response_frame(0xBEEF, 7, &resp, LengthField::Standard);
    assert_eq!(frame, hex("BE EF 00 00 00 05 07 03 02 27 10"));
    let (h, pdu) = split_datagram(&frame, false).unwrap();
    assert_eq!(h, MbapHeader { transaction: 0xBEEF, protocol: 0, length: 5, unit: 7 });
    assert_eq!(pdu, &frame[7..]);
}

#[test]
fn malformed_headers_are_reported() {
    assert_eq!(decode_header(&hex("00 01 00 00 00")), Err(FrameError::Truncated));
    assert_eq!(decode_header(&hex("00 01 00 01 00 06 01")), Err(FrameError::NotModbus));
    assert_eq!(decode_header(&hex("00 01 00 00 00 01 01")), Err(FrameError::BadLength));
    assert_eq!(decode_header(&hex("00 01 00 00 01 00 01")), Err(FrameError::BadLength));
    // Length says 6 but 4 bytes follow the unit; and a header with no PDU at all.
    assert_eq!(split_datagram(&hex("00 01 00 00 00 06 01 03 00 00"), true), Err(FrameError::BadLength));
    assert_eq!(split_datagram(&hex("00 01 00 00 00 00 01"), true), Err(FrameError::BadLength));
}

proptest! {
    #[test]
    fn frames_round_trip(tid: u16, unit: u8, pdu in prop::collection::vec(any::<u8>(), 1..=MAX_PDU_LEN), zero: bool) {
        let mut out = Vec::new();
        let length = if zero { LengthField::Zero } else { LengthField::Standard };
        encode(&mut out, tid, unit, &pdu, length);
        let (h, got) = split_datagram(&out, zero).unwrap();
        prop_assert_eq!((h.transaction, h.unit, h.protocol), (tid, unit, 0));
        prop_assert_eq!(got, &pdu[..]);
    }

    #[test]
    fn arbitrary_datagrams_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..300), allow: bool) {
        let _ = decode_header(&bytes);
        let _ = split_datagram(&bytes, allow);
    }
}
