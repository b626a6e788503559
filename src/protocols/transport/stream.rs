//! A link over a byte stream (TCP, serial port, a caller's stream): send a request, find
//! the reply's frame in the bytes that come back.
//!
//! Finding a frame is the protocol's [`Decoder`]: it consumes noise and frames that are not
//! whole yet stay buffered. The link owns the buffer, the read loop against the attempt's
//! deadline, and the flush of stale input that the half-duplex lines (and Modbus without
//! transaction ids) rely on.
//!
//! On a link whose replies name no request, [`StreamLink::settle`] keeps the transport's
//! rule before each send ([`super::owed`]): while a reply may still be owed, it opens a new
//! connection (under [`Guard::Replace`]) or holds the line until it has been silent for the
//! configured timeout (under [`Guard::Wait`]: the adaptive timer's ceiling, not its
//! current value, since the silence must cover every reply the configuration allows),
//! reading and dropping whatever arrives (late replies, and the duplicate answers to
//! retries they provoke); then it flushes input already waiting. Dropped input is counted
//! in bursts: bytes that arrive within [`BURST_GAP`] of each other are one reply. A line
//! that never falls silent is held at most [`MAX_HOLD`] timeouts, then used anyway (the
//! flush and the reply checks still apply).
//!
//! With a flight recorder ([`StreamLink::set_recorder`]) the link records what it writes
//! and reads (see `tap.rs`): each frame a decoder finds, with the noise it skipped before
//! it, waits for the protocol's verdict ([`StreamLink::judged`]); input thrown away by a
//! flush is one stale reply, input dropped while the line is held one stale reply per
//! burst (as the counters count them); noise a decoder drops while waiting, input cut
//! past [`MAX_BUFFER`] and input left when the stream closes are recorded as dropped.
//! Input a decoder refuses (an error) is recorded as malformed and thrown away with the
//! buffer: nothing after it can be trusted, and every caller resets or reopens anyway.

use std::io;
use std::sync::Arc;
use std::time::Duration;

use futures::FutureExt;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::time::Instant;
use tokio_util::bytes::{Buf, BytesMut};
use tokio_util::codec::Decoder;

use super::connection::{Backoff, Connection};
use super::endpoint::Endpoint;
use super::health::Settled;
use super::owed::{Clear, Guard, Owed};
use super::retry::{Attempt, AttemptError};
use crate::capture::{Recorder, Verdict};

/// Input kept while no frame is found; past it, the oldest half is noise and is cut, so a
/// babbling line cannot grow the buffer without bound.
const MAX_BUFFER: usize = 8192;

/// Input arriving within this of the previous input counts as the same reply.
const BURST_GAP: Duration = Duration::from_millis(5);

/// The longest hold, in configured timeouts.
const MAX_HOLD: u32 = 4;

/// A byte-stream link to one device, opened on first use and reopened after a loss.
pub(crate) struct StreamLink {
    conn: Connection,
    rx: BytesMut,
    /// The replies the link may still receive ([`super::owed`]).
    owed: Owed,
    /// The sends after the last [`StreamLink::settle`] are a retry's.
    retrying: bool,
    /// ... and a write's.
    writing: bool,
    /// The configured timeout from the last send: how long a reply under way may take.
    ceiling: Instant,
    /// A byte arrived since the last send.
    replying: bool,
}

impl StreamLink {
    /// A link over `endpoint` (any but [`Endpoint::Udp`]) under `guard`. A line
    /// ([`Guard::Wait`]) starts held: it may bring the reply to a request of a process
    /// before this one; a new connection ([`Guard::Replace`]) cannot.
    pub fn new(endpoint: Endpoint, backoff: Backoff, guard: Guard) -> Self {
        StreamLink {
            conn: Connection::new(endpoint, backoff),
            rx: BytesMut::with_capacity(512),
            owed: Owed::new(guard, false),
            retrying: false,
            writing: false,
            ceiling: Instant::now(),
            replying: false,
        }
    }

    /// Records every frame into `recorder` from now on.
    pub fn set_recorder(&mut self, recorder: Option<Arc<Recorder>>) {
        self.conn.tap = super::tap::Tap::new(recorder);
    }

    /// The protocol's verdict on the frame read last, for the recorder.
    pub fn judged(&mut self, verdict: Verdict) {
        self.conn.tap.judged(verdict);
    }

    /// Records the buffered input as thrown away with `verdict`, and forgets it.
    fn drop_input(&mut self, verdict: Verdict) {
        if !self.rx.is_empty() && self.conn.tap.on() {
            let time_us = self.conn.tap.now_us();
            self.conn.tap.discarded(time_us, &self.rx, verdict);
        }
        self.rx.clear();
    }

    /// Marks the line as possibly carrying a late reply (a reply was dropped as stale):
    /// the next request holds it first ([`StreamLink::settle`]).
    pub fn unsettle(&mut self) {
        self.owed.unsettle();
    }

    /// The reply to the last request sent was taken: nothing more is due.
    pub fn answered(&mut self) {
        self.owed.answered();
    }

    /// Before sending `attempt`, the transport's rule for links whose replies name no
    /// request ([`super::owed`]; nothing under [`Guard::Ids`]): while a reply may still be
    /// owed (an attempt not answered, a timeout, a reply that was not the request's, a
    /// line that may bring another process's reply), a new connection is opened
    /// ([`Guard::Replace`]) or the line is held until nothing has arrived for the
    /// configured timeout, counted from the last byte sent or received ([`Guard::Wait`]),
    /// dropping whatever arrives; then input already waiting is flushed. A write never
    /// answered is waited out before the next request rather than left behind on a closed
    /// connection ([`super::owed::Owed::before_send`]); `write` if this request writes.
    /// Returns the replies dropped and how long the line was held (not part of the attempt's round
    /// trip: the caller starts the attempt's reply window after its send,
    /// [`Attempt::restarted`]).
    pub async fn settle(&mut self, attempt: &Attempt, write: bool) -> Result<Settled, AttemptError> {
        self.retrying = !attempt.is_first();
        self.writing = write;
        let started = Instant::now();
        let mut replies = match self.owed.before_send(attempt.is_first()) {
            Clear::Nothing => 0,
            Clear::Replace => {
                self.reset();
                0
            }
            Clear::Wait => {
                let replies = self.hold(attempt).await?;
                self.owed.cleared();
                replies
            }
        };
        if self.owed.guard() != Guard::Ids {
            replies += u64::from(self.flush_stale(attempt.timeout).await?);
        }
        Ok(Settled { replies, held: started.elapsed() })
    }

    /// Reads and drops input until the line has been quiet for the configured timeout (or
    /// [`MAX_HOLD`] of them); returns the bursts dropped.
    async fn hold(&mut self, attempt: &Attempt) -> Result<u64, AttemptError> {
        // The configured timeout, not the adaptive one: a reply is only late beyond what
        // the configuration allows, and the adaptive timer must not shrink the silence that
        // drains it (a 20 ms window would let a reply 30 ms late through).
        let window = attempt.timeout;
        let give_up = Instant::now() + window * MAX_HOLD;
        let mut replies = u64::from(!self.rx.is_empty());
        let mut burst = Burst::default();
        if self.conn.tap.on() && !self.rx.is_empty() {
            burst.start(self.conn.tap.now_us(), &self.rx);
        }
        self.rx.clear();
        let held = self.hold_quiet(window, give_up, &mut replies, &mut burst).await;
        burst.record(&mut self.conn.tap);
        held.map(|()| replies)
    }

    /// The loop of [`StreamLink::hold`]: reads until the line is quiet for `window` (or
    /// `give_up`), counting bursts in `replies` and keeping them in `burst` for the recorder.
    async fn hold_quiet(
        &mut self,
        window: Duration,
        give_up: Instant,
        replies: &mut u64,
        burst: &mut Burst,
    ) -> Result<(), AttemptError> {
        self.conn.stream(window).await?;
        loop {
            let quiet = self.owed.quiet_at(window).min(give_up);
            if Instant::now() >= quiet {
                return Ok(());
            }
            let stream = self.conn.stream(Duration::ZERO).await?;
            match tokio::time::timeout_at(quiet, stream.read_buf(&mut self.rx)).await {
                Err(_) => {}
                Ok(Ok(0)) => return Err(self.lost(io::ErrorKind::UnexpectedEof.into())),
                Ok(Ok(_)) => {
                    let now = Instant::now();
                    let new_burst = *replies == 0 || now - self.owed.last_io() >= BURST_GAP;
                    if new_burst {
                        *replies += 1;
                    }
                    if self.conn.tap.on() {
                        if new_burst {
                            burst.record(&mut self.conn.tap);
                            burst.start(self.conn.tap.now_us(), &self.rx);
                        } else {
                            burst.bytes.extend_from_slice(&self.rx);
                        }
                    }
                    self.rx.clear();
                    self.owed.received();
                }
                Ok(Err(e)) => return Err(self.lost(e)),
            }
        }
    }

    /// When a byte was last sent or received (for line silence between frames).
    pub fn last_io(&self) -> Instant {
        self.owed.last_io()
    }

    /// Bytes received and not yet taken by a decoder.
    pub fn buffered(&self) -> usize {
        self.rx.len()
    }

    /// Throws away input already waiting (late replies to earlier requests, noise) and
    /// anything buffered; true if there was any. Opens the stream if needed.
    pub async fn flush_stale(&mut self, timeout: Duration) -> Result<bool, AttemptError> {
        let stale = !self.rx.is_empty();
        let mut burst = Burst::default();
        if stale && self.conn.tap.on() {
            burst.start(self.conn.tap.now_us(), &self.rx);
        }
        self.rx.clear();
        let flushed = self.flush_input(timeout, &mut burst).await;
        burst.record(&mut self.conn.tap);
        flushed.map(|more| stale || more)
    }

    /// The reads of [`StreamLink::flush_stale`]: true if any input was waiting, kept in
    /// `burst` for the recorder.
    async fn flush_input(&mut self, timeout: Duration, burst: &mut Burst) -> Result<bool, AttemptError> {
        let mut stale = false;
        let recorder = self.conn.tap.recorder().cloned();
        let stream = self.conn.stream(timeout).await?;
        loop {
            match stream.read_buf(&mut self.rx).now_or_never() {
                Some(Ok(n)) if n > 0 => {
                    stale = true;
                    if let Some(r) = &recorder {
                        if burst.bytes.is_empty() {
                            burst.time_us = r.now_us();
                        }
                        burst.bytes.extend_from_slice(&self.rx);
                    }
                    self.rx.clear();
                    self.owed.received();
                }
                Some(Ok(_)) => return Err(self.lost(io::ErrorKind::UnexpectedEof.into())),
                Some(Err(e)) => return Err(self.lost(e)),
                None => return Ok(stale),
            }
        }
    }

    /// Sends `bytes` within `timeout`. A write that times out is reported as a timeout; the
    /// caller decides whether the half-written frame means the stream must be reopened.
    pub async fn send(&mut self, bytes: &[u8], timeout: Duration) -> Result<(), AttemptError> {
        let stream = self.conn.stream(timeout).await?;
        let written = async {
            stream.write_all(bytes).await?;
            stream.flush().await
        };
        match tokio::time::timeout(timeout, written).await {
            Ok(Ok(())) => {
                self.conn.tap.sent(bytes);
                self.owed.sent(self.retrying, self.writing);
                self.ceiling = self.owed.last_io() + timeout;
                self.replying = false;
                Ok(())
            }
            Ok(Err(e)) => Err(self.lost(e)),
            Err(_) => Err(AttemptError::Timeout),
        }
    }

    /// Reads until `decoder` finds a frame; `Ok(None)` when `deadline` passes first with
    /// nothing received since the last send. Once bytes arrive, the reply is under way and
    /// may take until the send's own timeout (the adaptive timeout bounds the wait for the
    /// reply to begin, not a long reply at a low baud rate). A decoder error means the stream cannot be trusted past this point; it is returned as
    /// is, and the caller resets the link if the protocol cannot resynchronise.
    pub async fn read_frame<D>(
        &mut self,
        decoder: &mut D,
        deadline: Instant,
    ) -> Result<Option<D::Item>, AttemptError>
    where
        D: Decoder<Error = AttemptError>,
    {
        loop {
            let before = self.rx.len();
            self.conn.tap.look(&self.rx);
            let decoded = decoder.decode(&mut self.rx);
            if self.conn.tap.on() {
                self.tap_decoded(before, decoded.as_ref().map(Option::is_some));
            }
            if let Some(item) = decoded? {
                return Ok(Some(item));
            }
            if self.rx.len() > MAX_BUFFER {
                let cut = self.rx.len() - MAX_BUFFER / 2;
                if self.conn.tap.on() {
                    let time_us = self.conn.tap.now_us();
                    self.conn.tap.discarded(time_us, &self.rx[..cut], Verdict::Dropped);
                }
                self.rx.advance(cut);
            }
            let stream = self.conn.stream(Duration::ZERO).await?;
            let until = if self.replying { deadline.max(self.ceiling) } else { deadline };
            match tokio::time::timeout_at(until, stream.read_buf(&mut self.rx)).await {
                Err(_) => {
                    self.owed.unsettle();
                    return Ok(None);
                }
                Ok(Ok(0)) => return Err(self.lost(io::ErrorKind::UnexpectedEof.into())),
                Ok(Ok(_)) => {
                    self.owed.received();
                    self.replying = true;
                }
                Ok(Err(e)) => return Err(self.lost(e)),
            }
        }
    }

    /// Records what a decode made of the `before` bytes it looked at: a frame (`Ok(true)`,
    /// the bytes it consumed, judged later), noise dropped (`Ok(false)` with bytes
    /// consumed), or a refusal (`Err`: everything buffered is malformed and is thrown away).
    fn tap_decoded(&mut self, before: usize, outcome: Result<bool, &AttemptError>) {
        let consumed = before.saturating_sub(self.rx.len());
        match outcome {
            Ok(true) => self.conn.tap.seen_frame(consumed),
            Ok(false) if consumed > 0 => self.conn.tap.seen_discarded(consumed, Verdict::Dropped),
            Ok(false) => {}
            Err(_) => {
                self.conn.tap.seen_discarded(before, Verdict::Malformed);
                self.rx.clear();
            }
        }
    }

    /// Closes the stream and forgets buffered input; the next use reopens it. A new
    /// connection under [`Guard::Replace`] carries nothing late; a reopened line (or a
    /// gateway's connection to it) may, so what it owes stays owed.
    pub fn reset(&mut self) {
        self.conn.reset();
        self.drop_input(Verdict::Dropped);
        self.owed.reopened();
    }

    /// Resets the link after a carrier error and returns it as the attempt's failure.
    fn lost(&mut self, e: io::Error) -> AttemptError {
        self.reset();
        AttemptError::Io(e)
    }
}

/// Input thrown away in one go, kept for the recorder (empty when nothing records).
#[derive(Default)]
struct Burst {
    time_us: u64,
    bytes: Vec<u8>,
}

impl Burst {
    fn start(&mut self, time_us: u64, bytes: &[u8]) {
        self.time_us = time_us;
        self.bytes.clear();
        self.bytes.extend_from_slice(bytes);
    }

    /// Records the burst, if any, as a stale reply, and empties it.
    fn record(&mut self, tap: &mut super::tap::Tap) {
        if !self.bytes.is_empty() {
            tap.discarded(self.time_us, &self.bytes, Verdict::StaleReply);
            self.bytes.clear();
        }
    }
}

#[cfg(test)]
mod tests {
    use tokio::io::AsyncWriteExt;

    use super::*;

    /// Frames are lines ending in `\n`; a `!` line is refused.
    struct Lines;

    impl Decoder for Lines {
        type Item = Vec<u8>;
        type Error = AttemptError;

        fn decode(&mut self, src: &mut BytesMut) -> Result<Option<Vec<u8>>, AttemptError> {
            let Some(end) = src.iter().position(|&b| b == b'\n') else { return Ok(None) };
            let line = src.split_to(end + 1);
            if line.starts_with(b"!") {
                return Err(AttemptError::Malformed("refused line"));
            }
            Ok(Some(line[..end].to_vec()))
        }
    }

    #[tokio::test]
    async fn stale_input_is_flushed_and_frames_are_found_across_reads() {
        let (near, mut far) = tokio::io::duplex(64);
        let mut link = StreamLink::new(Endpoint::given(near), Backoff::default(), Guard::Ids);
        let timeout = Duration::from_millis(200);
        assert!(!link.flush_stale(timeout).await.unwrap(), "nothing waiting");
        far.write_all(b"late reply\n").await.unwrap();
        tokio::task::yield_now().await;
        assert!(link.flush_stale(timeout).await.unwrap(), "the late reply is thrown away");
        link.send(b"ask\n", timeout).await.unwrap();
        far.write_all(b"part").await.unwrap();
        let reader = tokio::spawn(async move {
            far.write_all(b"ial\nnext").await.unwrap();
            far
        });
        let deadline = Instant::now() + timeout;
        assert_eq!(link.read_frame(&mut Lines, deadline).await.unwrap(), Some(b"partial".to_vec()));
        let mut far = reader.await.unwrap();
        assert_eq!(link.buffered(), 4, "the start of the next frame stays buffered");
        assert_eq!(
            link.read_frame(&mut Lines, Instant::now() + Duration::from_millis(20)).await.unwrap(),
            None
        );
        far.write_all(b"\n!\n").await.unwrap();
        assert_eq!(link.read_frame(&mut Lines, deadline).await.unwrap(), Some(b"next".to_vec()));
        assert!(matches!(link.read_frame(&mut Lines, deadline).await, Err(AttemptError::Malformed(_))));
        drop(far);
        let err = link.read_frame(&mut Lines, deadline).await.unwrap_err();
        assert!(
            matches!(err, AttemptError::Io(ref e) if e.kind() == io::ErrorKind::UnexpectedEof),
            "{err:?}"
        );
        assert!(
            matches!(link.send(b"x", timeout).await, Err(AttemptError::Io(_))),
            "a given stream is not reopened"
        );
    }
}
