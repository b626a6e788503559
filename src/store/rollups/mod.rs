//! Rollups: the KPIs of the job history added up per minute, ten minutes, hour, day and
//! week, per device and per aisle, so that the figures of any period (`/api/v1/stats`) read a few thousand
//! rows whatever the history holds (issue 39).
//!
//! What a rollup row holds ([`Tally`]), for one bucket (`grain`, `bucket`: its start, Unix
//! ms) and one scope (`device:crane1`, `aisle:2`): jobs completed, failed attempts by
//! failure kind, busy time (the part of the bucket during which at least one job was on
//! the device, or in the aisle), and per job kind the completed jobs' count, summed
//! duration and a [`Sketch`] of their durations.
//!
//! Decisions:
//! - **Kept in the writer's own commit.** Every transition goes through the writer, which
//!   notes what it adds ([`Move`]) while a group is applied and writes it with the group's
//!   other rows ([`write::save`]), so rollups are exactly as durable as the jobs. The rows a
//!   group touches are read, added to and written back (read-modify-write: a sketch is not
//!   a sum SQL can do); on PostgreSQL under a transaction-level advisory lock
//!   ([`LOCK`]), since every node of a cluster commits, taken by the last statements of a
//!   writer's transaction (so that no holder of it waits for another lock); on SQLite the
//!   write transaction is the lock already.
//! - **Five grains: minute, ten minutes, hour, day (UTC) and week (from Thursday, as Unix
//!   time).** A period is cut into whole buckets, the largest that fit: minutes up to the
//!   first whole ten minutes, then tens up to the hour, hours up to the day, days up to the
//!   week, weeks, and back down to now. A year reads at most about 130 rows per scope (52
//!   weeks, 2 x 6 days, 2 x 23 hours, 2 x 5 tens, 2 x 9 minutes), eight hours at most about
//!   36. The ten minutes exist for the short periods' sake (a shift read 118 minute rows
//!   per scope without them: 1.3 ms against 0.3 ms on an empty store); the
//!   week for the year's: a busy day's row holds a few thousand bins of
//!   sketches (about 12 KB at 27,000 jobs a day), and 365 of them per scope were 17 MB
//!   to read and add up, about 70 ms (`bench history`, 10 million jobs).
//! - **A period starts on a whole minute.** `since` is taken down to its minute (the answer
//!   says the start used); the end is now, the current minute's row holding everything
//!   committed so far. Minute, ten-minute and hour rows are kept as long as the jobs are
//!   (`[retention]`); a period starting before that starts on its whole day. Day and week
//!   rows are kept
//!   forever, archive or not.
//! - **Busy time is the union of the jobs' spans**, a span running from `dispatched` to
//!   the job leaving `dispatched`, `running` and `cancelling` (an end, or a requeue). Each
//!   scope's count of jobs on it and since when it has been busy are kept in
//!   `rollup_busy`; when the count falls to zero the interval is cut at bucket bounds and
//!   added to each grain's rows. A read adds the open intervals up to now.
//! - **Durations** run from a job's latest `dispatched` to its completion, and count in the
//!   bucket of the completion; failures count in the bucket of the failure, by the kind the
//!   job failed with. A rebuild ([`rebuild`]) reads the kind from the job as stored, so an
//!   attempt retried since shows there as `unknown`: the history keeps no earlier kind.
//! - A job belongs to its device and to every aisle its locations are in.

pub mod fold;
pub mod rebuild;
pub mod sketch;
pub mod write;

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

pub use fold::{Busy, Fold, Move};

use crate::domain::JobSpec;
pub use sketch::Sketch;

/// A minute, in ms.
pub const MINUTE: i64 = 60_000;
/// Ten minutes, in ms.
pub const TEN_MINUTES: i64 = 600_000;
/// An hour, in ms.
pub const HOUR: i64 = 3_600_000;
/// A day, in ms (UTC days: Unix time has no leap seconds).
pub const DAY: i64 = 86_400_000;
/// A week, in ms: seven UTC days from a Thursday (as the Unix epoch).
pub const WEEK: i64 = 7 * DAY;
/// The grains, finest first.
pub const GRAINS: [i64; 5] = [MINUTE, TEN_MINUTES, HOUR, DAY, WEEK];

/// The grains kept only as long as the jobs (`history_from`): those finer than a day. Kept
/// forever, the hours were most of what a store with a 90-day retention gained in a year
/// (`bench retention`: 9% at a million jobs a year).
pub const SHORT: [i64; 3] = [MINUTE, TEN_MINUTES, HOUR];

/// The key of PostgreSQL's advisory lock that every writer of rollups takes for its
/// transaction (`pg_advisory_xact_lock`): "rackdrol" in ASCII.
pub const LOCK: i64 = 0x7261_636b_6472_6f6c;

/// The scope of a device.
pub fn device_scope(device: &str) -> String {
    format!("device:{device}")
}

/// The scope of an aisle.
pub fn aisle_scope(aisle: u16) -> String {
    format!("aisle:{aisle}")
}

/// The scopes of a job: its device's, then each aisle its locations are in.
pub fn scopes(device: Option<&str>, spec: Option<&JobSpec>) -> Vec<String> {
    let mut aisles: Vec<u16> =
        spec.map(|s| s.locations()).unwrap_or_default().iter().map(|l| l.aisle).collect();
    aisles.sort_unstable();
    aisles.dedup();
    device.map(device_scope).into_iter().chain(aisles.into_iter().map(aisle_scope)).collect()
}

/// The start of the bucket of `grain` holding `at`.
pub fn floor(at: i64, grain: i64) -> i64 {
    at.div_euclid(grain) * grain
}

/// A rollup row's key: grain, bucket start, scope.
pub type Key = (i64, i64, String);

/// What a rollup row holds (stored as JSON in `rollups.figures`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Tally {
    /// Jobs completed.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub completed: u64,
    /// Failed attempts by failure kind.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub failures: BTreeMap<String, u64>,
    /// Busy time, ms.
    #[serde(default, skip_serializing_if = "is_zero_ms")]
    pub busy_ms: i64,
    /// Completed jobs' durations by job kind.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub kinds: BTreeMap<String, Durations>,
}

/// The durations of the completed jobs of one kind.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Durations {
    /// How many.
    pub count: u64,
    /// Their sum, ms.
    pub sum_ms: i64,
    /// Their sketch.
    pub sketch: Sketch,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

fn is_zero_ms(n: &i64) -> bool {
    *n == 0
}

impl Tally {
    /// Adds everything `other` holds.
    pub fn merge(&mut self, other: &Tally) {
        self.completed += other.completed;
        for (kind, n) in &other.failures {
            *self.failures.entry(kind.clone()).or_insert(0) += n;
        }
        self.busy_ms += other.busy_ms;
        for (kind, d) in &other.kinds {
            let mine = self.kinds.entry(kind.clone()).or_default();
            mine.count += d.count;
            mine.sum_ms += d.sum_ms;
            mine.sketch.merge(&d.sketch);
        }
    }

    /// Whether it holds nothing.
    pub fn is_empty(&self) -> bool {
        *self == Tally::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tally_merges_and_keeps_its_stored_form_small() {
        let mut a = Tally { completed: 2, busy_ms: 500, ..Tally::default() };
        a.failures.insert("device_fault".into(), 1);
        let mut d = Durations { count: 1, sum_ms: 4000, sketch: Sketch::default() };
        d.sketch.add(4000);
        a.kinds.insert("store".into(), d.clone());
        let mut b = a.clone();
        b.merge(&a);
        assert_eq!((b.completed, b.busy_ms, b.failures["device_fault"]), (4, 1000, 2));
        assert_eq!(
            (b.kinds["store"].count, b.kinds["store"].sum_ms, b.kinds["store"].sketch.count()),
            (2, 8000, 2)
        );
        assert_eq!(serde_json::to_string(&Tally::default()).unwrap(), "{}");
        let back: Tally = serde_json::from_str(&serde_json::to_string(&b).unwrap()).unwrap();
        assert_eq!(back, b);
        assert_eq!(floor(-1, MINUTE), -MINUTE);
        assert_eq!(floor(DAY + 5, HOUR), DAY);
    }
}
