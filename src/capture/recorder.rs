//! The flight recorder of one device: a ring of the last frames on its link, both ways,
//! bounded by bytes and by age, always on.
//!
//! # Decisions
//! - **Cheap on the hot path.** [`Recorder::record`] reads the clock once
//!   (`Instant::now()`, no syscall beyond it: the wall clock is read once, when the
//!   recorder is made, and every time is that reading plus the monotonic time since), and
//!   holds the one mutex for the evictions and one copy of the frame into the device's
//!   byte ring ([`super::ring`]): no allocation per frame.
//! - **Bounds.** The bytes bound counts the ring's records whole (a frame's bytes plus an
//!   18-byte head and its annotations), so it is the recorder's memory; the age bound is
//!   applied exactly on every read, so a quiet link's old frames are gone when asked for
//!   even if nothing was recorded since. Recording evicts in batches (once the oldest
//!   frame is a second past the age bound, or the ring is full, down to the age bound and
//!   a 32nd of the bytes bound free): the ring's start is memory last touched minutes ago,
//!   and one walk over it a second costs less than a cache miss per frame. A frame whose
//!   record is larger than the bytes bound alone is counted and evicted at once.
//! - **Context.** Two things annotate frames without the caller passing them: the job and
//!   task being served ([`Recorder::set_serving`], set by device adapters around a
//!   hand-over), on every frame recorded while set; and the attempt under way
//!   ([`Recorder::set_attempt`], set by the transport's retry loop), on sent frames. A
//!   retry's sent frame carries its number, the verdict [`Verdict::Retry`] and the note
//!   `after a timeout` (or `after a malformed reply`, `after a lost connection`). A
//!   timeout has no bytes of its own, so it is not a frame: it shows as the retry it led
//!   to, and is counted ([`Stats::timeouts`]). Context the caller did set wins.
//! - **One link.** [`Recorder::link`] is the link as it is now: the transport updates the
//!   endpoints when a connection opens again (a UDP socket rebound on a new port, a TCP
//!   reconnect). Frames recorded before a change are written with the newest endpoints;
//!   a capture is one interface, and the device's end does not change.
//! - **Time** is tokio's clock, so tests on paused time see the age bound work.
//! - **Reads hold the lock for copies only** (issue 51): a [`Reader`](super::Reader)
//!   copies a part of the ring's bytes under the lock and decodes it after
//!   ([`super::reader`], where `Recorder::reader` and `Recorder::frames` are), so a capture
//!   of a full 256 MiB ring, decoded and written for a download, never keeps the device's
//!   own requests waiting on the recorder for longer than a copy of a part (256 KiB).

use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{SystemTime, UNIX_EPOCH};

use tokio::time::Instant;

use super::frame::{Annotations, Direction, Verdict};
use super::link::Link;
use super::ring::Ring;

/// How far past the age bound the oldest frame may get before recording evicts (a read
/// never returns it): 1 s.
const AGE_SLACK_US: u64 = 1_000_000;

/// How much a recorder keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Bytes of records kept at most (a frame's bytes, an 18-byte head, its annotations).
    pub bytes: usize,
    /// Seconds of frames kept at most.
    pub seconds: u64,
}

impl Default for Limits {
    /// 4 MiB or 10 minutes, whichever is reached first.
    fn default() -> Self {
        Limits { bytes: 4 * 1024 * 1024, seconds: 600 }
    }
}

/// A recorder's counters since it was made.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Stats {
    /// Frames recorded.
    pub recorded: u64,
    /// Frames evicted past a bound.
    pub evicted: u64,
    /// Attempts that timed out (they have no frame of their own).
    pub timeouts: u64,
    /// Frames kept now.
    pub frames: usize,
    /// Bytes kept now (whole records).
    pub bytes: usize,
}

/// The attempt under way, for sent frames.
#[derive(Clone, Copy, Debug, Default)]
struct AttemptContext {
    retry: u32,
    /// Why the previous attempt failed (`a timeout`), for a retry's note.
    after: Option<&'static str>,
}

#[derive(Debug)]
struct State {
    ring: Ring,
    link: Link,
    serving: Option<(i64, u16)>,
    attempt: AttemptContext,
    recorded: u64,
    evicted: u64,
    timeouts: u64,
}

/// A device's flight recorder; share it as `Arc<Recorder>`.
#[derive(Debug)]
pub struct Recorder {
    limits: Limits,
    /// The monotonic instant that `epoch_us` was read at.
    base: Instant,
    /// Microseconds since the Unix epoch at `base`.
    epoch_us: u64,
    state: Mutex<State>,
}

impl Recorder {
    /// An empty recorder of frames on `link`, keeping what `limits` allow.
    pub fn new(link: Link, limits: Limits) -> Arc<Recorder> {
        let epoch_us = SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_micros() as u64);
        Arc::new(Recorder {
            limits,
            base: Instant::now(),
            epoch_us,
            state: Mutex::new(State {
                ring: Ring::default(),
                link,
                serving: None,
                attempt: AttemptContext::default(),
                recorded: 0,
                evicted: 0,
                timeouts: 0,
            }),
        })
    }

    /// The bounds.
    pub fn limits(&self) -> Limits {
        self.limits
    }

    /// Now, in microseconds since the Unix epoch, on the recorder's clock.
    pub fn now_us(&self) -> u64 {
        self.epoch_us + self.base.elapsed().as_micros() as u64
    }

    fn state(&self) -> MutexGuard<'_, State> {
        // Frames and counters stay consistent at every unlock: usable after a panic elsewhere.
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Records a frame now, with the serving and attempt context added (see the module doc).
    pub fn record(&self, direction: Direction, bytes: &[u8], annotations: Annotations) {
        self.record_at(self.now_us(), direction, bytes, annotations);
    }

    /// Records a frame seen at `time_us` ([`Recorder::now_us`]), for a caller that learns
    /// what to make of a frame only after reading it.
    pub fn record_at(&self, time_us: u64, direction: Direction, bytes: &[u8], mut annotations: Annotations) {
        let mut s = self.state();
        if let (None, None, Some((job, task))) = (annotations.job, annotations.task, s.serving) {
            annotations.job = Some(job);
            annotations.task = Some(u32::from(task));
        }
        let context = s.attempt;
        if direction == Direction::Sent && annotations.retry == 0 && annotations.verdict.is_none() {
            annotations.retry = context.retry;
            if context.retry > 0 {
                annotations.verdict = Some(Verdict::Retry);
                if let (Some(after), true) = (context.after, annotations.note.is_empty()) {
                    annotations.note = format!("after {after}");
                }
            }
        }
        s.recorded += 1;
        let need = Ring::record_len(bytes.len(), &annotations);
        if need > self.limits.bytes {
            s.evicted += 1;
            self.evict(&mut s, time_us, 0, false);
            return;
        }
        self.evict(&mut s, time_us, need, false);
        s.ring.reserve(need, self.limits.bytes);
        s.ring.push(time_us, direction, bytes, &annotations);
    }

    /// Drops the oldest frames past the age bound, and as many more as leave `need` bytes
    /// within the bytes bound. Recording evicts in batches: only once the oldest frame is
    /// [`AGE_SLACK_US`] past the age bound, or the bytes bound is reached, and then down to
    /// the age bound and a 32nd of the bytes bound free. One walk over the ring's start
    /// every second or so, instead of a cache miss at each record on memory untouched
    /// since it was written. A read (`exact`) drops everything past the bounds first.
    fn evict(&self, s: &mut State, now_us: u64, need: usize, exact: bool) {
        let bound = self.limits.bytes;
        let oldest = now_us.saturating_sub(self.limits.seconds.saturating_mul(1_000_000));
        let slack = if exact { 0 } else { AGE_SLACK_US };
        let aged = s.ring.oldest_us().is_some_and(|t| t < oldest.saturating_sub(slack));
        let full = s.ring.len() + need > bound;
        if !aged && !full {
            return;
        }
        let room = if full && !exact { (need + bound / 32).min(bound) } else { need };
        while let Some(time_us) = s.ring.oldest_us() {
            if s.ring.len() + room <= bound && time_us >= oldest {
                break;
            }
            s.ring.pop();
            s.evicted += 1;
        }
    }

    /// Under the lock: the records kept now (past the bounds evicted first), as offsets,
    /// how many frames they are, the link, and now.
    pub(super) fn kept(&self) -> (std::ops::Range<u64>, usize, Link, u64) {
        let now = self.now_us();
        let mut s = self.state();
        self.evict(&mut s, now, 0, true);
        (s.ring.start()..s.ring.end(), s.ring.frames(), s.link.clone(), now)
    }

    /// Under the lock: appends to `out` the records' bytes from offset `at` (past the ring's
    /// start if those were evicted) up to `end`, about `max` of them (`Ring::copy`); the
    /// offset copied from.
    pub(super) fn copy(&self, at: u64, end: u64, max: usize, out: &mut Vec<u8>) -> u64 {
        let s = self.state();
        let from = at.max(s.ring.start());
        s.ring.copy(from, end, max, out);
        from
    }

    /// The link the frames travel on, with its newest endpoints.
    pub fn link(&self) -> Link {
        self.state().link.clone()
    }

    /// The link's endpoints changed (a new connection or socket).
    pub fn set_link(&self, link: Link) {
        self.state().link = link;
    }

    /// The job and task being served, if any; frames recorded while it is set carry them.
    pub fn set_serving(&self, serving: Option<(i64, u16)>) {
        self.state().serving = serving;
    }

    /// The job and task being served.
    pub fn serving(&self) -> Option<(i64, u16)> {
        self.state().serving
    }

    /// The attempt under way: `retry` is 0 for a request's first attempt; a retry names
    /// what the attempt before it ended with (`a timeout`). Sent frames carry it.
    pub fn set_attempt(&self, retry: u32, after: Option<&'static str>) {
        self.state().attempt = AttemptContext { retry, after };
    }

    /// An attempt got no reply in time.
    pub fn timed_out(&self) {
        self.state().timeouts += 1;
    }

    /// The counters now.
    pub fn stats(&self) -> Stats {
        let s = self.state();
        Stats {
            recorded: s.recorded,
            evicted: s.evicted,
            timeouts: s.timeouts,
            frames: s.ring.frames(),
            bytes: s.ring.len(),
        }
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;
    use crate::capture::{Frame, SerialProtocol};

    fn recorder(limits: Limits) -> Arc<Recorder> {
        Recorder::new(Link::Serial { protocol: SerialProtocol::Ppi, port: "ttyS0".into() }, limits)
    }

    fn sizes(frames: &[Frame]) -> Vec<usize> {
        frames.iter().map(|f| f.bytes.len()).collect()
    }

    #[test]
    fn the_oldest_frames_go_past_the_bytes_bound() {
        // Three records of plain frames: 18 bytes of head each, and 10 bytes of frames.
        let r = recorder(Limits { bytes: 3 * 18 + 10, seconds: 600 });
        for n in [4, 3, 2, 5] {
            r.record(Direction::Sent, &vec![0; n], Annotations::default());
        }
        // 63 bytes kept, and the fourth frame's record needs 23: the oldest go until it fits
        // with a 32nd of the bound (2 bytes) to spare.
        assert_eq!(sizes(&r.frames(None)), [2, 5], "4 and 3 evicted");
        r.record(Direction::Received, &[0; 47], Annotations::default());
        assert_eq!(
            sizes(&r.frames(None)),
            [2, 5],
            "a frame over the bound alone is not kept, nor makes room"
        );
        let stats = r.stats();
        assert_eq!((stats.recorded, stats.evicted, stats.frames, stats.bytes), (5, 3, 2, 43));
        r.record(Direction::Sent, &[0; 46], Annotations::default());
        assert_eq!(sizes(&r.frames(None)), [46], "exactly the bound is kept");
        assert_eq!(r.stats().bytes, 64);
    }

    #[tokio::test(start_paused = true)]
    async fn the_oldest_frames_go_past_the_age_bound_and_last_picks_a_span() {
        let r = recorder(Limits { bytes: 1 << 20, seconds: 10 });
        let start = r.now_us();
        r.record(Direction::Sent, b"a", Annotations::default());
        tokio::time::advance(Duration::from_secs(6)).await;
        r.record(Direction::Received, b"bb", Annotations::default());
        assert_eq!(r.now_us() - start, 6_000_000, "time follows tokio's clock");
        assert_eq!(sizes(&r.frames(Some(Duration::from_secs(2)))), [2], "the last 2 s");
        tokio::time::advance(Duration::from_secs(5)).await;
        assert_eq!(sizes(&r.frames(None)), [2], "11 s old: gone without a new record");
        tokio::time::advance(Duration::from_secs(10)).await;
        assert!(r.frames(None).is_empty());
        assert_eq!(r.stats().evicted, 2);
    }

    #[tokio::test(start_paused = true)]
    async fn recording_evicts_by_age_once_a_second_past_the_bound_and_a_read_at_once() {
        let r = recorder(Limits { bytes: 1 << 20, seconds: 10 });
        r.record(Direction::Sent, b"a", Annotations::default());
        tokio::time::advance(Duration::from_millis(10_500)).await;
        r.record(Direction::Sent, b"b", Annotations::default());
        assert_eq!(r.stats().frames, 2, "a is 0.5 s past the bound: kept until the next batch");
        tokio::time::advance(Duration::from_secs(1)).await;
        r.record(Direction::Sent, b"c", Annotations::default());
        assert_eq!((r.stats().frames, r.stats().evicted), (2, 1), "1.5 s past: evicted by recording");
        tokio::time::advance(Duration::from_millis(9_500)).await;
        assert_eq!(r.stats().frames, 2, "b is 0.5 s past the bound");
        assert_eq!(sizes(&r.frames(None)), [1], "a read never returns it");
        assert_eq!(r.stats().frames, 1);
    }

    #[test]
    fn serving_and_attempt_context_annotate_frames() {
        let r = recorder(Limits::default());
        r.record(Direction::Sent, b"1", Annotations::default());
        r.set_serving(Some((17, 4)));
        r.set_attempt(1, Some("a timeout"));
        r.record(Direction::Sent, b"2", Annotations::default());
        r.record(Direction::Received, b"3", Annotations { verdict: Some(Verdict::Ok), ..Default::default() });
        r.set_serving(None);
        r.set_attempt(0, None);
        r.timed_out();
        r.record(Direction::Sent, b"4", Annotations::default());
        let comments: Vec<String> = r.frames(None).iter().map(|f| f.annotations.comment()).collect();
        assert_eq!(
            comments,
            [
                "",
                "job 17, task 4, retry 1, verdict: retry, after a timeout",
                "job 17, task 4, verdict: ok",
                ""
            ]
        );
        assert_eq!(r.stats().timeouts, 1);
        assert_eq!(r.serving(), None);
    }

    #[test]
    fn the_link_is_the_newest() {
        let r = recorder(Limits::default());
        let ip = Link::Ip {
            transport: crate::capture::Transport::Udp,
            local: "127.0.0.1:4000".parse().unwrap(),
            remote: "127.0.0.1:502".parse().unwrap(),
        };
        r.set_link(ip.clone());
        assert_eq!(r.link(), ip);
    }
}
