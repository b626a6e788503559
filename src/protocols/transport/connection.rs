//! A connection that opens its endpoint on first use and reopens it after a loss, waiting
//! longer after each failed open: the one reconnect of every protocol.

use std::io;
use std::time::Duration;

use tokio::time::Instant;

use super::endpoint::{ByteStream, Carrier, DatagramPort, Endpoint};
use super::retry::AttemptError;
use super::tap::Tap;

/// How long to wait before reopening after failed opens: `first` after one failure, doubling
/// after each further one up to `max`, back to `first` after a success. A device that is off
/// is not hammered, and one that comes back is found within `max`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Backoff {
    /// The wait after the first failed open.
    pub first: Duration,
    /// The longest wait.
    pub max: Duration,
}

impl Default for Backoff {
    /// 100 ms doubling to 5 s.
    fn default() -> Self {
        Backoff { first: Duration::from_millis(100), max: Duration::from_secs(5) }
    }
}

/// An endpoint and, while it is open, its carrier.
pub(crate) struct Connection {
    endpoint: Endpoint,
    carrier: Option<Carrier>,
    backoff: Backoff,
    /// The wait after the next failed open.
    next_wait: Duration,
    /// No open before this instant (after a failed one).
    retry_at: Option<Instant>,
    last_error: Option<(io::ErrorKind, String)>,
    /// The flight recorder of the link, told of each new socket pair.
    pub tap: Tap,
}

impl Connection {
    /// A connection that opens `endpoint` when first used.
    pub fn new(endpoint: Endpoint, backoff: Backoff) -> Self {
        Connection {
            endpoint,
            carrier: None,
            backoff,
            next_wait: backoff.first,
            retry_at: None,
            last_error: None,
            tap: Tap::default(),
        }
    }

    /// The open byte stream, opening it first if needed (see [`Connection::open`]).
    pub async fn stream(&mut self, timeout: Duration) -> Result<&mut Box<dyn ByteStream>, AttemptError> {
        match self.open(timeout).await? {
            Carrier::Stream(stream) => Ok(stream),
            Carrier::Datagram(_) => Err(not_a("byte stream")),
        }
    }

    /// The open datagram port, opening it first if needed (see [`Connection::open`]).
    pub async fn datagram(&mut self, timeout: Duration) -> Result<&dyn DatagramPort, AttemptError> {
        match self.open(timeout).await? {
            Carrier::Datagram(socket) => Ok(&**socket),
            Carrier::Stream(_) => Err(not_a("datagram socket")),
        }
    }

    /// The carrier, opened first if needed. A reopen waits out the backoff unless that wait
    /// is longer than `timeout`: then it fails at once with the last open error, so a
    /// request to a device that is off fails in its own time, not the backoff's.
    async fn open(&mut self, timeout: Duration) -> Result<&mut Carrier, AttemptError> {
        if self.carrier.is_none() {
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
            match tokio::time::timeout(timeout, self.endpoint.open()).await {
                Ok(Ok((carrier, pair))) => {
                    if let Some((transport, local, remote)) = pair {
                        self.tap.opened(transport, local, remote);
                    }
                    self.carrier = Some(carrier);
                    self.next_wait = self.backoff.first;
                    self.retry_at = None;
                }
                Ok(Err(e)) => return Err(self.failed(e)),
                Err(_) => {
                    return Err(self.failed(io::Error::new(io::ErrorKind::TimedOut, "connect timed out")));
                }
            }
        }
        self.carrier.as_mut().ok_or(AttemptError::Timeout)
    }

    /// Closes the carrier after an error; the next use reopens it.
    pub fn reset(&mut self) {
        self.carrier = None;
    }

    /// Takes the open carrier away, if any, without closing it (a datagram port kept
    /// bound while replies to it may still come); the next use opens a new one.
    pub fn take(&mut self) -> Option<Carrier> {
        self.carrier.take()
    }

    fn failed(&mut self, e: io::Error) -> AttemptError {
        self.retry_at = Some(Instant::now() + self.next_wait);
        self.next_wait = (self.next_wait * 2).min(self.backoff.max);
        self.last_error = Some((e.kind(), e.to_string()));
        AttemptError::Io(e)
    }
}

fn not_a(what: &str) -> AttemptError {
    AttemptError::Io(io::Error::other(format!("the endpoint does not give a {what}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A socket on the test's device port: `SO_REUSEPORT`, so that the device can listen
    /// on the port while the test holds it bound (and not listening: connections refused),
    /// and nothing else takes the port meanwhile.
    fn shared_port() -> tokio::net::TcpSocket {
        let socket = tokio::net::TcpSocket::new_v4().unwrap();
        socket.set_reuseport(true).unwrap();
        socket
    }

    #[tokio::test]
    async fn failed_opens_back_off_and_a_success_resets_the_wait() {
        let held = shared_port();
        held.bind("127.0.0.1:0".parse().unwrap()).unwrap();
        let address = held.local_addr().unwrap().to_string();
        let backoff = Backoff { first: Duration::from_millis(100), max: Duration::from_millis(300) };
        let mut conn = Connection::new(Endpoint::Tcp(address.clone()), backoff);
        let timeout = Duration::from_millis(150);
        // The wait counts from the failed open, which comes after this.
        let before = Instant::now();
        assert!(matches!(conn.stream(timeout).await, Err(AttemptError::Io(_))));
        // The wait (100 ms) fits the timeout: it is waited out, and the open fails again.
        assert!(conn.stream(timeout).await.is_err());
        assert!(Instant::now() - before >= Duration::from_millis(100));
        // Now 200 ms: longer than the timeout, so it fails at once, saying why.
        let before = Instant::now();
        match conn.stream(timeout).await {
            Err(AttemptError::Io(e)) => assert!(e.to_string().contains("waiting to reconnect"), "{e}"),
            Err(other) => panic!("{other:?}"),
            Ok(_) => panic!("nothing listens"),
        }
        assert!(Instant::now() - before < Duration::from_millis(50), "no wait");
        assert_eq!(conn.next_wait, Duration::from_millis(300), "capped at max");
        // The device is back: an open whose wait fits its timeout waits and connects.
        let device = shared_port();
        device.bind(held.local_addr().unwrap()).unwrap();
        let listener = device.listen(16).unwrap();
        assert!(conn.stream(Duration::from_secs(1)).await.is_ok());
        assert_eq!(conn.next_wait, backoff.first, "a success resets the wait");
        drop(listener);
    }
}
