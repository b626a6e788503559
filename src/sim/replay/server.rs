//! The replay's sockets: a TCP listener (any number of connections one after another, as
//! rackd reconnects; they share one matcher) or a UDP socket, each request cut by the
//! dialect, taken by the [`Matcher`] and answered with its recorded replies at their
//! recorded delays. Over TCP one writer per connection sends the replies in the order of
//! their times, so a late reply still goes out after an earlier request's prompt one.

use std::collections::{BTreeMap, HashMap};
use std::net::SocketAddr;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::tcp::OwnedWriteHalf;
use tokio::net::{TcpListener, TcpStream, UdpSocket};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio::time::{Instant, sleep_until};

use super::dialect::Dialect;
use super::matcher::{Matcher, Request, Taken};
use super::script::Script;
use super::{Divergence, KEPT_DIVERGENCES, Report, hex_bytes};
use crate::capture::Transport;

/// What the connections share.
struct Shared {
    dialect: Dialect,
    start: Instant,
    matcher: Mutex<Matcher>,
    /// Recorded id -> the live id of the request that took it.
    ids: Mutex<HashMap<[u8; 2], [u8; 2]>>,
    divergences: Mutex<Vec<Divergence>>,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl Shared {
    /// The replies to `request`, each with its delay.
    fn answer(&self, request: &[u8]) -> Vec<(Duration, Vec<u8>)> {
        let now = self.start.elapsed();
        let d = self.dialect;
        let mut m = lock(&self.matcher);
        let expected = m.due().map(|i| m.requests()[i].bytes.clone());
        let key = d.key(request);
        let asked = Request { key: &key, read: d.is_read(request), data_at: d.data_at(request) };
        let (index, taken) = m.take(asked, now);
        if matches!(taken, Taken::Skipped | Taken::Unanswered) {
            let got = hex_bytes(request);
            let want = expected.as_deref().map_or("nothing".into(), hex_bytes);
            tracing::warn!(?taken, %got, expected = %want, "replay: the request does not follow the recording");
            let mut kept = lock(&self.divergences);
            if kept.len() < KEPT_DIVERGENCES {
                kept.push(Divergence { at: now, got: request.to_vec(), expected, taken });
            }
        }
        let Some(recorded) = index.map(|i| &m.requests()[i]) else { return Vec::new() };
        let mut ids = lock(&self.ids);
        if let (Some(live), Some(was)) = (d.id(request), d.id(&recorded.bytes)) {
            ids.insert(was, live);
        }
        let live_id = |bytes: &[u8]| d.id(bytes).and_then(|id| ids.get(&id).copied());
        recorded
            .replies
            .iter()
            .map(|r| match live_id(&r.bytes) {
                Some(id) => (r.after, d.with_id(&r.bytes, id)),
                None => (r.after, r.bytes.clone()),
            })
            .collect()
    }
}

/// A running replay.
pub struct ReplayServer {
    local_addr: SocketAddr,
    recorded: usize,
    shared: Arc<Shared>,
    task: JoinHandle<()>,
}

impl ReplayServer {
    /// Serves `script` on `listen` (port 0 picks a free one), taking writes up to `reorder`
    /// apart out of order (see [`super`]).
    pub async fn start(
        script: Script,
        listen: SocketAddr,
        reorder: Duration,
    ) -> std::io::Result<ReplayServer> {
        let recorded = script.requests.len();
        let shared = Arc::new(Shared {
            dialect: script.dialect,
            start: Instant::now(),
            matcher: Mutex::new(Matcher::new(script.requests, reorder)),
            ids: Mutex::default(),
            divergences: Mutex::default(),
        });
        let (local_addr, task) = match script.transport {
            Transport::Tcp => {
                let listener = TcpListener::bind(listen).await?;
                (listener.local_addr()?, tokio::spawn(serve_tcp(listener, shared.clone())))
            }
            Transport::Udp => {
                let socket = Arc::new(UdpSocket::bind(listen).await?);
                (socket.local_addr()?, tokio::spawn(serve_udp(socket, shared.clone())))
            }
        };
        Ok(ReplayServer { local_addr, recorded, shared, task })
    }

    /// Where it serves.
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
    }

    /// Whether the recording is played out: some request came, every recorded write is
    /// made and the clock has passed the last request.
    pub fn exhausted(&self) -> bool {
        let mut m = lock(&self.shared.matcher);
        let c = m.counters();
        c.matched + c.reordered + c.repeated + c.skipped + c.unanswered > 0
            && m.exhausted(self.shared.start.elapsed())
    }

    /// What it did so far.
    pub fn report(&self) -> Report {
        let m = lock(&self.shared.matcher);
        let (passed_over, not_reached) = m.writes_not_made();
        Report {
            recorded: self.recorded,
            counters: m.counters(),
            passed_over,
            not_reached,
            divergences: lock(&self.shared.divergences).clone(),
        }
    }

    /// Stops serving (open connections close) and reports.
    pub fn stop(self) -> Report {
        self.task.abort();
        self.report()
    }
}

impl Drop for ReplayServer {
    fn drop(&mut self) {
        self.task.abort();
    }
}

async fn serve_tcp(listener: TcpListener, shared: Arc<Shared>) {
    let mut connections = tokio::task::JoinSet::new();
    while let Ok((stream, peer)) = listener.accept().await {
        tracing::info!(%peer, "replay: connection");
        connections.spawn(connection(stream, shared.clone()));
    }
}

async fn connection(stream: TcpStream, shared: Arc<Shared>) {
    let (mut read, write) = stream.into_split();
    let (tx, rx) = mpsc::unbounded_channel();
    let writer = tokio::spawn(write_in_order(write, rx));
    let (mut pending, mut chunk) = (Vec::new(), vec![0u8; 8192]);
    while let Ok(n @ 1..) = read.read(&mut chunk).await {
        pending.extend_from_slice(&chunk[..n]);
        while let Some(len) = shared.dialect.frame_len(&pending) {
            let request: Vec<u8> = pending.drain(..len).collect();
            let arrived = Instant::now();
            for (after, bytes) in shared.answer(&request) {
                let _ = tx.send((arrived + after, bytes));
            }
        }
    }
    // rackd closed: replies still waiting would go nowhere.
    writer.abort();
}

/// Sends each reply at its time, earliest first.
async fn write_in_order(mut out: OwnedWriteHalf, mut rx: mpsc::UnboundedReceiver<(Instant, Vec<u8>)>) {
    let mut queue: BTreeMap<(Instant, u64), Vec<u8>> = BTreeMap::new();
    let mut seq = 0u64;
    loop {
        let next = queue.keys().next().map(|k| k.0);
        tokio::select! {
            got = rx.recv() => match got {
                Some((at, bytes)) => {
                    queue.insert((at, seq), bytes);
                    seq += 1;
                }
                None => return,
            },
            _ = sleep_until(next.unwrap_or_else(Instant::now)), if next.is_some() => {
                if let Some((_, bytes)) = queue.pop_first()
                    && out.write_all(&bytes).await.is_err()
                {
                    return;
                }
            }
        }
    }
}

async fn serve_udp(socket: Arc<UdpSocket>, shared: Arc<Shared>) {
    let mut buf = vec![0u8; 65_536];
    while let Ok((n, peer)) = socket.recv_from(&mut buf).await {
        let arrived = Instant::now();
        for (after, bytes) in shared.answer(&buf[..n]) {
            let socket = socket.clone();
            tokio::spawn(async move {
                sleep_until(arrived + after).await;
                let _ = socket.send_to(&bytes, peer).await;
            });
        }
    }
}

#[cfg(test)]
#[path = "server_tests.rs"]
mod tests;
