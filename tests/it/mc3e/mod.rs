//! The MC 3E client against the MC 3E server over real TCP and UDP sockets on 127.0.0.1.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use rackd::cli::sim::faults::FaultArgs;
use rackd::cli::sim::mc3e::{self as sim_mc3e, SimMc3eArgs, SimTransport};
use rackd::protocols::faults::Fault;
use rackd::protocols::link::LinkConfig;
use rackd::protocols::mc3e::{
    Bank, Device, Mc3eClient, Mc3eConfig, Mc3eServer, ServerState, TransportKind, WriteEvent,
};
use rackd::protocols::transport::Backoff;
use rackd::protocols::{DeviceCode, PlcError, PlcMemory, Protocol};
use tokio::net::UdpSocket;

mod more;

const BOTH: [TransportKind; 2] = [TransportKind::Tcp, TransportKind::Udp];

async fn server(kind: TransportKind, state: ServerState) -> Mc3eServer {
    let any = "127.0.0.1:0".parse().unwrap();
    match kind {
        TransportKind::Tcp => Mc3eServer::bind_tcp(any, state).await.unwrap(),
        TransportKind::Udp => Mc3eServer::bind_udp(any, state).await.unwrap(),
    }
}

fn client_for(address: String, kind: TransportKind, timeout_ms: u64, retries: u32) -> Mc3eClient {
    let mut config = Mc3eConfig::new(address, kind);
    config.link.timeout = Duration::from_millis(timeout_ms);
    config.link.retries = retries;
    config.link.backoff = Backoff { first: Duration::from_millis(20), max: Duration::from_millis(200) };
    Mc3eClient::new(config)
}

fn client(server: &Mc3eServer, kind: TransportKind, timeout_ms: u64, retries: u32) -> Mc3eClient {
    client_for(server.local_addr().to_string(), kind, timeout_ms, retries)
}

fn seen(server: &Mc3eServer) -> u64 {
    server.faults().requests_seen()
}

fn device_code(result: Result<impl std::fmt::Debug, PlcError>) -> u32 {
    match result {
        Err(PlcError::Device(DeviceCode::Mc3e(code))) => u32::from(code.0),
        other => panic!("expected an MC end code, got {other:?}"),
    }
}

#[tokio::test]
async fn words_and_bits_in_native_radix() {
    for kind in BOTH {
        let srv = server(kind, ServerState::new(Bank::default().shared())).await;
        let plc = client(&srv, kind, 1000, 1);
        let d200 = plc.parse_address("D200").unwrap();
        let values: Vec<u16> = (0..40).map(|i| 1000 + i).collect();
        plc.write_words(&d200, &values).await.unwrap();
        assert_eq!(plc.read_words(&d200, 40).await.unwrap(), values);
        assert_eq!(srv.bank().lock().unwrap().word(Device::D, 239), 1039);

        plc.write_words(&plc.parse_address("W1F").unwrap(), &[0xBEEF]).await.unwrap();
        assert_eq!(srv.bank().lock().unwrap().word(Device::W, 0x1F), 0xBEEF);
        srv.bank().lock().unwrap().set_word(Device::ZR, 100_000, 77);
        assert_eq!(plc.read_words(&plc.parse_address("ZR100000").unwrap(), 1).await.unwrap(), [77]);

        plc.write_bits(&plc.parse_address("Y1A").unwrap(), &[true, false, true]).await.unwrap();
        plc.write_bits(&plc.parse_address("Y10").unwrap(), &[true]).await.unwrap();
        let bank = srv.bank();
        {
            let b = bank.lock().unwrap();
            assert!(b.bit(Device::Y, 0x1A) && !b.bit(Device::Y, 0x1B) && b.bit(Device::Y, 0x1C));
            assert!(b.bit(Device::Y, 16) && !b.bit(Device::Y, 10), "Y10 is hexadecimal");
        }
        bank.lock().unwrap().set_bit(Device::X, 0x1A, true);
        bank.lock().unwrap().set_bit(Device::B, 0xFF, true);
        assert_eq!(plc.read_bits(&plc.parse_address("X19").unwrap(), 3).await.unwrap(), [false, true, false]);
        assert_eq!(plc.read_bits(&plc.parse_address("BFF").unwrap(), 1).await.unwrap(), [true]);
        plc.write_bits(&plc.parse_address("M100").unwrap(), &[true; 5]).await.unwrap();
        plc.write_bits(&plc.parse_address("L7").unwrap(), &[true]).await.unwrap();
        assert!(bank.lock().unwrap().bit(Device::L, 7));
        // Bit devices in word units: 16 points per word, the first in bit 0.
        assert_eq!(plc.read_words(&plc.parse_address("M96").unwrap(), 1).await.unwrap(), [0b1_1111_0000]);
        assert!(matches!(plc.read_bits(&d200, 1).await, Err(PlcError::OutOfRange(_))));
        srv.shutdown().await;
    }
}

#[tokio::test]
async fn large_requests_are_split_at_the_protocol_limits() {
    for kind in BOTH {
        let srv = server(kind, ServerState::new(Bank::default().shared())).await;
        let plc = client(&srv, kind, 2000, 1);
        let values: Vec<u16> = (0..2000).map(|i| i * 3).collect();
        let d0 = plc.parse_address("D0").unwrap();
        plc.write_words(&d0, &values).await.unwrap();
        assert_eq!(seen(&srv), 3, "960 + 960 + 80");
        assert_eq!(plc.read_words(&d0, 2000).await.unwrap(), values);
        assert_eq!(seen(&srv), 6);
        let bits: Vec<bool> = (0..8000).map(|i| i % 3 == 0).collect();
        let m0 = plc.parse_address("M0").unwrap();
        plc.write_bits(&m0, &bits).await.unwrap();
        assert_eq!(plc.read_bits(&m0, 8000).await.unwrap(), bits);
        assert_eq!(seen(&srv), 10, "7168 + 832 bits, twice");
    }
}

#[tokio::test]
async fn end_codes_are_surfaced_and_not_retried() {
    for kind in BOTH {
        let srv = server(kind, ServerState::new(Bank::default().shared())).await;
        let plc = client(&srv, kind, 1000, 3);
        // D has 12288 words in the default bank.
        assert_eq!(device_code(plc.read_words(&plc.parse_address("D12287").unwrap(), 2).await), 0xC056);
        assert_eq!(seen(&srv), 1);
        srv.faults().push(Fault::DeviceError(0xC051));
        let err = plc.read_words(&plc.parse_address("D0").unwrap(), 1).await.unwrap_err();
        assert!(err.to_string().contains("0xC051") && err.to_string().contains("points"), "{err}");
        srv.faults().update(|f| f.device_error = Some(0xC05F));
        assert_eq!(device_code(plc.write_bits(&plc.parse_address("M0").unwrap(), &[true]).await), 0xC05F);
        assert_eq!(seen(&srv), 3);
        assert!(!srv.bank().lock().unwrap().bit(Device::M, 0));
    }
}

#[tokio::test]
async fn error_replies_without_error_info_and_foreign_datagrams() {
    // A fake PLC: first a datagram with the wrong route, then a C059 without error info.
    let plc_socket = UdpSocket::bind("127.0.0.1:0").await.unwrap();
    let addr = plc_socket.local_addr().unwrap();
    let fake = tokio::spawn(async move {
        let mut buf = [0u8; 512];
        let (_, peer) = plc_socket.recv_from(&mut buf).await.unwrap();
        let foreign = [0xD0, 0x00, 0x01, 0xFF, 0xFF, 0x03, 0x00, 0x02, 0x00, 0x51, 0xC0];
        plc_socket.send_to(&foreign, peer).await.unwrap();
        let bare = [0xD0, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00, 0x02, 0x00, 0x59, 0xC0];
        plc_socket.send_to(&bare, peer).await.unwrap();
    });
    let plc = client_for(addr.to_string(), TransportKind::Udp, 1000, 0);
    assert_eq!(device_code(plc.read_words(&plc.parse_address("D0").unwrap(), 1).await), 0xC059);
    fake.await.unwrap();
}

#[tokio::test]
async fn dropped_udp_request_is_retried() {
    let srv = server(TransportKind::Udp, ServerState::new(Bank::default().shared())).await;
    srv.bank().lock().unwrap().set_word(Device::D, 5, 55);
    srv.faults().push(Fault::Drop);
    let plc = client(&srv, TransportKind::Udp, 300, 2);
    assert_eq!(plc.read_words(&plc.parse_address("D5").unwrap(), 1).await.unwrap(), [55]);
    assert_eq!(seen(&srv), 2);
    srv.faults().push(Fault::Drop).push(Fault::Drop);
    let once = client(&srv, TransportKind::Udp, 300, 1);
    let err = once.read_words(&plc.parse_address("D5").unwrap(), 1).await.unwrap_err();
    assert!(matches!(err, PlcError::Timeout { attempts: 2, .. }), "{err:?}");
}

#[tokio::test]
async fn a_late_reply_is_never_taken_for_the_next_answer() {
    for kind in BOTH {
        let srv = server(kind, ServerState::new(Bank::default().shared())).await;
        srv.bank().lock().unwrap().set_word(Device::D, 10, 1);
        // The first reply (D10 = 1) arrives 300 ms after the first timeout, while the
        // client waits for the second reply (D10 = 2), due 450 ms after it is sent.
        srv.faults()
            .push(Fault::Delay(Duration::from_millis(900)))
            .push(Fault::Delay(Duration::from_millis(450)));
        let plc = client(&srv, kind, 600, 0);
        let d10 = plc.parse_address("D10").unwrap();
        assert!(matches!(plc.read_words(&d10, 1).await, Err(PlcError::Timeout { .. })));
        srv.bank().lock().unwrap().set_word(Device::D, 10, 2);
        assert_eq!(plc.read_words(&d10, 1).await.unwrap(), [2], "{kind:?}: took the stale reply");
        // The same when the caller gives up (drops the request) before the client times out.
        srv.faults().push(Fault::Delay(Duration::from_millis(300)));
        let abandoned = tokio::time::timeout(Duration::from_millis(100), plc.read_words(&d10, 1)).await;
        assert!(abandoned.is_err());
        srv.bank().lock().unwrap().set_word(Device::D, 10, 3);
        srv.faults().push(Fault::Delay(Duration::from_millis(400)));
        assert_eq!(
            plc.read_words(&d10, 1).await.unwrap(),
            [3],
            "{kind:?}: took an abandoned request's reply"
        );
        srv.shutdown().await;
    }
}

#[tokio::test]
async fn tcp_reconnects_after_close_and_server_restart() {
    let srv = server(TransportKind::Tcp, ServerState::new(Bank::default().shared())).await;
    let addr = srv.local_addr();
    let plc = client(&srv, TransportKind::Tcp, 500, 2);
    let d0 = plc.parse_address("D0").unwrap();
    plc.write_words(&d0, &[1]).await.unwrap();
    srv.faults().push(Fault::Close);
    assert_eq!(plc.read_words(&d0, 1).await.unwrap(), [1]);
    assert_eq!(seen(&srv), 3);
    srv.shutdown().await;

    let err = plc.read_words(&d0, 1).await.unwrap_err();
    assert!(matches!(err, PlcError::Connection(_)), "{err:?}");

    let restarted = Mc3eServer::bind_tcp(addr, ServerState::new(Bank::default().shared())).await.unwrap();
    restarted.bank().lock().unwrap().set_word(Device::D, 0, 7);
    assert_eq!(plc.read_words(&d0, 1).await.unwrap(), [7]);
}

#[tokio::test]
async fn write_hook_sees_every_write() {
    let events = Arc::new(Mutex::new(Vec::new()));
    let sink = events.clone();
    let state =
        ServerState::new(Bank::default().shared()).on_write(Arc::new(move |e| sink.lock().unwrap().push(e)));
    let srv = server(TransportKind::Tcp, state).await;
    let plc = client(&srv, TransportKind::Tcp, 1000, 0);
    plc.write_words(&plc.parse_address("D21").unwrap(), &[1]).await.unwrap();
    plc.write_bits(&plc.parse_address("X10").unwrap(), &[true, true]).await.unwrap();
    plc.read_words(&plc.parse_address("D21").unwrap(), 1).await.unwrap();
    assert_eq!(
        *events.lock().unwrap(),
        [
            WriteEvent { device: Device::D, start: 21, points: 1 },
            WriteEvent { device: Device::X, start: 0x10, points: 2 },
        ]
    );
}

#[tokio::test]
async fn cli_pieces_build_a_client_and_a_simulator() {
    for (transport, protocol) in [(SimTransport::Udp, Protocol::Mc3eUdp), (SimTransport::Tcp, Protocol::Mc3e)]
    {
        let listen = "127.0.0.1:0".parse().unwrap();
        let args = SimMc3eArgs {
            listen,
            transport,
            faults: FaultArgs::default(),
            cpu: Default::default(),
            bench: Default::default(),
        };
        let sim = sim_mc3e::start(&args).await.unwrap().server;
        let address = sim.local_addr().to_string();
        let mut link = LinkConfig::new(protocol, address);
        (link.timeout, link.retries) = (Duration::from_secs(1), 1);
        let plc = rackd::protocols::link::connect(&link).await.unwrap();
        let zr = plc.parse_address("ZR1000000").unwrap();
        plc.write_words(&zr, &[9, 8]).await.unwrap();
        assert_eq!(plc.read_words(&zr, 2).await.unwrap(), [9, 8]);
        assert_eq!(sim.bank().lock().unwrap().word(Device::ZR, 1_000_001), 8);
    }
}

#[tokio::test]
async fn a_duplicated_reply_is_never_taken_for_the_next_answer() {
    for kind in BOTH {
        let srv = server(kind, ServerState::new(Bank::default().shared())).await;
        srv.bank().lock().unwrap().set_word(Device::D, 10, 1);
        let plc = client(&srv, kind, 500, 0);
        let d10 = plc.parse_address("D10").unwrap();
        srv.faults().push(Fault::Duplicate);
        assert_eq!(plc.read_words(&d10, 1).await.unwrap(), [1]);
        srv.bank().lock().unwrap().set_word(Device::D, 10, 2);
        assert_eq!(plc.read_words(&d10, 1).await.unwrap(), [2], "{kind:?}: took the duplicate");
        srv.shutdown().await;
    }
}
