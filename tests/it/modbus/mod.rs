//! The Modbus client against the Modbus server over real sockets (UDP, TCP, RTU over TCP)
//! and a pty pair (RTU), with the server's faults and quirks.

use std::sync::Arc;
use std::time::Duration;

use rackd::protocols::faults::{Faults, SharedFaults};
use rackd::protocols::modbus::server::{Bank, ModbusServer, ServerHandle, ServerOptions};
use rackd::protocols::modbus::{Exception, ModbusClient, ModbusConfig, Quirks, Request, Response, Transport};
use rackd::protocols::{DeviceCode, DropReason, Dropped, PlcError, PlcMemory};
use tokio::net::UdpSocket;

mod device_id;
mod diagnostics;
mod paused;
mod units;

async fn serve(transport: Transport, options: ServerOptions) -> (ServerHandle, Bank, String) {
    let bank = Bank::new();
    let server = ModbusServer::new(Arc::new(bank.clone()), options);
    let handle = match transport {
        Transport::Udp => server.serve_udp("127.0.0.1:0").await,
        Transport::Tcp => server.serve_tcp("127.0.0.1:0").await,
        Transport::RtuOverTcp => server.serve_rtu_over_tcp("127.0.0.1:0").await,
        Transport::RtuSerial => unreachable!("use a pty pair"),
    }
    .unwrap();
    let address = handle.local_addr().unwrap().to_string();
    (handle, bank, address)
}

fn config(transport: Transport, address: &str, timeout_ms: u64, retries: u32) -> ModbusConfig {
    let mut c = ModbusConfig::new(transport, address);
    c.timeout = Duration::from_millis(timeout_ms);
    c.retries = retries;
    c
}

async fn client(transport: Transport, address: &str, timeout_ms: u64, retries: u32) -> ModbusClient {
    ModbusClient::connect(config(transport, address, timeout_ms, retries)).await.unwrap()
}

/// An RTU server and client on the two ends of a pty pair.
fn pty(options: ServerOptions, timeout_ms: u64, retries: u32) -> (ServerHandle, Bank, ModbusClient) {
    pty_with(options, config(Transport::RtuSerial, "pty", timeout_ms, retries))
}

/// An RTU server and a client configured with `c` on the two ends of a pty pair.
fn pty_with(options: ServerOptions, mut c: ModbusConfig) -> (ServerHandle, Bank, ModbusClient) {
    let (a, b) = tokio_serial::SerialStream::pair().expect("pty pair");
    let bank = Bank::new();
    let handle = ModbusServer::new(Arc::new(bank.clone()), options).serve_rtu_stream(a, 115200);
    c.serial.baud = 115200;
    (handle, bank, ModbusClient::rtu_over_stream(c, b).unwrap())
}

/// Every function through the PlcMemory trait, checked against the bank.
async fn exercise(plc: &ModbusClient, bank: &Bank) {
    let at = |t: &str| plc.parse_address(t).unwrap();
    plc.write_words(&at("4x4700"), &[10000, 10001, 10002]).await.unwrap();
    assert_eq!(bank.holding(4700, 4), vec![10000, 10001, 10002, 0]);
    plc.write_words(&at("4x4703"), &[7]).await.unwrap();
    assert_eq!(plc.read_words(&at("4x4700"), 4).await.unwrap(), vec![10000, 10001, 10002, 7]);
    plc.write_bits(&at("0x10"), &[true, false, true]).await.unwrap();
    plc.write_bits(&at("0x13"), &[true]).await.unwrap();
    assert_eq!(plc.read_bits(&at("0x10"), 5).await.unwrap(), vec![true, false, true, true, false]);
    {
        let mut b = bank.lock();
        b.input_registers[3] = 33;
        b.discrete_inputs[65535] = true;
    }
    assert_eq!(plc.read_words(&at("3x3"), 1).await.unwrap(), vec![33]);
    assert_eq!(plc.read_bits(&at("1x65534"), 2).await.unwrap(), vec![false, true]);
    plc.link_check().await.unwrap();
}

#[tokio::test]
async fn all_functions_over_udp_tcp_and_rtu_over_tcp() {
    for transport in [Transport::Udp, Transport::Tcp, Transport::RtuOverTcp] {
        let (_server, bank, address) = serve(transport, ServerOptions::default()).await;
        exercise(&client(transport, &address, 1000, 1).await, &bank).await;
    }
}

#[tokio::test]
async fn all_functions_over_a_pty_pair() {
    let (_server, bank, plc) = pty(ServerOptions::default(), 1000, 1);
    exercise(&plc, &bank).await;
}

#[tokio::test]
async fn requests_are_split_at_the_limits() {
    let (server, bank, address) = serve(Transport::Tcp, ServerOptions::default()).await;
    let plc = client(Transport::Tcp, &address, 1000, 0).await;
    let words: Vec<u16> = (0..300).map(|i| i * 3 + 1).collect();
    let start = plc.parse_address("4x65236").unwrap();
    plc.write_words(&start, &words).await.unwrap(); // 123 + 123 + 54
    assert_eq!(server.stats().requests, 3);
    assert_eq!(bank.holding(65236, 300), words);
    assert_eq!(plc.read_words(&start, 300).await.unwrap(), words); // 125 + 125 + 50
    assert_eq!(server.stats().requests, 6);
    let bits: Vec<bool> = (0..4001).map(|i| i % 3 == 0).collect();
    plc.write_bits(&plc.parse_address("0x100").unwrap(), &bits).await.unwrap(); // 1968 * 2 + 65
    assert_eq!(server.stats().requests, 9);
    assert_eq!(plc.read_bits(&plc.parse_address("0x100").unwrap(), 4001).await.unwrap(), bits); // 2000 * 2 + 1
    assert_eq!(server.stats().requests, 12);
    assert!(matches!(plc.read_words(&start, 301).await, Err(PlcError::OutOfRange(_))));
}

#[tokio::test]
async fn udp_survives_20_percent_loss_without_mixing_up_replies() {
    let faults = Faults { drop_rate: 0.2, duplicate_rate: 1.0, ..Faults::default() };
    let (server, bank, address) =
        serve(Transport::Udp, ServerOptions { faults, ..ServerOptions::default() }).await;
    let values: Vec<u16> = (0..400).map(|i| i * 7 + 1).collect();
    bank.set_holding(0, &values);
    let plc = client(Transport::Udp, &address, 40, 12).await;
    for i in 0..200u16 {
        let got = plc.read_words(&plc.parse_address(&format!("4x{}", i * 2)).unwrap(), 2).await.unwrap();
        assert_eq!(got, values[i as usize * 2..i as usize * 2 + 2], "read {i}");
    }
    assert!(server.stats().dropped > 10, "the fault must have dropped requests: {:?}", server.stats());
    let stats = plc.stats();
    assert!(stats.sends > stats.requests, "retries must have happened: {stats:?}");
    assert!(stats.dropped > 0, "duplicates must have been dropped: {stats:?}");
}

#[tokio::test]
async fn a_late_reply_is_never_taken_for_a_newer_request() {
    for transport in [Transport::Udp, Transport::Tcp] {
        let (server, bank, address) = serve(transport, ServerOptions::default()).await;
        bank.set_holding(10, &[111]);
        bank.set_holding(20, &[222]);
        let plc = client(transport, &address, 300, 0).await;
        server.set_faults(Faults { delay: Duration::from_millis(400), ..Faults::default() });
        let first = plc.read_words(&plc.parse_address("4x10").unwrap(), 1).await;
        assert!(matches!(first, Err(PlcError::Timeout { attempts: 1, .. })), "{first:?}");
        server.set_faults(Faults::default());
        let second = plc.read_words(&plc.parse_address("4x20").unwrap(), 1).await.unwrap();
        assert_eq!(second, vec![222], "{transport:?}");
        assert_eq!(server.stats().replies, 2, "the late reply was sent");
        assert_eq!(plc.stats().dropped, 1, "and dropped by the client ({transport:?})");
    }
}

#[tokio::test]
async fn exceptions_surface_with_their_code_and_are_not_retried() {
    for transport in [Transport::Udp, Transport::Tcp, Transport::RtuOverTcp] {
        let faults =
            Faults { device_error: Some(Exception::ILLEGAL_DATA_ADDRESS.0.into()), ..Faults::default() };
        let (server, bank, address) =
            serve(transport, ServerOptions { faults, ..ServerOptions::default() }).await;
        let plc = client(transport, &address, 500, 2).await;
        let err = plc.write_words(&plc.parse_address("4x4000").unwrap(), &[1, 2]).await.unwrap_err();
        match err {
            PlcError::Device(DeviceCode::Modbus(e)) => {
                assert_eq!((e, e.meaning()), (Exception::ILLEGAL_DATA_ADDRESS, "illegal data address"))
            }
            other => panic!("{transport:?}: expected an exception, got {other:?}"),
        }
        assert_eq!(server.stats().requests, 1);
        assert_eq!(bank.holding(4000, 2), vec![0, 0], "a refused write changes nothing");
    }
}

#[tokio::test]
async fn the_server_answers_unknown_functions_with_exception_01() {
    let (_server, _bank, address) = serve(Transport::Udp, ServerOptions::default()).await;
    let socket = UdpSocket::bind("127.0.0.1:0").await.unwrap();
    socket.connect(&address).await.unwrap();
    // 0x11, report server id, which the server does not implement.
    socket.send(&[0, 9, 0, 0, 0, 2, 1, 0x11]).await.unwrap();
    let mut buf = [0u8; 64];
    let n = tokio::time::timeout(Duration::from_secs(2), socket.recv(&mut buf)).await.unwrap().unwrap();
    assert_eq!(&buf[..n], &[0, 9, 0, 0, 0, 3, 1, 0x91, 0x01]);
}

#[tokio::test]
async fn a_reply_from_the_wrong_unit_is_not_taken() {
    let options = || ServerOptions {
        faults: Faults { wrong_unit: Some(2), ..Faults::default() },
        ..ServerOptions::default()
    };
    for transport in [Transport::Udp, Transport::Tcp, Transport::RtuOverTcp] {
        let (server, _bank, address) = serve(transport, options()).await;
        let plc = client(transport, &address, 300, 1).await;
        let err = plc.read_words(&plc.parse_address("4x0").unwrap(), 1).await.unwrap_err();
        assert!(matches!(err, PlcError::Malformed("reply from the wrong unit")), "{transport:?}: {err:?}");
        assert_eq!(server.stats().replies, 2);
    }
    let (_server, _bank, plc) = pty(options(), 300, 0);
    let err = plc.read_words(&plc.parse_address("4x0").unwrap(), 1).await.unwrap_err();
    assert!(matches!(err, PlcError::Malformed("reply from the wrong unit")), "pty: {err:?}");
}

#[tokio::test]
async fn length0_replies_are_read_with_the_quirk() {
    for transport in [Transport::Udp, Transport::Tcp] {
        let (_server, bank, address) =
            serve(transport, ServerOptions { length0: true, ..ServerOptions::default() }).await;
        let mut c = config(transport, &address, 300, 0);
        c.quirks.length0 = true;
        exercise(&ModbusClient::connect(c.clone()).await.unwrap(), &bank).await;
        c.quirks = Quirks::default();
        let strict = ModbusClient::connect(c).await.unwrap();
        let err = strict.read_words(&strict.parse_address("4x4700").unwrap(), 1).await.unwrap_err();
        match transport {
            // Each datagram stands alone: the replies are dropped, and the timeout names the
            // quirk that would take them.
            Transport::Udp => {
                let length0 = Some(Dropped { count: 1, reason: DropReason::LengthZero });
                assert!(matches!(err, PlcError::Timeout { dropped, .. } if dropped == length0), "{err:?}");
                assert!(err.to_string().contains("the `length0` quirk would take them"), "{err}");
            }
            // On a stream a bad length breaks the framing: malformed, and the link reopened.
            _ => assert!(matches!(err, PlcError::Malformed(_)), "{transport:?}: {err:?}"),
        }
    }
}

#[tokio::test]
async fn the_seed_frames_on_the_wire() {
    let (_server, bank, address) =
        serve(Transport::Udp, ServerOptions { length0: true, ..ServerOptions::default() }).await;
    let socket = UdpSocket::bind("127.0.0.1:0").await.unwrap();
    socket.connect(&address).await.unwrap();
    let mut buf = [0u8; 64];
    let seed: [(&[u8], &[u8]); 3] = [
        (
            &[0, 0, 0, 0, 0, 6, 1, 6, 0x12, 0x5C, 0x27, 0x10],
            &[0, 0, 0, 0, 0, 0, 1, 6, 0x12, 0x5C, 0x27, 0x10],
        ),
        (&[0, 0, 0, 0, 0, 6, 1, 3, 0x12, 0x5C, 0, 1], &[0, 0, 0, 0, 0, 0, 1, 3, 2, 0x27, 0x10]),
        (
            &[0, 0, 0, 0, 0, 6, 1, 0x10, 0x12, 0x5C, 0, 3, 6, 0x27, 0x10, 0x27, 0x11, 0x27, 0x12],
            &[0, 0, 0, 0, 0, 0, 1, 0x10, 0x12, 0x5C, 0, 3],
        ),
    ];
    for (request, reply) in seed {
        socket.send(request).await.unwrap();
        let n = tokio::time::timeout(Duration::from_secs(2), socket.recv(&mut buf)).await.unwrap().unwrap();
        assert_eq!(&buf[..n], reply);
    }
    assert_eq!(bank.holding(4700, 3), vec![10000, 10001, 10002]);
}

#[tokio::test]
async fn tcp_reconnects_after_the_server_restarts() {
    // The port is held between the two servers, so nothing else takes it meanwhile.
    let port = crate::support::held::HeldPort::new();
    let bank = Bank::new();
    let server = ModbusServer::new(Arc::new(bank.clone()), ServerOptions::default());
    let server = server.serve_tcp_on(port.listen()).unwrap();
    bank.set_holding(1, &[1]);
    let plc = client(Transport::Tcp, &port.addr().to_string(), 500, 3).await;
    let at = plc.parse_address("4x1").unwrap();
    assert_eq!(plc.read_words(&at, 1).await.unwrap(), vec![1]);
    server.shutdown().await;
    let bank = Bank::new();
    bank.set_holding(1, &[2]);
    let _server =
        ModbusServer::new(Arc::new(bank), ServerOptions::default()).serve_tcp_on(port.listen()).unwrap();
    assert_eq!(plc.read_words(&at, 1).await.unwrap(), vec![2]);
}

#[tokio::test]
async fn closed_connections_and_garbage_are_recovered_by_retries() {
    let faults = Faults { close_rate: 0.3, garbage_rate: 0.3, ..Faults::default() };
    for transport in [Transport::Tcp, Transport::RtuOverTcp, Transport::Udp] {
        let (server, bank, address) =
            serve(transport, ServerOptions { faults: faults.clone(), ..ServerOptions::default() }).await;
        bank.set_holding(0, &(0..64).collect::<Vec<u16>>());
        let plc = client(transport, &address, 100, 15).await;
        for i in 0..40u16 {
            let got = plc.read_words(&plc.parse_address(&format!("4x{i}")).unwrap(), 3).await.unwrap();
            assert_eq!(got, vec![i, i + 1, i + 2], "{transport:?}");
        }
        assert!(server.stats().requests > 40, "{transport:?}: faults must have caused retries");
    }
    let (_server, bank, plc) = pty(
        ServerOptions {
            faults: Faults { garbage_rate: 0.5, ..Faults::default() },
            ..ServerOptions::default()
        },
        300,
        5,
    );
    bank.set_holding(0, &(0..64).collect::<Vec<u16>>());
    for i in 0..30u16 {
        let got = plc.read_words(&plc.parse_address(&format!("4x{i}")).unwrap(), 2).await.unwrap();
        assert_eq!(got, vec![i, i + 1], "pty");
    }
}

#[tokio::test]
async fn timeouts_count_every_attempt() {
    let faults = Faults { drop_rate: 1.0, ..Faults::default() };
    let (server, _bank, address) =
        serve(Transport::Udp, ServerOptions { faults, ..ServerOptions::default() }).await;
    let plc = client(Transport::Udp, &address, 100, 2).await;
    let err = plc.read_words(&plc.parse_address("4x0").unwrap(), 1).await.unwrap_err();
    assert!(matches!(err, PlcError::Timeout { attempts: 3, .. }), "{err:?}");
    assert_eq!(server.stats().requests, 3);
}

#[tokio::test]
async fn rtu_broadcasts_are_written_without_awaiting_a_reply() {
    let (server, bank, address) = serve(Transport::RtuOverTcp, ServerOptions::default()).await;
    let mut c = config(Transport::RtuOverTcp, &address, 100, 0);
    c.unit = 0;
    let plc = ModbusClient::connect(c).await.unwrap();
    plc.write_words(&plc.parse_address("4x5").unwrap(), &[5, 6]).await.unwrap();
    assert!(matches!(
        plc.read_words(&plc.parse_address("4x5").unwrap(), 1).await,
        Err(PlcError::OutOfRange(_))
    ));
    for _ in 0..200 {
        if bank.holding(5, 2) == [5, 6] {
            break;
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    assert_eq!(bank.holding(5, 2), vec![5, 6]);
    assert_eq!(server.stats().replies, 0);
}

#[tokio::test]
async fn devices_that_do_not_echo_the_transaction_id() {
    let options = ServerOptions { zero_transaction_id: true, ..ServerOptions::default() };
    for transport in [Transport::Udp, Transport::Tcp] {
        let (_server, bank, address) = serve(transport, options.clone()).await;
        let mut c = config(transport, &address, 200, 0);
        c.quirks.ignore_transaction_id = true;
        exercise(&ModbusClient::connect(c.clone()).await.unwrap(), &bank).await;
        c.quirks = Quirks::default();
        let strict = ModbusClient::connect(c).await.unwrap();
        let err = strict.read_words(&strict.parse_address("4x0").unwrap(), 1).await.unwrap_err();
        assert!(matches!(err, PlcError::Timeout { .. }), "{transport:?}: {err:?}");
    }
}

#[tokio::test]
async fn raw_requests_and_write_echo() {
    let (_server, _bank, address) = serve(Transport::Udp, ServerOptions::default()).await;
    let plc = client(Transport::Udp, &address, 500, 0).await;
    let echo = plc.call(&Request::WriteSingleRegister { address: 9, value: 99 }).await.unwrap();
    assert_eq!(echo, Response::WriteSingleRegister { address: 9, value: 99 });
    let too_many = Request::ReadHoldingRegisters { address: 0, count: 126 };
    assert!(matches!(plc.call(&too_many).await, Err(PlcError::OutOfRange(_))));
}

#[tokio::test]
async fn a_fast_lossy_udp_link_retries_within_milliseconds_and_is_flagged_degraded() {
    let (server, bank, address) = serve(Transport::Udp, ServerOptions::default()).await;
    bank.set_holding(0, &[1, 2]);
    let plc = client(Transport::Udp, &address, 1000, 8).await;
    let at = plc.parse_address("4x0").unwrap();
    assert_eq!(plc.link_stats().timeout_ms, 1000.0, "the ceiling until a round trip is known");
    for _ in 0..60 {
        plc.read_words(&at, 2).await.unwrap();
    }
    let clean = plc.link_stats();
    assert!(!clean.degraded, "{clean:?}");
    assert!(clean.srtt_ms.is_some_and(|ms| ms < 20.0), "{clean:?}");
    assert!(clean.timeout_ms < 100.0, "learned from the round trips: {clean:?}");

    server.set_faults(Faults { drop_rate: 0.2, ..Faults::default() });
    let start = std::time::Instant::now();
    for i in 0..200 {
        assert_eq!(plc.read_words(&at, 2).await.unwrap(), [1, 2], "read {i}");
    }
    // About 40 lost requests: 40 s with the fixed 1 s timeout.
    let took = start.elapsed();
    assert!(took < Duration::from_secs(10), "retried within milliseconds: {took:?}");
    let lossy = plc.link_stats();
    assert!(lossy.degraded, "{lossy:?}");
    assert!(lossy.retries > 10 && lossy.timeouts >= lossy.retries, "{lossy:?}");
    assert_eq!(lossy.requests, 260);

    server.set_faults(Faults::default());
    for _ in 0..60 {
        plc.read_words(&at, 2).await.unwrap();
    }
    assert!(!plc.link_stats().degraded, "healthy again once the window is clean");
}

#[tokio::test]
async fn replies_with_another_transaction_id_are_named_in_the_timeout() {
    let faults = Faults { wrong_id_rate: 1.0, ..Faults::default() };
    let (_server, _bank, address) =
        serve(Transport::Udp, ServerOptions { faults, ..ServerOptions::default() }).await;
    let plc = client(Transport::Udp, &address, 200, 2).await;
    let err = plc.read_words(&plc.parse_address("4x0").unwrap(), 1).await.unwrap_err();
    let three = Some(Dropped { count: 3, reason: DropReason::TransactionId });
    assert!(matches!(err, PlcError::Timeout { attempts: 3, dropped, .. } if dropped == three), "{err:?}");
    assert!(
        err.to_string().ends_with(
            "(3 replies arrived with another transaction id: the `no-transaction-id` quirk would take them)"
        ),
        "{err}"
    );
    assert_eq!(plc.link_stats().foreign, 3);
}

/// A split read (250 registers: two requests of 125, same function and size) whose first
/// request is answered late once (80 ms after the 400 ms timeout), after which the PLC
/// keeps a 30 ms turnaround: the late reply and the duplicate answer to the retry must never
/// become the second request's values (tokio-modbus issue #324). Every read returns its own
/// data or an error. The timer is fixed at the timeout (`min_timeout` = `timeout`), as for
/// a one-off `rackd plc` read, so the retry catches the late reply and the second request
/// meets the duplicate.
async fn late_replies_are_never_another_requests_answer(plc: &ModbusClient, faults: &SharedFaults) {
    let late =
        Faults { delay: Duration::from_millis(30), late: Duration::from_millis(450), ..Faults::default() };
    let at = plc.parse_address("4x0").unwrap();
    let values: Vec<u16> = (0..250).map(|i| i * 3 + 1).collect();
    plc.write_words(&at, &values[..100]).await.unwrap();
    plc.write_words(&plc.parse_address("4x100").unwrap(), &values[100..]).await.unwrap();
    let mut answered = 0;
    for round in 0..4 {
        faults.set(late.clone());
        match plc.read_words(&at, 250).await {
            Ok(got) => {
                assert_eq!(got, values, "round {round}: another request's answer");
                answered += 1;
            }
            Err(e) => assert!(matches!(e, PlcError::Timeout { .. }), "round {round}: {e:?}"),
        }
    }
    assert_eq!(answered, 4, "the late reply answers the retry; the duplicate is drained");
    let stats = plc.link_stats();
    assert!(stats.stale >= 1, "late replies and duplicates were drained: {stats:?}");
    faults.set(Faults::default());
    assert_eq!(plc.read_words(&at, 250).await.unwrap(), values, "and the line is clean after");
}

#[tokio::test]
async fn rtu_over_tcp_never_takes_a_late_reply_for_the_next_answer() {
    let (server, _bank, address) = serve(Transport::RtuOverTcp, ServerOptions::default()).await;
    let mut c = config(Transport::RtuOverTcp, &address, 400, 1);
    c.tuning.min_timeout = c.timeout;
    let plc = ModbusClient::connect(c).await.unwrap();
    late_replies_are_never_another_requests_answer(&plc, &server.faults()).await;
}

#[tokio::test]
async fn rtu_on_a_serial_line_never_takes_a_late_reply_for_the_next_answer() {
    let mut c = config(Transport::RtuSerial, "pty", 400, 1);
    c.tuning.min_timeout = c.timeout;
    let (server, _bank, plc) = pty_with(ServerOptions::default(), c);
    late_replies_are_never_another_requests_answer(&plc, &server.faults()).await;
}
