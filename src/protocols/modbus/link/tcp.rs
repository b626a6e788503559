//! Modbus TCP, client side: MBAP frames on one connection, reopened with backoff when lost.
//!
//! Replies are matched by transaction id like UDP ([`super::udp`]): frames with the id of an
//! earlier request (late replies after a timeout) are read and skipped. A frame that breaks
//! the stream (bad protocol id or length) drops the connection, since nothing after it can
//! be trusted. Without transaction ids (the `no-transaction-id` quirk: replies name no
//! request) the link keeps the transport's rule ([`StreamLink::settle`]): after an attempt
//! that was not answered the next one goes out on a new connection, which never receives
//! the old one's bytes.

use std::sync::Arc;

use tokio_util::bytes::{Buf, BytesMut};
use tokio_util::codec::Decoder;

use super::{Counters, Exchange, RecentIds, Verdict, judge_mbap, taken, timed_out};
use crate::protocols::Replies;
use crate::protocols::modbus::config::Quirks;
use crate::protocols::modbus::decode::response_pdu_len;
use crate::protocols::modbus::frame::{self, FrameError, LengthField, MBAP_LEN, MbapHeader};
use crate::protocols::modbus::pdu::Response;
use crate::protocols::transport::{Attempt, AttemptError, Backoff, Endpoint, Guard, StreamLink};

/// Finds MBAP frames in a byte stream; with `length0`, a length field of 0 is read as "as
/// long as the PDU says" (the shelf PLC's habit).
pub(crate) struct MbapDecoder {
    pub length0: bool,
}

impl Decoder for MbapDecoder {
    type Item = (MbapHeader, BytesMut);
    type Error = AttemptError;

    fn decode(&mut self, src: &mut BytesMut) -> Result<Option<Self::Item>, AttemptError> {
        if src.len() < MBAP_LEN {
            return Ok(None);
        }
        let header = frame::decode_header(src).map_err(|e| AttemptError::Malformed(e.message()))?;
        let pdu_len = match header.length {
            0 if self.length0 => match response_pdu_len(&src[MBAP_LEN..]) {
                Ok(Some(n)) => n,
                Ok(None) => return Ok(None),
                Err(e) => return Err(AttemptError::Malformed(e.message())),
            },
            0 => return Err(AttemptError::Malformed(FrameError::BadLength.message())),
            n => n as usize - 1,
        };
        if src.len() < MBAP_LEN + pdu_len {
            return Ok(None);
        }
        src.advance(MBAP_LEN);
        Ok(Some((header, src.split_to(pdu_len))))
    }
}

/// A Modbus TCP connection to one device.
pub(crate) struct TcpLink {
    link: StreamLink,
    quirks: Quirks,
    counters: Arc<Counters>,
    /// Whether replies carry the transaction id ([`Replies::Named`]).
    named: bool,
    ids: RecentIds,
    tids: Vec<u16>,
    tx: Vec<u8>,
}

impl TcpLink {
    /// A link to `address` that connects on first use.
    pub fn new(address: String, quirks: Quirks, replies: Replies, counters: Arc<Counters>) -> Self {
        Self::over(Endpoint::Tcp(address), quirks, replies, counters)
    }

    /// A link over connections to `endpoint` (TCP, or dialled streams).
    pub fn over(endpoint: Endpoint, quirks: Quirks, replies: Replies, counters: Arc<Counters>) -> Self {
        TcpLink {
            // The device ends the connection itself: a new one carries nothing of the old.
            link: StreamLink::new(endpoint, Backoff::default(), Guard::of(replies, true)),
            quirks,
            counters,
            named: replies == Replies::Named,
            ids: RecentIds::new(),
            tids: Vec::new(),
            tx: Vec::new(),
        }
    }

    /// Records the link's frames into `recorder`.
    pub fn set_recorder(&mut self, recorder: Option<Arc<crate::capture::Recorder>>) {
        self.link.set_recorder(recorder);
    }

    /// Sends the request with a new transaction id.
    pub async fn send(&mut self, ex: &Exchange<'_>, attempt: &Attempt) -> Result<(), AttemptError> {
        if attempt.is_first() {
            self.tids.clear();
        }
        self.counters.settled(self.link.settle(attempt, ex.request.is_write()).await?);
        let tid = self.ids.next();
        self.tids.push(tid);
        self.tx.clear();
        frame::encode(&mut self.tx, tid, ex.unit, ex.pdu, LengthField::Standard);
        Counters::bump(&self.counters.sends);
        match self.link.send(&self.tx, attempt.timeout).await {
            // Half a frame on the stream: nothing after it could be trusted.
            Err(AttemptError::Timeout) => {
                self.link.reset();
                Err(AttemptError::Timeout)
            }
            sent => sent,
        }
    }

    /// Sends the request and reads frames until the one that answers it; with it, the
    /// number of the attempt whose transaction id it carries (none under the quirk).
    pub async fn attempt(
        &mut self,
        ex: &Exchange<'_>,
        attempt: &Attempt,
    ) -> Result<(Response, Option<u32>), AttemptError> {
        self.send(ex, attempt).await?;
        let attempt = &attempt.restarted();
        let mut decoder = MbapDecoder { length0: self.quirks.length0 };
        let mut reason = None;
        loop {
            let (header, pdu) = match self.link.read_frame(&mut decoder, attempt.deadline).await {
                Ok(Some(found)) => found,
                Ok(None) => return Err(timed_out(reason)),
                Err(e) => {
                    self.link.reset();
                    return Err(e);
                }
            };
            let verdict = judge_mbap(&header, &pdu, ex, &self.tids, self.named.then_some(&self.ids));
            self.link.judged(verdict.capture());
            match verdict {
                Verdict::Take(reply) => {
                    self.link.answered();
                    let answered = match self.named {
                        false => None,
                        true => self.tids.iter().position(|&t| t == header.transaction).map(|i| i as u32),
                    };
                    return taken(reply).map(|r| (r, answered));
                }
                Verdict::Fail(msg) => return Err(AttemptError::Malformed(msg)),
                Verdict::Drop(why, msg) => {
                    self.counters.dropped(why);
                    self.link.unsettle();
                    reason = msg.or(reason);
                }
            }
        }
    }
}
