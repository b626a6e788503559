//! Modbus TCP, client side: MBAP frames on one connection, reopened with backoff when lost.
//!
//! Replies are matched by transaction id like UDP ([`super::udp`]): frames with the id of an
//! earlier request (late replies after a timeout) are read and skipped. A frame that breaks
//! the stream (bad protocol id or length) drops the connection, since nothing after it can
//! be trusted.

use std::sync::Arc;
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::time::Instant;

use super::{AttemptError, Connection, Counters, Exchange, Reply, Verdict, judge_mbap, timed_out};
use crate::protocols::modbus::config::Quirks;
use crate::protocols::modbus::decode::response_pdu_len;
use crate::protocols::modbus::frame::{self, FrameError, LengthField, MBAP_LEN};

/// A Modbus TCP connection to one device.
pub(crate) struct TcpLink {
    conn: Connection,
    quirks: Quirks,
    counters: Arc<Counters>,
    next_tid: u16,
    tids: Vec<u16>,
    tx: Vec<u8>,
    rx: Vec<u8>,
}

impl TcpLink {
    /// A link that connects on first use.
    pub fn new(conn: Connection, quirks: Quirks, counters: Arc<Counters>) -> Self {
        TcpLink {
            conn,
            quirks,
            counters,
            next_tid: rand::random(),
            tids: Vec::new(),
            tx: Vec::new(),
            rx: Vec::new(),
        }
    }

    /// Sends the request with a new transaction id.
    pub async fn send(&mut self, ex: &Exchange<'_>, timeout: Duration) -> Result<(), AttemptError> {
        if ex.first {
            self.tids.clear();
        }
        let tid = self.next_tid;
        self.next_tid = self.next_tid.wrapping_add(1);
        self.tids.push(tid);
        self.tx.clear();
        frame::encode(&mut self.tx, tid, ex.unit, ex.pdu, LengthField::Standard);
        let stream = self.conn.get(timeout).await?;
        Counters::bump(&self.counters.sends);
        let sent = tokio::time::timeout(timeout, stream.write_all(&self.tx)).await;
        match sent {
            Ok(Ok(())) => Ok(()),
            Ok(Err(e)) => Err(self.lost(AttemptError::Io(e))),
            Err(_) => Err(self.lost(AttemptError::Timeout)),
        }
    }

    /// Sends the request and reads frames until the one that answers it.
    pub async fn attempt(&mut self, ex: &Exchange<'_>, timeout: Duration) -> Result<Reply, AttemptError> {
        let deadline = Instant::now() + timeout;
        self.send(ex, timeout).await?;
        let mut reason = None;
        loop {
            let (len, verdict) = match self.next_frame(ex, deadline).await {
                Ok(found) => found,
                Err(AttemptError::Timeout) => {
                    if self.quirks.ignore_transaction_id {
                        // Without ids a late reply could not be told apart: start afresh.
                        self.lost(AttemptError::Timeout);
                    }
                    return Err(timed_out(reason));
                }
                Err(e) => return Err(self.lost(e)),
            };
            self.rx.drain(..len);
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

    /// Reads until one whole frame is buffered; returns its length and verdict.
    async fn next_frame(
        &mut self,
        ex: &Exchange<'_>,
        deadline: Instant,
    ) -> Result<(usize, Verdict), AttemptError> {
        loop {
            if let Some(len) = self.buffered_frame_len()? {
                let header =
                    frame::decode_header(&self.rx).map_err(|e| AttemptError::Malformed(e.message()))?;
                let pdu = &self.rx[MBAP_LEN..len];
                return Ok((
                    len,
                    judge_mbap(&header, pdu, ex, &self.tids, self.quirks.ignore_transaction_id),
                ));
            }
            let stream = self.conn.get(Duration::ZERO).await?;
            match tokio::time::timeout_at(deadline, stream.read_buf(&mut self.rx)).await {
                Err(_) => return Err(AttemptError::Timeout),
                Ok(Ok(0)) => return Err(AttemptError::Io(std::io::ErrorKind::UnexpectedEof.into())),
                Ok(Ok(_)) => {}
                Ok(Err(e)) => return Err(AttemptError::Io(e)),
            }
        }
    }

    /// The length of the first frame in the buffer, if it is all there.
    fn buffered_frame_len(&self) -> Result<Option<usize>, AttemptError> {
        if self.rx.len() < MBAP_LEN {
            return Ok(None);
        }
        let header = frame::decode_header(&self.rx).map_err(|e| AttemptError::Malformed(e.message()))?;
        let pdu_len = match header.length {
            0 if self.quirks.length0 => match response_pdu_len(&self.rx[MBAP_LEN..]) {
                Ok(Some(n)) => n,
                Ok(None) => return Ok(None),
                Err(e) => return Err(AttemptError::Malformed(e.message())),
            },
            0 => return Err(AttemptError::Malformed(FrameError::BadLength.message())),
            n => n as usize - 1,
        };
        Ok((self.rx.len() >= MBAP_LEN + pdu_len).then_some(MBAP_LEN + pdu_len))
    }

    /// Drops the connection and its buffered input; returns `e` for convenience.
    fn lost(&mut self, e: AttemptError) -> AttemptError {
        self.conn.reset();
        self.rx.clear();
        e
    }
}
