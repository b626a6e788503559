//! Byte-stream carriers (TCP, serial) and reconnection with backoff, in one place.

use std::io;
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncWrite};
use tokio::net::TcpStream;
use tokio::time::Instant;

use super::AttemptError;
use crate::protocols::serial::SerialSettings;

/// Any byte stream a Modbus link can run over (TCP socket, serial port, pty).
pub trait ByteStream: AsyncRead + AsyncWrite + Unpin + Send {}

impl<T: AsyncRead + AsyncWrite + Unpin + Send> ByteStream for T {}

/// Where a stream comes from.
pub(crate) enum Endpoint {
    /// A TCP connection to `HOST:PORT`.
    Tcp(String),
    /// A serial port.
    Serial(String, SerialSettings),
    /// A stream handed over by the caller; it cannot be reopened once lost.
    Given(Option<Box<dyn ByteStream>>),
}

/// First wait before reconnecting after a failed connect.
const BACKOFF_START: Duration = Duration::from_millis(100);
/// Longest wait between reconnects.
const BACKOFF_MAX: Duration = Duration::from_secs(5);

/// A stream that is (re)opened on demand, with exponential backoff after failed opens.
pub(crate) struct Connection {
    endpoint: Endpoint,
    stream: Option<Box<dyn ByteStream>>,
    backoff: Duration,
    retry_at: Option<Instant>,
    last_error: Option<(io::ErrorKind, String)>,
}

impl Connection {
    /// A connection that opens `endpoint` when first used.
    pub fn new(endpoint: Endpoint) -> Self {
        Connection { endpoint, stream: None, backoff: BACKOFF_START, retry_at: None, last_error: None }
    }

    /// The open stream, opening it first if needed. A reconnect waits out the backoff, unless
    /// that wait is longer than `timeout`: then it fails at once with the last open error.
    pub async fn get(&mut self, timeout: Duration) -> Result<&mut Box<dyn ByteStream>, AttemptError> {
        if self.stream.is_none() {
            if let Some(at) = self.retry_at {
                if at > Instant::now() + timeout {
                    let (kind, msg) =
                        self.last_error.clone().unwrap_or((io::ErrorKind::NotConnected, String::new()));
                    return Err(AttemptError::Io(io::Error::new(
                        kind,
                        format!("{msg} (waiting to reconnect)"),
                    )));
                }
                tokio::time::sleep_until(at).await;
            }
            match tokio::time::timeout(timeout, self.open()).await {
                Ok(Ok(stream)) => {
                    self.stream = Some(stream);
                    self.backoff = BACKOFF_START;
                    self.retry_at = None;
                }
                Ok(Err(e)) => return Err(self.failed(e)),
                Err(_) => {
                    return Err(self.failed(io::Error::new(io::ErrorKind::TimedOut, "connect timed out")));
                }
            }
        }
        self.stream.as_mut().ok_or(AttemptError::Timeout)
    }

    /// Forgets the stream after an error; the next [`Connection::get`] reopens it.
    pub fn reset(&mut self) {
        self.stream = None;
    }

    fn failed(&mut self, e: io::Error) -> AttemptError {
        self.retry_at = Some(Instant::now() + self.backoff);
        self.backoff = (self.backoff * 2).min(BACKOFF_MAX);
        self.last_error = Some((e.kind(), e.to_string()));
        AttemptError::Io(e)
    }

    async fn open(&mut self) -> io::Result<Box<dyn ByteStream>> {
        match &mut self.endpoint {
            Endpoint::Tcp(address) => {
                let stream = TcpStream::connect(address.as_str()).await?;
                stream.set_nodelay(true)?;
                Ok(Box::new(stream))
            }
            Endpoint::Serial(path, settings) => Ok(Box::new(settings.open(path)?)),
            Endpoint::Given(stream) => stream.take().ok_or_else(|| {
                io::Error::new(
                    io::ErrorKind::NotConnected,
                    "the given stream was closed and cannot be reopened",
                )
            }),
        }
    }
}
