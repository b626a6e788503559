//! An MC 3E/4E link: one request frame out, its reply in, over TCP or UDP, under the shared
//! transport's retry policy and reconnect.
//!
//! 4E frames carry a serial number the reply echoes: a reply with another serial (a late
//! answer to an earlier request) is dropped and counted as a stale reply, over UDP and TCP
//! alike, and the wait goes on for the right one. Plain 3E frames carry no serial number:
//! their replies name no request ([`crate::protocols::Protocol::replies`]), and the link
//! keeps the transport's rule for such links before each send (`StreamLink::settle`,
//! `DatagramLink::settle`): after an exchange that was not answered (a timeout, a
//! malformed reply, a caller that gave up), the TCP connection is replaced, or the UDP
//! socket moves to a new ephemeral port (the old one kept bound until its replies are
//! past), so a late reply to the old request can never be read as the next request's
//! answer; then input already waiting is thrown away. Every reply is also checked for
//! shape (subheader, route echo, data length for the points requested, command in the
//! error information), and on TCP the reply's length field is never trusted past the
//! longest valid reply.
//!
//! With a fixed local UDP port (`udp_local`, as some Ethernet-module open settings
//! require) the port cannot be replaced: the link holds the socket until nothing has
//! arrived for the configured timeout instead, before the request after an unanswered one.
//!
//! An error reply (nonzero end code) may carry any number of bytes after the end code (see
//! [`super::response`]): on TCP its length field is allowed up to the longest reply any
//! command has, so the end code surfaces and the stream stays in step.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use tokio_util::bytes::BytesMut;
use tokio_util::codec::Decoder;

use super::end_code::EndCode;
use super::frame::{self, Direction, MAX_WORD_POINTS, Route};
use super::response::{ErrorInfo, Outcome, Response};
use crate::capture::{Limits, Verdict};
use crate::protocols::transport::{
    Attempt, AttemptError, Backoff, DatagramLink, Endpoint, Guard, LinkHealth, LinkTuning, Retry,
    RetryPolicy, StreamLink, recorder_for,
};
use crate::protocols::{DeviceCode, DropReason, PlcError, Replies};

/// TCP or UDP.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TransportKind {
    /// A TCP connection, kept open and re-opened when lost.
    Tcp,
    /// UDP datagrams.
    Udp,
}

/// How to reach a PLC and how hard to try.
#[derive(Clone, Debug)]
pub struct LinkConfig {
    /// `HOST:PORT` of the PLC's Ethernet module.
    pub address: String,
    /// TCP or UDP.
    pub transport: TransportKind,
    /// Time allowed for one attempt (connect, send, reply).
    pub timeout: Duration,
    /// Further attempts after the first fails with a timeout, a lost connection or a
    /// malformed reply (an end code is an answer and is never retried).
    pub retries: u32,
    /// The adaptive timeout's floor and when the link counts as degraded.
    pub tuning: LinkTuning,
    /// Waits between failed TCP connects.
    pub backoff: Backoff,
    /// Fixed local UDP address (None: a fresh ephemeral port after an exchange that was not
    /// answered).
    pub udp_local: Option<SocketAddr>,
    /// The flight recorder's bounds; `None` records nothing.
    pub capture: Option<Limits>,
}

/// What a valid reply looks like.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Expect {
    /// The 4E serial number the reply must echo (None: 3E).
    pub serial: Option<u16>,
    pub route: Route,
    pub command: (u16, u16),
    pub data_len: usize,
    /// The request changes the PLC's memory.
    pub write: bool,
}

/// The longest data an error reply may declare: end code plus the longest reply data of any
/// command (960 words).
const MAX_ERROR_DATA: usize = 2 + 2 * MAX_WORD_POINTS as usize;

/// Finds one 3E or 4E response in a TCP stream. The length field is checked against the
/// longest reply the request allows (an error reply: [`MAX_ERROR_DATA`]) before anything
/// more is waited for.
struct Responses {
    max_len: usize,
}

impl Decoder for Responses {
    type Item = BytesMut;
    type Error = AttemptError;

    fn decode(&mut self, src: &mut BytesMut) -> Result<Option<BytesMut>, AttemptError> {
        let not_a_reply = |_| AttemptError::Malformed("reply does not start with a 3E/4E response header");
        let Some(size) = src.get(..2).map(|s| frame::header_size_of(s, Direction::Response)) else {
            return Ok(None);
        };
        let size = size.map_err(not_a_reply)?;
        let Some(header) = src.get(..size) else { return Ok(None) };
        let len = frame::parse_any_header(header, Direction::Response).map_err(not_a_reply)?.length;
        if len > self.max_len {
            // Only an error reply may be longer than the request's answer.
            let Some(end_code) = src.get(size..size + 2) else { return Ok(None) };
            if end_code == [0, 0] || len > MAX_ERROR_DATA {
                return Err(AttemptError::Malformed("reply length field exceeds what the request allows"));
            }
        }
        Ok((src.len() >= size + len).then(|| src.split_to(size + len)))
    }
}

/// Why a reply is not this request's answer.
enum Mismatch {
    /// A 4E reply with another serial number: a late answer, dropped.
    Serial,
    /// Anything else.
    Other(&'static str),
}

impl Mismatch {
    /// What a capture shows for a TCP reply that does not fit: a serial number's mismatch
    /// is a stale reply, anything else fails the attempt as malformed.
    fn verdict_on_tcp(&self) -> Verdict {
        match self {
            Mismatch::Serial => Verdict::StaleReply,
            Mismatch::Other(_) => Verdict::Malformed,
        }
    }
}

/// The carrier of a link.
enum Carrier {
    Tcp(StreamLink),
    Udp(DatagramLink),
}

/// A connection (or socket) to one PLC with its retry policy and health.
pub(crate) struct Link {
    carrier: Carrier,
    health: Arc<LinkHealth>,
}

impl Link {
    /// A link for `config`, whose replies name their request (4E frames) or not (3E).
    pub fn new(config: LinkConfig, replies: Replies) -> Link {
        let described = match config.transport {
            TransportKind::Tcp => Endpoint::Tcp(config.address.clone()),
            TransportKind::Udp => Endpoint::Udp { peer: config.address.clone(), local: config.udp_local },
        };
        let recorder = recorder_for(config.capture, &described, None);
        let named = replies == Replies::Named;
        let carrier = match config.transport {
            TransportKind::Tcp => {
                // The module ends the connection itself: a new one carries nothing of the old.
                let mut link = StreamLink::new(described, config.backoff, Guard::of(replies, true));
                link.set_recorder(recorder.clone());
                Carrier::Tcp(link)
            }
            TransportKind::Udp => {
                let mut link = DatagramLink::new(config.address, config.udp_local, config.backoff, named);
                link.set_recorder(recorder.clone());
                Carrier::Udp(link)
            }
        };
        let policy = RetryPolicy { timeout: config.timeout, retries: config.retries, tuning: config.tuning };
        Link { carrier, health: Arc::new(LinkHealth::new(policy).recording(recorder)) }
    }

    /// A link over carriers the caller dials (the seeded wire simulation of the tests):
    /// connections over `TransportKind::Tcp`, datagram ports over `TransportKind::Udp`.
    pub fn over(
        config: &LinkConfig,
        replies: Replies,
        dial: Arc<dyn crate::protocols::transport::Dial>,
    ) -> Link {
        let endpoint = Endpoint::Dial(dial);
        let guard = Guard::of(replies, true);
        let carrier = match config.transport {
            TransportKind::Tcp => Carrier::Tcp(StreamLink::new(endpoint, config.backoff, guard)),
            TransportKind::Udp => Carrier::Udp(DatagramLink::over(endpoint, config.backoff, guard)),
        };
        let policy = RetryPolicy { timeout: config.timeout, retries: config.retries, tuning: config.tuning };
        Link { carrier, health: Arc::new(LinkHealth::new(policy)) }
    }

    /// The link's health, shared with the client (read without the link's lock).
    pub fn health(&self) -> Arc<LinkHealth> {
        self.health.clone()
    }

    /// Sends `frame` and returns the reply's data, retrying as configured.
    pub async fn exchange(&mut self, frame: &[u8], expect: &Expect) -> Result<Vec<u8>, PlcError> {
        let health = self.health.clone();
        let mut retry = Retry::start(&health, "mc3e");
        while let Some(attempt) = retry.next_attempt() {
            let outcome = match &mut self.carrier {
                Carrier::Tcp(link) => tcp_attempt(link, frame, expect, &health, &attempt).await,
                Carrier::Udp(link) => udp_attempt(link, frame, expect, &health, &attempt).await,
            };
            match outcome {
                Ok(Outcome::Ok(data)) => {
                    retry.succeeded();
                    return Ok(data);
                }
                Ok(Outcome::Failed { end_code, .. }) => {
                    retry.failed(AttemptError::Device(DeviceCode::Mc3e(EndCode(end_code))))?
                }
                Err(e) => retry.failed(e)?,
            }
        }
        Err(retry.spent())
    }
}

async fn tcp_attempt(
    link: &mut StreamLink,
    frame: &[u8],
    expect: &Expect,
    health: &LinkHealth,
    attempt: &Attempt,
) -> Result<Outcome, AttemptError> {
    health.settled(link.settle(attempt, expect.write).await?);
    link.send(frame, attempt.timeout).await?;
    let attempt = &attempt.restarted();
    let mut responses = Responses { max_len: 2 + expect.data_len.max(ErrorInfo::LEN) };
    loop {
        let Some(bytes) = link.read_frame(&mut responses, attempt.deadline).await? else {
            return Err(AttemptError::Timeout);
        };
        let checked = check(&bytes, expect);
        link.judged(checked.as_ref().map_or_else(Mismatch::verdict_on_tcp, |_| Verdict::Ok));
        match checked {
            Ok(outcome) => {
                link.answered();
                return Ok(outcome);
            }
            Err(Mismatch::Serial) => {
                tracing::debug!("mc4e tcp: dropped a reply with another serial number");
                health.dropped(DropReason::Stale);
            }
            Err(Mismatch::Other(why)) => {
                link.unsettle();
                return Err(AttemptError::Malformed(why));
            }
        }
    }
}

async fn udp_attempt(
    link: &mut DatagramLink,
    frame: &[u8],
    expect: &Expect,
    health: &LinkHealth,
    attempt: &Attempt,
) -> Result<Outcome, AttemptError> {
    health.settled(link.settle(attempt, expect.write).await?);
    link.send(frame, attempt.timeout).await?;
    let attempt = &attempt.restarted();
    loop {
        let Some(datagram) = link.recv(attempt.deadline).await? else { return Err(AttemptError::Timeout) };
        let checked = check(datagram, expect);
        link.judged(checked.as_ref().map_or(Verdict::StaleReply, |_| Verdict::Ok));
        match checked {
            Ok(outcome) => {
                link.answered();
                return Ok(outcome);
            }
            Err(Mismatch::Serial) => {
                tracing::debug!("mc4e udp: dropped a reply with another serial number");
                health.dropped(DropReason::Stale);
            }
            Err(Mismatch::Other(why)) => {
                tracing::debug!(why, "mc3e udp: discarded a datagram that is not this reply");
                health.dropped(DropReason::Stale);
                link.unsettle();
            }
        }
    }
}

/// Decodes a reply and checks it answers the expected request.
fn check(bytes: &[u8], expect: &Expect) -> Result<Outcome, Mismatch> {
    let other = Mismatch::Other;
    let response =
        Response::decode(bytes).map_err(|_| other("reply is not a well-formed 3E/4E binary response"))?;
    match (response.serial, expect.serial) {
        (Some(got), Some(sent)) if got != sent => return Err(Mismatch::Serial),
        (Some(_), Some(_)) | (None, None) => {}
        _ => return Err(other("reply's frame (3E or 4E) is not the request's")),
    }
    if response.route != expect.route {
        return Err(other("reply's route fields do not echo the request's"));
    }
    match &response.outcome {
        Outcome::Ok(data) if data.len() != expect.data_len => {
            Err(other("reply's data length does not match the points requested"))
        }
        Outcome::Failed { info: Some(info), .. } if (info.command, info.subcommand) != expect.command => {
            Err(other("error information names another command"))
        }
        Outcome::Failed { trailing, .. } => {
            if !trailing.is_empty() {
                tracing::debug!(
                    bytes = trailing.len(),
                    "mc3e: error reply with trailing data other than error information"
                );
            }
            Ok(response.outcome)
        }
        Outcome::Ok(_) => Ok(response.outcome),
    }
}
