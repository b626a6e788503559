//! The client side of each Modbus framing: send one request, wait for its reply.
//!
//! A [`Link`] performs single *attempts* over the shared transport
//! ([`crate::protocols::transport`]); [`super::ModbusClient`] runs them under the one retry
//! policy. Each attempt either returns the decoded reply that answers this request, or says
//! why not. Datagrams or frames that do not answer this request (stale transaction id, other
//! unit) are dropped and counted.

mod rtu;
mod tcp;
mod udp;

use std::sync::atomic::{AtomicU64, Ordering};

pub(crate) use rtu::RtuLink;
pub(crate) use tcp::TcpLink;
pub(crate) use udp::UdpLink;

use super::decode::{DecodeError, decode_response};
use super::exception::Exception;
use super::frame::MbapHeader;
use super::pdu::{Request, Response};
use crate::protocols::DeviceCode;
use crate::protocols::transport::{Attempt, AttemptError};

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

/// Counters shared by a client and its link.
#[derive(Debug, Default)]
pub(crate) struct Counters {
    pub requests: AtomicU64,
    pub sends: AtomicU64,
    pub dropped: AtomicU64,
}

impl Counters {
    pub fn bump(counter: &AtomicU64) {
        counter.fetch_add(1, Ordering::Relaxed);
    }
}

/// The link a client owns.
pub(crate) enum Link {
    Udp(UdpLink),
    Tcp(TcpLink),
    Rtu(RtuLink),
}

impl Link {
    /// Sends the request and waits until the attempt's deadline for its reply.
    pub async fn attempt(&mut self, ex: &Exchange<'_>, attempt: &Attempt) -> Result<Response, AttemptError> {
        match self {
            Link::Udp(l) => l.attempt(ex, attempt).await,
            Link::Tcp(l) => l.attempt(ex, attempt).await,
            Link::Rtu(l) => l.attempt(ex, attempt).await,
        }
    }

    /// Sends the request without awaiting a reply (broadcast).
    pub async fn send_only(&mut self, ex: &Exchange<'_>, attempt: &Attempt) -> Result<(), AttemptError> {
        match self {
            Link::Udp(l) => l.send(ex, attempt).await,
            Link::Tcp(l) => l.send(ex, attempt).await,
            Link::Rtu(l) => l.send(ex, attempt).await,
        }
    }
}

/// What to do with a frame that arrived while waiting for a reply.
pub(crate) enum Verdict {
    /// It answers the request.
    Take(Reply),
    /// It is not ours: drop it and keep waiting; the reason is kept for the timeout report.
    Drop(Option<&'static str>),
    /// It claims to answer the request but is wrong.
    Fail(&'static str),
}

/// Judges an MBAP frame against the request and the transaction ids of its attempts.
pub(crate) fn judge_mbap(
    header: &MbapHeader,
    pdu: &[u8],
    ex: &Exchange<'_>,
    tids: &[u16],
    ignore_tid: bool,
) -> Verdict {
    if !ignore_tid && !tids.contains(&header.transaction) {
        return Verdict::Drop(None);
    }
    judge(header.unit, pdu, ex, ignore_tid)
}

/// Judges a frame's unit and PDU against the request. Without a transaction id to go by
/// (`loose`), a reply to another function is taken for a stale one and dropped.
pub(crate) fn judge(unit: u8, pdu: &[u8], ex: &Exchange<'_>, loose: bool) -> Verdict {
    if unit != ex.unit {
        return Verdict::Drop(Some("reply from the wrong unit"));
    }
    match decode_response(pdu, ex.request) {
        Ok(reply) => Verdict::Take(reply),
        Err(DecodeError::FunctionMismatch) if loose => {
            Verdict::Drop(Some("function code in the reply differs from the request"))
        }
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
