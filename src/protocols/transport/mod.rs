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
//! must never be read as the answer to a later request. Whether a link's replies name their
//! request is decided in one place, [`crate::protocols::Protocol::replies`], from the
//! protocol *and* the quirks; every defence below, the adaptive timeout's floor
//! ([`LinkTuning::for_replies`]), Karn's rule on round trips and whether a dropped reply is
//! counted stale or foreign ask it.
//!
//! **Links whose replies name their request** (Modbus TCP and UDP with transaction ids,
//! MC 4E with serial numbers): every attempt gets a new id; a reply is taken only if it
//! carries the id of an attempt of the current request (a retry's answer and a slow first
//! answer are equally good). A reply with the id of an earlier request of this link is
//! dropped as *stale*; one with an id this link never sent as *foreign* (another master, or
//! a rackd before a restart).
//!
//! **Links whose replies name no request** (Modbus RTU on a line or over TCP, Modbus TCP
//! and UDP with `no-transaction-id`, MC 3E, MEWTOCOL, PPI) keep one rule, in the links
//! ([`StreamLink::settle`], [`DatagramLink::settle`], bookkeeping in `owed.rs`):
//!
//! > A request goes out only on a carrier on which no earlier request can still be
//! > answered. Until then the link either replaces the carrier by one that carries nothing
//! > of the old, or holds it until nothing has arrived for the reply lifetime `L`.
//!
//! The model it is proved under, and which every site must meet:
//! 1. *Lifetime.* A device answers a request, if at all, within `L` = the link's configured
//!    `timeout_ms` of its sending (the adaptive timeout only decides when to retry; it
//!    never shortens `L`). A reply later than that is one no protocol without ids can tell
//!    from the next answer: such a device needs a longer `timeout_ms`.
//! 2. *Copies travel together.* A frame the network or a device duplicates arrives with its
//!    original (back to back: a flooding switch, a loop, a device answering twice), not
//!    an arbitrary time later. A network that holds copies back needs ids.
//! 3. A request is answered at most once per copy of it that reaches the device.
//!
//! The bookkeeping: a link *owes* a reply while a request it sent has not been answered (it
//! timed out, failed, or its caller gave up on it), after a retry, after a reply that was
//! not the request's, and from the start (see "Requests under way" below). Before each
//! send, while it owes:
//! - **Replace** (a TCP connection the device itself ends: Modbus TCP, MC 3E; a UDP socket
//!   on an ephemeral port): a new connection never receives the old one's bytes; a new UDP
//!   port receives nothing sent to the old, which stays bound ("retired", drained and
//!   counted stale) until `L` after its last send, so no one else is given its number.
//! - **Wait** (a serial line; a TCP connection to a serial gateway, which hands whatever the
//!   line brings to whichever connection is open; a UDP socket on a fixed port; the first
//!   request of any link): the carrier is read and everything arriving dropped until it
//!   has been quiet for `L` since the last thing sent or received.
//!
//! Then input already waiting is thrown away (copies that came with their originals), and
//! on the half-duplex lines the replies are also checked for station, command and length.
//!
//! The argument (for replies; the same holds for late writes reaching the device, with
//! "the device" for "the carrier"). Let `R` be a request sent at time `t`. (a) Before `t`
//! the link owed nothing, or it replaced the carrier, or it held it quiet for `L`. If it owed nothing,
//! every earlier request was answered one for one, and by 2 and 3 no further copy of an
//! earlier reply exists beyond the ones that arrived with their originals, which the flush
//! threw away. If it replaced the carrier, nothing sent for an earlier request can reach
//! the new one. If it held, the last earlier send was at least `L` before `t`, so by 1
//! every earlier reply has arrived (and been dropped) or never will. (b) So any reply that
//! arrives on the carrier after `t` answers an attempt of `R`, and all of `R`'s attempts
//! ask the same thing: taking it is right. (c) The next request finds `R` answered one for
//! one, or owing, and (a) applies again. Retries keep to the rule too: an attempt that was
//! not answered is owed, so a retry replaces the carrier or waits (on a half-duplex line
//! the wait also keeps the retry from talking over a late reply).
//!
//! **Requests under way.** The rule above is about replies; a *request* can be late too.
//! A write whose attempt was never answered may still reach the device after a later
//! request, and undo it (a late "state 0" into a slot the PLC has started; a late "task
//! id 4" into a slot rackd has since cleared, which the PLC runs again). On a carrier that
//! keeps its order (a line, one TCP connection) it cannot overtake; across a new
//! connection or a new UDP port, and on datagrams at all, it can. So on every link,
//! whether its replies name their request or not, such a write is waited out (`L` of
//! quiet) before the next request; the write's own retries go at once, since they write
//! the same. A process before this one (rackd killed mid-write and started again, a
//! standby that took over) may have left writes under way too: every link, ids or not,
//! starts *cold*, and its first request waits `L` of quiet. A read that is never answered
//! needs nothing of this: a late read changes nothing.
//!
//! What it costs: nothing while requests are answered; a new connection or socket, or one
//! `L` of silence, after a timeout (after a timed-out write always the silence); one `L`
//! when a link starts. That is why such links get a 20 ms floor under their
//! adaptive timeout (a spurious timeout is not cheap there) and named ones 2 ms. A line
//! that never falls silent is held at most four `L`, then used anyway (the flush and the
//! reply checks still apply): another master on the line is outside the model.
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
mod ids;
mod owed;
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
pub use endpoint::{
    ByteStream, Carrier, DatagramPort, DatagramServerPort, Dial, Dialing, Endpoint, recv_from, send_to,
};
pub use health::LinkStats;
pub(crate) use health::{LinkHealth, Settled};
pub(crate) use ids::RecentIds;
pub(crate) use owed::Guard;
pub use policy::{LinkTuning, RetryPolicy};
pub(crate) use retry::{Attempt, AttemptError, Retry};
pub use round_trips::{BOUNDS as ROUND_TRIP_BOUNDS, RoundTrips};
pub use scan::Scan;
pub(crate) use scan::Scanner;
pub use server::StreamServer;
pub(crate) use server::spawn_tcp;
pub(crate) use stream::StreamLink;
pub(crate) use tap::{recorder_for, verdict_of};
