use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpStream, UdpSocket};

use super::*;
use crate::capture::{Capture, Direction, Frame, Link};

const READ: [u8; 21] = [0x50, 0, 0, 0xFF, 0xFF, 3, 0, 0x0C, 0, 0x10, 0, 1, 4, 0, 0, 0xE8, 3, 0, 0xA8, 2, 0];
const ANSWER: [u8; 15] = [0xD0, 0, 0, 0xFF, 0xFF, 3, 0, 6, 0, 0, 0, 1, 0, 2, 0];

fn capture(transport: Transport, frames: Vec<Frame>) -> Script {
    let link = Link::Ip {
        transport,
        local: "127.0.0.1:40000".parse().unwrap(),
        remote: "127.0.0.1:8000".parse().unwrap(),
    };
    Script::new(&Capture { link, frames }).unwrap()
}

#[tokio::test]
async fn a_late_reply_over_tcp_stays_late_and_a_cut_request_is_whole() {
    // The device answered 150 ms late.
    let script = capture(
        Transport::Tcp,
        vec![
            Frame::new(Direction::Sent, 1_000, READ.to_vec()),
            Frame::new(Direction::Received, 151_000, ANSWER.to_vec()),
        ],
    );
    let server = ReplayServer::start(script, "127.0.0.1:0".parse().unwrap(), Duration::ZERO).await.unwrap();
    let mut c = TcpStream::connect(server.local_addr()).await.unwrap();
    let sent = Instant::now();
    c.write_all(&READ[..4]).await.unwrap();
    tokio::time::sleep(Duration::from_millis(5)).await;
    c.write_all(&READ[4..]).await.unwrap();
    let mut got = [0u8; 15];
    c.read_exact(&mut got).await.unwrap();
    assert_eq!(got, ANSWER);
    assert!(sent.elapsed() >= Duration::from_millis(150), "{:?}", sent.elapsed());
    // Something never recorded: no answer, counted, kept for the report.
    let mut odd = READ;
    odd[15] = 0x99;
    c.write_all(&odd).await.unwrap();
    let silent = tokio::time::timeout(Duration::from_millis(50), c.read(&mut got)).await;
    assert!(silent.is_err(), "no answer");
    let report = server.stop();
    assert_eq!((report.counters.matched, report.counters.unanswered), (1, 1));
    assert_eq!(report.divergences[0].got, odd);
}

#[tokio::test]
async fn modbus_over_udp_answers_with_the_live_transaction_id() {
    let read = |tid: u8| vec![0, tid, 0, 0, 0, 6, 1, 3, 0, 0, 0, 1];
    let answer = |tid: u8| vec![0, tid, 0, 0, 0, 5, 1, 3, 2, 0, 42];
    let script = capture(
        Transport::Udp,
        vec![
            Frame::new(Direction::Sent, 0, read(7)),
            Frame::new(Direction::Received, 1_000, answer(7)),
            // A late answer to an earlier attempt (transaction 6): sent as it was, with
            // the id that attempt has in this run.
            Frame::new(Direction::Received, 2_000, answer(6)),
        ],
    );
    assert_eq!(script.dialect, Dialect::Mbap);
    let server = ReplayServer::start(script, "127.0.0.1:0".parse().unwrap(), Duration::ZERO).await.unwrap();
    let c = UdpSocket::bind("127.0.0.1:0").await.unwrap();
    c.send_to(&read(200), server.local_addr()).await.unwrap();
    let mut buf = [0u8; 64];
    let n = c.recv(&mut buf).await.unwrap();
    assert_eq!(&buf[..n], answer(200));
    let n = c.recv(&mut buf).await.unwrap();
    assert_eq!(&buf[..n], answer(6), "an id this run never used is left as recorded");
    assert_eq!(server.report().counters.matched, 1);
}
