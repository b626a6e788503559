//! What holds a queued job back for other jobs: its sequence and its dependencies.
//!
//! **Sequences.** The members of one sequence reach their destination in `position` order.
//! Positions run 1, 2, 3...; a position is *delivered* when its job completed, *passed* when
//! its job was cancelled (or, once the sequence is complete, when nobody posted it). The
//! member *due* is the lowest position neither delivered nor passed; only it may be handed
//! out, and only once the member before it has completed: a crane's cycle has no upper
//! bound (an alarm can stop it for an hour), so nothing can be promised about a box still
//! in the rack. Decisions where the issue left them open:
//! - a missing position holds the later ones (the WMS may still post it, and a member posted
//!   as the `last` only says where the sequence ends); once the WMS completes the sequence
//!   (`POST /api/v1/sequences/{name}/complete`: no member will join any more), it is
//!   passed;
//! - a failed member holds the sequence (`sequence`, naming it) until an operator retries it
//!   and it completes, or the WMS cancels the sequence: a tote missing from a pick order is
//!   the picker's business, not something to skip silently (openTCS's `failureFatal` would
//!   withdraw the rest; a WMS that wants that cancels the sequence);
//! - a member cancelled alone is passed: the WMS chose to drop it.
//!
//! **Across aisles.** A member in aisle B whose predecessor ran in aisle A is released at
//! `t + transit(A) - transit(B)`, `t` being when the predecessor completed and `transit` the
//! station's `[[site.stations]]` times from each aisle's exit (0 when not listed): it then
//! reaches the station no earlier than its predecessor, as long as a box takes at least
//! its aisle's transit. Without a sequencing buffer between the aisles and the station that
//! is all rackd can promise: members run one after the other, each starting no earlier than
//! its predecessor's end (less the difference of transits), so a sequence spread over
//! several aisles takes the sum of its members' cycles. Other work fills the cranes
//! meanwhile.
//!
//! **Dependencies.** A job waits until every job its `after` names has completed. A
//! dependency that failed or was cancelled holds it (`dependency`, naming the job) until the
//! dependency is retried and completes, or the job is cancelled: a job that made sense only
//! after another must not run when that one did not.
//!
//! The book keeps only sequences with an unfinished member and references an unfinished job
//! waits for, fed by the writer's commits ([`Book::committed`], [`Book::sequenced`]). What
//! it has not seen (at start, or a sequence whose members all ended long ago) is read from
//! the store by [`resolve`] before the job may go: until then it waits.

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};

use crate::config::StationConfig;
use crate::domain::{Job, JobState, Waiting, WaitingReason};
use crate::store::sequences::Row;

/// One sequence's members as the book knows them.
#[derive(Debug, Default)]
struct Seq {
    /// The sequence's row (None until read).
    row: Option<Row>,
    /// Members by position.
    members: BTreeMap<u32, Member>,
}

/// A member: its job, the job's state, its aisle and when it last changed (Unix ms).
#[derive(Clone, Copy, Debug)]
struct Member {
    job: i64,
    state: JobState,
    aisle: Option<u16>,
    at: i64,
}

/// What became of a job a reference names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Dep {
    job: i64,
    state: JobState,
}

/// The sequences and dependencies of unfinished jobs.
#[derive(Debug, Default)]
pub struct Book {
    sequences: HashMap<String, Seq>,
    /// Each reference an unfinished job waits for, with what became of its job (None: not
    /// read yet).
    refs: HashMap<String, Option<Dep>>,
    /// The unfinished jobs waiting for each reference.
    waiters: HashMap<String, BTreeSet<i64>>,
    /// The stations, by id.
    stations: HashMap<u16, StationConfig>,
    /// Every unfinished job with a deadline: (deadline in Unix ms, job).
    deadlines: BTreeSet<(i64, i64)>,
    /// Unfinished jobs told late (a `job.late` event committed or asked for).
    late: HashSet<i64>,
    /// Jobs that ended after their deadline, since the start.
    pub ended_late: u64,
    /// Members delivered out of order since the start, by station (0: none): completed
    /// while an earlier position was neither delivered nor passed, or due at the station
    /// (its end plus its aisle's transit) before the member ahead of it.
    pub inversions: BTreeMap<u16, u64>,
}

/// Deadlines and sequences as `/metrics` shows them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Orders {
    /// Unfinished jobs past their deadline.
    pub late: usize,
    /// Jobs that ended after their deadline, since the start.
    pub ended_late: u64,
    /// Seconds to the nearest deadline of an unfinished job (negative once passed).
    pub slack: Option<f64>,
    /// Sequence members delivered out of order, by station (0: none), since the start.
    pub inversions: BTreeMap<u16, u64>,
}

/// What [`resolve`] must read: sequences and references the book has not seen.
#[derive(Debug, Default, PartialEq, Eq)]
pub struct Unknown {
    /// Sequences with no row.
    pub sequences: BTreeSet<String>,
    /// References with no state.
    pub refs: BTreeSet<String>,
}

impl Unknown {
    /// Whether nothing is unknown.
    pub fn is_empty(&self) -> bool {
        self.sequences.is_empty() && self.refs.is_empty()
    }
}

fn aisle_of(job: &Job) -> Option<u16> {
    job.spec().and_then(|s| s.locations().first().map(|l| l.aisle))
}

impl Book {
    /// Sets the stations (at start, and on a reload).
    pub fn set_stations(&mut self, stations: &[StationConfig]) {
        self.stations = stations.iter().map(|s| (s.id, s.clone())).collect();
    }

    /// Takes in committed jobs; true when the book changed (a job it holds may move, or
    /// there is something to read).
    pub fn committed(&mut self, jobs: &[&Job]) -> bool {
        let mut changed = false;
        for job in jobs {
            if job.sequence.is_some() || !job.after.is_empty() {
                changed = true;
            }
            if let Some(deadline) = job.deadline.map(crate::domain::time::to_ms) {
                changed = true;
                if job.state.is_terminal() {
                    self.deadlines.remove(&(deadline, job.id));
                    self.late.remove(&job.id);
                    if job.late_at(0).is_some() {
                        self.ended_late += 1;
                    }
                } else {
                    self.deadlines.insert((deadline, job.id));
                }
            }
            if let Some(m) = &job.sequence {
                let member = Member {
                    job: job.id,
                    state: job.state,
                    aisle: aisle_of(job),
                    at: crate::domain::time::to_ms(job.updated_at),
                };
                self.delivered(&m.name, m.position, member);
                self.sequences.entry(m.name.clone()).or_default().members.insert(m.position, member);
            }
            if let Some(r) = &job.reference
                && let Some(dep) = self.refs.get_mut(r)
            {
                *dep = Some(Dep { job: job.id, state: job.state });
                changed = true;
            }
            for r in &job.after {
                let waiters = self.waiters.entry(r.clone()).or_default();
                if job.state.is_terminal() {
                    waiters.remove(&job.id);
                } else {
                    waiters.insert(job.id);
                    self.refs.entry(r.clone()).or_insert(None);
                }
            }
        }
        if changed {
            self.forget();
        }
        changed
    }

    /// Takes in committed sequence rows. A sequence the book does not hold is left to
    /// [`resolve`], which reads its members with it.
    pub fn sequenced(&mut self, rows: &[Row]) {
        for row in rows {
            if let Some(seq) = self.sequences.get_mut(&row.name) {
                seq.row = Some(row.clone());
            }
        }
    }

    /// Takes in what [`resolve`] read: sequence rows with their ended members, and what
    /// became of references (a reference no job has is left unknown: the job keeps
    /// waiting, as it would for a job never posted).
    pub fn read(
        &mut self,
        sequences: Vec<crate::store::sequences::Stored>,
        refs: Vec<(String, i64, JobState)>,
    ) {
        for stored in sequences {
            let seq = self.sequences.entry(stored.row.name.clone()).or_default();
            for (position, m) in stored.members {
                // What a commit told is newer than what the read saw.
                if seq.members.contains_key(&position) {
                    continue;
                }
                let Some(state) = m.state else { continue };
                let member = Member { job: m.job, state, aisle: m.aisle, at: m.updated_at.unwrap_or(0) };
                seq.members.insert(position, member);
            }
            if seq.row.is_none() {
                seq.row = Some(stored.row);
            }
        }
        for (r, job, state) in refs {
            if let Some(dep) = self.refs.get_mut(&r)
                && dep.is_none()
            {
                *dep = Some(Dep { job, state });
            }
        }
    }

    /// Counts an inversion if `member`, which completes now, should not have: a position
    /// before it is neither delivered nor passed, or its box reaches the station before the
    /// box of the member ahead of it.
    fn delivered(&mut self, name: &str, position: u32, member: Member) {
        let Some(seq) = self.sequences.get(name) else { return };
        let was = seq.members.get(&position).map(|m| m.state);
        if member.state != JobState::Completed || was == Some(JobState::Completed) || seq.row.is_none() {
            return;
        }
        let station = seq.row.as_ref().and_then(|r| r.station).and_then(|s| u16::try_from(s).ok());
        let early = match due(seq) {
            Due::Position(p) => p != position,
            Due::Done => false,
        };
        // Its box reaches the station before the box ahead of it: it ended before its release.
        let overtakes =
            self.release(seq, position, member.aisle).is_some_and(|(release, _, _)| member.at < release);
        if early || overtakes {
            tracing::warn!(sequence = name, position, "a sequence member was delivered out of order");
            *self.inversions.entry(station.unwrap_or(0)).or_default() += 1;
        }
    }

    /// The unfinished jobs whose deadline passed by `now` and that were not told late yet,
    /// now noted as told.
    pub fn newly_late(&mut self, now: i64) -> Vec<i64> {
        let late: Vec<i64> = self
            .deadlines
            .range(..(now, i64::MAX))
            .map(|&(_, id)| id)
            .filter(|id| !self.late.contains(id))
            .collect();
        self.late.extend(late.iter().copied());
        late
    }

    /// The next deadline after `now`, if any.
    pub fn next_deadline(&self, now: i64) -> Option<i64> {
        self.deadlines.range((now, i64::MAX)..).next().map(|&(d, _)| d)
    }

    /// Unfinished jobs past their deadline at `now`, and the seconds to the nearest
    /// deadline of an unfinished job (negative once passed), if any has one.
    pub fn lateness(&self, now: i64) -> (usize, Option<f64>) {
        let late = self.deadlines.range(..(now, i64::MAX)).count();
        let slack = self.deadlines.first().map(|&(d, _)| (d - now) as f64 / 1000.0);
        (late, slack)
    }

    /// Drops what no unfinished job needs any more.
    fn forget(&mut self) {
        self.sequences.retain(|_, s| s.members.values().any(|m| !m.state.is_terminal()));
        self.waiters.retain(|_, w| !w.is_empty());
        let waiters = &self.waiters;
        self.refs.retain(|r, _| waiters.contains_key(r));
    }

    /// What the book has not read yet.
    pub fn unknown(&self) -> Unknown {
        Unknown {
            sequences: self
                .sequences
                .iter()
                .filter(|(_, s)| s.row.is_none())
                .map(|(n, _)| n.clone())
                .collect(),
            refs: self.refs.iter().filter(|(_, d)| d.is_none()).map(|(r, _)| r.clone()).collect(),
        }
    }

    /// Why `job` may not start at `now` (Unix ms) for another job, if anything holds it:
    /// a dependency first, then its sequence.
    pub fn why(&self, job: &Job, now: i64) -> Option<Waiting> {
        for r in &job.after {
            let hold = |text: String, id: Option<i64>| {
                let mut w = Waiting::new(WaitingReason::Dependency, text);
                w.job = id;
                Some(w)
            };
            match self.refs.get(r).copied().flatten() {
                None => return hold(format!("waits for job {r:?}: reading what became of it"), None),
                Some(d) if d.state == JobState::Completed => continue,
                Some(d) if d.state.is_terminal() => {
                    let text = format!(
                        "job {} ({r:?}) it waits for {}: retry it, or cancel this job",
                        d.job,
                        d.state.as_str()
                    );
                    return hold(text, Some(d.job));
                }
                Some(d) => return hold(format!("waits for job {} ({r:?}) to complete", d.job), Some(d.job)),
            }
        }
        let m = job.sequence.as_ref()?;
        let hold = |text: String, id: Option<i64>| {
            let mut w = Waiting::new(WaitingReason::Sequence, format!("sequence {:?}: {text}", m.name));
            w.job = id;
            Some(w)
        };
        let Some(seq) = self.sequences.get(&m.name).filter(|s| s.row.is_some()) else {
            return hold("reading its members".into(), None);
        };
        let row = seq.row.as_ref()?;
        if row.cancelled_at.is_some() {
            return hold("cancelled".into(), None);
        }
        match due(seq) {
            Due::Position(p) if p == m.position => {}
            Due::Position(p) => {
                return match seq.members.get(&p) {
                    Some(other) if other.state == JobState::Failed => hold(
                        format!("position {p} (job {}) failed: retry it, or cancel the sequence", other.job),
                        Some(other.job),
                    ),
                    Some(other) => {
                        hold(format!("position {p} (job {}) goes first", other.job), Some(other.job))
                    }
                    None => hold(format!("position {p} is not posted yet"), None),
                };
            }
            Due::Done => return None,
        }
        // The due member: released once its predecessor's box is far enough ahead.
        if let Some((release, p, ahead)) = self.release(seq, m.position, aisle_of(job))
            && now < release
        {
            let secs = (release - now + 999) / 1000;
            let text = format!("released in {secs} s, so that it reaches the station after position {p}");
            return hold(text, Some(ahead));
        }
        None
    }

    /// Seconds from `aisle`'s exit to the station of `seq` (0 without either).
    fn transit(&self, seq: &Seq, aisle: Option<u16>) -> f64 {
        let station = seq.row.as_ref().and_then(|r| r.station).and_then(|s| u16::try_from(s).ok());
        match (station.and_then(|s| self.stations.get(&s)), aisle) {
            (Some(s), Some(a)) => s.transit_s(a),
            _ => 0.0,
        }
    }

    /// When the member at `position` of `seq`, from `aisle`, may go (Unix ms), after the
    /// nearest member ahead of it that completed: that one's end plus the difference of
    /// their transits. With the position and job of that member; None without one.
    fn release(&self, seq: &Seq, position: u32, aisle: Option<u16>) -> Option<(i64, u32, i64)> {
        let (&p, ahead) =
            seq.members.range(..position).rev().find(|(_, b)| b.state == JobState::Completed)?;
        let lead = self.transit(seq, ahead.aisle) - self.transit(seq, aisle);
        Some((ahead.at + (lead * 1000.0).ceil() as i64, p, ahead.job))
    }

    /// The earliest time (Unix ms) after `now` at which a member held for transit alone is
    /// released, if any: the dispatcher wakes then.
    pub fn next_release(&self, now: i64) -> Option<i64> {
        self.sequences
            .values()
            .filter(|seq| seq.row.is_some())
            .filter_map(|seq| {
                let Due::Position(p) = due(seq) else { return None };
                let member = seq.members.get(&p)?;
                Some(self.release(seq, p, member.aisle)?.0)
            })
            .filter(|&release| release > now)
            .min()
    }
}

/// Which position of a sequence is due.
#[derive(Debug, PartialEq, Eq)]
enum Due {
    /// This one (posted or not).
    Position(u32),
    /// None: every position is delivered or passed.
    Done,
}

fn due(seq: &Seq) -> Due {
    let row = seq.row.as_ref();
    let last = row.and_then(|r| r.last).and_then(|l| u32::try_from(l).ok());
    let closed = row.is_some_and(|r| r.completed_at.is_some());
    match next_due(seq.members.iter().map(|(&p, m)| (p, m.state)), last, closed) {
        Some(p) => Due::Position(p),
        None => Due::Done,
    }
}

/// The position due of a sequence whose members are `members` (by position, in order),
/// whose last position is `last` once known, and that is `closed` once the WMS completed
/// it: the lowest neither delivered (completed) nor passed (cancelled, or never posted in
/// a closed sequence); None when every one is.
pub fn next_due(
    members: impl IntoIterator<Item = (u32, JobState)>,
    last: Option<u32>,
    closed: bool,
) -> Option<u32> {
    let mut expect = 1u32;
    for (p, state) in members {
        if p > expect && !closed {
            return Some(expect);
        }
        match state {
            JobState::Completed | JobState::Cancelled => expect = p.saturating_add(1),
            _ => return Some(p),
        }
    }
    match last {
        _ if closed => None,
        Some(l) if expect > l => None,
        _ => Some(expect),
    }
}

/// Reads what `book` has not seen from the store: the sequences' rows and members, the
/// references' jobs.
pub async fn resolve(pool: &crate::store::Pool, unknown: &Unknown) -> Result<ReadBack, sqlx::Error> {
    let sequences = crate::store::sequences::many(pool, &unknown.sequences).await?.into_values().collect();
    let mut refs = Vec::new();
    for r in &unknown.refs {
        let filter = crate::store::JobFilter { reference: Some(r.clone()), limit: 1, ..Default::default() };
        if let Some(job) = crate::store::jobs::list(pool, &filter).await?.into_iter().next() {
            refs.push((r.clone(), job.id, job.state));
        }
    }
    Ok(ReadBack { sequences, refs })
}

/// What [`resolve`] read.
pub struct ReadBack {
    /// The sequences, with their members.
    pub sequences: Vec<crate::store::sequences::Stored>,
    /// Each reference found: its job and state.
    pub refs: Vec<(String, i64, JobState)>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Transit;
    use crate::domain::{JobSpec, Location, Member as Place, NewJob, Priority, Terms};
    use crate::store::sequences::Stored;
    use JobState::*;

    #[test]
    fn the_position_due_passes_only_what_was_delivered_cancelled_or_never_posted_once_closed() {
        let due = |m: &[(u32, JobState)], last, closed| next_due(m.iter().copied(), last, closed);
        assert_eq!(due(&[], None, false), Some(1));
        assert_eq!(due(&[(1, Completed), (3, Queued)], None, false), Some(2), "a gap holds");
        assert_eq!(
            due(&[(1, Completed), (3, Queued)], Some(3), false),
            Some(2),
            "also once the last is known"
        );
        assert_eq!(due(&[(1, Completed), (3, Queued)], Some(3), true), Some(3), "closed: the gap is passed");
        assert_eq!(due(&[(1, Cancelled), (2, Failed), (3, Queued)], None, false), Some(2), "a failure holds");
        assert_eq!(due(&[(1, Completed), (2, Completed)], Some(2), false), None);
        assert_eq!(due(&[(1, Completed)], Some(2), false), Some(2));
        assert_eq!(due(&[(1, Completed)], None, true), None);
    }

    fn member(id: i64, aisle: u16, position: u32, state: JobState, at: i64) -> Job {
        let from = Location { aisle, row: 1, bay: 1, level: 1, position: 1 };
        let terms = Terms { sequence: Some(Place { name: "S".into(), position }), ..Terms::default() };
        let new = NewJob {
            spec: JobSpec::Retrieve { from },
            reference: None,
            priority: Priority::DEFAULT,
            barcode: None,
            device: None,
            serves: None,
            terms,
        };
        let mut job = new.accepted(id, at);
        job.state = state;
        job
    }

    fn row(station: Option<i64>) -> Row {
        Row {
            name: "S".into(),
            station,
            last: None,
            completed_at: None,
            cancelled_at: None,
            created_at: 0,
            updated_at: 0,
        }
    }

    #[test]
    fn a_member_from_a_nearer_aisle_waits_out_the_transit_of_the_one_ahead() {
        let mut book = Book::default();
        let transit = vec![Transit { aisle: 2, seconds: 40.0 }, Transit { aisle: 3, seconds: 10.0 }];
        book.set_stations(&[StationConfig { id: 1, name: None, transit }]);
        let (one, two) = (member(1, 2, 1, Completed, 100_000), member(2, 3, 2, Queued, 90_000));
        book.committed(&[&one, &two]);
        assert!(book.why(&two, 200_000).unwrap().text.contains("reading"), "not read yet: it waits");
        book.read(vec![Stored { row: row(Some(1)), members: Default::default() }], Vec::new());
        // Aisle 2's box needs 40 s to the station, aisle 3's 10 s: position 2 goes 30 s later.
        let held = book.why(&two, 129_000).expect("held for the transit");
        assert_eq!((held.reason, held.job), (WaitingReason::Sequence, Some(1)), "{held:?}");
        assert_eq!(book.next_release(129_000), Some(130_000));
        assert_eq!(book.why(&two, 130_000), None);
        // Without a station, it goes once the one ahead completed.
        let mut other = Book::default();
        other.committed(&[&one, &two]);
        other.read(vec![Stored { row: row(None), members: Default::default() }], Vec::new());
        assert_eq!(other.why(&two, 100_000), None);
    }

    #[test]
    fn a_member_completed_out_of_turn_is_counted_an_inversion() {
        let mut book = Book::default();
        let (one, two) = (member(1, 2, 1, Queued, 0), member(2, 2, 2, Queued, 0));
        book.committed(&[&one, &two]);
        book.read(vec![Stored { row: row(None), members: Default::default() }], Vec::new());
        let two_done = member(2, 2, 2, Completed, 1000);
        book.committed(&[&two_done]);
        assert_eq!(book.inversions.get(&0), Some(&1));
        let one_done = member(1, 2, 1, Completed, 2000);
        book.committed(&[&one_done]);
        assert_eq!(book.inversions.get(&0), Some(&1), "position 1 was due: in turn");
    }
}
