//! The client side of a half-duplex line: one request at a time over one byte stream.
//!
//! Neither MEWTOCOL-COM nor PPI numbers its frames in a way every device echoes, so the
//! defence against late replies is here: before each request, input already waiting (a late
//! reply to an earlier, timed-out request, or line noise) is read and thrown away.

use std::io;
use std::time::Duration;

use futures::FutureExt;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::time::Instant;

use crate::protocols::PlcError;
use crate::protocols::modbus::transport::{AttemptError, Connection, Endpoint};

/// The largest input kept while waiting for a frame; more is noise and is cut.
const MAX_BUFFER: usize = 8192;

/// A byte-stream link to one device, opened on first use and reopened after a loss.
pub(crate) struct LineLink {
    conn: Connection,
    /// Bytes received and not yet consumed by the protocol's scanner.
    pub rx: Vec<u8>,
    /// Chunks of stale input thrown away so far.
    pub flushed: u64,
}

impl LineLink {
    /// A link over `endpoint`.
    pub fn new(endpoint: Endpoint) -> Self {
        LineLink { conn: Connection::new(endpoint), rx: Vec::new(), flushed: 0 }
    }

    /// Throws away input already waiting (stale replies, noise), then sends `bytes`.
    pub async fn send_fresh(&mut self, bytes: &[u8], timeout: Duration) -> Result<(), AttemptError> {
        self.rx.clear();
        let stream = self.conn.get(timeout).await?;
        let mut scratch = Vec::new();
        loop {
            match stream.read_buf(&mut scratch).now_or_never() {
                Some(Ok(n)) if n > 0 => {
                    self.flushed += 1;
                    scratch.clear();
                }
                Some(Ok(_)) => return Err(self.lost(io::ErrorKind::UnexpectedEof.into())),
                Some(Err(e)) => return Err(self.lost(e)),
                None => break,
            }
        }
        self.send(bytes, timeout).await
    }

    /// Sends `bytes` without flushing input (the second step of a two-step exchange).
    pub async fn send(&mut self, bytes: &[u8], timeout: Duration) -> Result<(), AttemptError> {
        let stream = self.conn.get(timeout).await?;
        let written = async {
            stream.write_all(bytes).await?;
            stream.flush().await
        };
        match tokio::time::timeout(timeout, written).await {
            Ok(Ok(())) => Ok(()),
            Ok(Err(e)) => Err(self.lost(e)),
            Err(_) => Err(AttemptError::Timeout),
        }
    }

    /// Reads more input into [`LineLink::rx`]; `Ok(false)` when `deadline` passed first.
    pub async fn fill(&mut self, deadline: Instant) -> Result<bool, AttemptError> {
        if self.rx.len() > MAX_BUFFER {
            self.rx.drain(..self.rx.len() - MAX_BUFFER / 2);
        }
        let stream = self.conn.get(Duration::ZERO).await?;
        match tokio::time::timeout_at(deadline, stream.read_buf(&mut self.rx)).await {
            Err(_) => Ok(false),
            Ok(Ok(0)) => Err(self.lost(io::ErrorKind::UnexpectedEof.into())),
            Ok(Ok(_)) => Ok(true),
            Ok(Err(e)) => Err(self.lost(e)),
        }
    }

    fn lost(&mut self, e: io::Error) -> AttemptError {
        self.conn.reset();
        self.rx.clear();
        AttemptError::Io(e)
    }
}

/// The error a request reports once its attempts are spent.
pub(crate) fn attempt_error(e: AttemptError, attempts: u32, timeout: Duration) -> PlcError {
    match e {
        AttemptError::Timeout => PlcError::Timeout { attempts, timeout },
        AttemptError::Io(e) => PlcError::Connection(e),
        AttemptError::Malformed(msg) => PlcError::Malformed(msg),
    }
}
