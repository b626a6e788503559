//! Which recorded request a live one is: pure logic over the script and the time since the
//! replay began, so every rule is tested without sockets. The rules are the module doc's
//! of [`super`] ("Matching").

use std::collections::HashMap;
use std::time::Duration;

use super::script::Recorded;

/// How a live request was taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Taken {
    /// In order: a write that was due (or owed), a read answered as of the replay clock.
    Matched,
    /// Made a little ahead of a write still due (within the reorder tolerance of it in
    /// the recording): a write, taken out of order; a read, answered as recorded there.
    Reordered,
    /// Sent again (a retry), or sent after the recording ran out: the last answer to the
    /// same request.
    Repeated,
    /// Divergence: found only further on in the recording, which the replay skipped to.
    Skipped,
    /// Divergence: in the recording nowhere it could be taken; not answered.
    Unanswered,
}

/// A live request as compared: its bytes with ids zeroed, whether it only reads, and where
/// a write's data begins ([`super::dialect::Dialect::data_at`]).
#[derive(Clone, Copy, Debug)]
pub struct Request<'a> {
    /// The bytes as compared.
    pub key: &'a [u8],
    /// It only reads.
    pub read: bool,
    /// A write naming one place: where its data begins.
    pub data_at: Option<usize>,
}

/// How many live requests were taken each way.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// [`Taken::Matched`].
    pub matched: u64,
    /// [`Taken::Reordered`].
    pub reordered: u64,
    /// [`Taken::Repeated`].
    pub repeated: u64,
    /// [`Taken::Skipped`].
    pub skipped: u64,
    /// [`Taken::Unanswered`].
    pub unanswered: u64,
    /// Recorded writes no live one made, because the device already held their data when
    /// the replay clock reached them (not live requests: not among the divergences).
    pub in_place: u64,
}

impl Counters {
    /// Requests that did not follow the recording: skipped to, or not answered.
    pub fn diverged(&self) -> u64 {
        self.skipped + self.unanswered
    }

    fn count(&mut self, taken: Taken) {
        *match taken {
            Taken::Matched => &mut self.matched,
            Taken::Reordered => &mut self.reordered,
            Taken::Repeated => &mut self.repeated,
            Taken::Skipped => &mut self.skipped,
            Taken::Unanswered => &mut self.unanswered,
        } += 1;
    }
}

/// The last write taken, or the start: where the replay clock runs from.
#[derive(Clone, Copy, Debug)]
struct Anchor {
    /// The recorded request (None: before the first).
    index: Option<usize>,
    /// Its time in the recording.
    recorded: Duration,
    /// The live time it was taken at.
    live: Duration,
}

/// Follows a live conversation through a script.
#[derive(Debug)]
pub struct Matcher {
    requests: Vec<Recorded>,
    /// Per recorded request: a write that a live one has taken.
    made: Vec<bool>,
    anchor: Option<Anchor>,
    /// The last write taken, for retries.
    last_write: Option<usize>,
    /// What the device holds as rackd last wrote it live: a write's place (its key up to
    /// its data) to its data.
    memory: HashMap<Vec<u8>, Vec<u8>>,
    reorder: Duration,
    counters: Counters,
}

impl Matcher {
    /// A matcher over `requests`; writes up to `reorder` ahead of the one due are taken out
    /// of order without counting as divergence.
    pub fn new(requests: Vec<Recorded>, reorder: Duration) -> Matcher {
        let made = vec![false; requests.len()];
        Matcher {
            requests,
            made,
            anchor: None,
            last_write: None,
            memory: HashMap::new(),
            reorder,
            counters: Counters::default(),
        }
    }

    /// The recorded requests.
    pub fn requests(&self) -> &[Recorded] {
        &self.requests
    }

    /// The counts so far.
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// The first write not yet made after the anchor: the replay clock stops at it.
    pub fn due(&self) -> Option<usize> {
        let from = self.anchor.and_then(|a| a.index).map_or(0, |i| i + 1);
        (from..self.requests.len()).find(|&i| !self.requests[i].read && !self.made[i])
    }

    /// The recording's time that live time `now` stands for: the anchor's, plus the time
    /// since it was taken, never past the write due.
    pub fn clock(&self, now: Duration) -> Duration {
        let Some(a) = self.anchor else { return self.requests.first().map_or(Duration::ZERO, |r| r.at) };
        let clock = a.recorded + now.saturating_sub(a.live);
        match self.due() {
            Some(d) => clock.min(self.requests[d].at),
            None => clock,
        }
    }

    /// Every write is made and the clock has passed the last request.
    pub fn exhausted(&mut self, now: Duration) -> bool {
        self.settle(now);
        self.due().is_none() && self.requests.last().is_none_or(|r| self.clock(now) > r.at)
    }

    /// Recorded writes that no live one made: passed over (before the anchor), and not
    /// reached (after it).
    pub fn writes_not_made(&self) -> (usize, usize) {
        let upto = self.anchor.and_then(|a| a.index).map_or(0, |i| i + 1);
        let open = |r: std::ops::Range<usize>| r.filter(|&i| !self.requests[i].read && !self.made[i]).count();
        (open(0..upto), open(upto..self.requests.len()))
    }

    /// Takes a live request (`key`: its bytes as compared) arriving at `now`: the recorded
    /// request whose replies answer it, if any, and how it was taken.
    pub fn take(&mut self, request: Request<'_>, now: Duration) -> (Option<usize>, Taken) {
        if self.anchor.is_none() {
            let recorded = self.requests.first().map_or(Duration::ZERO, |r| r.at);
            self.anchor = Some(Anchor { index: None, recorded, live: now });
        }
        self.settle(now);
        let key = request.key;
        let (index, taken) = if request.read { self.take_read(key, now) } else { self.take_write(key, now) };
        self.counters.count(taken);
        if let (false, Some(at), Some(_)) = (request.read, request.data_at, index) {
            self.memory.insert(key[..at].to_vec(), key[at..].to_vec());
        }
        (index, taken)
    }

    /// Recorded write `i` would leave the device as it is: rackd last wrote the same data
    /// to the same place.
    fn in_place(&self, i: usize) -> bool {
        let r = &self.requests[i];
        r.data_at.is_some_and(|at| self.memory.get(&r.key[..at]).is_some_and(|held| *held == r.key[at..]))
    }

    /// Takes as made each write due that the device already holds, once the clock (run on
    /// past it) reaches it: rackd has nothing to write there, and the device cannot tell.
    /// The anchor moves to it at the live time the clock reached it, so the clock runs on
    /// without a jump.
    fn settle(&mut self, now: Duration) {
        while let (Some(d), Some(a)) = (self.due(), self.anchor) {
            let at = self.requests[d].at;
            let reached = a.live + at.saturating_sub(a.recorded);
            if !self.in_place(d) || reached > now {
                return;
            }
            self.made[d] = true;
            self.counters.in_place += 1;
            self.anchor = Some(Anchor { index: Some(d), recorded: at, live: reached });
        }
    }

    fn same(&self, i: usize, key: &[u8]) -> bool {
        self.requests[i].key == key
    }

    fn move_anchor(&mut self, index: usize, now: Duration) {
        self.anchor = Some(Anchor { index: Some(index), recorded: self.requests[index].at, live: now });
    }

    /// A read: the latest recorded one at or before the clock, else the first after it,
    /// both before the write due.
    fn take_read(&mut self, key: &[u8], now: Duration) -> (Option<usize>, Taken) {
        let clock = self.clock(now);
        let end = self.due().unwrap_or(self.requests.len());
        let before = (0..end).rev().find(|&i| self.same(i, key) && self.requests[i].at <= clock);
        let after = || (0..end).find(|&i| self.same(i, key) && self.requests[i].at > clock);
        if let Some(i) = before.or_else(after) {
            let taken = if self.exhausted(now) { Taken::Repeated } else { Taken::Matched };
            return (Some(i), taken);
        }
        let Some(i) = (end..self.requests.len()).find(|&i| self.same(i, key)) else {
            return (None, Taken::Unanswered);
        };
        // `end` is the write due: a read made a little before it, as in the recording a
        // little after, is answered and leaves the clock where it is.
        if self.requests[i].at.saturating_sub(self.requests[end].at) <= self.reorder {
            return (Some(i), Taken::Reordered);
        }
        self.move_anchor(i, now);
        (Some(i), Taken::Skipped)
    }

    /// A write: the one due; a retry of the last; one owed from before; one a little
    /// ahead; one further ahead (skipped to); after the recording's writes, the last.
    fn take_write(&mut self, key: &[u8], now: Duration) -> (Option<usize>, Taken) {
        let open = |m: &Matcher, i: usize| !m.requests[i].read && !m.made[i] && m.same(i, key);
        let Some(due) = self.due() else {
            let last = (0..self.requests.len()).rev().find(|&i| self.same(i, key));
            return (last, if last.is_some() { Taken::Repeated } else { Taken::Unanswered });
        };
        if self.same(due, key) {
            self.made[due] = true;
            self.last_write = Some(due);
            self.move_anchor(due, now);
            return (Some(due), Taken::Matched);
        }
        if let Some(last) = self.last_write.filter(|&i| self.same(i, key)) {
            return (Some(last), Taken::Repeated);
        }
        if let Some(owed) = (0..due).find(|&i| open(self, i)) {
            self.made[owed] = true;
            return (Some(owed), Taken::Matched);
        }
        let Some(ahead) = (due + 1..self.requests.len()).find(|&i| open(self, i)) else {
            return (None, Taken::Unanswered);
        };
        self.made[ahead] = true;
        self.last_write = Some(ahead);
        let near = self.requests[ahead].at.saturating_sub(self.requests[due].at) <= self.reorder;
        self.move_anchor(ahead, now);
        (Some(ahead), if near { Taken::Reordered } else { Taken::Skipped })
    }
}

#[cfg(test)]
#[path = "matcher_tests.rs"]
mod tests;
