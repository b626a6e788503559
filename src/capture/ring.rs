//! The flight recorder's memory: one byte ring per device holding each frame as a record
//! (a fixed head, the annotations that are set, the frame's bytes), oldest first.
//!
//! # Decisions
//! - **One buffer, no allocation per frame.** A record is copied into the ring
//!   (`VecDeque<u8>`, two `memcpy`s at most) and evicted by moving its start: recording
//!   allocates nothing once the ring has grown to what its bounds keep. A ring of frames
//!   each in its own allocation cost a `malloc` and a `free` per frame, and five times the
//!   frames' own bytes in bookkeeping for 20-byte Modbus frames.
//! - **The bound is the memory.** The bytes bound counts whole records, heads and
//!   annotations included, and the ring grows by doubling only up to it (never past the
//!   bound rounded up to a power of two); a ring bounded by age stays as large as that
//!   age's traffic, not the bytes bound.
//! - **Layout** (little-endian): time in µs (8 bytes), the record's length (4), the retry
//!   number (4), flags (1: received, job, task, verdict, note), the verdict's code (1: its place in `ALL_VERDICTS`, whose order is
//!   therefore kept);
//!   then the job (8) and the task (4) when set, the note (2 bytes of length, at most
//!   65,535 bytes, then UTF-8) when set; then the frame's bytes to the record's end.
//! - **Read by copying bytes, decoded elsewhere.** A reader copies whole records' bytes out
//!   ([`Ring::copy`], two `memcpy`s at most) by their offsets in the stream of every byte
//!   ever pushed, and decodes them ([`decode_records`]) once the recorder's lock is let go:
//!   a read never moves the ring (`make_contiguous`) nor decodes under the lock. An
//!   offset stays valid until its record is evicted, which the reader sees
//!   ([`Ring::start`] past it).

use std::collections::VecDeque;

use bytes::Bytes;

use super::frame::{ALL_VERDICTS as VERDICTS, Annotations, Direction, Frame};

/// The fixed head of a record.
const HEAD: usize = 18;
/// The smallest capacity the ring grows to at first.
const MIN_CAPACITY: usize = 4096;

const RECEIVED: u8 = 1;
const JOB: u8 = 2;
const TASK: u8 = 4;
const VERDICT: u8 = 8;
const NOTE: u8 = 16;

/// Records of frames, oldest first, in one growing byte ring.
#[derive(Debug, Default)]
pub(super) struct Ring {
    bytes: VecDeque<u8>,
    frames: usize,
    /// The oldest record's time, kept apart: the age bound is checked on every record, and
    /// the ring's start is memory nobody touched for minutes (a cache miss each time).
    oldest_us: Option<u64>,
    /// The offset of the oldest record's first byte in the stream of every byte ever pushed.
    start: u64,
}

impl Ring {
    /// Frames kept.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Bytes kept: the records, heads and annotations included.
    pub fn len(&self) -> usize {
        self.bytes.len()
    }

    /// The offset of the oldest record kept, in the stream of every byte ever pushed.
    pub fn start(&self) -> u64 {
        self.start
    }

    /// The offset just past the newest record kept.
    pub fn end(&self) -> u64 {
        self.start + self.bytes.len() as u64
    }

    /// The bytes a frame of `len` bytes with `annotations` takes as a record.
    pub fn record_len(len: usize, annotations: &Annotations) -> usize {
        HEAD + annotations.job.map_or(0, |_| 8)
            + annotations.task.map_or(0, |_| 4)
            + if annotations.note.is_empty() { 0 } else { 2 + note(annotations).len() }
            + len
    }

    /// Makes room for `need` more bytes within `bound`, growing the ring by doubling up to
    /// the bound.
    pub fn reserve(&mut self, need: usize, bound: usize) {
        let wanted = self.bytes.len() + need;
        if wanted > self.bytes.capacity() {
            let target = (self.bytes.capacity() * 2).max(MIN_CAPACITY).min(bound).max(wanted);
            self.bytes.reserve_exact(target - self.bytes.len());
        }
    }

    /// Appends a record (room made first: [`Ring::reserve`]).
    pub fn push(&mut self, time_us: u64, direction: Direction, frame: &[u8], annotations: &Annotations) {
        let len = Ring::record_len(frame.len(), annotations);
        let mut flags = if direction == Direction::Received { RECEIVED } else { 0 };
        let verdict = annotations.verdict.map_or(0, |v| {
            flags |= VERDICT;
            VERDICTS.iter().position(|&known| known == v).unwrap_or(0) as u8
        });
        flags |= if annotations.job.is_some() { JOB } else { 0 };
        flags |= if annotations.task.is_some() { TASK } else { 0 };
        flags |= if annotations.note.is_empty() { 0 } else { NOTE };
        let mut head = [0u8; HEAD];
        head[0..8].copy_from_slice(&time_us.to_le_bytes());
        head[8..12].copy_from_slice(&(len as u32).to_le_bytes());
        head[12..16].copy_from_slice(&annotations.retry.to_le_bytes());
        head[16] = flags;
        head[17] = verdict;
        self.bytes.extend(&head);
        if let Some(job) = annotations.job {
            self.bytes.extend(&job.to_le_bytes());
        }
        if let Some(task) = annotations.task {
            self.bytes.extend(&task.to_le_bytes());
        }
        if !annotations.note.is_empty() {
            let note = note(annotations);
            self.bytes.extend(&(note.len() as u16).to_le_bytes());
            self.bytes.extend(note.as_bytes());
        }
        self.bytes.extend(frame);
        self.frames += 1;
        self.oldest_us.get_or_insert(time_us);
    }

    /// The oldest record's time, if any.
    pub fn oldest_us(&self) -> Option<u64> {
        self.oldest_us
    }

    /// Drops the oldest record.
    pub fn pop(&mut self) {
        if self.bytes.is_empty() {
            return;
        }
        let len = u32::from_le_bytes(self.head_bytes::<4>(8)) as usize;
        let len = len.min(self.bytes.len());
        self.bytes.drain(..len);
        self.start += len as u64;
        self.frames -= 1;
        self.oldest_us = (!self.bytes.is_empty()).then(|| u64::from_le_bytes(self.head_bytes::<8>(0)));
    }

    /// `N` bytes from `at` (0: the oldest record's first byte).
    fn head_bytes<const N: usize>(&self, at: usize) -> [u8; N] {
        let mut out = [0u8; N];
        match self.bytes.as_slices().0.get(at..at + N) {
            Some(part) => out.copy_from_slice(part),
            // Across the ring's wrap.
            None => out.iter_mut().zip(self.bytes.range(at..at + N)).for_each(|(o, b)| *o = *b),
        }
        out
    }

    /// Appends to `out` the bytes from offset `at` (a record's start, at or past
    /// [`Ring::start`]) up to `end` (at most [`Ring::end`]), `max` of them at most but the
    /// whole first record whatever its size; the bytes appended. The last record may be
    /// cut: [`decode_records`] leaves it for the next copy.
    pub fn copy(&self, at: u64, end: u64, max: usize, out: &mut Vec<u8>) -> usize {
        let (from, to) = ((at.max(self.start) - self.start) as usize, end.min(self.end()));
        let to = (to.saturating_sub(self.start) as usize).max(from);
        let first =
            if to - from >= HEAD { u32::from_le_bytes(self.head_bytes::<4>(from + 8)) as usize } else { 0 };
        let to = to.min(from + max.max(first));
        let (a, b) = self.bytes.as_slices();
        let split = a.len();
        if from < split {
            out.extend_from_slice(&a[from..to.min(split)]);
        }
        if to > split {
            out.extend_from_slice(&b[from.max(split) - split..to - split]);
        }
        to - from
    }
}

/// Decodes the whole records at the start of `bytes` (as [`Ring::copy`] copied them),
/// pushing those from `from_us` on to `frames`; the bytes of whole records read (a record
/// cut at the end is left).
pub(super) fn decode_records(bytes: &[u8], from_us: u64, frames: &mut Vec<Frame>) -> usize {
    let mut at = 0;
    while at + HEAD <= bytes.len() {
        let record = &bytes[at..];
        let len = (u32::from_le_bytes(record[8..12].try_into().unwrap_or_default()) as usize).max(HEAD);
        if len > record.len() {
            break;
        }
        let time_us = u64::from_le_bytes(record[0..8].try_into().unwrap_or_default());
        if time_us >= from_us {
            frames.push(decode(&record[..len], time_us));
        }
        at += len;
    }
    at
}

/// The note as kept: at most 65,535 bytes, cut at a character's boundary.
fn note(annotations: &Annotations) -> &str {
    let note = annotations.note.as_str();
    let mut end = note.len().min(usize::from(u16::MAX));
    while !note.is_char_boundary(end) {
        end -= 1;
    }
    &note[..end]
}

/// One record as a frame.
fn decode(record: &[u8], time_us: u64) -> Frame {
    let retry = u32::from_le_bytes(record[12..16].try_into().unwrap_or_default());
    let (flags, verdict) = (record[16], record[17]);
    let mut at = HEAD;
    let mut take = |n: usize| {
        let part = record.get(at..at + n).unwrap_or_default();
        at += n;
        part
    };
    let job = (flags & JOB != 0).then(|| i64::from_le_bytes(take(8).try_into().unwrap_or_default()));
    let task = (flags & TASK != 0).then(|| u32::from_le_bytes(take(4).try_into().unwrap_or_default()));
    let note = if flags & NOTE != 0 {
        let n = u16::from_le_bytes(take(2).try_into().unwrap_or_default());
        String::from_utf8_lossy(take(usize::from(n))).into_owned()
    } else {
        String::new()
    };
    let verdict = (flags & VERDICT != 0).then(|| VERDICTS.get(usize::from(verdict)).copied()).flatten();
    let direction = if flags & RECEIVED != 0 { Direction::Received } else { Direction::Sent };
    let bytes = Bytes::copy_from_slice(record.get(at..).unwrap_or_default());
    Frame { direction, time_us, bytes, annotations: Annotations { job, task, retry, verdict, note } }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capture::Verdict;

    impl Ring {
        /// The frames kept from `from_us` on, copied `max` bytes at a time.
        fn read(&self, from_us: u64, max: usize) -> Vec<Frame> {
            let (mut at, mut frames, mut buf) = (self.start(), Vec::new(), Vec::new());
            while at < self.end() {
                buf.clear();
                self.copy(at, self.end(), max, &mut buf);
                let read = decode_records(&buf, from_us, &mut frames);
                assert!(read > 0, "a copy holds a whole record at least");
                at += read as u64;
            }
            frames
        }
    }

    #[test]
    fn records_read_back_as_the_frames_they_were() {
        let mut ring = Ring::default();
        let plain = Annotations::default();
        let full = Annotations {
            job: Some(-17),
            task: Some(70_000),
            retry: 3,
            verdict: Some(Verdict::Malformed),
            note: "after a timeout".into(),
        };
        ring.reserve(1000, 1 << 20);
        ring.push(5, Direction::Sent, b"\x50\x00", &plain);
        ring.push(9, Direction::Received, b"", &full);
        assert_eq!(ring.len(), Ring::record_len(2, &plain) + Ring::record_len(0, &full));
        assert_eq!(Ring::record_len(0, &full), HEAD + 8 + 4 + 2 + 15);
        let frames = ring.read(0, 1);
        assert_eq!(
            frames,
            [
                Frame::new(Direction::Sent, 5, b"\x50\x00".to_vec()),
                Frame { direction: Direction::Received, time_us: 9, bytes: Bytes::new(), annotations: full }
            ]
        );
        assert_eq!(ring.read(6, 1 << 20).len(), 1, "from a time on");
    }

    #[test]
    fn the_oldest_record_goes_first_and_the_ring_wraps() {
        let mut ring = Ring::default();
        let plain = Annotations::default();
        for i in 0..2000u64 {
            while ring.len() + HEAD + 3 > 4096 {
                ring.pop();
            }
            ring.reserve(HEAD + 3, 4096);
            ring.push(i, Direction::Sent, &[i as u8; 3], &plain);
        }
        assert_eq!(ring.frames(), 4096 / (HEAD + 3));
        assert!(ring.bytes.capacity() <= 4096, "grown to the bound, no further");
        assert_eq!(ring.oldest_us(), Some(2000 - 4096 / (HEAD + 3) as u64));
        assert_eq!(ring.read(0, 1000), ring.read(0, 1 << 20), "copied in parts or whole, across the wrap");
        let frames = ring.read(0, 100);
        assert_eq!(
            frames.last().map(|f| (f.time_us, f.bytes.to_vec())),
            Some((1999, vec![1999u64 as u8; 3]))
        );
        while ring.len() > 0 {
            ring.pop();
        }
        assert_eq!((ring.frames(), ring.oldest_us()), (0, None));
    }

    #[test]
    fn every_verdict_and_a_long_note_survive() {
        let mut ring = Ring::default();
        for v in VERDICTS {
            let a = Annotations { verdict: Some(v), note: "é".repeat(40_000), ..Annotations::default() };
            ring.reserve(Ring::record_len(1, &a), 1 << 20);
            ring.push(1, Direction::Received, &[1], &a);
        }
        let frames = ring.read(0, 10);
        let verdicts: Vec<Option<Verdict>> = frames.iter().map(|f| f.annotations.verdict).collect();
        assert_eq!(verdicts, VERDICTS.map(Some));
        assert_eq!(frames[0].annotations.note.len(), 65_534, "cut at a character within 65,535 bytes");
        assert_eq!(frames[0].bytes.as_ref(), [1]);
    }
}
