//! The client side of each Modbus framing: send one request, wait for its reply.
//!
//! A [`Link`] performs single *attempts* over the shared transport
//! ([`crate::protocols::transport`]); [`super::ModbusClient`] runs them under the one retry
//! policy. Each attempt either returns the decoded reply that answers this request, or says
//! why not. Datagrams or frames that do not answer this request (stale transaction id, other
//! unit) are dropped and counted, in the client's counters and in the link's health with a
//! [`DropReason`]. Without a transaction id to go by (RTU, and MBAP with the
//! `no-transaction-id` quirk), the transport's rule keeps late replies off the link before
//! each send (`StreamLink::settle`, `DatagramLink::settle`), and a reply that does not match
//! the request anyway (another function, a byte count other than the request's, a write
//! echo of another address or quantity) is dropped and counted as stale, never data.

mod rtu;
mod tcp;
mod udp;

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

pub(crate) use rtu::RtuLink;
pub(crate) use tcp::TcpLink;
pub(crate) use udp::UdpLink;

use super::decode::{DecodeError, decode_response};
use super::exception::Exception;
use super::frame::MbapHeader;
use super::pdu::{Request, Response};
use crate::capture::Recorder;
use crate::protocols::transport::{Attempt, AttemptError, LinkHealth, verdict_of};
pub(crate) use crate::protocols::transport::{RecentIds, Settled};
use crate::protocols::{DeviceCode, DropReason};

/// A decoded reply: data, or the device's exception.
pub(crate) type Reply = Result<Response, Exception>;

/// One request as the links see it.
pub(crate) struct Exchange<'a> {
    /// Unit id addressed.
    pub unit: u8,
    /// The request, for matching and decoding the reply.
    pub request: &'a Request,
    /// The request's encoded PDU.
    pub pdu: &'a [u8],
}

/// Counters shared by a client and its link, and the link's health.
#[derive(Debug)]
pub(crate) struct Counters {
    pub requests: AtomicU64,
    pub sends: AtomicU64,
    pub dropped: AtomicU64,
    pub health: LinkHealth,
}

impl Counters {
    /// Zero counters and a fresh health under `health`'s policy.
    pub fn new(health: LinkHealth) -> Self {
        Counters { requests: AtomicU64::new(0), sends: AtomicU64::new(0), dropped: AtomicU64::new(0), health }
    }

    pub fn bump(counter: &AtomicU64) {
        counter.fetch_add(1, Ordering::Relaxed);
    }

    /// A frame or datagram dropped for `reason`.
    pub fn dropped(&self, reason: DropReason) {
        self.dropped_n(reason, 1);
    }

    /// `n` frames or datagrams dropped for `reason`.
    pub fn dropped_n(&self, reason: DropReason, n: u64) {
        self.dropped.fetch_add(n, Ordering::Relaxed);
        self.health.dropped_n(reason, n);
    }

    /// What the link did before a send ([`crate::protocols::transport::StreamLink::settle`]):
    /// the replies it dropped are stale, and the time it held the line is no round trip.
    pub fn settled(&self, settled: Settled) {
        self.dropped.fetch_add(settled.replies, Ordering::Relaxed);
        self.health.settled(settled);
    }
}

/// The link a client owns.
pub(crate) enum Link {
    Udp(UdpLink),
    Tcp(TcpLink),
    Rtu(RtuLink),
}

impl Link {
    /// Records the link's frames into `recorder`.
    pub fn set_recorder(&mut self, recorder: Option<Arc<Recorder>>) {
        match self {
            Link::Udp(l) => l.set_recorder(recorder),
            Link::Tcp(l) => l.set_recorder(recorder),
            Link::Rtu(l) => l.set_recorder(recorder),
        }
    }

    /// Sends the request and waits until the attempt's deadline for its reply. With the
    /// reply, the number of the attempt it answers when its transaction id says so (for an
    /// unambiguous round trip), `None` when it cannot be told.
    pub async fn attempt(
        &mut self,
        ex: &Exchange<'_>,
        attempt: &Attempt,
    ) -> Result<(Response, Option<u32>), AttemptError> {
        match self {
            Link::Udp(l) => l.attempt(ex, attempt).await,
            Link::Tcp(l) => l.attempt(ex, attempt).await,
            Link::Rtu(l) => l.attempt(ex, attempt).await.map(|r| (r, None)),
        }
    }

    /// Sends the request without awaiting a reply (broadcast).
    pub async fn send_only(&mut self, ex: &Exchange<'_>, attempt: &Attempt) -> Result<(), AttemptError> {
        match self {
            Link::Udp(l) => l.send(ex, attempt).await,
            Link::Tcp(l) => l.send(ex, attempt).await,
            // A broadcast is never answered: nothing is owed for it.
            Link::Rtu(l) => l.send(ex, attempt).await.map(|()| l.answered()),
        }
    }
}

/// What to do with a frame that arrived while waiting for a reply.
pub(crate) enum Verdict {
    /// It answers the request.
    Take(Reply),
    /// It is not ours: drop it and keep waiting. The message, if any, is kept for the
    /// attempt's report (a malformed reply rather than a timeout).
    Drop(DropReason, Option<&'static str>),
    /// It claims to answer the request but is wrong.
    Fail(&'static str),
}

impl Verdict {
    /// What a capture shows for the frame so judged.
    pub fn capture(&self) -> crate::capture::Verdict {
        match self {
            Verdict::Take(_) => crate::capture::Verdict::Ok,
            Verdict::Drop(why, _) => verdict_of(*why),
            Verdict::Fail(_) => crate::capture::Verdict::Malformed,
        }
    }
}

/// Judges an MBAP frame against the request and the transaction ids of its attempts.
/// `ids` is the link's ids when its replies carry them: an id of an earlier request of the
/// link is a stale reply, any other id not the request's a foreign one. Without them
/// (`None`, the `no-transaction-id` quirk) the id is not looked at.
pub(crate) fn judge_mbap(
    header: &MbapHeader,
    pdu: &[u8],
    ex: &Exchange<'_>,
    tids: &[u16],
    ids: Option<&RecentIds>,
) -> Verdict {
    match ids {
        Some(ids) if !tids.contains(&header.transaction) => {
            let why =
                if ids.ours(header.transaction) { DropReason::Stale } else { DropReason::TransactionId };
            Verdict::Drop(why, None)
        }
        _ => judge(header.unit, pdu, ex, ids.is_none()),
    }
}

/// Judges a frame's unit and PDU against the request. Without a transaction id to go by
/// (`loose`), a reply that answers another request (function, byte count, write echo) is
/// taken for a stale one and dropped.
pub(crate) fn judge(unit: u8, pdu: &[u8], ex: &Exchange<'_>, loose: bool) -> Verdict {
    if unit != ex.unit {
        return Verdict::Drop(DropReason::Unit, Some("reply from the wrong unit"));
    }
    match decode_response(pdu, ex.request) {
        Ok(reply) => Verdict::Take(reply),
        Err(
            e @ (DecodeError::FunctionMismatch | DecodeError::ByteCountMismatch | DecodeError::EchoMismatch),
        ) if loose => Verdict::Drop(DropReason::Stale, Some(e.message())),
        Err(e) => Verdict::Fail(e.message()),
    }
}

/// The attempt's outcome for a reply that answers the request: an exception is the
/// device's answer, final for the request.
pub(crate) fn taken(reply: Reply) -> Result<Response, AttemptError> {
    reply.map_err(|e| AttemptError::Device(DeviceCode::Modbus(e)))
}

/// The error for an attempt that timed out after dropping frames for `reason`.
pub(crate) fn timed_out(reason: Option<&'static str>) -> AttemptError {
    reason.map_or(AttemptError::Timeout, AttemptError::Malformed)
}
