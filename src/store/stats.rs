//! KPIs of a period, from the rollups ([`crate::store::rollups`]): per device and per
//! aisle, jobs completed (and per hour), failures by kind, utilisation, and durations by
//! job kind. What each figure means, and what was decided where the spec is silent, is in
//! the rollups' module doc; here, how a period is read.
//!
//! A period `[from, to]` starts on its whole minute (on its whole day when it starts
//! before the minute rows kept, `history_from`), and is cut into the largest whole buckets
//! that fit ([`plan`]); the bucket holding `to` is read whole (it holds what was committed
//! up to now). One read transaction reads them and the scopes still busy, whose open
//! interval counts up to `to`. Means are exact; p95 is the nearest-rank percentile read
//! from the merged sketches, within 1% of the exact one (plus the rounding to the
//! millisecond).

use std::collections::BTreeMap;

use serde::Serialize;
use utoipa::ToSchema;

use super::rollups::write::HISTORY_FROM;
use super::rollups::{DAY, GRAINS, HOUR, MINUTE, TEN_MINUTES, Tally, WEEK, floor};
use super::{Pool, read};

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
    /// 95th percentile (nearest rank, within 1%), seconds.
    pub p95_s: f64,
}

/// The figures of a period.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Period {
    /// Its start as used (Unix ms): the start asked, down to its minute or day.
    pub from: i64,
    /// Per device that had anything, by id.
    pub devices: BTreeMap<String, Figures>,
    /// Per aisle that had anything, by number.
    pub aisles: BTreeMap<u16, Figures>,
}

/// The whole buckets `[from, to]` is cut into, as (grain, first bucket, end) runs: the
/// largest grain that fits at each point, the bucket holding `to` included.
pub fn plan(from: i64, to: i64) -> Vec<(i64, i64, i64)> {
    let end = floor(to, MINUTE) + MINUTE;
    let mut runs: Vec<(i64, i64, i64)> = Vec::new();
    let mut t = floor(from, MINUTE);
    while t < end {
        let grain = GRAINS.into_iter().rev().find(|&g| floor(t, g) == t && t + g <= end).unwrap_or(MINUTE);
        match runs.last_mut() {
            Some((g, _, hi)) if *g == grain && *hi == t => *hi = t + grain,
            _ => runs.push((grain, t, t + grain)),
        }
        t += grain;
    }
    runs
}

/// The figures of `[from, to]` (Unix ms); see the module doc.
pub async fn period(pool: &Pool, from: i64, to: i64) -> Result<Period, sqlx::Error> {
    let mut tx = pool.read_tx().await?;
    let minutes_from: Option<i64> = read!(tx.reader(), p => {
        sqlx::query_scalar("SELECT at FROM rollup_marks WHERE name = $1").bind(HISTORY_FROM).fetch_optional(p).await
    })?;
    let from = if minutes_from.is_some_and(|m| from < m) { floor(from, DAY) } else { floor(from, MINUTE) };
    let runs = plan(from, to);
    let mut tallies: BTreeMap<String, Tally> = BTreeMap::new();
    if !runs.is_empty() {
        let sql: Vec<String> = (0..runs.len())
            .map(|i| {
                let n = 3 * i;
                format!(
                    "SELECT scope, figures FROM rollups WHERE grain = ${} AND bucket >= ${} AND bucket < ${}",
                    n + 1,
                    n + 2,
                    n + 3
                )
            })
            .collect();
        let sql = sqlx::AssertSqlSafe(sql.join(" UNION ALL "));
        let rows: Vec<(String, String)> = read!(tx.reader(), p => {
            let mut q = sqlx::query_as(sql);
            for (grain, lo, hi) in &runs {
                q = q.bind(*grain).bind(*lo).bind(*hi);
            }
            q.fetch_all(p).await
        })?;
        for (scope, figures) in rows {
            if let Ok(t) = serde_json::from_str::<Tally>(&figures) {
                tallies.entry(scope).or_default().merge(&t);
            }
        }
    }
    let busy: Vec<(String, i64)> = read!(tx.reader(), p => {
        sqlx::query_as("SELECT scope, since FROM rollup_busy WHERE active > 0").fetch_all(p).await
    })?;
    tx.finish().await?;
    for (scope, since) in busy {
        let open = to - since.max(from);
        if open > 0 {
            tallies.entry(scope).or_default().busy_ms += open;
        }
    }
    let mut out = Period { from, ..Period::default() };
    for (scope, tally) in tallies {
        let figures = figures(tally, from, to);
        if let Some(device) = scope.strip_prefix("device:") {
            out.devices.insert(device.to_owned(), figures);
        } else if let Some(aisle) = scope.strip_prefix("aisle:").and_then(|a| a.parse().ok()) {
            out.aisles.insert(aisle, figures);
        }
    }
    Ok(out)
}

/// A tally of `[from, to]` as figures.
fn figures(t: Tally, from: i64, to: i64) -> Figures {
    let span = (to - from).max(1);
    let durations = t
        .kinds
        .iter()
        .filter(|(_, d)| d.count > 0)
        .map(|(kind, d)| KindDurations {
            kind: kind.clone(),
            count: d.count,
            mean_s: d.sum_ms as f64 / d.count as f64 / 1000.0,
            p95_s: d.sketch.quantile(0.95).unwrap_or(0.0).round() / 1000.0,
        })
        .collect();
    Figures {
        completed: t.completed,
        per_hour: t.completed as f64 / (span as f64 / HOUR as f64),
        failed: t.failures.values().sum(),
        failures: t.failures,
        utilisation: (t.busy_ms as f64 / span as f64).min(1.0),
        durations,
    }
}

/// The most buckets a period of `days` reads per scope (for the docs and the tests).
pub fn most_buckets(days: i64) -> i64 {
    days / 7
        + 2 * (WEEK / DAY - 1)
        + 2 * (DAY / HOUR - 1)
        + 2 * (HOUR / TEN_MINUTES - 1)
        + 2 * (TEN_MINUTES / MINUTE - 1)
        + 1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_period_is_cut_into_the_largest_whole_buckets() {
        let t = |d: i64, h: i64, m: i64| d * DAY + h * HOUR + m * MINUTE;
        // 8 hours from 02:37:20 to 10:37:25: minutes to 02:40, tens to 03:00, hours to
        // 10:00, tens to 10:30, minutes to 10:38.
        let runs = plan(t(10, 2, 37) + 20_000, t(10, 10, 37) + 25_000);
        assert_eq!(
            runs,
            vec![
                (MINUTE, t(10, 2, 37), t(10, 2, 40)),
                (TEN_MINUTES, t(10, 2, 40), t(10, 3, 0)),
                (HOUR, t(10, 3, 0), t(10, 10, 0)),
                (TEN_MINUTES, t(10, 10, 0), t(10, 10, 30)),
                (MINUTE, t(10, 10, 30), t(10, 10, 38))
            ]
        );
        let buckets: i64 = runs.iter().map(|(g, lo, hi)| (hi - lo) / g).sum();
        assert_eq!(buckets, 3 + 2 + 7 + 3 + 8);
        // A year from a Thursday (day 0, as the epoch) 05:10: the first day's tens and
        // hours, the days to the next week, whole weeks, then days, hours, tens, minutes.
        let runs = plan(t(0, 5, 10), t(365, 4, 3));
        assert_eq!(runs[0], (TEN_MINUTES, t(0, 5, 10), t(0, 6, 0)));
        assert_eq!(runs[1], (HOUR, t(0, 6, 0), t(1, 0, 0)));
        assert_eq!(runs[2], (DAY, t(1, 0, 0), t(7, 0, 0)));
        assert_eq!(runs[3], (WEEK, t(7, 0, 0), t(364, 0, 0)));
        assert_eq!(runs[4], (DAY, t(364, 0, 0), t(365, 0, 0)));
        assert_eq!(runs[5], (HOUR, t(365, 0, 0), t(365, 4, 0)));
        assert_eq!(runs[6], (MINUTE, t(365, 4, 0), t(365, 4, 4)));
        let buckets: i64 = runs.iter().map(|(g, lo, hi)| (hi - lo) / g).sum();
        assert!(buckets <= most_buckets(365), "{buckets}");
        // Within one minute: that minute.
        assert_eq!(plan(t(3, 0, 0) + 5, t(3, 0, 0) + 7), vec![(MINUTE, t(3, 0, 0), t(3, 0, 1))]);
        // Every millisecond of the period is in exactly one bucket.
        for (from, to) in [(t(1, 23, 59), t(3, 0, 1)), (t(0, 0, 0), t(2, 0, 0) - 1), (t(5, 1, 1), t(5, 1, 1))]
        {
            let runs = plan(from, to);
            assert_eq!(runs[0].1, floor(from, MINUTE));
            for pair in runs.windows(2) {
                assert_eq!(pair[0].2, pair[1].1, "{runs:?}");
            }
            assert_eq!(runs.last().unwrap().2, floor(to, MINUTE) + MINUTE);
        }
    }

    #[test]
    fn figures_are_made_from_a_tally() {
        let mut t = Tally { completed: 6, busy_ms: HOUR / 2, ..Tally::default() };
        t.failures.insert("alarm".into(), 2);
        let mut d = super::super::rollups::Durations::default();
        for ms in [1000, 2000, 3000, 4000] {
            d.count += 1;
            d.sum_ms += ms;
            d.sketch.add(ms);
        }
        t.kinds.insert("store".into(), d);
        let f = figures(t, 0, 2 * HOUR);
        assert_eq!((f.completed, f.failed, f.per_hour, f.utilisation), (6, 2, 3.0, 0.25));
        assert_eq!(f.durations[0].mean_s, 2.5);
        assert!((f.durations[0].p95_s - 4.0).abs() <= 0.04 + 0.0005, "{}", f.durations[0].p95_s);
    }
}
