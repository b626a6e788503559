//! Modbus UDP, client side: one MBAP frame per datagram, replies matched by transaction
//! id, unit and function.
//!
//! Every attempt gets a fresh transaction id; a reply carrying the id of *any* attempt of
//! the current request is taken (a retry's answer and a slow first answer are equally
//! good), while ids of earlier requests are stale and dropped ([`RecentIds`] tells them
//! from ids this link never sent, which are foreign). So a late reply after a timeout is
//! never taken for the answer to a newer request. Without ids (the `no-transaction-id`
//! quirk: the replies name no request) the link keeps the transport's rule before each
//! send ([`DatagramLink::settle`]): after an attempt that was not answered the request goes
//! out from a new port, the old one kept bound until its replies are past.

use std::sync::Arc;

use super::{Counters, Exchange, RecentIds, Verdict, judge_mbap, taken, timed_out};
use crate::protocols::modbus::config::Quirks;
use crate::protocols::modbus::frame::{self, FrameError, LengthField};
use crate::protocols::modbus::pdu::Response;
use crate::protocols::transport::{Attempt, AttemptError, Backoff, DatagramLink};
use crate::protocols::{DropReason, Replies};

/// A UDP link to one device.
pub(crate) struct UdpLink {
    link: DatagramLink,
    quirks: Quirks,
    counters: Arc<Counters>,
    /// Whether replies carry the transaction id ([`Replies::Named`]).
    named: bool,
    ids: RecentIds,
    tids: Vec<u16>,
    tx: Vec<u8>,
}

impl UdpLink {
    /// A link to `address` from an ephemeral local port, bound on first use.
    pub fn new(address: String, quirks: Quirks, replies: Replies, counters: Arc<Counters>) -> Self {
        let named = replies == Replies::Named;
        Self::over(DatagramLink::new(address, None, Backoff::default(), named), quirks, replies, counters)
    }

    /// A link over `link` (a UDP socket or a simulated one).
    pub fn over(link: DatagramLink, quirks: Quirks, replies: Replies, counters: Arc<Counters>) -> Self {
        UdpLink {
            link,
            quirks,
            counters,
            named: replies == Replies::Named,
            ids: RecentIds::new(),
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
        }
        self.counters.settled(self.link.settle(attempt, ex.request.is_write()).await?);
        let tid = self.ids.next();
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
        let attempt = &attempt.restarted();
        let mut reason = None;
        loop {
            let Some(datagram) = self.link.recv(attempt.deadline).await? else {
                return Err(timed_out(reason));
            };
            let mut tid = None;
            let verdict = match frame::split_datagram(datagram, self.quirks.length0) {
                Ok((header, pdu)) => {
                    tid = Some(header.transaction);
                    judge_mbap(&header, pdu, ex, &self.tids, self.named.then_some(&self.ids))
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
                    self.link.answered();
                    let answered = match self.named {
                        false => None,
                        true => tid.and_then(|t| self.tids.iter().position(|&x| x == t)).map(|i| i as u32),
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
