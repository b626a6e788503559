//! The transport layer under every protocol: where a device is ([`Endpoint`]), the
//! connection to it and its reconnect ([`Backoff`]), byte-stream and datagram links, and the
//! one retry policy ([`RetryPolicy`]).
//!
//! # What a transport is
//! A *carrier* moves bytes: a TCP connection, a UDP socket, a serial port, or a stream the
//! caller opened (a pty in tests). A *link* is a carrier plus the few operations a client
//! needs on it: flush stale input, send a request, and wait until a deadline for the reply
//! (a datagram, or a frame that the protocol's [`Decoder`](tokio_util::codec::Decoder) finds
//! in the byte stream). A *client* (Modbus, MC 3E, MEWTOCOL, PPI) owns one link behind a
//! mutex, so requests to one device go one at a time, as the devices expect.
//!
//! Simulators serving a byte-stream protocol over TCP or one stream run as a
//! [`StreamServer`].
//!
//! Connections open on first use and reopen after a loss, with one exponential backoff, so
//! a device that is off when rackd starts does not stop it and is not hammered while off.
//!
//! # Where retries happen, and why only there
//! Each client runs every request through [`RetryPolicy`]: `retries + 1` attempts of
//! `timeout` each, a device's own error code returned at once (it answered), timeouts, lost
//! connections and malformed replies tried again. Nothing above the client retries a
//! request (device adapters only poll again on their next cycle), and nothing below it
//! does, so the attempts and the time a caller can wait are what the configuration says.
//!
//! # Why a late reply cannot be mistaken for the next answer
//! A reply that arrives after its request timed out (or after the caller gave up on it)
//! must never be read as the answer to a later request. Each protocol uses the strongest
//! defence its frames allow:
//! - **Ids.** Modbus TCP and UDP give every attempt a new transaction id, PPI a new PDU
//!   reference; a reply is taken only if it carries the id of an attempt of the current
//!   request (a retry's answer and a slow first answer are equally good), anything else is
//!   dropped and counted.
//! - **A fresh carrier.** MC 3E (no serial number in 3E frames) and Modbus TCP with the
//!   `no-transaction-id` quirk run *exclusive* exchanges: after an exchange that did not
//!   finish (timed out, malformed, or abandoned by its caller), the TCP connection is
//!   closed, or the UDP socket rebound on a new port, before the next request, so the late
//!   reply lands on a closed socket.
//! - **Flushing.** On the half-duplex lines (Modbus RTU, MEWTOCOL, PPI) a carrier cannot be
//!   reopened at will, so input already waiting is thrown away before each request, and a
//!   reply must match the request's station, command and length. A reply so late that it
//!   arrives after the *next* request went out cannot be told apart when those agree: the
//!   protocols have no way to, so such links need a timeout above the device's worst reply
//!   time (see each protocol's module docs).

mod connection;
mod datagram;
mod endpoint;
mod retry;
mod server;
mod stream;

pub use connection::Backoff;
pub(crate) use datagram::DatagramLink;
pub use endpoint::{ByteStream, Endpoint};
pub use retry::RetryPolicy;
pub(crate) use retry::{Attempt, AttemptError};
pub use server::StreamServer;
pub(crate) use server::spawn_tcp;
pub(crate) use stream::StreamLink;
