//! Modbus UDP, client side: one MBAP frame per datagram, replies matched by transaction
//! id, unit and function.
//!
//! Every attempt gets a fresh transaction id; a reply carrying the id of *any* attempt of
//! the current request is taken (a retry's answer and a slow first answer are equally
//! good), while ids of earlier requests are stale and dropped. So a late reply after a
//! timeout is never taken for the answer to a newer request. Without ids (the
//! `ignore_transaction_id` quirk) datagrams already queued are flushed before each request.

use std::sync::Arc;

use super::{Counters, Exchange, Verdict, judge_mbap, taken, timed_out};
use crate::protocols::DropReason;
use crate::protocols::modbus::config::Quirks;
use crate::protocols::modbus::frame::{self, FrameError, LengthField};
use crate::protocols::modbus::pdu::Response;
use crate::protocols::transport::{Attempt, AttemptError, Backoff, DatagramLink};

/// A UDP link to one device.
pub(crate) struct UdpLink {
    link: DatagramLink,
    quirks: Quirks,
    counters: Arc<Counters>,
    next_tid: u16,
    tids: Vec<u16>,
    tx: Vec<u8>,
}

impl UdpLink {
    /// A link to `address` from an ephemeral local port, bound on first use.
    pub fn new(address: String, quirks: Quirks, counters: Arc<Counters>) -> Self {
        UdpLink {
            link: DatagramLink::new(address, None, Backoff::default()),
            quirks,
            counters,
            next_tid: rand::random(),
            tids: Vec::new(),
            tx: Vec::with_capacity(300),
        }
    }

    /// Binds the socket now, so a bad address is reported when the client is built.
    pub async fn open(&mut self, timeout: std::time::Duration) -> Result<(), AttemptError> {
        self.link.open(timeout).await
    }

    /// Records the link's frames into `recorder`.
    pub fn set_recorder(&mut self, recorder: Option<Arc<crate::capture::Recorder>>) {
        self.link.set_recorder(recorder);
    }

    /// Sends the request in a datagram with a new transaction id.
    pub async fn send(&mut self, ex: &Exchange<'_>, attempt: &Attempt) -> Result<(), AttemptError> {
        if attempt.is_first() {
            self.tids.clear();
            if self.quirks.ignore_transaction_id {
                let stale = self.link.flush_stale(attempt.timeout).await?;
                self.counters.dropped_n(DropReason::Stale, stale);
            }
        }
        let tid = self.next_tid;
        self.next_tid = self.next_tid.wrapping_add(1);
        self.tids.push(tid);
        self.tx.clear();
        frame::encode(&mut self.tx, tid, ex.unit, ex.pdu, LengthField::Standard);
        Counters::bump(&self.counters.sends);
        self.link.send(&self.tx, attempt.timeout).await
    }

    /// Sends the request and waits for the datagram that answers it; with it, the number
    /// of the attempt whose transaction id it carries (none under the quirk).
    pub async fn attempt(
        &mut self,
        ex: &Exchange<'_>,
        attempt: &Attempt,
    ) -> Result<(Response, Option<u32>), AttemptError> {
        self.send(ex, attempt).await?;
        let mut reason = None;
        loop {
            let Some(datagram) = self.link.recv(attempt.deadline).await? else {
                return Err(timed_out(reason));
            };
            let mut tid = None;
            let verdict = match frame::split_datagram(datagram, self.quirks.length0) {
                Ok((header, pdu)) => {
                    tid = Some(header.transaction);
                    judge_mbap(&header, pdu, ex, &self.tids, self.quirks.ignore_transaction_id)
                }
                // A standard length field of 0: what the `length0` quirk takes.
                Err(FrameError::BadLength) if datagram.get(4..6) == Some(&[0, 0]) => {
                    Verdict::Drop(DropReason::LengthZero, None)
                }
                // Datagrams are independent: a broken one is dropped, the right one may follow.
                Err(e) => Verdict::Drop(DropReason::Malformed, Some(e.message())),
            };
            self.link.judged(verdict.capture());
            match verdict {
                Verdict::Take(reply) => {
                    let answered = match self.quirks.ignore_transaction_id {
                        true => None,
                        false => tid.and_then(|t| self.tids.iter().position(|&x| x == t)).map(|i| i as u32),
                    };
                    return taken(reply).map(|r| (r, answered));
                }
                Verdict::Fail(msg) => return Err(AttemptError::Malformed(msg)),
                Verdict::Drop(why, msg) => {
                    self.counters.dropped(why);
                    reason = msg.or(reason);
                }
            }
        }
    }
}
