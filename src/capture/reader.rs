//! Reading a recorder's frames part by part (issue 51): a [`Reader`] copies a part of the
//! ring's records under the recorder's lock, and decodes it once the lock is let go.
//!
//! # Decisions
//! - **What a reader reads is fixed when it is made**: the frames kept then (of the span
//!   asked), oldest first; frames recorded later are not read, so a download ends.
//! - **Parts of [`PART`] bytes** of records (a single larger record whole): the lock is held
//!   for one copy of at most that, tens of microseconds, and a reader holds one part in
//!   memory at a time, not the ring, whatever the number of readers.
//! - **A reader slower than the ring** (a client that downloads for minutes while the
//!   device's traffic turns the ring over) finds its next records evicted: it goes on from
//!   the oldest record kept, and the first frame after the gap says so in its note. It
//!   never holds frames back from eviction: the recorder's bound is its memory.

use std::ops::Range;
use std::sync::Arc;
use std::time::Duration;

use super::frame::Frame;
use super::link::Link;
use super::recorder::Recorder;
use super::ring::decode_records;

/// Bytes of records a reader copies at once: 256 KiB.
pub const PART: usize = 256 * 1024;

/// The note on the first frame read after frames the reader had not read yet were evicted.
pub const GAP_NOTE: &str = "frames before this one were evicted before the capture read them";

/// Reads the frames a recorder kept when the reader was made; see the module doc.
#[derive(Debug)]
pub struct Reader {
    recorder: Arc<Recorder>,
    link: Link,
    /// Frames from this time on (µs since the Unix epoch).
    from_us: u64,
    /// Offsets of the records still to read, in the stream of every byte the ring took.
    left: Range<u64>,
    /// Frames the recorder held when the reader was made.
    held: usize,
    /// Records' bytes copied but not decoded yet (the start of a record cut by a copy).
    buf: Vec<u8>,
}

impl Recorder {
    /// The frames kept, oldest first: all of them, or those of the `last` span. Read part
    /// by part ([`Recorder::reader`]): recording goes on between the parts.
    pub fn frames(self: &Arc<Self>, last: Option<Duration>) -> Vec<Frame> {
        let mut reader = self.reader(last);
        let mut frames = Vec::new();
        loop {
            let part = reader.next(PART);
            if part.is_empty() {
                return frames;
            }
            frames.extend(part);
        }
    }

    /// A reader of the frames kept now, oldest first: all of them, or those of the `last`
    /// span; frames recorded after this call are not read.
    pub fn reader(self: &Arc<Self>, last: Option<Duration>) -> Reader {
        let (left, held, link, now) = self.kept();
        let from_us = last.map_or(0, |d| now.saturating_sub(d.as_micros() as u64));
        Reader::new(self.clone(), link, from_us, left, held)
    }
}

impl Reader {
    fn new(recorder: Arc<Recorder>, link: Link, from_us: u64, left: Range<u64>, held: usize) -> Self {
        Reader { recorder, link, from_us, left, held, buf: Vec::new() }
    }

    /// The link, as it was when the reader was made.
    pub fn link(&self) -> &Link {
        &self.link
    }

    /// Frames the recorder held when the reader was made (those of the span asked among
    /// them).
    pub fn held(&self) -> usize {
        self.held
    }

    /// The next frames, oldest first, from about `max` bytes of records (one record at
    /// least); none once every record is read.
    pub fn next(&mut self, max: usize) -> Vec<Frame> {
        let mut frames = Vec::new();
        while frames.is_empty() && self.left.start < self.left.end {
            self.buf.clear();
            let at = self.recorder.copy(self.left.start, self.left.end, max, &mut self.buf);
            let gap = at > self.left.start;
            let read = decode_records(&self.buf, self.from_us, &mut frames);
            if read == 0 {
                // Nothing left to read: the records were evicted up to the end.
                self.left.start = self.left.end;
                break;
            }
            self.left.start = at + read as u64;
            if let (true, Some(first)) = (gap, frames.first_mut()) {
                let note = &mut first.annotations.note;
                *note = if note.is_empty() { GAP_NOTE.to_owned() } else { format!("{GAP_NOTE}; {note}") };
            }
        }
        frames
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capture::{Annotations, Direction, Limits, SerialProtocol};

    fn recorder(bytes: usize) -> Arc<Recorder> {
        let link = Link::Serial { protocol: SerialProtocol::Ppi, port: "ttyS0".into() };
        Recorder::new(link, Limits { bytes, seconds: 600 })
    }

    fn sizes(frames: &[Frame]) -> Vec<usize> {
        frames.iter().map(|f| f.bytes.len()).collect()
    }

    #[test]
    fn a_reader_reads_what_was_kept_when_it_was_made_part_by_part() {
        let r = recorder(1 << 20);
        for n in 1..=5 {
            r.record(Direction::Sent, &vec![0; n], Annotations::default());
        }
        let mut reader = r.reader(None);
        assert_eq!(reader.held(), 5);
        // 18 bytes of head and a few of frame each: 40 bytes take two records.
        assert_eq!(sizes(&reader.next(40)), [1, 2]);
        r.record(Direction::Received, &[7; 6], Annotations::default());
        assert_eq!(sizes(&reader.next(1)), [3], "one record at least, and recording went on");
        assert_eq!(sizes(&reader.next(1 << 20)), [4, 5], "not the frame recorded after it was made");
        assert!(reader.next(1 << 20).is_empty());
        assert_eq!(sizes(&r.frames(None)), [1, 2, 3, 4, 5, 6]);
    }

    #[test]
    fn a_slow_reader_skips_what_was_evicted_and_says_so() {
        // Five records of 18 + 10 bytes fill the bound.
        let r = recorder(5 * 28);
        for i in 0..5u8 {
            r.record(Direction::Sent, &[i; 10], Annotations::default());
        }
        let mut reader = r.reader(None);
        assert_eq!(reader.next(28).len(), 1);
        // One more record evicts two (to make room with a 32nd of the bound to spare):
        // frame 1, which the reader has not read, is gone.
        r.record(Direction::Sent, &[5; 10], Annotations::default());
        let rest = reader.next(1 << 20);
        let firsts: Vec<u8> = rest.iter().map(|f| f.bytes[0]).collect();
        assert_eq!(firsts, [2, 3, 4], "on from the oldest kept, up to where the reader's end was");
        assert_eq!(rest[0].annotations.note, GAP_NOTE);
        assert_eq!(rest[1].annotations.note, "");
        assert!(reader.next(1 << 20).is_empty());
    }
}
