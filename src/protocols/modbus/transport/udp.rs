//! Modbus UDP, client side: one MBAP frame per datagram, replies matched by transaction
//! id, unit and function.
//!
//! Every attempt gets a fresh transaction id; a reply carrying the id of *any* attempt of
//! the current request is taken (a retry's answer and a slow first answer are equally
//! good), while ids of earlier requests are stale and dropped. So a late reply after a
//! timeout is never taken for the answer to a newer request.

use std::io;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use tokio::net::UdpSocket;

use super::{AttemptError, Counters, Exchange, Reply, Verdict, judge_mbap, timed_out};
use crate::protocols::modbus::config::Quirks;
use crate::protocols::modbus::frame::{self, LengthField};

/// A connected UDP socket to one device.
pub(crate) struct UdpLink {
    socket: UdpSocket,
    quirks: Quirks,
    counters: Arc<Counters>,
    next_tid: u16,
    tids: Vec<u16>,
    tx: Vec<u8>,
    rx: Box<[u8]>,
}

impl UdpLink {
    /// Binds an ephemeral local port and connects it to `address` (so the kernel already
    /// drops datagrams from other senders).
    pub async fn connect(address: &str, quirks: Quirks, counters: Arc<Counters>) -> io::Result<Self> {
        let peer = tokio::net::lookup_host(address)
            .await?
            .next()
            .ok_or_else(|| io::Error::new(io::ErrorKind::NotFound, "address resolves to nothing"))?;
        let local: SocketAddr = if peer.is_ipv4() { "0.0.0.0:0".parse() } else { "[::]:0".parse() }
            .map_err(|_| io::Error::other("bad local address"))?;
        let socket = UdpSocket::bind(local).await?;
        socket.connect(peer).await?;
        Ok(UdpLink {
            socket,
            quirks,
            counters,
            next_tid: rand::random(),
            tids: Vec::new(),
            tx: Vec::with_capacity(300),
            rx: vec![0; 1024].into_boxed_slice(),
        })
    }

    /// Sends the request in a datagram with a new transaction id.
    pub async fn send(&mut self, ex: &Exchange<'_>) -> Result<(), AttemptError> {
        if ex.first {
            self.tids.clear();
            if self.quirks.ignore_transaction_id {
                self.flush_stale();
            }
        }
        let tid = self.next_tid;
        self.next_tid = self.next_tid.wrapping_add(1);
        self.tids.push(tid);
        self.tx.clear();
        frame::encode(&mut self.tx, tid, ex.unit, ex.pdu, LengthField::Standard);
        Counters::bump(&self.counters.sends);
        self.socket.send(&self.tx).await.map_err(AttemptError::Io)?;
        Ok(())
    }

    /// Sends the request and waits for the datagram that answers it.
    pub async fn attempt(&mut self, ex: &Exchange<'_>, timeout: Duration) -> Result<Reply, AttemptError> {
        self.send(ex).await?;
        let deadline = tokio::time::Instant::now() + timeout;
        let mut reason = None;
        loop {
            let n = match tokio::time::timeout_at(deadline, self.socket.recv(&mut self.rx)).await {
                Err(_) => return Err(timed_out(reason)),
                Ok(Err(e)) => return Err(AttemptError::Io(e)),
                Ok(Ok(n)) => n,
            };
            let verdict = match frame::split_datagram(&self.rx[..n], self.quirks.length0) {
                Ok((header, pdu)) => {
                    judge_mbap(&header, pdu, ex, &self.tids, self.quirks.ignore_transaction_id)
                }
                // Datagrams are independent: a broken one is dropped, the right one may follow.
                Err(e) => Verdict::Drop(Some(e.message())),
            };
            match verdict {
                Verdict::Take(reply) => return Ok(reply),
                Verdict::Fail(msg) => return Err(AttemptError::Malformed(msg)),
                Verdict::Drop(why) => {
                    Counters::bump(&self.counters.dropped);
                    reason = why.or(reason);
                }
            }
        }
    }

    /// Drops every datagram already queued (replies to earlier requests).
    fn flush_stale(&mut self) {
        while self.socket.try_recv(&mut self.rx).is_ok() {
            Counters::bump(&self.counters.dropped);
        }
    }
}
