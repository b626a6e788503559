//! KPIs of a period, from the job history: per device and per aisle, jobs completed (and
//! per hour), failures by kind, utilisation, and durations by job kind.
//!
//! Decisions where the spec is silent:
//! - A job counts from the moment its device took it (`dispatched`) until it ended
//!   (`completed`, `failed`, `cancelled`); a retry starts the count again. That span is
//!   the job's duration (only completed jobs' durations are reported: a failure's duration
//!   says little) and, clipped to the period, what utilisation adds up: the share of the
//!   period during which at least one job of the device (aisle) was on it. A job still on
//!   its device counts until the end of the period.
//! - A job belongs to its device and to every aisle its locations are in.
//! - Failures are counted per failed attempt in the period, by the job's failure kind as
//!   stored; an attempt retried since has no kind left and counts as `unknown`.
//! - p95 is the nearest-rank percentile.
//!
//! One query streams the history of every job that changed in the period or is still on a
//! device, a job at a time; the arithmetic is a pure function, tested on its own.

use std::collections::{BTreeMap, BTreeSet};

use serde::Serialize;
use utoipa::ToSchema;

use futures::TryStreamExt;

use super::{Reader, read};
use crate::domain::JobSpec;

/// One history entry with what the KPIs need of its job.
#[derive(Clone, Debug, sqlx::FromRow)]
pub struct Step {
    /// The job.
    pub job_id: i64,
    /// Its kind (`store`, ...).
    pub kind: String,
    /// Its device, if any.
    pub device: Option<String>,
    /// Its spec as stored (JSON).
    pub spec: String,
    /// Its failure kind as stored (the last attempt's).
    pub failure_kind: Option<String>,
    /// The state entered.
    pub state: String,
    /// When (Unix ms).
    pub at: i64,
}

/// The history entries that matter for `[from, to]` (Unix ms): every entry up to `to` of
/// every job that changed in the period or is still on a device, by job then in order.
const STEPS: &str = "SELECT h.job_id, j.kind, j.device, j.spec, j.failure_kind, h.state, h.at \
     FROM job_history h JOIN jobs j ON j.id = h.job_id \
     WHERE h.at <= $2 AND h.job_id IN ( \
         SELECT job_id FROM job_history WHERE at >= $1 AND at <= $2 \
         UNION SELECT id FROM jobs WHERE state IN ('dispatched', 'running', 'cancelling')) \
     ORDER BY h.job_id, h.id";

/// The figures per device and per aisle for `[from, to]` (Unix ms), from the history as
/// it streams from the database: a job at a time is held, never the period's history (at
/// 1,000 jobs an hour, 30 days of it are 330,000 rows: 150 MiB held, and kept by the
/// allocator, when they were read whole).
pub async fn period(
    db: impl Into<Reader<'_>>,
    from: i64,
    to: i64,
) -> Result<(BTreeMap<String, Figures>, BTreeMap<u16, Figures>), sqlx::Error> {
    let mut tallies = Tallies::default();
    let mut job: Vec<Step> = Vec::new();
    read!(db.into(), p => {
        let mut rows = sqlx::query_as::<_, Step>(STEPS).bind(from).bind(to).fetch(p);
        while let Some(step) = rows.try_next().await? {
            if job.first().is_some_and(|first| first.job_id != step.job_id) {
                tallies.job(&job, from, to);
                job.clear();
            }
            job.push(step);
        }
    });
    if !job.is_empty() {
        tallies.job(&job, from, to);
    }
    Ok(tallies.finish(from, to))
}

/// The figures of one device or aisle.
#[derive(Clone, Debug, Default, PartialEq, Serialize, ToSchema)]
pub struct Figures {
    /// Jobs completed in the period.
    pub completed: u64,
    /// Completed per hour of the period.
    pub per_hour: f64,
    /// Attempts that failed in the period.
    pub failed: u64,
    /// Failed attempts by failure kind.
    pub failures: BTreeMap<String, u64>,
    /// 0..1: the share of the period with at least one job on the device (in the aisle).
    pub utilisation: f64,
    /// Completed jobs' durations, by kind.
    pub durations: Vec<KindDurations>,
}

/// How long the completed jobs of one kind took, from dispatch to completion.
#[derive(Clone, Debug, PartialEq, Serialize, ToSchema)]
pub struct KindDurations {
    /// The job kind.
    pub kind: String,
    /// How many completed.
    pub count: u64,
    /// Mean duration, seconds.
    pub mean_s: f64,
    /// 95th percentile (nearest rank), seconds.
    pub p95_s: f64,
}

/// What is being added up for one device or aisle.
#[derive(Default)]
struct Tally {
    completed: u64,
    failures: BTreeMap<String, u64>,
    spans: Vec<(i64, i64)>,
    durations: BTreeMap<String, Vec<i64>>,
}

/// The figures per device and per aisle for `[from, to]`, from `steps` in job order.
pub fn figures(steps: &[Step], from: i64, to: i64) -> (BTreeMap<String, Figures>, BTreeMap<u16, Figures>) {
    let mut tallies = Tallies::default();
    for job in steps.chunk_by(|a, b| a.job_id == b.job_id) {
        tallies.job(job, from, to);
    }
    tallies.finish(from, to)
}

/// The tallies of every device and aisle, a job at a time.
#[derive(Default)]
struct Tallies {
    devices: BTreeMap<String, Tally>,
    aisles: BTreeMap<u16, Tally>,
}

impl Tallies {
    /// Adds one job's steps (its history entries, in order).
    fn job(&mut self, job: &[Step], from: i64, to: i64) {
        let Some(first) = job.first() else { return };
        let spec: Option<JobSpec> = serde_json::from_str(&first.spec).ok().flatten();
        let job_aisles: BTreeSet<u16> =
            spec.map(|s| s.locations()).unwrap_or_default().iter().map(|l| l.aisle).collect();
        let mut started: Option<i64> = None;
        let mut events: Vec<Event> = Vec::new();
        for step in job {
            match step.state.as_str() {
                "dispatched" => started = Some(step.at),
                "queued" => started = None,
                "completed" | "failed" | "cancelled" => {
                    if let Some(start) = started.take() {
                        events.push(Event::Span(start, step.at));
                        if step.state == "completed" && step.at >= from {
                            events.push(Event::Took(step.at - start));
                        }
                    }
                    if step.at >= from && step.state == "completed" {
                        events.push(Event::Completed);
                    }
                    if step.at >= from && step.state == "failed" {
                        events.push(Event::Failed(
                            step.failure_kind.clone().unwrap_or_else(|| "unknown".into()),
                        ));
                    }
                }
                _ => {}
            }
        }
        if let Some(start) = started {
            events.push(Event::Span(start, to));
        }
        if let Some(d) = &first.device {
            apply(self.devices.entry(d.clone()).or_default(), &events, &first.kind);
        }
        for a in job_aisles {
            apply(self.aisles.entry(a).or_default(), &events, &first.kind);
        }
    }

    /// The figures of each device and aisle.
    fn finish(self, from: i64, to: i64) -> (BTreeMap<String, Figures>, BTreeMap<u16, Figures>) {
        let hours = (to - from).max(1) as f64 / 3_600_000.0;
        let done = |t: Tally| finish(t, from, to, hours);
        (
            self.devices.into_iter().map(|(k, t)| (k, done(t))).collect(),
            self.aisles.into_iter().map(|(k, t)| (k, done(t))).collect(),
        )
    }
}

/// What one job adds to a tally.
enum Event {
    Span(i64, i64),
    Took(i64),
    Completed,
    Failed(String),
}

fn apply(tally: &mut Tally, events: &[Event], kind: &str) {
    for e in events {
        match e {
            Event::Span(a, b) => tally.spans.push((*a, *b)),
            Event::Took(ms) => tally.durations.entry(kind.to_owned()).or_default().push(*ms),
            Event::Completed => tally.completed += 1,
            Event::Failed(k) => *tally.failures.entry(k.clone()).or_default() += 1,
        }
    }
}

fn finish(mut t: Tally, from: i64, to: i64, hours: f64) -> Figures {
    let durations = t
        .durations
        .iter_mut()
        .map(|(kind, ms)| {
            ms.sort_unstable();
            let count = ms.len();
            let mean = ms.iter().sum::<i64>() as f64 / count as f64;
            let rank = ((count as f64) * 0.95).ceil() as usize;
            let p95 = ms[rank.clamp(1, count) - 1];
            KindDurations {
                kind: kind.clone(),
                count: count as u64,
                mean_s: mean / 1000.0,
                p95_s: p95 as f64 / 1000.0,
            }
        })
        .collect();
    Figures {
        completed: t.completed,
        per_hour: t.completed as f64 / hours,
        failed: t.failures.values().sum(),
        failures: t.failures,
        utilisation: covered(&mut t.spans, from, to) as f64 / (to - from).max(1) as f64,
        durations,
    }
}

/// How much of `[from, to]` the spans cover together (overlaps counted once).
fn covered(spans: &mut [(i64, i64)], from: i64, to: i64) -> i64 {
    spans.sort_unstable();
    let mut total = 0;
    let mut reach = from;
    for &(a, b) in spans.iter() {
        let (a, b) = (a.max(reach), b.min(to));
        if b > a {
            total += b - a;
            reach = b;
        }
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;

    const SPEC_A1: &str = r#"{"kind":"store","to":{"aisle":1,"row":1,"bay":1,"level":1,"position":1}}"#;

    fn step(job_id: i64, state: &str, at: i64, failure: Option<&str>) -> Step {
        Step {
            job_id,
            kind: "store".into(),
            device: Some("shelf1".into()),
            spec: SPEC_A1.into(),
            failure_kind: failure.map(str::to_owned),
            state: state.into(),
            at,
        }
    }

    #[test]
    fn completions_failures_durations_and_utilisation() {
        let hour = 3_600_000;
        let steps = vec![
            step(1, "queued", 0, None),
            step(1, "dispatched", 1000, None),
            step(1, "running", 1500, None),
            step(1, "completed", 3000, None),
            step(2, "queued", 0, None),
            step(2, "dispatched", 2000, None),
            step(2, "completed", 6000, None),
            step(3, "dispatched", 10_000, None),
            step(3, "failed", 11_000, Some("device_fault")),
            step(4, "dispatched", hour - 1000, None),
        ];
        let (devices, aisles) = figures(&steps, 0, hour);
        let d = &devices["shelf1"];
        assert_eq!((d.completed, d.failed), (2, 1));
        assert_eq!(d.failures["device_fault"], 1);
        assert!((d.per_hour - 2.0).abs() < 1e-9);
        assert_eq!(d.durations.len(), 1);
        assert_eq!((d.durations[0].count, d.durations[0].mean_s, d.durations[0].p95_s), (2, 3.0, 4.0));
        // 1000..6000 (two jobs overlapping), 10000..11000, the last second still running.
        let expected = (5000 + 1000 + 1000) as f64 / hour as f64;
        assert!((d.utilisation - expected).abs() < 1e-12, "{}", d.utilisation);
        assert_eq!(&aisles[&1], d, "one aisle, one device: the same figures");
    }

    #[test]
    fn a_retry_starts_the_count_again_and_the_period_clips() {
        let steps = vec![
            step(1, "dispatched", -5000, None),
            step(1, "failed", 1000, None),
            step(1, "queued", 2000, None),
            step(1, "dispatched", 3000, None),
            step(1, "completed", 4000, None),
        ];
        let (devices, _) = figures(&steps, 0, 10_000);
        let d = &devices["shelf1"];
        assert_eq!((d.completed, d.failed), (1, 1));
        assert_eq!(d.failures["unknown"], 1, "retried since: its kind is gone");
        assert_eq!(d.durations[0].mean_s, 1.0);
        assert!((d.utilisation - 0.2).abs() < 1e-12, "0..1000 and 3000..4000 of 10000");
    }
}
