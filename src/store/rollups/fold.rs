//! Transitions into rollup rows: what each adds to the buckets of its scopes, and the
//! busy intervals each scope opens and closes. The same arithmetic serves the writer (a
//! group's transitions, all at the group's time) and a rebuild (the history replayed in
//! order); it touches no database.

use std::collections::BTreeMap;

use super::{Durations, GRAINS, Key, SHORT, Tally, floor};

/// What one transition of a job adds to the rollups.
#[derive(Clone, Debug, PartialEq)]
pub struct Move {
    /// When (Unix ms).
    pub at: i64,
    /// The job's kind (`store`, ...).
    pub kind: String,
    /// Its device's and aisles' scopes.
    pub scopes: Vec<String>,
    /// +1: the job went on its device; -1: it left it (an end, or a requeue); 0: neither.
    pub on: i64,
    /// How the attempt ended, if it did.
    pub end: Option<End>,
}

/// The end of an attempt, as the rollups count it.
#[derive(Clone, Debug, PartialEq)]
pub enum End {
    /// Completed; the time since its latest dispatch (ms), if it was on its device.
    Completed(Option<i64>),
    /// Failed, with this failure kind.
    Failed(String),
}

/// A scope's jobs on it and since when it has been busy (a row of `rollup_busy`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Busy {
    /// Jobs on it.
    pub active: i64,
    /// Since when at least one has been (Unix ms; meaningless when `active` is 0).
    pub since: i64,
}

/// Transitions being added up: each scope's busy state, and what the rows gain.
#[derive(Debug)]
pub struct Fold {
    /// Each scope's busy state (loaded before, written after).
    pub busy: BTreeMap<String, Busy>,
    /// What each row gains.
    pub rows: BTreeMap<Key, Tally>,
    /// Busy time before this is not added to any row (a rebuild's start).
    pub clip: i64,
    /// Busy time before this is not added to the rows finer than a day (kept only since
    /// then).
    pub minutes_from: i64,
    /// Jobs that left a scope no job was on (the state lost, e.g. rows written by another
    /// tool): not counted, told in the logs.
    pub strays: u64,
}

impl Default for Fold {
    fn default() -> Fold {
        Fold {
            busy: BTreeMap::new(),
            rows: BTreeMap::new(),
            clip: i64::MIN,
            minutes_from: i64::MIN,
            strays: 0,
        }
    }
}

impl Fold {
    /// Adds one transition.
    pub fn add(&mut self, m: &Move) {
        let counted = m.at >= self.clip;
        for scope in &m.scopes {
            match m.end.as_ref().filter(|_| counted) {
                Some(End::Completed(took)) => {
                    self.each_grain(m.at, scope, |t| {
                        t.completed += 1;
                        if let Some(ms) = *took {
                            let d: &mut Durations = t.kinds.entry(m.kind.clone()).or_default();
                            d.count += 1;
                            d.sum_ms += ms;
                            d.sketch.add(ms);
                        }
                    });
                }
                Some(End::Failed(kind)) => {
                    self.each_grain(m.at, scope, |t| *t.failures.entry(kind.clone()).or_insert(0) += 1);
                }
                None => {}
            }
            let busy = self.busy.entry(scope.clone()).or_default();
            if m.on > 0 {
                if busy.active <= 0 {
                    *busy = Busy { active: 0, since: m.at };
                }
                busy.active += 1;
            } else if m.on < 0 {
                if busy.active <= 0 {
                    self.strays += 1;
                    continue;
                }
                busy.active -= 1;
                if busy.active == 0 {
                    let since = busy.since;
                    self.add_busy(scope, since, m.at);
                }
            }
        }
    }

    /// Runs `f` on the row of each grain holding `at` in `scope`.
    fn each_grain(&mut self, at: i64, scope: &str, mut f: impl FnMut(&mut Tally)) {
        for grain in GRAINS {
            f(self.rows.entry((grain, floor(at, grain), scope.to_owned())).or_default());
        }
    }

    /// Adds the busy interval `[from, to)` to every row it overlaps, at each grain.
    fn add_busy(&mut self, scope: &str, from: i64, to: i64) {
        for grain in GRAINS {
            let start = if SHORT.contains(&grain) {
                from.max(self.clip).max(self.minutes_from)
            } else {
                from.max(self.clip)
            };
            let mut bucket = floor(start, grain);
            while bucket < to {
                let part = to.min(bucket + grain) - start.max(bucket);
                if part > 0 {
                    self.rows.entry((grain, bucket, scope.to_owned())).or_default().busy_ms += part;
                }
                bucket += grain;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{DAY, HOUR, MINUTE, TEN_MINUTES, WEEK};
    use super::*;

    fn on(at: i64, on: i64, end: Option<End>) -> Move {
        Move { at, kind: "store".into(), scopes: vec!["device:crane1".into()], on, end }
    }

    fn busy(fold: &Fold, grain: i64, bucket: i64) -> i64 {
        fold.rows.get(&(grain, bucket, "device:crane1".to_owned())).map_or(0, |t| t.busy_ms)
    }

    #[test]
    fn overlapping_jobs_count_their_union_cut_at_every_grain() {
        let mut f = Fold::default();
        // Job 1 from 0:59:30 to 1:01:00, job 2 from 1:00:30 to 1:02:15: busy 0:59:30..1:02:15.
        let t = |m: i64, s: i64| m * MINUTE + s * 1000;
        f.add(&on(t(59, 30), 1, None));
        f.add(&on(t(60, 30), 1, None));
        f.add(&on(t(61, 0), -1, Some(End::Completed(Some(t(1, 30))))));
        assert_eq!(busy(&f, HOUR, 0), 0, "still busy: nothing added yet");
        f.add(&on(t(62, 15), -1, Some(End::Failed("device_fault".into()))));
        assert_eq!(busy(&f, MINUTE, t(59, 0)), 30_000);
        assert_eq!(busy(&f, MINUTE, t(60, 0)), 60_000);
        assert_eq!(busy(&f, MINUTE, t(61, 0)), 60_000);
        assert_eq!(busy(&f, MINUTE, t(62, 0)), 15_000);
        assert_eq!((busy(&f, HOUR, 0), busy(&f, HOUR, HOUR)), (30_000, 135_000));
        assert_eq!((busy(&f, TEN_MINUTES, t(50, 0)), busy(&f, TEN_MINUTES, t(60, 0))), (30_000, 135_000));
        assert_eq!(busy(&f, DAY, 0), 165_000);
        assert_eq!(busy(&f, WEEK, 0), 165_000);
        let hour1 = &f.rows[&(HOUR, HOUR, "device:crane1".to_owned())];
        assert_eq!((hour1.completed, hour1.failures["device_fault"]), (1, 1));
        assert_eq!((hour1.kinds["store"].count, hour1.kinds["store"].sum_ms), (1, 90_000));
        assert_eq!(f.busy["device:crane1"].active, 0);
    }

    #[test]
    fn a_stray_end_and_the_clip_add_nothing_before_their_time() {
        let mut f = Fold { clip: HOUR, minutes_from: HOUR + 30 * MINUTE, ..Fold::default() };
        f.add(&on(10, -1, None));
        assert_eq!((f.strays, f.rows.len()), (1, 0));
        f.add(&on(HOUR - 1000, 1, None));
        f.add(&on(HOUR + 31 * MINUTE, -1, None));
        assert_eq!(busy(&f, HOUR, 0), 0, "before the clip");
        assert_eq!(busy(&f, DAY, 0), 31 * MINUTE, "from the clip");
        assert_eq!(busy(&f, HOUR, HOUR), MINUTE, "rows finer than a day start later");
        assert_eq!(busy(&f, MINUTE, HOUR), 0);
        assert_eq!(busy(&f, MINUTE, HOUR + 30 * MINUTE), MINUTE);
    }
}
