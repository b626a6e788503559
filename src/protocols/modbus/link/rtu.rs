//! Modbus RTU, client side, over any byte stream: a serial port, a pty, or raw TCP to a
//! serial-to-Ethernet gateway.
//!
//! Before sending, input left over from earlier exchanges (late replies, noise) is thrown
//! away and the line must have been quiet for 3.5 characters. While waiting, the buffer is
//! scanned for the first frame with a valid CRC ([`RtuDecoder`]), so garbage before a reply
//! is skipped. RTU has no transaction id: a reply is matched by unit, function, byte count
//! and write echo. A reply so late that it arrives after the *next* request has gone out
//! cannot be told from that request's answer when function and size agree: RTU itself has
//! no way to tell, so keep the timeout above the device's worst reply time on such links.

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
    /// A link over `link` that keeps `silence` between frames.
    pub fn new(link: StreamLink, silence: Duration, counters: Arc<Counters>) -> Self {
        RtuLink { link, silence, counters, tx: Vec::new() }
    }

    /// Flushes stale input, waits for the inter-frame silence and sends the request.
    pub async fn send(&mut self, ex: &Exchange<'_>, attempt: &Attempt) -> Result<(), AttemptError> {
        self.tx.clear();
        rtu::encode(&mut self.tx, ex.unit, ex.pdu);
        if self.link.flush_stale(attempt.timeout).await? {
            Counters::bump(&self.counters.dropped);
        }
        tokio::time::sleep_until(self.link.last_io() + self.silence).await;
        Counters::bump(&self.counters.sends);
        self.link.send(&self.tx, attempt.timeout).await
    }

    /// Sends the request and waits for a valid frame that answers it.
    pub async fn attempt(&mut self, ex: &Exchange<'_>, attempt: &Attempt) -> Result<Response, AttemptError> {
        self.send(ex, attempt).await?;
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
            match judge(unit, &pdu, ex, false) {
                Verdict::Take(reply) => return taken(reply),
                Verdict::Fail(msg) => return Err(AttemptError::Malformed(msg)),
                Verdict::Drop(why) => {
                    Counters::bump(&self.counters.dropped);
                    reason = why.or(reason);
                }
            }
        }
    }
}
