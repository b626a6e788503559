//! Where a link meets its flight recorder ([`crate::capture::Recorder`]): every frame a
//! link writes, and every frame or run of bytes it reads, is recorded once, here.
//!
//! Decisions:
//! - **At the links, not in the protocols.** [`super::StreamLink`] and
//!   [`super::DatagramLink`] own a tap, so every protocol on them is recorded by the same
//!   few lines: a send, a datagram or decoded frame, input thrown away by a flush or while
//!   the line is held, and bytes a decoder refused or skipped as noise.
//! - **The verdict comes from the protocol.** A link reads a frame before its protocol
//!   judges it, so the frame waits in the tap until the protocol says what it was
//!   ([`Tap::judged`]: taken, or dropped for a [`DropReason`]). A frame nobody judged
//!   (one a protocol skips without a word, such as an RS-485 echo) is recorded without a
//!   verdict when the link next reads or writes; its time is when it was read either way.
//! - **Verdicts follow the link's counters** ([`super::LinkStats`]), so a capture and the
//!   counters agree: another transaction id or PDU reference is a foreign reply, another
//!   unit a wrong unit (both counted as foreign), a stale reply stale, a length-0 or
//!   undecodable reply malformed. Input thrown away before a request or while the line is
//!   held is a stale reply, one frame per burst, as the counters count it.
//! - **The attempt** (retry number, and what the previous attempt ended with) is set on
//!   the recorder by the retry loop ([`super::Retry`]), which also counts timeouts there.
//! - **Endpoints.** When a connection opens (first use, a reconnect, a UDP socket rebound
//!   after an unfinished exclusive exchange) the tap gives the recorder the new socket pair.

use std::net::SocketAddr;
use std::sync::Arc;

use crate::capture::{Annotations, Direction, Limits, Link, Recorder, SerialProtocol, Transport, Verdict};
use crate::protocols::DropReason;

use super::Endpoint;

/// A recorder for a link to `endpoint`, when `limits` are given. `line` names the protocol
/// of a byte stream that is not IP-native (Modbus RTU, MEWTOCOL, PPI): such a link is
/// recorded as a serial one even through a TCP gateway, so the file opens with the
/// protocol's dissector; an IP-native protocol's link starts with unspecified addresses,
/// filled in when it connects.
pub(crate) fn recorder_for(
    limits: Option<Limits>,
    endpoint: &Endpoint,
    line: Option<SerialProtocol>,
) -> Option<Arc<Recorder>> {
    let unspecified = SocketAddr::from(([0, 0, 0, 0], 0));
    let ip = |transport, address: &str| Link::Ip {
        transport,
        local: unspecified,
        remote: address.parse().unwrap_or(unspecified),
    };
    let link = match (endpoint, line) {
        (Endpoint::Tcp(address), Some(protocol)) => Link::Serial { protocol, port: format!("tcp {address}") },
        (Endpoint::Serial { path, .. }, Some(protocol)) => Link::Serial { protocol, port: path.clone() },
        (Endpoint::Given(_) | Endpoint::Dial(_), Some(protocol)) => {
            Link::Serial { protocol, port: "stream".into() }
        }
        (Endpoint::Tcp(address), None) => ip(Transport::Tcp, address),
        (Endpoint::Udp { peer, .. }, _) => ip(Transport::Udp, peer),
        // No IP-native protocol runs on a serial port or a given stream.
        (Endpoint::Serial { path, .. }, None) => {
            Link::Serial { protocol: SerialProtocol::ModbusRtu, port: path.clone() }
        }
        (Endpoint::Dial(_), None) => ip(Transport::Udp, "0.0.0.0:0"),
        (Endpoint::Given(_), None) => {
            Link::Serial { protocol: SerialProtocol::ModbusRtu, port: "stream".into() }
        }
    };
    limits.map(|limits| Recorder::new(link, limits))
}

/// The verdict a capture shows for a reply dropped for `reason`.
pub(crate) fn verdict_of(reason: DropReason) -> Verdict {
    match reason {
        DropReason::TransactionId | DropReason::PduReference => Verdict::ForeignReply,
        DropReason::Unit => Verdict::WrongUnit,
        DropReason::Stale => Verdict::StaleReply,
        DropReason::LengthZero | DropReason::Malformed => Verdict::Malformed,
    }
}

/// A link's recorder, if it has one, and the frame it read last. The tap's buffers are
/// kept from frame to frame: recording allocates nothing once they have grown.
#[derive(Default)]
pub(crate) struct Tap {
    recorder: Option<Arc<Recorder>>,
    /// When the frame read last and not yet judged came, if there is one.
    unjudged_at: Option<u64>,
    /// Its bytes.
    unjudged: Vec<u8>,
    /// The input a decoder is looking at ([`Tap::look`]).
    seen: Vec<u8>,
}

impl Tap {
    /// A tap into `recorder` (none: nothing is recorded, at the cost of a branch).
    pub fn new(recorder: Option<Arc<Recorder>>) -> Tap {
        Tap { recorder, ..Tap::default() }
    }

    /// The recorder, if any.
    pub fn recorder(&self) -> Option<&Arc<Recorder>> {
        self.recorder.as_ref()
    }

    /// True when frames are recorded.
    pub fn on(&self) -> bool {
        self.recorder.is_some()
    }

    /// A connection opened between `local` and `remote`.
    pub fn opened(&self, transport: Transport, local: SocketAddr, remote: SocketAddr) {
        if let Some(r) = &self.recorder {
            // A line protocol carried over TCP by a gateway keeps its serial link.
            if matches!(r.link(), Link::Ip { .. }) {
                r.set_link(Link::Ip { transport, local, remote });
            }
        }
    }

    /// `bytes` were sent.
    pub fn sent(&mut self, bytes: &[u8]) {
        self.settle_unjudged();
        if let Some(r) = &self.recorder {
            r.record(Direction::Sent, bytes, Annotations::default());
        }
    }

    /// A frame was read; it is recorded once judged ([`Tap::judged`]).
    pub fn read(&mut self, bytes: &[u8]) {
        if let Some(time_us) = self.recorder.as_ref().map(|r| r.now_us()) {
            self.settle_unjudged();
            self.unjudged.clear();
            self.unjudged.extend_from_slice(bytes);
            self.unjudged_at = Some(time_us);
        }
    }

    /// Keeps a copy of the input a decoder is about to consume, so that what it takes is
    /// recorded afterwards ([`Tap::seen_frame`], [`Tap::seen_discarded`]).
    pub fn look(&mut self, input: &[u8]) {
        if self.on() {
            self.seen.clear();
            self.seen.extend_from_slice(input);
        }
    }

    /// The first `n` bytes looked at were a frame: recorded once judged, as [`Tap::read`].
    pub fn seen_frame(&mut self, n: usize) {
        if let Some(time_us) = self.recorder.as_ref().map(|r| r.now_us()) {
            self.settle_unjudged();
            std::mem::swap(&mut self.unjudged, &mut self.seen);
            self.unjudged.truncate(n);
            self.unjudged_at = Some(time_us);
        }
    }

    /// The first `n` bytes looked at (all of them, at most) were thrown away as `verdict`.
    pub fn seen_discarded(&mut self, n: usize, verdict: Verdict) {
        self.settle_unjudged();
        if let Some(r) = &self.recorder {
            let annotations = Annotations { verdict: Some(verdict), ..Annotations::default() };
            r.record(Direction::Received, &self.seen[..n.min(self.seen.len())], annotations);
        }
    }

    /// The protocol judged the frame read last.
    pub fn judged(&mut self, verdict: Verdict) {
        if let (Some(r), Some(time_us)) = (&self.recorder, self.unjudged_at.take()) {
            let annotations = Annotations { verdict: Some(verdict), ..Annotations::default() };
            r.record_at(time_us, Direction::Received, &self.unjudged, annotations);
        }
    }

    /// Bytes read and thrown away by the link itself, recorded at once with `verdict`;
    /// `time_us` is when the first of them came.
    pub fn discarded(&mut self, time_us: u64, bytes: &[u8], verdict: Verdict) {
        self.settle_unjudged();
        if let Some(r) = &self.recorder {
            let annotations = Annotations { verdict: Some(verdict), ..Annotations::default() };
            r.record_at(time_us, Direction::Received, bytes, annotations);
        }
    }

    /// Now on the recorder's clock (0 without one).
    pub fn now_us(&self) -> u64 {
        self.recorder.as_ref().map_or(0, |r| r.now_us())
    }

    /// Records a frame read and never judged, without a verdict.
    fn settle_unjudged(&mut self) {
        if let (Some(r), Some(time_us)) = (&self.recorder, self.unjudged_at.take()) {
            r.record_at(time_us, Direction::Received, &self.unjudged, Annotations::default());
        }
    }
}
