//! A TCP proxy for tests that can stop forwarding (the connections stay open, nothing gets
//! through: a partition, not a reset), and tells when it last and first forwarded from the
//! client's side (what a node sent a machine, say).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::time::Instant;

/// The proxy's shared state.
#[derive(Default)]
struct State {
    blocked: AtomicBool,
    /// When bytes from a client were first and last forwarded.
    sent: Mutex<Option<(Instant, Instant)>>,
}

/// A running proxy.
pub struct Proxy {
    /// Where clients connect.
    pub addr: std::net::SocketAddr,
    state: Arc<State>,
}

impl Proxy {
    /// A proxy to `server` (`HOST:PORT`).
    pub async fn to(server: &str) -> Proxy {
        let server = server.to_owned();
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let state = Arc::new(State::default());
        let shared = state.clone();
        tokio::spawn(async move {
            while let Ok((client, _)) = listener.accept().await {
                let Ok(upstream) = TcpStream::connect(&server).await else { continue };
                let (cr, cw) = client.into_split();
                let (ur, uw) = upstream.into_split();
                tokio::spawn(pipe(cr, uw, shared.clone(), true));
                tokio::spawn(pipe(ur, cw, shared.clone(), false));
            }
        });
        Proxy { addr, state }
    }

    /// A proxy to the PostgreSQL server of `url`, and the URL that goes through it.
    pub async fn to_postgres(url: &str) -> (Proxy, String) {
        let (head, rest) = url.rsplit_once('@').unwrap();
        let (server, name) = rest.split_once('/').unwrap();
        let proxy = Proxy::to(server).await;
        let url = format!("{head}@{}/{name}", proxy.addr);
        (proxy, url)
    }

    /// Stops forwarding, both ways.
    pub fn block(&self) {
        self.state.blocked.store(true, Ordering::SeqCst);
    }

    /// When bytes from a client were first and last forwarded (None: never).
    pub fn sent(&self) -> Option<(Instant, Instant)> {
        *self.state.sent.lock().unwrap()
    }
}

async fn pipe(
    mut from: impl AsyncReadExt + Unpin,
    mut to: impl AsyncWriteExt + Unpin,
    state: Arc<State>,
    from_client: bool,
) {
    let mut buf = vec![0u8; 16 * 1024];
    loop {
        let Ok(n) = from.read(&mut buf).await else { return };
        if n == 0 {
            return;
        }
        while state.blocked.load(Ordering::SeqCst) {
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        if from_client {
            let now = Instant::now();
            let mut sent = state.sent.lock().unwrap();
            *sent = Some(sent.map_or((now, now), |(first, _)| (first, now)));
        }
        if to.write_all(&buf[..n]).await.is_err() {
            return;
        }
    }
}
