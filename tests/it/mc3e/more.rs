//! Issue 15's MC additions over real sockets: error replies with trailing data, 4E frames,
//! the CPU model name, random and block reads, K4 word views and timer/counter devices.

use std::time::Duration;

use rackd::cli::sim::faults::FaultArgs;
use rackd::cli::sim::mc3e::{self as sim_mc3e, CpuArgs, SimMc3eArgs, SimTransport};
use rackd::protocols::faults::Fault;
use rackd::protocols::link::LinkConfig;
use rackd::protocols::mc3e::{
    Bank, Device, FrameKind, Mc3eClient, Mc3eConfig, ServerState, TransportKind, TypeName,
};
use rackd::protocols::notation::{self, Items};
use rackd::protocols::{PlcError, PlcMemory, Protocol};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, UdpSocket};

use super::{BOTH, client, client_for, device_code, seen, server};

fn four_e(server: &rackd::protocols::mc3e::Mc3eServer, kind: TransportKind) -> Mc3eClient {
    let mut config = Mc3eConfig::new(server.local_addr().to_string(), kind);
    config.link.timeout = Duration::from_millis(1000);
    config.link.retries = 0;
    config.frame = FrameKind::E4;
    Mc3eClient::new(config)
}

/// An error reply to the seed's read, with `trailing` bytes after the end code C051.
fn error_reply(trailing: &[u8]) -> Vec<u8> {
    let mut reply = vec![0xD0, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00];
    reply.extend_from_slice(&(2 + trailing.len() as u16).to_le_bytes());
    reply.extend_from_slice(&[0x51, 0xC0]);
    reply.extend_from_slice(trailing);
    reply
}

#[tokio::test]
async fn error_replies_with_any_trailing_data_surface_the_end_code() {
    // Issue 15: a peer server sent data other than the 9-byte error information after the
    // end code; rackd called it malformed (a timeout over UDP). 0, 2, 4 and 30 bytes.
    let tails: [&[u8]; 4] = [&[], &[0x00, 0xFF], &[1, 2, 3, 4], &[0xEE; 30]];
    for tail in tails {
        let udp = UdpSocket::bind("127.0.0.1:0").await.unwrap();
        let addr = udp.local_addr().unwrap();
        let reply = error_reply(tail);
        let fake = tokio::spawn(async move {
            let mut buf = [0u8; 512];
            let (_, peer) = udp.recv_from(&mut buf).await.unwrap();
            udp.send_to(&reply, peer).await.unwrap();
        });
        let plc = client_for(addr.to_string(), TransportKind::Udp, 1000, 0);
        assert_eq!(device_code(plc.read_words(&plc.parse_address("D1000").unwrap(), 2).await), 0xC051);
        fake.await.unwrap();

        let tcp = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = tcp.local_addr().unwrap();
        let reply = error_reply(tail);
        let fake = tokio::spawn(async move {
            let (mut stream, _) = tcp.accept().await.unwrap();
            let mut request = [0u8; 21];
            stream.read_exact(&mut request).await.unwrap();
            // Then a normal reply on the same connection: the stream must stay in step.
            stream.write_all(&reply).await.unwrap();
            stream.read_exact(&mut request).await.unwrap();
            stream
                .write_all(&[0xD0, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00, 0x06, 0x00, 0, 0, 1, 0, 2, 0])
                .await
                .unwrap();
        });
        let plc = client_for(addr.to_string(), TransportKind::Tcp, 1000, 0);
        let d1000 = plc.parse_address("D1000").unwrap();
        assert_eq!(device_code(plc.read_words(&d1000, 2).await), 0xC051, "tcp, {} bytes", tail.len());
        assert_eq!(plc.read_words(&d1000, 2).await.unwrap(), [1, 2]);
        fake.await.unwrap();
    }
}

#[tokio::test]
async fn four_e_and_three_e_share_the_simulator_port() {
    for kind in BOTH {
        let srv = server(kind, ServerState::new(Bank::default().shared())).await;
        let four = four_e(&srv, kind);
        let three = client(&srv, kind, 1000, 0);
        let d100 = four.parse_address("D100").unwrap();
        four.write_words(&d100, &[11, 22]).await.unwrap();
        assert_eq!(three.read_words(&d100, 2).await.unwrap(), [11, 22]);
        three.write_bits(&three.parse_address("Y1A").unwrap(), &[true]).await.unwrap();
        assert_eq!(four.read_bits(&four.parse_address("Y19").unwrap(), 2).await.unwrap(), [false, true]);
        srv.faults().push(Fault::DeviceError(0xC05F));
        assert_eq!(device_code(four.read_words(&d100, 1).await), 0xC05F);
        assert_eq!(four.read_type_name().await.unwrap(), TypeName::default());
        srv.shutdown().await;
    }
}

#[tokio::test]
async fn a_4e_reply_with_another_serial_is_dropped_and_counted() {
    // A fake PLC answers first with a reply carrying a wrong serial, then the right one.
    let reply = |serial: u16, value: u8| {
        let mut r = vec![0xD4, 0x00];
        r.extend_from_slice(&serial.to_le_bytes());
        r.extend_from_slice(&[0x00, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00, 0x04, 0x00, 0x00, 0x00, value, 0x00]);
        r
    };
    let udp = UdpSocket::bind("127.0.0.1:0").await.unwrap();
    let addr = udp.local_addr().unwrap();
    let fake = tokio::spawn(async move {
        let mut buf = [0u8; 512];
        let (n, peer) = udp.recv_from(&mut buf).await.unwrap();
        assert_eq!(&buf[..2], [0x54, 0x00]);
        let serial = u16::from_le_bytes([buf[2], buf[3]]);
        udp.send_to(&reply(serial.wrapping_add(7), 1), peer).await.unwrap();
        udp.send_to(&reply(serial, 2), peer).await.unwrap();
        n
    });
    let mut config = Mc3eConfig::new(addr.to_string(), TransportKind::Udp);
    config.link.retries = 0;
    config.frame = FrameKind::E4;
    let plc = Mc3eClient::new(config);
    assert_eq!(plc.read_words(&plc.parse_address("D0").unwrap(), 1).await.unwrap(), [2]);
    assert_eq!(fake.await.unwrap(), 25, "a 4E read request is 25 bytes");
    assert_eq!(plc.link_stats().stale, 1);

    let tcp = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = tcp.local_addr().unwrap();
    let fake = tokio::spawn(async move {
        let (mut stream, _) = tcp.accept().await.unwrap();
        let mut request = [0u8; 25];
        stream.read_exact(&mut request).await.unwrap();
        let serial = u16::from_le_bytes([request[2], request[3]]);
        let mut both = reply(serial.wrapping_sub(1), 1);
        both.extend_from_slice(&reply(serial, 3));
        stream.write_all(&both).await.unwrap();
        let _ = stream.read(&mut request).await;
    });
    let mut config = Mc3eConfig::new(addr.to_string(), TransportKind::Tcp);
    config.link.retries = 0;
    config.frame = FrameKind::E4;
    let plc = Mc3eClient::new(config);
    assert_eq!(plc.read_words(&plc.parse_address("D0").unwrap(), 1).await.unwrap(), [3]);
    assert_eq!(plc.link_stats().stale, 1);
    drop(plc);
    fake.await.unwrap();

    // The simulator's --wrong-id fault: every reply's serial is off by one, so a 4E client
    // drops them all and times out, counting each; a 3E client is not affected.
    for kind in BOTH {
        let srv = server(kind, ServerState::new(Bank::default().shared())).await;
        srv.faults().update(|f| f.wrong_id_rate = 1.0);
        let mut config = Mc3eConfig::new(srv.local_addr().to_string(), kind);
        (config.link.timeout, config.link.retries, config.frame) =
            (Duration::from_millis(300), 0, FrameKind::E4);
        let four = Mc3eClient::new(config);
        let err = four.read_words(&four.parse_address("D0").unwrap(), 1).await.unwrap_err();
        assert!(matches!(err, PlcError::Timeout { .. }), "{kind:?}: {err:?}");
        assert_eq!(four.link_stats().stale, 1, "{kind:?}");
        let three = client(&srv, kind, 1000, 0);
        assert_eq!(three.read_words(&three.parse_address("D0").unwrap(), 1).await.unwrap(), [0]);
    }
}

#[tokio::test]
async fn random_and_block_reads_over_both_transports_and_frames() {
    for kind in BOTH {
        let srv = server(kind, ServerState::new(Bank::default().shared())).await;
        {
            let bank = srv.bank();
            let mut b = bank.lock().unwrap();
            b.set_word(Device::D, 0, 0x1995);
            b.set_word(Device::TN, 0, 0x1202);
            b.write_words(Device::M, 100, &[0x2030, 0x4849]).unwrap();
            b.write_words(Device::D, 1500, &[0x5678, 0x1234]).unwrap();
            b.set_bit(Device::X, 0x20, true);
        }
        for plc in [client(&srv, kind, 1000, 0), four_e(&srv, kind)] {
            let at = |t: &str| plc.parse_address(t).unwrap();
            let (words, dwords) = plc
                .read_random(&[at("D0"), at("TN0"), at("K4M100"), at("K4X20")], &[at("D1500"), at("K4M100")])
                .await
                .unwrap();
            assert_eq!(words, [0x1995, 0x1202, 0x2030, 0x0001]);
            assert_eq!(dwords, [0x1234_5678, 0x4849_2030]);
            let blocks =
                plc.read_blocks(&[(at("K4M100"), 2), (at("D0"), 1), (at("D1500"), 2)]).await.unwrap();
            assert_eq!(blocks, [vec![0x2030, 0x4849], vec![0x1995], vec![0x5678, 0x1234]]);
            // Limits are checked before anything is sent.
            let before = seen(&srv);
            let many: Vec<_> = (0..193).map(|i| at(&format!("D{i}"))).collect();
            assert!(matches!(plc.read_random(&many, &[]).await, Err(PlcError::OutOfRange(_))));
            let blocks: Vec<_> = (0..121).map(|i| (at(&format!("D{i}")), 1)).collect();
            assert!(matches!(plc.read_blocks(&blocks).await, Err(PlcError::OutOfRange(_))));
            assert!(matches!(plc.read_blocks(&[(at("D0"), 961)]).await, Err(PlcError::OutOfRange(_))));
            assert!(matches!(plc.read_random(&[at("M100")], &[]).await, Err(PlcError::OutOfRange(_))));
            assert_eq!(seen(&srv), before, "nothing sent past the limits");
            // The server's own range check still answers.
            assert_eq!(device_code(plc.read_blocks(&[(at("D12287"), 2)]).await), 0xC056);
        }
        srv.shutdown().await;
    }
}

#[tokio::test]
async fn k4_word_views_and_timer_counter_devices() {
    for kind in BOTH {
        let srv = server(kind, ServerState::new(Bank::default().shared())).await;
        let plc = client(&srv, kind, 1000, 0);
        let k4m100 = plc.parse_address("K4M100").unwrap();
        plc.write_words(&k4m100, &[0x8001, 0x0002]).await.unwrap();
        let bits = plc.read_bits(&plc.parse_address("M100").unwrap(), 32).await.unwrap();
        let on: Vec<usize> = bits.iter().enumerate().filter(|(_, b)| **b).map(|(i, _)| i).collect();
        assert_eq!(on, [0, 15, 17], "K4M100 word 1 is M100..M115, bit 0 = M100");
        assert_eq!(plc.read_words(&k4m100, 2).await.unwrap(), [0x8001, 0x0002]);
        assert!(matches!(plc.read_bits(&k4m100, 1).await, Err(PlcError::OutOfRange(_))));

        srv.bank().lock().unwrap().set_word(Device::TN, 5, 123);
        srv.bank().lock().unwrap().set_bit(Device::TS, 5, true);
        assert_eq!(plc.read_words(&plc.parse_address("TN5").unwrap(), 1).await.unwrap(), [123]);
        assert_eq!(plc.read_bits(&plc.parse_address("TS4").unwrap(), 2).await.unwrap(), [false, true]);
        plc.write_words(&plc.parse_address("CN2").unwrap(), &[7]).await.unwrap();
        plc.write_bits(&plc.parse_address("STC1").unwrap(), &[true]).await.unwrap();
        plc.write_words(&plc.parse_address("SN3").unwrap(), &[9]).await.unwrap();
        {
            let bank = srv.bank();
            let b = bank.lock().unwrap();
            assert_eq!((b.word(Device::CN, 2), b.word(Device::STN, 3)), (7, 9));
            assert!(b.bit(Device::STC, 1) && !b.bit(Device::CC, 1));
        }
        assert!(matches!(
            plc.read_bits(&plc.parse_address("TN5").unwrap(), 1).await,
            Err(PlcError::OutOfRange(_))
        ));
        srv.shutdown().await;
    }
    // check-config's view: contacts and coils are bits, current values words, K4 words of 16.
    let shape = |t| notation::shape(Protocol::Mc4eUdp, t).unwrap();
    assert_eq!((shape("TS1").items, shape("TS1").writable), (Items::Bits, false));
    assert_eq!((shape("CN1").items, shape("CN1").writable), (Items::Words, true));
    assert_eq!((shape("K4M100").items, shape("K4M100").step), (Items::Words, 16));
}

#[tokio::test]
async fn the_simulator_command_answers_mc4e_and_its_configured_type_name() {
    for (transport, protocol) in [(SimTransport::Udp, Protocol::Mc4eUdp), (SimTransport::Tcp, Protocol::Mc4e)]
    {
        let args = SimMc3eArgs {
            listen: "127.0.0.1:0".parse().unwrap(),
            transport,
            faults: FaultArgs::default(),
            cpu: CpuArgs { model: "R04CPU".into(), code: 0x4800 },
            bench: Default::default(),
        };
        let sim = sim_mc3e::start(&args).await.unwrap().server;
        let mut link = LinkConfig::new(protocol, sim.local_addr().to_string());
        (link.timeout, link.retries) = (Duration::from_secs(1), 0);
        let plc = rackd::protocols::link::connect(&link).await.unwrap();
        let tn = plc.parse_address("TN10").unwrap();
        plc.write_words(&tn, &[42]).await.unwrap();
        assert_eq!(sim.bank().lock().unwrap().word(Device::TN, 10), 42);
        let transport = if transport == SimTransport::Udp { TransportKind::Udp } else { TransportKind::Tcp };
        let direct = four_e(&sim, transport);
        assert_eq!(direct.read_type_name().await.unwrap(), TypeName { model: "R04CPU".into(), code: 0x4800 });
    }
    let bad = SimMc3eArgs {
        listen: "127.0.0.1:0".parse().unwrap(),
        transport: SimTransport::Tcp,
        faults: FaultArgs::default(),
        cpu: CpuArgs { model: "A-MODEL-NAME-TOO-LONG".into(), code: 1 },
        bench: Default::default(),
    };
    assert!(sim_mc3e::start(&bad).await.is_err());
}
