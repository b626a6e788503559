//! Sequential Modbus throughput over loopback, next to a raw UDP ping-pong.
//!
//! ```text
//! cargo run --release --example bench_modbus [SECONDS_PER_RUN]
//! ```
//!
//! Measures, in one process and one tokio runtime:
//! - a raw UDP echo ping-pong between two sockets (12-byte datagrams): the floor of what
//!   any sequential request/reply client can do on this machine;
//! - sequential 2-register reads (function 03) by [`ModbusClient`] against the project's own
//!   server, over UDP and over TCP;
//!
//! and prints each rate with its ratio to the ping-pong. Not a test: nothing is asserted.

use std::sync::Arc;
use std::time::{Duration, Instant};

use rackd::protocols::PlcMemory;
use rackd::protocols::modbus::server::{Bank, ModbusServer, ServerOptions};
use rackd::protocols::modbus::{ModbusClient, ModbusConfig, Transport};
use tokio::net::UdpSocket;

/// Runs `op` repeatedly for `secs` seconds (after a short warm-up); returns operations/s.
async fn rate<F, Fut>(secs: f64, mut op: F) -> f64
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = ()>,
{
    for _ in 0..500 {
        op().await;
    }
    let start = Instant::now();
    let budget = Duration::from_secs_f64(secs);
    let mut n = 0u64;
    while start.elapsed() < budget {
        for _ in 0..100 {
            op().await;
        }
        n += 100;
    }
    n as f64 / start.elapsed().as_secs_f64()
}

async fn udp_ping_pong(secs: f64) -> f64 {
    let echo = UdpSocket::bind("127.0.0.1:0").await.expect("bind echo");
    let echo_addr = echo.local_addr().expect("echo address");
    let task = tokio::spawn(async move {
        let mut buf = [0u8; 64];
        while let Ok((n, peer)) = echo.recv_from(&mut buf).await {
            let _ = echo.send_to(&buf[..n], peer).await;
        }
    });
    let socket = Arc::new(UdpSocket::bind("127.0.0.1:0").await.expect("bind client"));
    socket.connect(echo_addr).await.expect("connect");
    let ping = [0u8; 12];
    let r = rate(secs, || {
        let socket = socket.clone();
        async move {
            let mut buf = [0u8; 64];
            socket.send(&ping).await.expect("send");
            socket.recv(&mut buf).await.expect("recv");
        }
    })
    .await;
    task.abort();
    r
}

async fn modbus(transport: Transport, secs: f64) -> f64 {
    let bank = Bank::new();
    bank.set_holding(4700, &[10000, 10001]);
    let server = ModbusServer::new(Arc::new(bank), ServerOptions::default());
    let handle = match transport {
        Transport::Udp => server.serve_udp("127.0.0.1:0").await,
        _ => server.serve_tcp("127.0.0.1:0").await,
    }
    .expect("serve");
    let address = handle.local_addr().expect("server address").to_string();
    let client =
        Arc::new(ModbusClient::connect(ModbusConfig::new(transport, address)).await.expect("client"));
    let start = client.parse_address("4x4700").expect("address");
    let r = rate(secs, || {
        let (client, start) = (client.clone(), start.clone());
        async move {
            let words = client.read_words(&start, 2).await.expect("read");
            assert_eq!(words, [10000, 10001]);
        }
    })
    .await;
    handle.shutdown().await;
    r
}

#[tokio::main]
async fn main() {
    let secs: f64 = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(3.0);
    let ping = udp_ping_pong(secs).await;
    println!("raw UDP ping-pong     {ping:>9.0} round trips/s  (baseline)");
    for (name, transport) in
        [("Modbus UDP 2-reg read", Transport::Udp), ("Modbus TCP 2-reg read", Transport::Tcp)]
    {
        let r = modbus(transport, secs).await;
        println!("{name} {r:>9.0} requests/s     {:>5.1}% of ping-pong", 100.0 * r / ping);
    }
}
