//! The PPI client against the simulated S7-200 over TCP and a pty pair, with faults: lost
//! acknowledgements, lost responses, noise, delays, return codes and refusals.

use std::time::Duration;

use rackd::protocols::faults::Fault;
use rackd::protocols::ppi::ReturnCode;
use rackd::protocols::ppi::server::{self, ServerState};
use rackd::protocols::ppi::{Bank, Item, MemArea, PpiClient, PpiConfig, PpiTransport, Size};
use rackd::protocols::transport::StreamServer;
use rackd::protocols::{DeviceCode, PlcError, PlcMemory};

fn config(transport: PpiTransport, address: &str) -> PpiConfig {
    let mut c = PpiConfig::new(transport, address);
    c.timeout = Duration::from_millis(500);
    c.retries = 1;
    c
}

async fn tcp(state: &ServerState, tweak: impl FnOnce(&mut PpiConfig)) -> (StreamServer, PpiClient) {
    let server = server::serve_tcp("127.0.0.1:0", state.clone()).await.unwrap();
    let mut c = config(PpiTransport::Tcp, &server.local_addr().unwrap().to_string());
    tweak(&mut c);
    (server, PpiClient::new(c).unwrap())
}

fn pty(state: &ServerState, tweak: impl FnOnce(&mut PpiConfig)) -> (StreamServer, PpiClient) {
    let (a, b) = tokio_serial::SerialStream::pair().expect("pty pair");
    let server = server::serve_stream(a, state.clone());
    let mut c = config(PpiTransport::Serial, "pty");
    tweak(&mut c);
    (server, PpiClient::over_stream(c, b).unwrap())
}

fn state() -> ServerState {
    ServerState::new(Bank::default().shared())
}

fn v(state: &ServerState, range: std::ops::Range<usize>) -> Vec<u8> {
    state.bank.lock().unwrap().bytes(MemArea::V)[range].to_vec()
}

/// Words, bytes, double words, bits, timers, RUN and STOP, checked against the bank.
async fn exercise(plc: &PpiClient, s: &ServerState) {
    let at = |t: &str| plc.parse_address(t).unwrap();
    plc.write_words(&at("VW100"), &[0x1234, 0xABCD]).await.unwrap();
    assert_eq!(v(s, 100..104), [0x12, 0x34, 0xAB, 0xCD]);
    assert_eq!(plc.read_words(&at("VW100"), 2).await.unwrap(), vec![0x1234, 0xABCD]);
    assert_eq!(plc.read_words(&at("VB101"), 2).await.unwrap(), vec![0x34, 0xAB]);
    plc.write_words(&at("VB0"), &[0x99, 0x34, 0x56]).await.unwrap();
    assert_eq!(v(s, 0..3), [0x99, 0x34, 0x56]);
    assert!(matches!(plc.write_words(&at("VB0"), &[256]).await, Err(PlcError::OutOfRange(_))));
    plc.write_words(&at("VD4"), &[0xFFFF, 0x0001]).await.unwrap();
    assert_eq!(v(s, 4..8), [0xFF, 0xFF, 0x00, 0x01]);
    assert_eq!(plc.read_words(&at("VD4"), 2).await.unwrap(), vec![0xFFFF, 1]);
    // Split over several frames (100 words per request).
    let many: Vec<u16> = (0..250).map(|i| i * 7).collect();
    plc.write_words(&at("VW2000"), &many).await.unwrap();
    assert_eq!(plc.read_words(&at("VW2000"), 250).await.unwrap(), many);
    // Bits: V10.3 is bit 3 of VB10; Q0.1 an output.
    plc.write_bits(&at("V10.3"), &[true]).await.unwrap();
    plc.write_bits(&at("V10.7"), &[true, true]).await.unwrap();
    assert_eq!(v(s, 10..12), [0x88, 0x01]);
    assert_eq!(plc.read_bits(&at("V10.3"), 1).await.unwrap(), vec![true]);
    assert_eq!(
        plc.read_bits(&at("V10.2"), 7).await.unwrap(),
        vec![false, true, false, false, false, true, true]
    );
    plc.write_bits(&at("Q0.1"), &[true]).await.unwrap();
    assert_eq!(plc.read_words(&at("QB0"), 1).await.unwrap(), vec![2]);
    s.bank.lock().unwrap().bytes_mut(MemArea::I)[0] = 0x01;
    assert_eq!(plc.read_bits(&at("I0.0"), 2).await.unwrap(), vec![true, false]);
    plc.write_words(&at("MW4"), &[7]).await.unwrap();
    assert_eq!(plc.read_words(&at("MB5"), 1).await.unwrap(), vec![7]);
    s.bank.lock().unwrap().bytes_mut(MemArea::T)[74..76].copy_from_slice(&[0x01, 0x2C]);
    assert_eq!(plc.read_words(&at("T37"), 1).await.unwrap(), vec![300]);
    // Item-level API.
    let smb = Item { size: Size::Byte, count: 2, area: MemArea::SM, offset: 0 };
    assert_eq!(plc.read(smb).await.unwrap(), vec![0, 0]);
    plc.stop().await.unwrap();
    assert!(!s.bank.lock().unwrap().running);
    plc.run().await.unwrap();
    assert!(s.bank.lock().unwrap().running);
}

#[tokio::test]
async fn everything_over_tcp_and_a_pty() {
    let s = state();
    let (_server, plc) = tcp(&s, |_| {}).await;
    exercise(&plc, &s).await;
    let s = state();
    let (_server, plc) = pty(&s, |_| {});
    exercise(&plc, &s).await;
}

#[tokio::test]
async fn other_station_addresses() {
    let mut s = state();
    s.address = 5;
    let (_server, plc) = pty(&s, |c| {
        c.plc = 5;
        c.master = 1;
    });
    exercise(&plc, &s).await;
    let (_server, wrong) = tcp(&s, |c| c.retries = 0).await;
    let err = wrong.read_words(&wrong.parse_address("VW0").unwrap(), 1).await.unwrap_err();
    assert!(matches!(err, PlcError::Timeout { attempts: 1, .. }), "{err:?}");
}

#[tokio::test]
async fn return_codes_and_refusals_surface() {
    let s = state();
    let (_server, plc) = pty(&s, |_| {});
    let at = |t: &str| plc.parse_address(t).unwrap();
    // Past the simulated V memory: the item's own return code 05.
    match plc.read_words(&at("VW10240"), 1).await.unwrap_err() {
        PlcError::Device(DeviceCode::Ppi(code @ ReturnCode::Item(0x05))) => {
            assert_eq!(code.meaning(), "address out of range")
        }
        other => panic!("{other:?}"),
    }
    s.faults.push(Fault::DeviceError(0x0A));
    match plc.read_bits(&at("M0.0"), 1).await.unwrap_err() {
        PlcError::Device(DeviceCode::Ppi(code @ ReturnCode::Item(0x0A))) => {
            assert_eq!(code.meaning(), "object does not exist")
        }
        other => panic!("{other:?}"),
    }
    s.faults.push(Fault::DeviceError(0x8500));
    match plc.write_words(&at("VB100"), &[0x12]).await.unwrap_err() {
        PlcError::Device(DeviceCode::Ppi(ReturnCode::Refused { class: 0x85, code: 0 })) => {}
        other => panic!("{other:?}"),
    }
    // Not retried: one request per call reached the PLC.
    assert_eq!(s.faults.requests_seen(), 3);
    assert_eq!(v(&s, 100..101), [0]);
}

#[tokio::test]
async fn lost_acknowledgements_responses_and_noise() {
    let s = state();
    s.bank.lock().unwrap().bytes_mut(MemArea::V)[0..2].copy_from_slice(&[0x12, 0x34]);
    let (_server, plc) = pty(&s, |c| c.retries = 2);
    let vw0 = plc.parse_address("VW0").unwrap();
    s.faults.push(Fault::DropAck).push(Fault::Drop);
    assert_eq!(plc.read_words(&vw0, 1).await.unwrap(), vec![0x1234]);
    assert_eq!(s.faults.requests_seen(), 3);
    s.faults.push(Fault::Garbage(vec![0x68, 0x05, 0x00, 0xFF, 0x10, 0x02, 0x16]));
    assert_eq!(plc.read_words(&vw0, 1).await.unwrap(), vec![0x1234]);
    for _ in 0..3 {
        s.faults.push(Fault::DropAck);
    }
    let err = plc.read_words(&vw0, 1).await.unwrap_err();
    assert!(matches!(err, PlcError::Timeout { attempts: 3, .. }), "{err:?}");
    s.faults.update(|f| f.garbage_rate = 1.0);
    for _ in 0..10 {
        assert_eq!(plc.read_words(&vw0, 1).await.unwrap(), vec![0x1234]);
    }
}

#[tokio::test]
async fn a_late_response_is_not_taken_for_the_next_answer() {
    let s = state();
    {
        let mut bank = s.bank.lock().unwrap();
        bank.bytes_mut(MemArea::V)[0..4].copy_from_slice(&[0x11, 0x11, 0x22, 0x22]);
    }
    let (_server, plc) = tcp(&s, |c| {
        c.retries = 0;
        c.timeout = Duration::from_millis(400);
    })
    .await;
    let at = |t: &str| plc.parse_address(t).unwrap();
    s.faults.push(Fault::Delay(Duration::from_millis(600)));
    assert!(matches!(plc.read_words(&at("VW0"), 1).await, Err(PlcError::Timeout { .. })));
    // Same request shape, other data: the late VW0 response must not answer VW2.
    assert_eq!(plc.read_words(&at("VW2"), 1).await.unwrap(), vec![0x2222]);
    assert_eq!(plc.read_words(&at("VW0"), 1).await.unwrap(), vec![0x1111]);
}

/// A fake S7-200 on TCP: `E5` to every request frame, `response` to every poll.
async fn fake(response: Vec<u8>) -> String {
    use rackd::protocols::ppi::frame::{self, Frame, Scan};
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let address = listener.local_addr().unwrap().to_string();
    tokio::spawn(async move {
        let (mut stream, _) = listener.accept().await.unwrap();
        let mut rx = Vec::new();
        while let Ok(1..) = stream.read_buf(&mut rx).await {
            while let Scan::Found { end, frame } = frame::scan(&rx) {
                rx.drain(..end);
                let out = match frame {
                    Frame::Long { .. } => vec![frame::ACK],
                    _ => response.clone(),
                };
                if stream.write_all(&out).await.is_err() {
                    return;
                }
            }
        }
    });
    address
}

fn hex(text: &str) -> Vec<u8> {
    text.split_whitespace().map(|b| u8::from_str_radix(b, 16).unwrap()).collect()
}

#[tokio::test]
async fn responses_with_a_wrong_fcs_are_rejected() {
    let seed = "68 18 18 68 00 02 08 32 03 00 00 00 00 00 02 00 07 00 00 04 01 FF 04 00 18 99 34 56 8B 16";
    let read = Item { size: Size::Byte, count: 3, area: MemArea::V, offset: 800 };
    // The seed's response as is (PDU reference 0, so reference matching is off).
    let mut c = config(PpiTransport::Tcp, &fake(hex(seed)).await);
    c.match_pdu_ref = false;
    assert_eq!(PpiClient::new(c).unwrap().read(read).await.unwrap(), vec![0x99, 0x34, 0x56]);
    // With reference matching on, a reference-0 response is not ours.
    let mut c = config(PpiTransport::Tcp, &fake(hex(seed)).await);
    c.retries = 0;
    let err = PpiClient::new(c).unwrap().read(read).await.unwrap_err();
    assert!(matches!(err, PlcError::Malformed(m) if m.contains("foreign")), "{err:?}");
    // The same response with its FCS changed: rejected on every attempt.
    let mut c = config(PpiTransport::Tcp, &fake(hex(&seed.replace("8B 16", "8C 16"))).await);
    c.match_pdu_ref = false;
    let err = PpiClient::new(c).unwrap().read(read).await.unwrap_err();
    assert!(matches!(err, PlcError::Malformed("FCS error in the response")), "{err:?}");
    // The seed's refusal `85 00`.
    let refused = hex("68 0F 0F 68 00 02 08 32 02 00 00 00 00 00 00 00 00 85 00 C3 16");
    let mut c = config(PpiTransport::Tcp, &fake(refused).await);
    c.match_pdu_ref = false;
    let err = PpiClient::new(c).unwrap().write(read, &[1, 2, 3]).await.unwrap_err();
    assert!(
        matches!(err, PlcError::Device(DeviceCode::Ppi(ReturnCode::Refused { class: 0x85, code: 0 }))),
        "{err:?}"
    );
}

/// A fake S7-200 that answers each poll with a stale response (the previous PDU reference,
/// other data) right before the real one: only the real one may be taken.
#[tokio::test]
async fn a_response_with_an_old_pdu_reference_is_skipped() {
    use rackd::protocols::ppi::frame::{self, Frame, Scan};
    use rackd::protocols::ppi::{Reply, Request};
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let address = listener.local_addr().unwrap().to_string();
    tokio::spawn(async move {
        let (mut stream, _) = listener.accept().await.unwrap();
        let (mut rx, mut last) = (Vec::new(), None);
        while let Ok(1..) = stream.read_buf(&mut rx).await {
            while let Scan::Found { end, frame } = frame::scan(&rx) {
                rx.drain(..end);
                let mut out = Vec::new();
                match frame {
                    Frame::Long { payload, .. } => {
                        last = Request::decode(&payload).ok();
                        out.push(frame::ACK);
                    }
                    _ => {
                        let Some((r, request)) = last.take() else { continue };
                        for (pdu_ref, data) in [(r.wrapping_sub(1), [0xDE, 0xAD]), (r, [0x12, 0x34])] {
                            let mut pdu = Vec::new();
                            Reply::Data(data.to_vec()).encode(&request, pdu_ref, &mut pdu);
                            frame::encode_long(&mut out, 0, 2, frame::FC_RESPONSE, &pdu);
                        }
                    }
                }
                if stream.write_all(&out).await.is_err() {
                    return;
                }
            }
        }
    });
    let plc = PpiClient::new(config(PpiTransport::Tcp, &address)).unwrap();
    let vw0 = plc.parse_address("VW0").unwrap();
    for _ in 0..3 {
        assert_eq!(plc.read_words(&vw0, 1).await.unwrap(), vec![0x1234]);
    }
}

#[tokio::test]
async fn wrong_ids_and_sources_are_not_taken_and_duplicates_do_not_desync() {
    let s = state();
    s.bank.lock().unwrap().bytes_mut(MemArea::V)[0..2].copy_from_slice(&[0x12, 0x34]);
    let (_server, plc) = pty(&s, |c| c.retries = 1);
    let vw0 = plc.parse_address("VW0").unwrap();
    // A response with another PDU reference, then one from another address: each attempt
    // ignores its wrong answer, so both fail with the reason kept.
    s.faults.push(Fault::WrongId).push(Fault::WrongUnit(7));
    let err = plc.read_words(&vw0, 1).await.unwrap_err();
    assert!(matches!(err, PlcError::Timeout { attempts: 2, .. } | PlcError::Malformed(_)), "{err:?}");
    assert_eq!(s.faults.requests_seen(), 2);
    // A response sent twice: the copy is flushed before the next request.
    s.faults.push(Fault::Duplicate);
    assert_eq!(plc.read_words(&vw0, 1).await.unwrap(), vec![0x1234]);
    s.bank.lock().unwrap().bytes_mut(MemArea::V)[0..2].copy_from_slice(&[0, 7]);
    assert_eq!(plc.read_words(&vw0, 1).await.unwrap(), vec![7]);
}

/// A master that sends "setup communication" first (libnodave, python-snap7's
/// `PPIClient.connect`): the simulator acknowledges it with E5 and, on the poll, grants
/// AmQ 1/1 and a PDU of 240 (the request is libnodave's, asking for 960), then serves a
/// read on the same connection.
#[tokio::test]
async fn setup_communication_is_answered_before_reads() {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let s = state();
    s.bank.lock().unwrap().bytes_mut(MemArea::V)[0..2].copy_from_slice(&[0x12, 0x34]);
    let server = server::serve_tcp("127.0.0.1:0", s.clone()).await.unwrap();
    let mut master = tokio::net::TcpStream::connect(server.local_addr().unwrap()).await.unwrap();
    async fn exchange(master: &mut tokio::net::TcpStream, request: &str, reply_len: usize) -> Vec<u8> {
        master.write_all(&hex(request)).await.unwrap();
        let mut ack = [0u8; 1];
        master.read_exact(&mut ack).await.unwrap();
        assert_eq!(ack, [0xE5]);
        master.write_all(&hex("10 02 00 5C 5E 16")).await.unwrap();
        let mut reply = vec![0u8; reply_len];
        master.read_exact(&mut reply).await.unwrap();
        reply
    }
    let setup = "68 15 15 68 02 00 6C 32 01 00 00 00 01 00 08 00 00 F0 00 00 01 00 01 03 C0 5F 16";
    let granted = "68 17 17 68 00 02 08 32 03 00 00 00 01 00 08 00 00 00 00 F0 00 00 01 00 01 00 F0 2A 16";
    assert_eq!(exchange(&mut master, setup, 29).await, hex(granted));
    // Read VB0..VB1 (PDU reference 1), as in the OpcBridge fixture of libnodave's read.
    let read =
        "68 1B 1B 68 02 00 6C 32 01 00 00 00 01 00 0E 00 00 04 01 12 0A 10 02 00 02 00 01 84 00 00 00 6A 16";
    let data = "68 17 17 68 00 02 08 32 03 00 00 00 01 00 02 00 06 00 00 04 01 FF 04 00 10 12 34 A6 16";
    assert_eq!(exchange(&mut master, read, 29).await, hex(data));
}
