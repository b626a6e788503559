//! A link over UDP: one request per datagram, one reply per datagram, on a socket connected
//! to the device (so datagrams from anyone else never reach it).
//!
//! With a flight recorder ([`DatagramLink::set_recorder`]) every datagram sent and read is
//! recorded (see `tap.rs`): a datagram read waits for its protocol's verdict
//! ([`DatagramLink::judged`]); one flushed before a request is a stale reply.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use tokio::time::Instant;

use super::connection::{Backoff, Connection};
use super::endpoint::Endpoint;
use super::retry::AttemptError;
use crate::capture::{Recorder, Verdict};

/// Largest datagram read; longer ones are cut (no reply of these protocols comes close).
const MAX_DATAGRAM: usize = 8192;

/// A UDP link to one device; the socket is bound on first use and again after a reset.
pub(crate) struct DatagramLink {
    conn: Connection,
    rx: Box<[u8]>,
}

impl DatagramLink {
    /// A link to `peer` (`HOST:PORT`) from `local`, or from an ephemeral port when `None`.
    pub fn new(peer: String, local: Option<SocketAddr>, backoff: Backoff) -> Self {
        DatagramLink {
            conn: Connection::new(Endpoint::Udp { peer, local }, backoff),
            rx: vec![0; MAX_DATAGRAM].into(),
        }
    }

    /// Records every datagram into `recorder` from now on.
    pub fn set_recorder(&mut self, recorder: Option<Arc<Recorder>>) {
        self.conn.tap = super::tap::Tap::new(recorder);
    }

    /// The protocol's verdict on the datagram read last, for the recorder.
    pub fn judged(&mut self, verdict: Verdict) {
        self.conn.tap.judged(verdict);
    }

    /// Starts an exchange that must have the socket to itself: after an unfinished one the
    /// socket is closed and the next send binds a new one ([`Connection::begin_exclusive`]).
    pub fn begin_exclusive(&mut self) {
        self.conn.begin_exclusive();
    }

    /// Marks the exclusive exchange as answered.
    pub fn finished(&mut self) {
        self.conn.finished();
    }

    /// Binds the socket now rather than on the first request, to report a bad address early.
    pub async fn open(&mut self, timeout: Duration) -> Result<(), AttemptError> {
        self.conn.datagram(timeout).await.map(|_| ())
    }

    /// Drops every datagram already queued (late replies to earlier requests); returns how
    /// many there were.
    pub async fn flush_stale(&mut self, timeout: Duration) -> Result<u64, AttemptError> {
        let mut stale = 0;
        loop {
            let socket = self.conn.datagram(timeout).await?;
            let Ok(n) = socket.try_recv(&mut self.rx) else { return Ok(stale) };
            stale += 1;
            if self.conn.tap.on() {
                let time_us = self.conn.tap.now_us();
                self.conn.tap.discarded(time_us, &self.rx[..n], Verdict::StaleReply);
            }
        }
    }

    /// Sends one datagram.
    pub async fn send(&mut self, bytes: &[u8], timeout: Duration) -> Result<(), AttemptError> {
        let socket = self.conn.datagram(timeout).await?;
        socket.send(bytes).await?;
        self.conn.tap.sent(bytes);
        Ok(())
    }

    /// The next datagram, or `Ok(None)` once `deadline` passes. An error (an ICMP "port
    /// unreachable" for an earlier datagram) leaves the socket open.
    pub async fn recv(&mut self, deadline: Instant) -> Result<Option<&[u8]>, AttemptError> {
        let socket = self.conn.datagram(Duration::ZERO).await?;
        match tokio::time::timeout_at(deadline, socket.recv(&mut self.rx)).await {
            Err(_) => Ok(None),
            Ok(Ok(n)) => {
                self.conn.tap.read(&self.rx[..n]);
                Ok(Some(&self.rx[..n]))
            }
            Ok(Err(e)) => Err(AttemptError::Io(e)),
        }
    }
}
