//! Byte-exact tests of the S7 PDUs against every example of spec/ppi.md (seed 004), and
//! property tests.

use proptest::prelude::*;

use super::*;
use crate::protocols::ppi::frame::{self, Frame, Scan, tests::hex};

fn request_frame(request: &Request) -> Vec<u8> {
    let mut pdu = Vec::new();
    request.encode(0, &mut pdu);
    let mut out = Vec::new();
    frame::encode_long(&mut out, 2, 0, request.fc(), &pdu);
    out
}

fn reply_frame(reply: &Reply, request: &Request) -> Vec<u8> {
    let mut pdu = Vec::new();
    reply.encode(request, 0, &mut pdu);
    let mut out = Vec::new();
    frame::encode_long(&mut out, 0, 2, frame::FC_RESPONSE, &pdu);
    out
}

fn payload(bytes: &[u8]) -> Vec<u8> {
    match frame::scan(bytes) {
        Scan::Found { frame: Frame::Long { payload, .. }, .. } => payload,
        other => panic!("{other:?}"),
    }
}

fn item(size: Size, count: u16, area: MemArea, offset: u32) -> Item {
    Item { size, count, area, offset }
}

const WRITE_OK: &str = "68 12 12 68 00 02 08 32 03 00 00 00 00 00 02 00 01 00 00 05 01 FF 47 16";
const REFUSED: &str = "68 0F 0F 68 00 02 08 32 02 00 00 00 00 00 00 00 00 85 00 C3 16";
const RUN_STOP_OK: &str = "68 10 10 68 00 02 08 32 03 00 00 00 00 00 01 00 00 00 00 29 69 16";

#[test]
fn seed_read_and_its_response() {
    let read = Request::Read(item(Size::Byte, 3, MemArea::V, 100 * 8));
    let seed = hex(
        "68 1B 1B 68 02 00 6C 32 01 00 00 00 00 00 0E 00 00 04 01 12 0A 10 02 00 03 00 01 84 00 03 20 8D 16",
    );
    assert_eq!(request_frame(&read), seed);
    assert_eq!(Request::decode(&payload(&seed)), Ok((0, read.clone())));
    let response =
        hex("68 18 18 68 00 02 08 32 03 00 00 00 00 00 02 00 07 00 00 04 01 FF 04 00 18 99 34 56 8B 16");
    let data = Reply::Data(vec![0x99, 0x34, 0x56]);
    assert_eq!(Reply::decode(&payload(&response), &read), Ok((0, data.clone())));
    assert_eq!(reply_frame(&data, &read), response);
}

#[test]
fn seed_writes_byte_exact() {
    let cases = [
        (
            Request::Write(item(Size::Byte, 1, MemArea::V, 800), vec![0x12]),
            "68 20 20 68 02 00 7C 32 01 00 00 00 00 00 0E 00 05 05 01 12 0A 10 02 00 01 00 01 84 00 03 20 00 04 00 08 12 BF 16",
        ),
        (
            Request::Write(item(Size::Word, 1, MemArea::V, 800), vec![0x12, 0x34]),
            "68 21 21 68 02 00 7C 32 01 00 00 00 00 00 0E 00 06 05 01 12 0A 10 04 00 01 00 01 84 00 03 20 00 04 00 10 12 34 FE 16",
        ),
        (
            Request::Write(item(Size::DWord, 1, MemArea::V, 0), vec![0xFF; 4]),
            "68 23 23 68 02 00 7C 32 01 00 00 00 00 00 0E 00 08 05 01 12 0A 10 06 00 01 00 01 84 00 00 00 00 04 00 20 FF FF FF FF A5 16",
        ),
        (
            Request::Write(item(Size::Byte, 1, MemArea::Q, 0), vec![0xFF]),
            "68 20 20 68 02 00 7C 32 01 00 00 00 00 00 0E 00 05 05 01 12 0A 10 02 00 01 00 00 82 00 00 00 00 04 00 08 FF 86 16",
        ),
    ];
    for (request, seed) in cases {
        let seed = hex(seed);
        assert_eq!(request_frame(&request), seed, "{request:?}");
        assert_eq!(Request::decode(&payload(&seed)), Ok((0, request.clone())));
        assert_eq!(reply_frame(&Reply::Written, &request), hex(WRITE_OK));
        assert_eq!(Reply::decode(&payload(&hex(WRITE_OK)), &request), Ok((0, Reply::Written)));
        let refused = Reply::Refused { class: 0x85, code: 0 };
        assert_eq!(Reply::decode(&payload(&hex(REFUSED)), &request), Ok((0, refused.clone())));
        assert_eq!(reply_frame(&refused, &request), hex(REFUSED));
    }
}

#[test]
fn seed_run_and_stop() {
    let stop = hex(
        "68 1D 1D 68 02 00 6C 32 01 00 00 00 00 00 10 00 00 29 00 00 00 00 00 09 50 5F 50 52 4F 47 52 41 4D AA 16",
    );
    let run = hex(
        "68 21 21 68 02 00 6C 32 01 00 00 00 00 00 14 00 00 28 00 00 00 00 00 00 FD 00 00 09 50 5F 50 52 4F 47 52 41 4D AA 16",
    );
    assert_eq!(request_frame(&Request::Stop), stop);
    assert_eq!(request_frame(&Request::Run), run);
    assert_eq!(Request::decode(&payload(&run)), Ok((0, Request::Run)));
    for request in [Request::Stop, Request::Run] {
        assert_eq!(Reply::decode(&payload(&hex(RUN_STOP_OK)), &request), Ok((0, Reply::Done(STOP))));
    }
    assert_eq!(reply_frame(&Reply::Done(STOP), &Request::Stop), hex(RUN_STOP_OK));
}

/// The setup communication request libnodave's `_daveNegPDUlengthRequest` sends over PPI
/// (AmQ 1/1, PDU 960; PDU reference 1, PLC 2, master 0), as written out byte by byte in
/// the OpcBridge project's `S7PpiCodecTests.BuildNegotiateRequest_Fixture`.
const SETUP_REQUEST: &str =
    "68 15 15 68 02 00 6C 32 01 00 00 00 01 00 08 00 00 F0 00 00 01 00 01 03 C0 5F 16";
/// What the simulated S7-200 answers: ack-data, AmQ 1/1, PDU 960 clamped to 240.
const SETUP_REPLY: &str =
    "68 17 17 68 00 02 08 32 03 00 00 00 01 00 08 00 00 00 00 F0 00 00 01 00 01 00 F0 2A 16";

#[test]
fn setup_communication_is_answered_like_an_s7_200() {
    let asked = Setup { amq_calling: 1, amq_called: 1, pdu_len: 960 };
    let request = Request::Setup(asked);
    let mut pdu = Vec::new();
    request.encode(1, &mut pdu);
    let mut frame_bytes = Vec::new();
    frame::encode_long(&mut frame_bytes, 2, 0, request.fc(), &pdu);
    assert_eq!(frame_bytes, hex(SETUP_REQUEST));
    assert_eq!(Request::decode(&payload(&hex(SETUP_REQUEST))), Ok((1, request.clone())));
    let granted = asked.negotiated();
    assert_eq!(granted, Setup { amq_calling: 1, amq_called: 1, pdu_len: 240 });
    let mut pdu = Vec::new();
    Reply::Setup(granted).encode(&request, 1, &mut pdu);
    let mut reply = Vec::new();
    frame::encode_long(&mut reply, 0, 2, frame::FC_RESPONSE, &pdu);
    assert_eq!(reply, hex(SETUP_REPLY));
    assert_eq!(Reply::decode(&payload(&reply), &request), Ok((1, Reply::Setup(granted))));
    // Smaller proposals are granted as asked; a short parameter block is malformed.
    let small = Setup { amq_calling: 0, amq_called: 1, pdu_len: 120 };
    assert_eq!(small.negotiated(), small);
    let short = hex("32 01 00 00 00 01 00 06 00 00 F0 00 00 01 00 01");
    assert_eq!(Request::decode(&short), Err(PduError::BadLength));
}

#[test]
fn item_errors_and_mismatches() {
    let read = Request::Read(item(Size::Word, 2, MemArea::V, 0));
    let mut pdu = Vec::new();
    Reply::ItemError(0x0A).encode(&read, 7, &mut pdu);
    assert_eq!(Reply::decode(&pdu, &read), Ok((7, Reply::ItemError(0x0A))));
    // Data of the wrong size, a write reply to a read, a short PDU, another protocol.
    let mut pdu = Vec::new();
    Reply::Data(vec![1, 2]).encode(&read, 0, &mut pdu);
    assert_eq!(Reply::decode(&pdu, &read), Err(PduError::Mismatch));
    let mut pdu = Vec::new();
    Reply::Written.encode(&Request::Stop, 0, &mut pdu);
    assert_eq!(Reply::decode(&pdu, &read), Err(PduError::Mismatch));
    assert_eq!(Reply::decode(&[0x32, 3, 0], &read), Err(PduError::NotS7));
    assert_eq!(Reply::decode(&[0x72; 12], &read), Err(PduError::NotS7));
    let mut long = pdu.clone();
    long.push(0);
    assert_eq!(Reply::decode(&long, &Request::Stop), Err(PduError::BadLength));
    assert_eq!(Request::decode(&[0x32, 1, 0, 0, 0, 0, 0, 1, 0, 0, 0x99]), Err(PduError::Unsupported));
    assert_eq!(Request::decode(&[0x32, 1, 0, 0, 0, 0, 0, 2, 0, 0, 0x99]), Err(PduError::BadLength));
    assert!(Request::Read(item(Size::Word, 101, MemArea::V, 0)).check().is_err());
    assert!(Request::Read(item(Size::Word, 0, MemArea::V, 0)).check().is_err());
    assert!(Request::Read(item(Size::Bit, 2, MemArea::V, 0)).check().is_err());
    assert!(Request::Write(item(Size::Word, 1, MemArea::V, 0), vec![1]).check().is_err());
}

fn an_item() -> impl Strategy<Value = Item> {
    let sizes = [Size::Bit, Size::Byte, Size::Word, Size::DWord, Size::Timer, Size::Counter];
    (0..6usize, 1..50u16, 0..10usize, 0..0xFF_FFFFu32).prop_map(move |(s, count, a, offset)| {
        let count = if sizes[s] == Size::Bit { 1 } else { count };
        item(sizes[s], count, MemArea::ALL[a], offset)
    })
}

proptest! {
    #[test]
    fn requests_and_replies_round_trip(it in an_item(), r: u16, seed: u8) {
        let data: Vec<u8> = (0..it.data_len()).map(|i| seed.wrapping_add(i as u8)).collect();
        for (request, reply) in [
            (Request::Read(it), Reply::Data(data.clone())),
            (Request::Read(it), Reply::ItemError(5)),
            (Request::Write(it, data.clone()), Reply::Written),
            (Request::Write(it, data.clone()), Reply::ItemError(3)),
            (Request::Run, Reply::Done(RUN)),
            (Request::Stop, Reply::Refused { class: 0x85, code: 1 }),
            (Request::Setup(Setup { amq_calling: r, amq_called: 1, pdu_len: 240 }),
             Reply::Setup(Setup { amq_calling: 1, amq_called: 1, pdu_len: r })),
        ] {
            let mut pdu = Vec::new();
            request.encode(r, &mut pdu);
            prop_assert_eq!(Request::decode(&pdu), Ok((r, request.clone())));
            let mut pdu = Vec::new();
            reply.encode(&request, r, &mut pdu);
            prop_assert_eq!(Reply::decode(&pdu, &request), Ok((r, reply)));
        }
    }

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..80), it in an_item()) {
        let _ = Request::decode(&bytes);
        for request in [Request::Read(it), Request::Write(it, vec![]), Request::Run] {
            let _ = Reply::decode(&bytes, &request);
        }
        let mut s7 = vec![0x32, 3, 0, 0, 0, 0];
        s7.extend_from_slice(&bytes);
        let _ = Reply::decode(&s7, &Request::Read(it));
        let mut job = vec![0x32, 1, 0, 0, 0, 0];
        job.extend_from_slice(&bytes);
        let _ = Request::decode(&job);
    }
}
