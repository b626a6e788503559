//! A TCP proxy for tests that can stop forwarding (the connections stay open, nothing gets
//! through: a partition, not a reset), tells when it last and first forwarded from the
//! client's side (what a node sent a machine, say), and can cut a connection at a message
//! the client sends (a PostgreSQL `COMMIT`, say), with or without delivering it, and never
//! its answer.

use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
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
    /// Connections still to cut where a client's bytes hold `needle`, and how.
    cuts: AtomicU32,
    needle: Mutex<Vec<u8>>,
    deliver: AtomicBool,
    /// Cuts done (delivered, not delivered), and when each was done.
    done: Mutex<Vec<(bool, Instant)>>,
    /// When bytes holding the needle came from a client (cut or not).
    seen: Mutex<Vec<Instant>>,
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
                let (cut, _) = tokio::sync::watch::channel(false);
                let cut = Arc::new(cut);
                tokio::spawn(pipe(cr, uw, shared.clone(), true, cut.clone()));
                tokio::spawn(pipe(ur, cw, shared.clone(), false, cut));
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

    /// Forwards again what waited and what comes.
    pub fn unblock(&self) {
        self.state.blocked.store(false, Ordering::SeqCst);
    }

    /// Cuts the next `count` connections on which a client sends bytes holding `needle`:
    /// those bytes are forwarded if `deliver` (the server acts on them) or dropped, and no
    /// answer reaches the client; both sockets are closed.
    pub fn cut_at(&self, needle: &[u8], count: u32, deliver: bool) {
        *self.state.needle.lock().unwrap() = needle.to_vec();
        self.state.deliver.store(deliver, Ordering::SeqCst);
        self.state.cuts.store(count, Ordering::SeqCst);
    }

    /// The cuts done so far: whether each delivered its message, and when.
    pub fn cuts(&self) -> Vec<(bool, Instant)> {
        self.state.done.lock().unwrap().clone()
    }

    /// When bytes holding the needle last given to [`Proxy::cut_at`] came from a client,
    /// cut or not.
    pub fn seen(&self) -> Vec<Instant> {
        self.state.seen.lock().unwrap().clone()
    }

    /// When bytes from a client were first and last forwarded (None: never).
    pub fn sent(&self) -> Option<(Instant, Instant)> {
        *self.state.sent.lock().unwrap()
    }
}

/// Forwards one way until either side closes or the connection is cut (`cut`, shared by
/// both ways of a connection).
async fn pipe(
    mut from: impl AsyncReadExt + Unpin,
    mut to: impl AsyncWriteExt + Unpin,
    state: Arc<State>,
    from_client: bool,
    cut: Arc<tokio::sync::watch::Sender<bool>>,
) {
    let mut buf = vec![0u8; 16 * 1024];
    let mut told = cut.subscribe();
    loop {
        let n = tokio::select! {
            read = from.read(&mut buf) => match read {
                Ok(0) | Err(_) => return,
                Ok(n) => n,
            },
            _ = told.wait_for(|c| *c) => return,
        };
        if *cut.borrow() {
            return;
        }
        if from_client && cuts_here(&state, &buf[..n]) {
            // Marked cut before the message goes on, so its answer is never forwarded.
            cut.send_replace(true);
            let deliver = state.deliver.load(Ordering::SeqCst);
            if deliver {
                let _ = to.write_all(&buf[..n]).await;
                let _ = to.flush().await;
            }
            state.done.lock().unwrap().push((deliver, Instant::now()));
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

/// Whether `bytes` from a client hold the needle while cuts remain (taking one if so);
/// bytes holding it are noted.
fn cuts_here(state: &State, bytes: &[u8]) -> bool {
    let needle = state.needle.lock().unwrap();
    if needle.is_empty() || !bytes.windows(needle.len()).any(|w| w == needle.as_slice()) {
        return false;
    }
    state.seen.lock().unwrap().push(Instant::now());
    state.cuts.fetch_update(Ordering::SeqCst, Ordering::SeqCst, |c| c.checked_sub(1)).is_ok()
}
