//! Modbus RTU, client side, over any byte stream: a serial port, a pty, or raw TCP to a
//! serial-to-Ethernet gateway.
//!
//! Before sending, input left over from earlier exchanges (late replies, noise) is thrown
//! away and the line must have been quiet for 3.5 characters. While waiting, the buffer is
//! scanned for the first frame with a valid CRC ([`rtu::scan`]), so garbage before a reply
//! is skipped. RTU has no transaction id: a reply is matched by unit, function, byte count
//! and write echo. A reply so late that it arrives after the *next* request has gone out
//! cannot be told from that request's answer when function and size agree: RTU itself has
//! no way to tell, so keep the timeout above the device's worst reply time on such links.

use std::sync::Arc;
use std::time::Duration;

use futures::FutureExt;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::time::Instant;

use super::{AttemptError, Connection, Counters, Exchange, Reply, Verdict, judge, timed_out};
use crate::protocols::modbus::rtu::{self, Direction};

/// An RTU link to one device (or one bus).
pub(crate) struct RtuLink {
    conn: Connection,
    silence: Duration,
    counters: Arc<Counters>,
    last_io: Instant,
    tx: Vec<u8>,
    rx: Vec<u8>,
}

impl RtuLink {
    /// A link that opens `conn` on first use and keeps `silence` between frames.
    pub fn new(conn: Connection, silence: Duration, counters: Arc<Counters>) -> Self {
        RtuLink { conn, silence, counters, last_io: Instant::now(), tx: Vec::new(), rx: Vec::new() }
    }

    /// Flushes stale input, waits for the inter-frame silence and sends the request.
    pub async fn send(&mut self, ex: &Exchange<'_>, timeout: Duration) -> Result<(), AttemptError> {
        self.tx.clear();
        rtu::encode(&mut self.tx, ex.unit, ex.pdu);
        let stream = self.conn.get(timeout).await?;
        let mut discarded = false;
        loop {
            match stream.read_buf(&mut self.rx).now_or_never() {
                Some(Ok(n)) if n > 0 => {
                    discarded = true;
                    self.rx.clear();
                    self.last_io = Instant::now();
                }
                Some(Ok(_)) => return Err(self.lost(std::io::ErrorKind::UnexpectedEof.into())),
                Some(Err(e)) => return Err(self.lost(e)),
                None => break,
            }
        }
        if discarded {
            Counters::bump(&self.counters.dropped);
        }
        self.rx.clear();
        tokio::time::sleep_until(self.last_io + self.silence).await;
        let stream = self.conn.get(timeout).await?;
        Counters::bump(&self.counters.sends);
        let written = async {
            stream.write_all(&self.tx).await?;
            stream.flush().await
        };
        match tokio::time::timeout(timeout, written).await {
            Ok(Ok(())) => {
                self.last_io = Instant::now();
                Ok(())
            }
            Ok(Err(e)) => Err(self.lost(e)),
            Err(_) => Err(AttemptError::Timeout),
        }
    }

    /// Sends the request and waits for a valid frame that answers it.
    pub async fn attempt(&mut self, ex: &Exchange<'_>, timeout: Duration) -> Result<Reply, AttemptError> {
        let deadline = Instant::now() + timeout;
        self.send(ex, timeout).await?;
        let mut reason = None;
        loop {
            while let Some(found) = rtu::scan(&self.rx, Direction::Response) {
                let verdict = judge(found.unit(&self.rx), found.pdu(&self.rx), ex, false);
                self.rx.drain(..found.start + found.len);
                match verdict {
                    Verdict::Take(reply) => return Ok(reply),
                    Verdict::Fail(msg) => return Err(AttemptError::Malformed(msg)),
                    Verdict::Drop(why) => {
                        Counters::bump(&self.counters.dropped);
                        reason = why.or(reason);
                    }
                }
            }
            if self.rx.len() > 2 * rtu::MAX_FRAME {
                self.rx.drain(..self.rx.len() - rtu::MAX_FRAME);
            }
            let stream = self.conn.get(timeout).await?;
            match tokio::time::timeout_at(deadline, stream.read_buf(&mut self.rx)).await {
                Err(_) if !self.rx.is_empty() && reason.is_none() => {
                    return Err(AttemptError::Malformed(
                        "no frame with a valid CRC (CRC error or noise on the line)",
                    ));
                }
                Err(_) => return Err(timed_out(reason)),
                Ok(Ok(0)) => return Err(self.lost(std::io::ErrorKind::UnexpectedEof.into())),
                Ok(Ok(_)) => self.last_io = Instant::now(),
                Ok(Err(e)) => return Err(self.lost(e)),
            }
        }
    }

    fn lost(&mut self, e: std::io::Error) -> AttemptError {
        self.conn.reset();
        self.rx.clear();
        AttemptError::Io(e)
    }
}
