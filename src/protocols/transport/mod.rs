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
//! - **Flushing and holding.** On the half-duplex lines (Modbus RTU on serial or over TCP,
//!   MEWTOCOL, PPI) a carrier cannot be reopened at will, so input already waiting is thrown
//!   away before each request, and a reply must match the request's station, command and
//!   length (a mismatch is dropped as stale, never taken as data). After an attempt timed
//!   out, and after a request that needed a retry, the line is also *held*: the next request
//!   goes out only once nothing has arrived for the configured timeout (not the adaptive
//!   one: the silence must cover every reply the configuration allows, so on these lines
//!   a retry waits as long as before the adaptive timer); whatever arrives meanwhile is
//!   read, dropped and counted as stale
//!   ([`StreamLink::settle`]). A late reply, and the duplicate answer to the retry it
//!   provoked, are so drained before the next request. What is left is a device whose reply
//!   comes later than `timeout_ms` of silence after everything else: no protocol
//!   without ids can tell that apart, and such a device needs a longer `timeout_ms`.
//!
//! # Adaptive timeouts and link health
//! Each client keeps one [`LinkHealth`] (see `health.rs` and `rtt.rs`): an RFC 6298
//! retransmission timer between `min_timeout_ms` and `timeout_ms`, a degraded flag with
//! hysteresis over recent requests, and counters ([`LinkStats`]) that the device status
//! shows. The retry loop feeds it; links report the replies they drop and why.
//!
//! # The flight recorder
//! A client given a [`crate::capture::Recorder`] hands it to its link and its health: the
//! links record every frame they write and read (`tap.rs`), the protocol gives each read
//! frame its verdict, and the retry loop marks retries and counts timeouts.

mod connection;
mod datagram;
mod endpoint;
mod health;
mod policy;
mod retry;
mod round_trips;
mod rtt;
mod scan;
mod server;
mod stream;
mod tap;

pub use connection::Backoff;
pub(crate) use datagram::DatagramLink;
pub use endpoint::{ByteStream, Endpoint};
pub(crate) use health::LinkHealth;
pub use health::LinkStats;
pub use policy::{LinkTuning, RetryPolicy};
pub(crate) use retry::{Attempt, AttemptError, Retry};
pub use round_trips::{BOUNDS as ROUND_TRIP_BOUNDS, RoundTrips};
pub use scan::Scan;
pub(crate) use scan::Scanner;
pub use server::StreamServer;
pub(crate) use server::spawn_tcp;
pub(crate) use stream::StreamLink;
pub(crate) use tap::{recorder_for, verdict_of};
