//! Modbus RTU, client side, over any byte stream: a serial port, a pty, or raw TCP to a
//! serial-to-Ethernet gateway.
//!
//! Before sending, input left over from earlier exchanges (late replies, noise) is thrown
//! away and the line must have been quiet for 3.5 characters. While waiting, the buffer is
//! scanned for the first frame with a valid CRC ([`RtuDecoder`]), so garbage before a reply
//! is skipped. RTU has no transaction id: a reply is matched by unit, function, byte count
//! and write echo, and one that does not match is dropped as stale (never taken as data).
//! While a reply may be owed (a timeout, a retry, a caller that gave up) the line is held
//! silent for the configured timeout before the next request, the transport's rule for
//! links whose replies name no request ([`StreamLink::settle`]), so a late reply and the
//! duplicate answer to the retry it provoked are drained, not read as the next request's
//! answer (tokio-modbus #324). RTU over TCP is a line too: a serial gateway hands the late
//! reply to whichever connection is open, so a new connection does not clear it. A reply
//! later than the configured timeout still cannot be told from the next answer when
//! function and size agree: RTU has no way to, so keep the timeout above the device's
//! worst reply time on such links.

use std::sync::Arc;
use std::time::Duration;

use tokio_util::bytes::{Buf, BytesMut};
use tokio_util::codec::Decoder;

use super::{Counters, Exchange, Verdict, judge, taken, timed_out};
use crate::protocols::modbus::pdu::Response;
use crate::protocols::modbus::rtu::{self, Direction};
use crate::protocols::transport::{Attempt, AttemptError, StreamLink};

/// Finds RTU frames with a valid CRC in a byte stream, skipping whatever comes before them;
/// yields the unit and the PDU.
pub(crate) struct RtuDecoder {
    /// Which way the frames travel (this decides how a frame's length is worked out).
    pub direction: Direction,
}

impl Decoder for RtuDecoder {
    type Item = (u8, BytesMut);
    type Error = AttemptError;

    fn decode(&mut self, src: &mut BytesMut) -> Result<Option<Self::Item>, AttemptError> {
        let Some(found) = rtu::scan(src, self.direction) else {
            // No frame starts in the older bytes any more; keep what a frame could still use.
            if src.len() > 2 * rtu::MAX_FRAME {
                src.advance(src.len() - rtu::MAX_FRAME);
            }
            return Ok(None);
        };
        let unit = found.unit(src);
        src.advance(found.start + 1);
        let pdu = src.split_to(found.len - 3);
        src.advance(2);
        Ok(Some((unit, pdu)))
    }
}

/// An RTU link to one device (or one bus).
pub(crate) struct RtuLink {
    link: StreamLink,
    silence: Duration,
    counters: Arc<Counters>,
    tx: Vec<u8>,
}

impl RtuLink {
    /// Records the link's frames into `recorder`.
    pub fn set_recorder(&mut self, recorder: Option<Arc<crate::capture::Recorder>>) {
        self.link.set_recorder(recorder);
    }

    /// A link over `link` that keeps `silence` between frames.
    pub fn new(link: StreamLink, silence: Duration, counters: Arc<Counters>) -> Self {
        RtuLink { link, silence, counters, tx: Vec::new() }
    }

    /// Keeps the transport's rule (holds the line while a reply may be owed, flushes stale
    /// input), waits for the inter-frame silence and sends the request.
    pub async fn send(&mut self, ex: &Exchange<'_>, attempt: &Attempt) -> Result<(), AttemptError> {
        self.tx.clear();
        rtu::encode(&mut self.tx, ex.unit, ex.pdu);
        self.counters.settled(self.link.settle(attempt, ex.request.is_write()).await?);
        tokio::time::sleep_until(self.link.last_io() + self.silence).await;
        Counters::bump(&self.counters.sends);
        self.link.send(&self.tx, attempt.timeout).await
    }

    /// Nothing is owed for the request sent last (a broadcast, which is never answered).
    pub fn answered(&mut self) {
        self.link.answered();
    }

    /// Sends the request and waits for a valid frame that answers it.
    pub async fn attempt(&mut self, ex: &Exchange<'_>, attempt: &Attempt) -> Result<Response, AttemptError> {
        self.send(ex, attempt).await?;
        let attempt = &attempt.restarted();
        let mut decoder = RtuDecoder { direction: Direction::Response };
        let mut reason = None;
        loop {
            let Some((unit, pdu)) = self.link.read_frame(&mut decoder, attempt.deadline).await? else {
                if self.link.buffered() > 0 && reason.is_none() {
                    return Err(AttemptError::Malformed(
                        "no frame with a valid CRC (CRC error or noise on the line)",
                    ));
                }
                return Err(timed_out(reason));
            };
            let verdict = judge(unit, &pdu, ex, true);
            self.link.judged(verdict.capture());
            match verdict {
                Verdict::Take(reply) => {
                    self.link.answered();
                    return taken(reply);
                }
                Verdict::Fail(msg) => {
                    self.link.unsettle();
                    return Err(AttemptError::Malformed(msg));
                }
                Verdict::Drop(why, msg) => {
                    self.counters.dropped(why);
                    self.link.unsettle();
                    reason = msg.or(reason);
                }
            }
        }
    }
}
