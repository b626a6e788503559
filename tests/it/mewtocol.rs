//! The MEWTOCOL-COM client against the simulated PLC over TCP and a pty pair, with faults:
//! noise, lost replies, delays, error codes, BCC modes and stations.

use std::time::Duration;

use rackd::protocols::faults::{Fault, Faults};
use rackd::protocols::mewtocol::ErrorCode;
use rackd::protocols::mewtocol::server::{self, ServerState};
use rackd::protocols::mewtocol::{Bank, ContactArea, MewtocolClient, MewtocolConfig, MewtocolTransport};
use rackd::protocols::transport::StreamServer;
use rackd::protocols::{DeviceCode, PlcError, PlcMemory};

fn config(transport: MewtocolTransport, address: &str, timeout_ms: u64, retries: u32) -> MewtocolConfig {
    let mut c = MewtocolConfig::new(transport, address);
    c.timeout = Duration::from_millis(timeout_ms);
    c.retries = retries;
    c
}

async fn tcp(
    state: &ServerState,
    config_fn: impl FnOnce(&mut MewtocolConfig),
) -> (StreamServer, MewtocolClient) {
    let server = server::serve_tcp("127.0.0.1:0", state.clone()).await.unwrap();
    let address = server.local_addr().unwrap().to_string();
    let mut c = config(MewtocolTransport::Tcp, &address, 500, 1);
    config_fn(&mut c);
    (server, MewtocolClient::new(c).unwrap())
}

fn pty(state: &ServerState, config_fn: impl FnOnce(&mut MewtocolConfig)) -> (StreamServer, MewtocolClient) {
    let (a, b) = tokio_serial::SerialStream::pair().expect("pty pair");
    let server = server::serve_stream(a, state.clone());
    let mut c = config(MewtocolTransport::Serial, "pty", 500, 1);
    config_fn(&mut c);
    (server, MewtocolClient::over_stream(c, b).unwrap())
}

fn state() -> ServerState {
    ServerState::new(Bank::default().shared())
}

/// Every command through the PlcMemory trait, checked against the bank.
async fn exercise(plc: &MewtocolClient, state: &ServerState) {
    let at = |t: &str| plc.parse_address(t).unwrap();
    plc.write_words(&at("DT100"), &[1, 2, 0xABCD]).await.unwrap();
    assert_eq!(state.bank.lock().unwrap().dt(102), Some(0xABCD));
    assert_eq!(plc.read_words(&at("DT100"), 4).await.unwrap(), vec![1, 2, 0xABCD, 0]);
    // More than one frame each way (27 words per read, 24 per write with `%` frames).
    let many: Vec<u16> = (0..100).map(|i| i * 3 + 1).collect();
    plc.write_words(&at("DT2000"), &many).await.unwrap();
    assert_eq!(plc.read_words(&at("DT2000"), 100).await.unwrap(), many);
    // Contact words, then the bits inside them (WY0 = 0x0700: Y8, Y9, YA on).
    plc.write_words(&at("WY0"), &[0x0700, 0x8001]).await.unwrap();
    assert_eq!(plc.read_bits(&at("Y8"), 1).await.unwrap(), vec![true]);
    assert_eq!(plc.read_bits(&at("Y7"), 5).await.unwrap(), vec![false, true, true, true, false]);
    let bits = plc.read_bits(&at("Y0"), 32).await.unwrap();
    assert_eq!(bits.iter().filter(|b| **b).count(), 5);
    assert!(bits[16] && bits[31]);
    // Single and multiple contact writes (WCS, WCP in chunks of 8).
    plc.write_bits(&at("R1F"), &[true]).await.unwrap();
    let pattern: Vec<bool> = (0..11).map(|i| i % 3 == 0).collect();
    plc.write_bits(&at("R0020"), &pattern).await.unwrap();
    assert_eq!(plc.read_bits(&at("R20"), 11).await.unwrap(), pattern);
    {
        let bank = state.bank.lock().unwrap();
        assert_eq!(bank.word(ContactArea::R, 1), Some(0x8000));
        assert!(bank.bit(ContactArea::R, 32).unwrap() && bank.bit(ContactArea::R, 35).unwrap());
    }
    assert_eq!(plc.read_words(&at("WR2"), 1).await.unwrap(), vec![0x249]);
}

#[tokio::test]
async fn all_commands_over_tcp_and_a_pty() {
    let s = state();
    let (_server, plc) = tcp(&s, |_| {}).await;
    exercise(&plc, &s).await;
    let s = state();
    let (_server, plc) = pty(&s, |_| {});
    exercise(&plc, &s).await;
}

#[tokio::test]
async fn without_bcc_long_frames_and_another_station() {
    let mut s = state();
    s.station = 42;
    let (_server, plc) = tcp(&s, |c| {
        c.bcc = false;
        c.long_frames = true;
        c.station = 42;
    })
    .await;
    exercise(&plc, &s).await;
    // A client for station 1 gets no answer from station 42.
    let (_server2, other) = tcp(&s, |c| c.retries = 0).await;
    let err = other.read_words(&other.parse_address("DT0").unwrap(), 1).await.unwrap_err();
    assert!(matches!(err, PlcError::Timeout { attempts: 1, .. }), "{err:?}");
}

#[tokio::test]
async fn error_replies_surface_with_their_code() {
    let s = state();
    let (_server, plc) = pty(&s, |_| {});
    let at = |t: &str| plc.parse_address(t).unwrap();
    s.faults.push(Fault::DeviceError(63));
    match plc.write_words(&at("DT0"), &[1]).await.unwrap_err() {
        PlcError::Device(DeviceCode::Mewtocol(code @ ErrorCode(63))) => {
            assert_eq!(code.meaning(), "PLC mode error")
        }
        other => panic!("{other:?}"),
    }
    // Not retried: exactly one request reached the PLC.
    assert_eq!(s.faults.requests_seen(), 1);
    // Past the simulated bank: data error 61 from the device itself.
    match plc.read_words(&at("DT40000"), 1).await.unwrap_err() {
        PlcError::Device(DeviceCode::Mewtocol(ErrorCode(61))) => {}
        other => panic!("{other:?}"),
    }
    // Beyond what the notation allows: refused before sending.
    assert!(matches!(plc.read_words(&at("DT99999"), 2).await, Err(PlcError::OutOfRange(_))));
    assert!(plc.parse_address("DT100000").is_err());
}

#[tokio::test]
async fn garbage_drops_and_delays_are_survived() {
    let s = state();
    s.bank.lock().unwrap().set_dt(5, 77);
    let (_server, plc) = pty(&s, |c| c.retries = 2);
    let dt5 = plc.parse_address("DT5").unwrap();
    s.faults.push(Fault::Garbage(b"\x00%0#\r$$\xff%".to_vec()));
    assert_eq!(plc.read_words(&dt5, 1).await.unwrap(), vec![77]);
    s.faults.push(Fault::Drop).push(Fault::Drop);
    assert_eq!(plc.read_words(&dt5, 1).await.unwrap(), vec![77]);
    s.faults.push(Fault::Drop).push(Fault::Drop).push(Fault::Drop);
    let err = plc.read_words(&dt5, 1).await.unwrap_err();
    assert!(matches!(err, PlcError::Timeout { attempts: 3, .. }), "{err:?}");
    // Random noise before every reply still lets every request through.
    s.faults.update(|f| f.garbage_rate = 1.0);
    for _ in 0..10 {
        assert_eq!(plc.read_words(&dt5, 1).await.unwrap(), vec![77]);
    }
}

#[tokio::test]
async fn a_late_reply_is_not_taken_for_the_next_answer() {
    let s = state();
    {
        let mut bank = s.bank.lock().unwrap();
        bank.set_dt(0, 1111);
        bank.set_dt(1, 2222);
        bank.set_word(ContactArea::R, 0, 1);
    }
    let (_server, plc) = tcp(&s, |c| {
        c.retries = 0;
        c.timeout = Duration::from_millis(400);
    })
    .await;
    let at = |t: &str| plc.parse_address(t).unwrap();
    s.faults.push(Fault::Delay(Duration::from_millis(600)));
    assert!(matches!(plc.read_words(&at("DT0"), 1).await, Err(PlcError::Timeout { .. })));
    // The late `RD` reply to DT0 arrives while this RCS waits: it must be skipped, and the
    // RCS answer taken.
    assert_eq!(plc.read_bits(&at("R0"), 1).await.unwrap(), vec![true]);
    assert_eq!(plc.read_words(&at("DT1"), 1).await.unwrap(), vec![2222]);
}

/// A fake PLC on TCP answering every command (one per CR) with `reply`; counts commands.
async fn fake(reply: &'static [u8]) -> (String, std::sync::Arc<std::sync::atomic::AtomicU32>) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let address = listener.local_addr().unwrap().to_string();
    let count = std::sync::Arc::new(std::sync::atomic::AtomicU32::new(0));
    let seen = count.clone();
    tokio::spawn(async move {
        let (mut stream, _) = listener.accept().await.unwrap();
        let mut buf = [0u8; 256];
        while let Ok(n @ 1..) = stream.read(&mut buf).await {
            for _ in buf[..n].iter().filter(|&&b| b == b'\r') {
                seen.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                if stream.write_all(reply).await.is_err() {
                    return;
                }
            }
        }
    });
    (address, count)
}

#[tokio::test]
async fn bcc_errors_and_missing_bcc_in_replies() {
    // `%01$WC` has BCC 14 (spec); 15 is wrong: rejected, retried, then reported.
    let (address, count) = fake(b"%01$WC15\r").await;
    let plc = MewtocolClient::new(config(MewtocolTransport::Tcp, &address, 200, 1)).unwrap();
    let err = plc.write_words(&plc.parse_address("WR0").unwrap(), &[1]).await.unwrap_err();
    assert!(matches!(err, PlcError::Malformed("BCC error in the reply")), "{err:?}");
    assert_eq!(count.load(std::sync::atomic::Ordering::SeqCst), 2);
    // `**` is refused while BCC is required, accepted when it is off.
    let (address, _) = fake(b"%01$WC**\r").await;
    let plc = MewtocolClient::new(config(MewtocolTransport::Tcp, &address, 200, 0)).unwrap();
    assert!(matches!(
        plc.write_words(&plc.parse_address("WR0").unwrap(), &[1]).await,
        Err(PlcError::Malformed(_))
    ));
    let (address, _) = fake(b"%01$WC**\r").await;
    let mut c = config(MewtocolTransport::Tcp, &address, 200, 0);
    c.bcc = false;
    let plc = MewtocolClient::new(c).unwrap();
    plc.write_words(&plc.parse_address("WR0").unwrap(), &[1]).await.unwrap();
    // A device error reply with its BCC (`%01!40` + `01`): code 40 surfaces.
    let (address, _) = fake(b"%01!4001\r").await;
    let plc = MewtocolClient::new(config(MewtocolTransport::Tcp, &address, 200, 0)).unwrap();
    match plc.read_words(&plc.parse_address("DT0").unwrap(), 1).await.unwrap_err() {
        PlcError::Device(DeviceCode::Mewtocol(code @ ErrorCode(40))) => {
            assert_eq!(code.meaning(), "BCC error")
        }
        other => panic!("{other:?}"),
    }
}

/// A read split into four commands (27 words each, the last shorter) whose first command
/// is answered late once (80 ms after the 400 ms timeout), after which the PLC keeps a 30 ms
/// turnaround: the late reply and the duplicate answer to the retry are never taken for a
/// later command's answer. The timer is fixed at the timeout (`min_timeout` = `timeout`),
/// as for a one-off `rackd plc` read, so the retry catches the late reply and the next
/// command meets the duplicate.
async fn late_replies_are_never_another_commands_answer(plc: &MewtocolClient, state: &ServerState) {
    let late =
        Faults { delay: Duration::from_millis(30), late: Duration::from_millis(450), ..Faults::default() };
    let at = plc.parse_address("DT0").unwrap();
    let values: Vec<u16> = (0..100).map(|i| i * 3 + 1).collect();
    plc.write_words(&at, &values).await.unwrap();
    let mut answered = 0;
    for round in 0..4 {
        state.faults.set(late.clone());
        match plc.read_words(&at, 100).await {
            Ok(got) => {
                assert_eq!(got, values, "round {round}: another command's answer");
                answered += 1;
            }
            Err(e) => assert!(matches!(e, PlcError::Timeout { .. }), "round {round}: {e:?}"),
        }
    }
    assert_eq!(answered, 4, "the late reply answers the retry; the duplicate is drained");
    let stats = plc.link_stats();
    assert!(stats.stale >= 1, "late replies and duplicates were drained: {stats:?}");
    state.faults.set(Faults::default());
    assert_eq!(plc.read_words(&at, 100).await.unwrap(), values, "and the line is clean after");
}

fn fixed_400_ms(c: &mut MewtocolConfig) {
    c.timeout = Duration::from_millis(400);
    c.tuning.min_timeout = c.timeout;
}

#[tokio::test]
async fn a_late_reply_is_never_the_next_commands_answer_over_tcp() {
    let s = state();
    let (_server, plc) = tcp(&s, fixed_400_ms).await;
    late_replies_are_never_another_commands_answer(&plc, &s).await;
}

#[tokio::test]
async fn a_late_reply_is_never_the_next_commands_answer_on_a_serial_line() {
    let s = state();
    let (_server, plc) = pty(&s, fixed_400_ms);
    late_replies_are_never_another_commands_answer(&plc, &s).await;
}

/// The global station `EE` (238): a client addressing it is answered by a PLC of any
/// number, over TCP and a pty, and the reply on the wire is signed `EE` as an FP-X's.
#[tokio::test]
async fn the_global_station_ee_is_answered_whatever_the_station() {
    use rackd::protocols::mewtocol::frame::GLOBAL_STATION;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut s = state();
    s.station = 42;
    let (server, plc) = tcp(&s, |c| c.station = GLOBAL_STATION).await;
    exercise(&plc, &s).await;
    let (_pty_server, over_pty) = pty(&s, |c| c.station = GLOBAL_STATION);
    exercise(&over_pty, &s).await;
    // On the wire: RD of DT1 sent to EE comes back as `%EE$RD` + the word + BCC.
    plc.write_words(&plc.parse_address("DT1").unwrap(), &[0x0063]).await.unwrap();
    let mut raw = tokio::net::TcpStream::connect(server.local_addr().unwrap()).await.unwrap();
    raw.write_all(b"%EE#RDD0000100001**\r").await.unwrap();
    let mut reply = [0u8; 13];
    raw.read_exact(&mut reply).await.unwrap();
    assert_eq!(&reply, b"%EE$RD630012\r");
    // Station 41 is still someone else's.
    let (_other_server, other) = tcp(&s, |c| (c.station, c.retries) = (41, 0)).await;
    let err = other.read_words(&other.parse_address("DT0").unwrap(), 1).await.unwrap_err();
    assert!(matches!(err, PlcError::Timeout { attempts: 1, .. }), "{err:?}");
}
