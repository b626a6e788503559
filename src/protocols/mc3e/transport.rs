//! The one place where timeouts, retries, reconnection and stale-reply defences live.
//!
//! Plain 3E frames carry no serial number, so a reply cannot be matched to its request by
//! content alone. The defences:
//! - one request in flight per link (the client holds the link's lock for the exchange);
//! - TCP: after a timeout or any malformed reply the connection is closed, so a late reply
//!   can never be read as the answer to the next request; reconnection backs off
//!   exponentially between `reconnect_min` and `reconnect_max`;
//! - UDP: before each send, datagrams already waiting are drained and discarded; every
//!   datagram is checked for shape (subheader, route echo, data length for the points
//!   requested, command in the error information) and discarded if it does not fit; after
//!   a timeout the socket is closed and the next attempt binds a new ephemeral port, so a
//!   late reply to the old request lands on a closed port.
//!
//! Limitation (UDP with a fixed local port, `udp_local`, as some Ethernet-module open
//! settings require): a late reply that arrives after the drain and has the same shape as
//! the new request's reply (same command and point count) cannot be told apart and will be
//! taken. Use ephemeral ports, or TCP, where this matters.

use std::net::SocketAddr;
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpStream, UdpSocket};
use tokio::time::{Instant, timeout_at};

use super::end_code;
use super::frame::{self, RESPONSE_SUBHEADER, Route};
use super::response::{ErrorInfo, Outcome, Response};
use crate::protocols::PlcError;

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
    /// First delay before reconnecting after a failed TCP connect.
    pub reconnect_min: Duration,
    /// Longest delay between TCP connect attempts.
    pub reconnect_max: Duration,
    /// Fixed local UDP address (None: a fresh ephemeral port after each timeout).
    pub udp_local: Option<SocketAddr>,
}

/// What a valid reply looks like.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Expect {
    pub route: Route,
    pub command: (u16, u16),
    pub data_len: usize,
}

enum Failure {
    Timeout,
    Io(std::io::Error),
    Malformed(&'static str),
}

/// A connection (or socket) to one PLC with its retry state.
pub(crate) struct Link {
    config: LinkConfig,
    tcp: Option<TcpStream>,
    udp: Option<UdpSocket>,
    connect_failures: u32,
    next_connect: Option<Instant>,
}

impl Link {
    pub fn new(config: LinkConfig) -> Link {
        Link { config, tcp: None, udp: None, connect_failures: 0, next_connect: None }
    }

    /// Sends `frame` and returns the reply's data, retrying as configured.
    pub async fn exchange(&mut self, frame: &[u8], expect: &Expect) -> Result<Vec<u8>, PlcError> {
        let attempts = self.config.retries.saturating_add(1);
        let mut last = PlcError::Timeout { attempts, timeout: self.config.timeout };
        for attempt in 1..=attempts {
            let deadline = Instant::now() + self.config.timeout;
            let result = match self.config.transport {
                TransportKind::Tcp => self.tcp_attempt(frame, expect, deadline).await,
                TransportKind::Udp => self.udp_attempt(frame, expect, deadline).await,
            };
            let failure = match result {
                Ok(Outcome::Ok(data)) => return Ok(data),
                Ok(Outcome::Failed { end_code, .. }) => return Err(end_code::to_error(end_code)),
                Err(failure) => failure,
            };
            // Whatever went wrong, the attempt dropped its connection or socket (it may
            // still deliver a late reply); the next attempt opens a new one.
            last = match failure {
                Failure::Timeout => PlcError::Timeout { attempts: attempt, timeout: self.config.timeout },
                Failure::Io(e) => PlcError::Connection(e),
                Failure::Malformed(what) => PlcError::Malformed(what),
            };
            tracing::debug!(address = %self.config.address, attempt, error = %last, "mc3e attempt failed");
        }
        Err(last)
    }

    async fn tcp_attempt(
        &mut self,
        frame: &[u8],
        expect: &Expect,
        deadline: Instant,
    ) -> Result<Outcome, Failure> {
        // The stream stays out of `self` until a valid reply is read: if this future is
        // dropped mid-exchange, the stream is dropped (closed) with it and a reply still in
        // flight can never be read by the next request.
        let mut stream = match self.tcp.take() {
            Some(stream) => stream,
            None => self.connect(deadline).await?,
        };
        let outcome = timeout_at(deadline, tcp_exchange(&mut stream, frame, expect))
            .await
            .map_err(|_| Failure::Timeout)??;
        self.tcp = Some(stream);
        Ok(outcome)
    }

    async fn connect(&mut self, deadline: Instant) -> Result<TcpStream, Failure> {
        if let Some(at) = self.next_connect {
            tokio::time::sleep_until(at.min(deadline)).await;
        }
        let result = timeout_at(deadline, TcpStream::connect(self.config.address.as_str())).await;
        match result {
            Ok(Ok(stream)) => {
                let _ = stream.set_nodelay(true);
                self.connect_failures = 0;
                self.next_connect = None;
                Ok(stream)
            }
            failed => {
                self.connect_failures = self.connect_failures.saturating_add(1);
                let doubling = 2u32.saturating_pow(self.connect_failures - 1);
                let delay = self.config.reconnect_min.saturating_mul(doubling).min(self.config.reconnect_max);
                self.next_connect = Some(Instant::now() + delay);
                Err(match failed {
                    Ok(Err(e)) => Failure::Io(e),
                    _ => Failure::Timeout,
                })
            }
        }
    }

    async fn udp_attempt(
        &mut self,
        frame: &[u8],
        expect: &Expect,
        deadline: Instant,
    ) -> Result<Outcome, Failure> {
        // As for TCP, the socket is put back only after a valid reply.
        let socket = match self.udp.take() {
            Some(socket) => socket,
            None => self.udp_socket().await?,
        };
        let mut buf = vec![0u8; 8192];
        while let Ok(stale) = socket.try_recv(&mut buf) {
            tracing::debug!(bytes = stale, "mc3e udp: discarded a stale datagram");
        }
        socket.send(frame).await.map_err(Failure::Io)?;
        loop {
            let len = timeout_at(deadline, socket.recv(&mut buf))
                .await
                .map_err(|_| Failure::Timeout)?
                .map_err(Failure::Io)?;
            match check(&buf[..len], expect) {
                Ok(outcome) => {
                    self.udp = Some(socket);
                    return Ok(outcome);
                }
                Err(why) => tracing::debug!(why, "mc3e udp: discarded a datagram that is not this reply"),
            }
        }
    }

    async fn udp_socket(&self) -> Result<UdpSocket, Failure> {
        let peer = tokio::net::lookup_host(self.config.address.as_str())
            .await
            .map_err(Failure::Io)?
            .next()
            .ok_or(Failure::Malformed("address resolves to nothing"))?;
        let local = self.config.udp_local.unwrap_or_else(|| match peer {
            SocketAddr::V4(_) => SocketAddr::from(([0, 0, 0, 0], 0)),
            SocketAddr::V6(_) => SocketAddr::from(([0u16; 8], 0)),
        });
        let socket = UdpSocket::bind(local).await.map_err(Failure::Io)?;
        // A connected socket only receives datagrams from the PLC's address.
        socket.connect(peer).await.map_err(Failure::Io)?;
        Ok(socket)
    }
}

/// One request and its reply over a TCP stream.
async fn tcp_exchange(stream: &mut TcpStream, frame: &[u8], expect: &Expect) -> Result<Outcome, Failure> {
    stream.write_all(frame).await.map_err(Failure::Io)?;
    let mut header = [0u8; frame::HEADER_LEN];
    stream.read_exact(&mut header).await.map_err(Failure::Io)?;
    let (_, len) = frame::parse_header(&header, RESPONSE_SUBHEADER)
        .map_err(|_| Failure::Malformed("reply does not start with a 3E response header"))?;
    // Never trust the length field: read no more than the longest valid reply.
    if len > 2 + expect.data_len.max(ErrorInfo::LEN) {
        return Err(Failure::Malformed("reply length field exceeds what the request allows"));
    }
    let mut bytes = header.to_vec();
    bytes.resize(frame::HEADER_LEN + len, 0);
    stream.read_exact(&mut bytes[frame::HEADER_LEN..]).await.map_err(Failure::Io)?;
    check(&bytes, expect).map_err(Failure::Malformed)
}

/// Decodes a reply and checks it answers the expected request.
fn check(bytes: &[u8], expect: &Expect) -> Result<Outcome, &'static str> {
    let response = Response::decode(bytes).map_err(|_| "reply is not a well-formed 3E binary response")?;
    if response.route != expect.route {
        return Err("reply's route fields do not echo the request's");
    }
    match &response.outcome {
        Outcome::Ok(data) if data.len() != expect.data_len => {
            Err("reply's data length does not match the points requested")
        }
        Outcome::Failed { info: Some(info), .. } if (info.command, info.subcommand) != expect.command => {
            Err("error information names another command")
        }
        _ => Ok(response.outcome),
    }
}
