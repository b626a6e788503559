//! Byte-exact RTU tests (CRC examples from the Modbus serial line specification) and
//! resynchronisation after noise.

use super::*;
use crate::protocols::modbus::pdu::{Request, Response};
use proptest::prelude::*;

fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace().map(|b| u8::from_str_radix(b, 16).unwrap()).collect()
}

#[test]
fn crc_of_classic_examples() {
    assert_eq!(crc16(&hex("01 03 00 00 00 0A")).to_le_bytes(), [0xC5, 0xCD]);
    assert_eq!(crc16(&hex("11 03 00 6B 00 03")).to_le_bytes(), [0x76, 0x87]);
    assert_eq!(crc16(&[]), 0xFFFF);
}

#[test]
fn encodes_a_read_request() {
    let mut pdu = Vec::new();
    Request::ReadHoldingRegisters { address: 0, count: 10 }.encode(&mut pdu);
    let mut frame = Vec::new();
    encode(&mut frame, 1, &pdu);
    assert_eq!(frame, hex("01 03 00 00 00 0A C5 CD"));
    assert!(crc_ok(&frame));
    let mut bad = frame.clone();
    bad[7] ^= 1;
    assert!(!crc_ok(&bad));
    assert!(!crc_ok(&frame[..3]));
}

#[test]
fn scan_finds_requests_and_responses() {
    let req = hex("11 03 00 6B 00 03 76 87");
    let found = scan(&req, Direction::Request).unwrap();
    assert_eq!((found.start, found.len, found.unit(&req)), (0, 8, 0x11));
    assert_eq!(found.pdu(&req), &req[1..6]);
    // The same frame read as a response is a 03 reply with byte count 0: no valid frame.
    assert_eq!(scan(&req, Direction::Response), None);
    let mut resp = Vec::new();
    let mut pdu = Vec::new();
    Response::ReadHoldingRegisters(vec![0x022B, 0, 0x64]).encode(&mut pdu);
    encode(&mut resp, 0x11, &pdu);
    assert_eq!(resp, hex("11 03 06 02 2B 00 00 00 64 C8 BA"));
    assert_eq!(scan(&resp, Direction::Response), Some(Found { start: 0, len: 11 }));
}

#[test]
fn scan_skips_noise_and_waits_for_the_whole_frame() {
    let frame = hex("01 03 00 00 00 0A C5 CD");
    let mut line = hex("FF 00 01 03 7F");
    line.extend_from_slice(&frame);
    assert_eq!(scan(&line, Direction::Request), Some(Found { start: 5, len: 8 }));
    assert_eq!(scan(&frame[..7], Direction::Request), None);
    let exception = hex("01 83 02 C0 F1");
    assert_eq!(scan(&exception, Direction::Response), Some(Found { start: 0, len: 5 }));
}

#[test]
fn silence_is_three_and_a_half_characters() {
    assert_eq!(silence(9600), std::time::Duration::from_micros(4010));
    assert_eq!(silence(115200), std::time::Duration::from_micros(1750));
    assert_eq!(silence(0), std::time::Duration::from_micros(1750));
}

proptest! {
    #[test]
    fn frames_are_found_after_noise(
        unit in 0x11u8..=0x7F,
        pdu in prop::collection::vec(any::<u8>(), 1..20),
        noise in prop::collection::vec(0x11u8..=0x7F, 0..12),
    ) {
        // A 16 request with a consistent byte count, so the PDU length is known.
        let mut body = vec![0x10, 0, 0, 0, pdu.len().div_ceil(2) as u8, pdu.len() as u8];
        body.extend_from_slice(&pdu);
        let mut line = noise.clone();
        encode(&mut line, unit, &body);
        let found = scan(&line, Direction::Request).unwrap();
        prop_assert_eq!(found.start, noise.len());
        prop_assert_eq!(found.pdu(&line), &body[..]);
    }

    #[test]
    fn arbitrary_bytes_never_panic_the_scanner(bytes in prop::collection::vec(any::<u8>(), 0..300)) {
        let _ = scan(&bytes, Direction::Request);
        if let Some(f) = scan(&bytes, Direction::Response) {
            prop_assert!(crc_ok(&bytes[f.start..f.start + f.len]));
        }
    }
}
