//! A link over datagrams: one request per datagram, one reply per datagram, on a port
//! connected to the device (so datagrams from anyone else never reach it): a UDP socket, or
//! a simulated one ([`super::DatagramPort`]).
//!
//! On a link whose replies name no request, [`DatagramLink::settle`] keeps the transport's
//! rule before each send ([`super::owed`]): while a reply may still be owed, it moves to a
//! new ephemeral port (under [`Guard::Replace`]) or holds the socket until nothing has
//! arrived for the configured timeout (under [`Guard::Wait`]: a fixed local port, and the
//! first request of a link, since a fresh port may be one a rackd before a restart used).
//! A port left behind is *retired*, not closed: it stays bound until every reply owed to
//! it is past (the configured timeout after its last send), so the kernel cannot hand its
//! number to anyone, and what arrives on it meanwhile is drained and counted stale before
//! each request. At most [`MAX_RETIRED`] ports are kept; past that the link waits instead.
//!
//! With a flight recorder ([`DatagramLink::set_recorder`]) every datagram sent and read is
//! recorded (see `tap.rs`): a datagram read waits for its protocol's verdict
//! ([`DatagramLink::judged`]); one flushed before a request, drained from a retired port or
//! read while the socket is held is a stale reply.

use std::future::poll_fn;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use tokio::io::ReadBuf;
use tokio::time::Instant;

use super::connection::{Backoff, Connection};
use super::endpoint::{Carrier, DatagramPort, Endpoint};
use super::health::Settled;
use super::owed::{Clear, Guard, Owed};
use super::retry::{Attempt, AttemptError};
use crate::capture::{Recorder, Verdict};

/// Largest datagram read; longer ones are cut (no reply of these protocols comes close).
const MAX_DATAGRAM: usize = 8192;

/// The most ports kept bound while replies to them may still come.
pub(crate) const MAX_RETIRED: usize = 16;

/// The longest hold, in configured timeouts (as a stream link's).
const MAX_HOLD: u32 = 4;

/// A port left behind, bound until `until`.
struct Retired {
    port: Box<dyn DatagramPort>,
    until: Instant,
}

/// A datagram link to one device; the port is bound on first use and again after a reset
/// or a replacement.
pub(crate) struct DatagramLink {
    conn: Connection,
    rx: Box<[u8]>,
    owed: Owed,
    /// The sends after the last [`DatagramLink::settle`] are a retry's.
    retrying: bool,
    /// ... and a write's.
    writing: bool,
    retired: Vec<Retired>,
}

impl DatagramLink {
    /// A UDP link to `peer` (`HOST:PORT`) from `local`, or from an ephemeral port when
    /// `None`, for a link whose replies name their request or not (`replies_named`).
    pub fn new(peer: String, local: Option<SocketAddr>, backoff: Backoff, replies_named: bool) -> Self {
        let guard = match (replies_named, local) {
            (true, _) => Guard::Ids,
            (false, None) => Guard::Replace,
            (false, Some(_)) => Guard::Wait,
        };
        Self::over(Endpoint::Udp { peer, local }, backoff, guard)
    }

    /// A link over `endpoint` (a UDP peer, or dialled datagram ports) under `guard`. It
    /// starts held: a fresh port may bring a reply a process before this one asked for.
    pub fn over(endpoint: Endpoint, backoff: Backoff, guard: Guard) -> Self {
        DatagramLink {
            conn: Connection::new(endpoint, backoff),
            rx: vec![0; MAX_DATAGRAM].into(),
            owed: Owed::new(guard, true),
            retrying: false,
            writing: false,
            retired: Vec::new(),
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

    /// The reply to the last request sent was taken.
    pub fn answered(&mut self) {
        self.owed.answered();
    }

    /// A datagram that was not the request's answer came: another may follow.
    pub fn unsettle(&mut self) {
        self.owed.unsettle();
    }

    /// Binds the socket now rather than on the first request, to report a bad address early.
    pub async fn open(&mut self, timeout: Duration) -> Result<(), AttemptError> {
        self.conn.datagram(timeout).await.map(|_| ())
    }

    /// Before sending `attempt`, the transport's rule for links whose replies name no
    /// request: while a reply may still be owed, the port is retired and a new one bound
    /// ([`Guard::Replace`]), or the socket is held until nothing has arrived for the
    /// configured timeout ([`Guard::Wait`], and the first request); then datagrams already
    /// waiting, on the port and on retired ones, are dropped. On every datagram link, ids
    /// or not, a write never answered is waited out before the next request, since
    /// datagrams may overtake each other ([`super::owed::Owed::before_send`]); `write` if
    /// this request writes. Returns the replies dropped and how long the socket was held.
    pub async fn settle(&mut self, attempt: &Attempt, write: bool) -> Result<Settled, AttemptError> {
        self.retrying = !attempt.is_first();
        self.writing = write;
        let started = Instant::now();
        let mut replies = 0;
        match self.owed.before_send(attempt.is_first()) {
            Clear::Nothing => {}
            Clear::Replace if self.retired.len() < MAX_RETIRED => {
                if let Some(Carrier::Datagram(port)) = self.conn.take() {
                    let until = self.owed.past_at(attempt.timeout);
                    self.retired.push(Retired { port, until });
                }
                self.owed.replaced();
            }
            Clear::Replace | Clear::Wait => {
                replies += self.hold(attempt.timeout).await?;
                self.owed.cleared();
            }
        }
        if self.owed.guard() != Guard::Ids {
            replies += self.flush_stale(attempt.timeout).await?;
        }
        Ok(Settled { replies, held: started.elapsed() })
    }

    /// Reads and drops datagrams until none has come for `window` since the last thing
    /// sent or received (at most [`MAX_HOLD`] windows); returns how many.
    async fn hold(&mut self, window: Duration) -> Result<u64, AttemptError> {
        let give_up = Instant::now() + window * MAX_HOLD;
        let mut dropped = 0;
        loop {
            let quiet = self.owed.quiet_at(window).min(give_up);
            if Instant::now() >= quiet {
                return Ok(dropped);
            }
            let port = self.conn.datagram(window).await?;
            let mut buf = ReadBuf::new(&mut self.rx);
            let read = poll_fn(|cx| port.poll_recv(cx, &mut buf));
            match tokio::time::timeout_at(quiet, read).await {
                Err(_) => {}
                Ok(Ok(())) => {
                    let n = buf.filled().len();
                    self.owed.received();
                    dropped += 1;
                    if self.conn.tap.on() {
                        let time_us = self.conn.tap.now_us();
                        self.conn.tap.discarded(time_us, &self.rx[..n], Verdict::StaleReply);
                    }
                }
                // An ICMP error for an earlier datagram: the socket stays usable.
                Ok(Err(_)) => self.owed.received(),
            }
        }
    }

    /// Drops every datagram already queued (late replies to earlier requests), on the
    /// port and on retired ports, and lets go of retired ports whose replies are past;
    /// returns how many datagrams there were.
    pub async fn flush_stale(&mut self, timeout: Duration) -> Result<u64, AttemptError> {
        let mut stale = 0;
        let now = Instant::now();
        let mut retired = std::mem::take(&mut self.retired);
        for old in &retired {
            stale += self.drain(old.port.as_ref());
        }
        retired.retain(|old| old.until > now);
        self.retired = retired;
        loop {
            let port = self.conn.datagram(timeout).await?;
            let Ok(n) = port.try_recv(&mut self.rx) else { break };
            stale += 1;
            if self.conn.tap.on() {
                let time_us = self.conn.tap.now_us();
                self.conn.tap.discarded(time_us, &self.rx[..n], Verdict::StaleReply);
            }
        }
        Ok(stale)
    }

    /// Drops the datagrams waiting on a retired `port`; returns how many.
    fn drain(&mut self, port: &dyn DatagramPort) -> u64 {
        let mut stale = 0;
        while let Ok(n) = port.try_recv(&mut self.rx) {
            stale += 1;
            if self.conn.tap.on() {
                let time_us = self.conn.tap.now_us();
                self.conn.tap.discarded(time_us, &self.rx[..n], Verdict::StaleReply);
            }
        }
        stale
    }

    /// Sends one datagram.
    pub async fn send(&mut self, bytes: &[u8], timeout: Duration) -> Result<(), AttemptError> {
        let port = self.conn.datagram(timeout).await?;
        poll_fn(|cx| port.poll_send(cx, bytes)).await?;
        self.owed.sent(self.retrying, self.writing);
        self.conn.tap.sent(bytes);
        Ok(())
    }

    /// The next datagram, or `Ok(None)` once `deadline` passes (the reply may still come:
    /// it is owed). An error (an ICMP "port unreachable" for an earlier datagram) leaves
    /// the socket open.
    pub async fn recv(&mut self, deadline: Instant) -> Result<Option<&[u8]>, AttemptError> {
        let port = self.conn.datagram(Duration::ZERO).await?;
        let mut buf = ReadBuf::new(&mut self.rx);
        let read = poll_fn(|cx| port.poll_recv(cx, &mut buf));
        match tokio::time::timeout_at(deadline, read).await {
            Err(_) => {
                self.owed.unsettle();
                Ok(None)
            }
            Ok(Ok(())) => {
                let n = buf.filled().len();
                self.owed.received();
                self.conn.tap.read(&self.rx[..n]);
                Ok(Some(&self.rx[..n]))
            }
            Ok(Err(e)) => Err(AttemptError::Io(e)),
        }
    }
}

#[cfg(test)]
mod tests {
    use tokio::net::UdpSocket;

    use super::*;
    use crate::protocols::transport::RetryPolicy;

    /// A retried request moves the link to a new port, and the old one stays bound (its
    /// late reply is drained as stale, never read as the next answer).
    #[tokio::test]
    async fn an_unanswered_request_moves_the_link_to_a_new_port_and_keeps_the_old_one_bound() {
        let device = UdpSocket::bind("127.0.0.1:0").await.unwrap();
        let peer = device.local_addr().unwrap().to_string();
        let mut link = DatagramLink::new(peer, None, Backoff::default(), false);
        let policy = RetryPolicy::new(Duration::from_millis(100), 1);
        let attempt = Attempt::single(&policy);
        // The first request holds the fresh port for the timeout (it could be an old one).
        let settled = link.settle(&attempt, false).await.unwrap();
        assert!(settled.held >= Duration::from_millis(100), "{:?}", settled.held);
        link.send(b"first", policy.timeout).await.unwrap();
        let mut buf = [0u8; 16];
        let (_, first_port) = device.recv_from(&mut buf).await.unwrap();
        assert!(link.recv(Instant::now() + Duration::from_millis(5)).await.unwrap().is_none());
        // Unanswered: the next send goes from another port, at once.
        let settled = link.settle(&attempt.restarted(), false).await.unwrap();
        assert!(settled.held < Duration::from_millis(50), "replaced, not held: {:?}", settled.held);
        link.send(b"second", policy.timeout).await.unwrap();
        let (_, second_port) = device.recv_from(&mut buf).await.unwrap();
        assert_ne!(first_port, second_port, "a new ephemeral port");
        // The late reply to the first lands on the retired port, still bound.
        device.send_to(b"late", first_port).await.unwrap();
        device.send_to(b"answer", second_port).await.unwrap();
        let got = link.recv(Instant::now() + Duration::from_secs(1)).await.unwrap().map(<[u8]>::to_vec);
        assert_eq!(got.as_deref(), Some(&b"answer"[..]));
        link.answered();
        tokio::time::sleep(Duration::from_millis(20)).await;
        let settled = link.settle(&attempt.restarted(), false).await.unwrap();
        assert_eq!(settled.replies, 1, "the late reply, drained from the retired port");
        assert_eq!(link.retired.len(), 1, "still within its reply lifetime");
        tokio::time::sleep(Duration::from_millis(120)).await;
        link.settle(&attempt.restarted(), false).await.unwrap();
        assert!(link.retired.is_empty(), "past its lifetime: let go");
    }
}
