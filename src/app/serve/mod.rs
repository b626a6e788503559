//! Accepting and serving connections: rackd's own accept loop around hyper's HTTP/1
//! connections (hyper-util's `auto::Builder`, with upgrades for the WebSocket), with a
//! timer on every connection that serves no one, a cap on connections, TLS when
//! `[server.tls]` is set ([`tls`]), and the graceful shutdown `axum::serve` had.
//!
//! Why not `axum::serve`: it has no header-read timeout, never closes an idle keep-alive
//! connection and takes every connection it is offered, so a few thousand clients that
//! send half a request and then nothing (slowloris) hold a file descriptor each, without a
//! key, until the process can accept nothing, `/healthz` included.
//!
//! Decisions:
//! - **A connection's phases** ([`table::Phase`]): waiting for a request's headers, serving
//!   it, idle between two requests, or a WebSocket. The socket, the request and its
//!   response's body say when it changes ([`io`]); the connection's task holds one timer,
//!   set from the phase: `server.header_timeout_ms` (10 s) to send a request's headers,
//!   counted from the accept for the first request (the TLS handshake included) and from
//!   the first byte for each keep-alive one; `server.idle_timeout_ms` (60 s) for an idle
//!   keep-alive connection, and for a response the client does not read (a write that
//!   cannot go out for that long closes the connection). Serving a request has no timer
//!   here: `server.request_timeout_secs` bounds it. A WebSocket leaves HTTP and lives on its
//!   own pings and send timeout (`[events]`). Bytes that a client pipelines behind a
//!   request are read while the request is served; if they are half a request, the
//!   connection is idle, not waiting for headers, when the response is out: such a client
//!   gets `idle_timeout_ms`, no more.
//! - **The cap, and whom it closes.** At most `server.max_connections` (1024) are open,
//!   WebSockets included. At the cap, a new connection does not wait behind the others (a
//!   slowloris would then keep everyone out until its timeouts ran, 10 s at a time): it
//!   takes the place of the connection that has waited longest without being served, one
//!   waiting for its headers or idle between two requests, oldest phase first. Closing such
//!   a connection costs its client at most a request it had not finished sending, or a
//!   reconnect, and neither is anyone's work lost. Under a flood of half-open connections
//!   arriving at R a second, a real client has cap / R seconds to send its headers (a
//!   second at 1,000 connections a second), and it is served as soon as they are in; a
//!   connection being served is never closed to make room. When every connection is being
//!   served (or is a WebSocket), the newcomer is closed at once, not kept waiting: the
//!   server is busy, and a closed connection says so sooner than a silent one. A flood is
//!   taken in at the pace evicted connections close, at most [`table::CLOSING`] (32)
//!   evictions ahead, so the open sockets stay under the cap plus 32, within the
//!   descriptors kept in reserve.
//! - **The listen backlog** is 1024 (`app::bind`), not the standard library's 128: a
//!   burst of connections overflows 128 at once, and the kernel then drops SYNs, a real
//!   client's among them, which is sent again only a second later.
//! - **The open-files limit** ([`files`]): the server raises its soft `RLIMIT_NOFILE` to the
//!   hard limit and serves no more connections than the limit leaves room for. If
//!   `accept` still fails for want of descriptors (another part of rackd used them), the
//!   connection waiting longest unserved is closed to make room, as at the cap.
//! - **HTTP/1.1 only**, as `axum::serve` was built here (no `http2` feature): the clients
//!   are WMSs, dashboards and scripts, and the h2 crate would add to the build for nothing.
//! - **Graceful shutdown** as `axum::serve` does it: stop accepting, let each connection
//!   finish the request it is serving and close (an idle one at once), wait for them.
//!   WebSockets are handed off by hyper on upgrade and end as before, when the event hub
//!   closes (`close 1001 "server stopping"`). A connection still waiting for its headers
//!   at the stop (a request line and part of its headers in) has a second more to finish
//!   them, and is closed then, where `axum::serve` waited for it for ever.
//! - Every request carries axum's `ConnectInfo<SocketAddr>` with the client's address.

pub(crate) mod certificate;
mod files;
mod io;
mod table;
pub(crate) mod tls;

use std::future::{Future, poll_fn};
use std::net::SocketAddr;
use std::pin::{Pin, pin};
use std::sync::Arc;
use std::task::Poll;
use std::time::Duration;

use hyper_util::rt::{TokioExecutor, TokioIo};
use hyper_util::server::conn::auto;
use tokio::net::{TcpListener, TcpStream};
use tokio_util::sync::CancellationToken;
use tokio_util::task::TaskTracker;

use crate::config::ServerConfig;
use io::{Stream, Tracked};
use table::{Admit, Conn, Phase, Slot, Table};
use tls::Certificates;

/// The timers and the cap of `[server]`.
#[derive(Clone, Debug)]
pub(crate) struct Limits {
    /// `header_timeout_ms`.
    pub(crate) header_timeout: Duration,
    /// `idle_timeout_ms`.
    pub(crate) idle_timeout: Duration,
    /// `max_connections`.
    pub(crate) max_connections: usize,
}

impl Limits {
    /// The limits `server` sets.
    pub(crate) fn of(server: &ServerConfig) -> Limits {
        Limits {
            header_timeout: Duration::from_millis(server.header_timeout_ms),
            idle_timeout: Duration::from_millis(server.idle_timeout_ms),
            max_connections: server.max_connections,
        }
    }
}

/// What every connection's task shares.
struct Shared {
    router: axum::Router,
    limits: Limits,
    tls: Option<Certificates>,
}

/// Serves `router` on `listener` until `stop` completes, then shuts down gracefully.
pub(crate) async fn serve(
    listener: TcpListener,
    router: axum::Router,
    limits: Limits,
    tls: Option<Certificates>,
    stop: impl Future<Output = ()> + Send,
) {
    let table = Table::new(files::cap(limits.max_connections));
    let stopping = CancellationToken::new();
    let connections = TaskTracker::new();
    if let Some(tls) = &tls {
        tls.watch(stopping.clone());
    }
    let shared = Arc::new(Shared { router, limits, tls });
    let mut stop = pin!(stop);
    let mut full_since: Option<tokio::time::Instant> = None;
    loop {
        let (tcp, remote) = tokio::select! {
            _ = &mut stop => break,
            accepted = listener.accept() => match accepted {
                Ok(accepted) => accepted,
                Err(e) => {
                    out_of_files(&table, e).await;
                    continue;
                }
            },
        };
        // No Nagle: live events and replies are small writes that must leave at once
        // (Nagle's wait for an ACK, against a delayed ACK, stalls them by up to 40 ms).
        if let Err(e) = tcp.set_nodelay(true) {
            tracing::debug!(error = %e, "TCP_NODELAY");
        }
        let admitted = loop {
            match table.admit() {
                Admit::Serve(slot, conn) => break Some((slot, conn)),
                Admit::Wait => table.a_close().await,
                Admit::Refuse => break None,
            }
        };
        let Some((slot, conn)) = admitted else {
            tracing::debug!(%remote, "refused: every connection is being served");
            continue;
        };
        if table.len() >= table.cap() {
            // Once a minute at most: a flood must not flood the log too.
            let now = tokio::time::Instant::now();
            if full_since.is_none_or(|t| now - t > Duration::from_secs(60)) {
                tracing::warn!(
                    connections = table.len(),
                    "at server.max_connections: new connections take the place of those waiting longest unserved"
                );
                full_since = Some(now);
            }
        }
        connections.spawn(connection(tcp, remote, slot, conn, shared.clone(), stopping.clone()));
    }
    drop(listener);
    stopping.cancel();
    connections.close();
    connections.wait().await;
}

/// `accept` failed: out of descriptors, make room as at the cap; anything else (a client
/// that left before it was accepted) is the client's.
async fn out_of_files(table: &Table, e: std::io::Error) {
    let out = matches!(e.raw_os_error(), Some(code) if code == rustix::io::Errno::MFILE.raw_os_error()
        || code == rustix::io::Errno::NFILE.raw_os_error());
    if !out {
        tracing::debug!(error = %e, "accept");
        return;
    }
    if table.relieve() {
        table.a_close().await;
    } else {
        tracing::warn!(error = %e, "accept: out of file descriptors, and every connection is being served");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// Why a connection was closed by the server.
#[derive(Debug)]
enum End {
    /// hyper is done with it (the client closed, an error, an upgrade, the shutdown).
    Done,
    /// Its phase's timer ran out.
    Expired(Phase),
    /// It made room for a newer one.
    Evicted,
}

/// Serves one connection: the TLS handshake, then HTTP until it ends, times out or is
/// evicted.
async fn connection(
    tcp: TcpStream,
    remote: SocketAddr,
    slot: Slot,
    conn: Arc<Conn>,
    shared: Arc<Shared>,
    stopping: CancellationToken,
) {
    let mut watch = Watch::new(&conn, &shared.limits);
    let stream = match &shared.tls {
        None => Stream::Plain(tcp),
        Some(tls) => {
            // The handshake is the start of sending the first request: the same timer.
            let mut handshake = tls.acceptor().accept(tcp);
            let done = poll_fn(|cx| match Pin::new(&mut handshake).poll(cx) {
                Poll::Ready(done) => Poll::Ready(Ok(done)),
                Poll::Pending => watch.poll(cx).map(Err),
            });
            let done = tokio::select! {
                done = done => done,
                _ = stopping.cancelled() => return,
            };
            match done {
                Ok(Ok(tls)) => Stream::Tls(Box::new(tls)),
                Ok(Err(e)) => {
                    tracing::debug!(%remote, error = %e, "TLS handshake failed");
                    return;
                }
                Err(end) => {
                    tracing::debug!(%remote, ?end, "closed during the TLS handshake");
                    return;
                }
            }
        }
    };
    let io = TokioIo::new(Tracked::new(stream, conn.clone(), slot));
    let service = io::Service { router: shared.router.clone(), conn: conn.clone(), remote };
    let builder = auto::Builder::new(TokioExecutor::new());
    let mut http = pin!(builder.serve_connection_with_upgrades(io, service));
    let mut stopped = pin!(stopping.cancelled());
    let mut draining = false;
    let end = poll_fn(|cx| {
        if !draining && stopped.as_mut().poll(cx).is_ready() {
            draining = true;
            watch.drain();
            http.as_mut().graceful_shutdown();
        }
        if let Poll::Ready(result) = http.as_mut().poll(cx) {
            if let Err(e) = result {
                tracing::debug!(%remote, error = %e, "connection ended");
            }
            return Poll::Ready(End::Done);
        }
        watch.poll(cx)
    })
    .await;
    match end {
        End::Done => {}
        End::Expired(Phase::Head) => {
            tracing::debug!(%remote, "closed: no request headers in server.header_timeout_ms")
        }
        End::Expired(_) => {
            tracing::debug!(%remote, "closed: idle (or not reading) for server.idle_timeout_ms")
        }
        End::Evicted => tracing::debug!(%remote, "closed to make room for a new connection"),
    }
}

/// A connection's timer and its eviction, as one poll: ready when the connection is to be
/// closed. Its deadline follows the phase, read again at each poll, which comes after any
/// change (every change is made while hyper's connection is polled, in the same task).
struct Watch<'a> {
    conn: &'a Conn,
    limits: &'a Limits,
    timer: Pin<Box<tokio::time::Sleep>>,
    evicted: Pin<Box<tokio::sync::futures::Notified<'a>>>,
    /// When the server began to stop.
    draining: Option<tokio::time::Instant>,
}

/// How long, once the server stops, a client in the middle of sending its headers has to
/// finish them (its request is then served): a stop waits for no slowloris.
const DRAIN_HEADERS: Duration = Duration::from_secs(1);

impl<'a> Watch<'a> {
    fn new(conn: &'a Conn, limits: &'a Limits) -> Watch<'a> {
        let timer = Box::pin(tokio::time::sleep_until(tokio::time::Instant::now() + limits.header_timeout));
        Watch { conn, limits, timer, evicted: Box::pin(conn.evicted.notified()), draining: None }
    }

    /// The server is stopping.
    fn drain(&mut self) {
        self.draining = Some(tokio::time::Instant::now());
    }

    fn poll(&mut self, cx: &mut std::task::Context<'_>) -> Poll<End> {
        if self.evicted.as_mut().poll(cx).is_ready() {
            return Poll::Ready(End::Evicted);
        }
        let Some((mut at, phase)) = self.conn.deadline(self.limits) else { return Poll::Pending };
        if let (Some(since), Phase::Head) = (self.draining, phase) {
            at = at.min(since + DRAIN_HEADERS);
        }
        if self.timer.deadline() != at {
            self.timer.as_mut().reset(at);
        }
        match self.timer.as_mut().poll(cx) {
            Poll::Ready(()) if phase == Phase::Evicted => Poll::Ready(End::Evicted),
            Poll::Ready(()) => Poll::Ready(End::Expired(phase)),
            Poll::Pending => Poll::Pending,
        }
    }
}
