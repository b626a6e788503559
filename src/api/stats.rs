//! `/api/v1/stats`: the store's KPIs over a period, per device and per aisle.
//!
//! The period runs from `since` to now. `since` is an RFC 3339 time or a duration back
//! from now (`90s`, `30m`, `1h`, `8h` for a shift, `2d`, `365d`); the default is one
//! hour, and it reaches back at most 366 days (older is a 400, as is a time in the
//! future). The period starts on `since`'s whole minute (its whole day, UTC, beyond the
//! minute rollups, kept as long as the jobs); the answer's `since` is the start used. Every
//! configured device that runs jobs and every aisle of the layout is listed, with zeros
//! when nothing happened. How the figures are made is in [`crate::store::stats`] and
//! [`crate::store::rollups`].

use axum::extract::State;
use serde::{Deserialize, Serialize};
use time::OffsetDateTime;
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::error::{ApiError, ErrorBody};
use super::extract::{Json, Query};
use super::state::AppState;
use crate::domain::time::{from_ms, now_ms, to_ms};
use crate::store::stats::{self, Figures};

/// How far back `since` may reach: a year, a leap year's included.
pub const MAX_BACK_MS: i64 = 366 * 24 * 3_600_000;

/// The default period: one hour.
const DEFAULT_BACK_MS: i64 = 3_600_000;

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(get_stats))
}

/// The period.
#[derive(Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct StatsParams {
    /// Start of the period: an RFC 3339 time, or a duration back from now (`30m`, `1h`,
    /// `8h`, `2d`, `365d`); default `1h`, at most 366 days back. Taken down to its whole
    /// minute (its day beyond the retention of jobs).
    #[param(example = "8h")]
    since: Option<String>,
}

/// One device's figures.
#[derive(Debug, Serialize, ToSchema)]
pub struct DeviceStats {
    /// The device.
    pub device: String,
    /// Its figures.
    #[serde(flatten)]
    pub figures: Figures,
}

/// One aisle's figures (every job touching it, whichever device ran it).
#[derive(Debug, Serialize, ToSchema)]
pub struct AisleStats {
    /// The aisle.
    pub aisle: u16,
    /// Its figures.
    #[serde(flatten)]
    pub figures: Figures,
}

/// The KPIs of a period.
#[derive(Debug, Serialize, ToSchema)]
#[schema(example = json!({"since": "2026-11-21T07:00:00Z", "until": "2026-11-21T08:00:00Z",
    "devices": [{"device": "crane1", "completed": 41, "per_hour": 41.0, "failed": 1, "failures": {"alarm": 1},
        "utilisation": 0.62, "durations": [{"kind": "store", "count": 30, "mean_s": 48.2, "p95_s": 61.0}]}],
    "aisles": [{"aisle": 2, "completed": 41, "per_hour": 41.0, "failed": 1, "failures": {"alarm": 1},
        "utilisation": 0.62, "durations": [{"kind": "store", "count": 30, "mean_s": 48.2, "p95_s": 61.0}]}]}))]
pub struct Stats {
    /// Start of the period as used: `since` down to its whole minute (or hour).
    #[serde(with = "time::serde::rfc3339")]
    #[schema(value_type = String, format = DateTime)]
    pub since: OffsetDateTime,
    /// End of the period (now).
    #[serde(with = "time::serde::rfc3339")]
    #[schema(value_type = String, format = DateTime)]
    pub until: OffsetDateTime,
    /// Per device that runs jobs, by id.
    pub devices: Vec<DeviceStats>,
    /// Per aisle of the layout, by number.
    pub aisles: Vec<AisleStats>,
}

/// KPIs per device and per aisle: jobs completed (and per hour), failures by kind,
/// utilisation, mean and p95 duration by job kind (p95 within 1%), from the rollups.
#[utoipa::path(get, path = "/stats", tag = "operations", params(StatsParams),
    responses(
        (status = 200, description = "The period's figures", body = Stats),
        (status = 400, description = "`since` is not a time or a duration, is in the future or more than 366 days back", body = ErrorBody),
    ))]
async fn get_stats(
    State(app): State<AppState>,
    Query(p): Query<StatsParams>,
) -> Result<Json<Stats>, ApiError> {
    let until = now_ms();
    let from = match p.since.as_deref() {
        None => until - DEFAULT_BACK_MS,
        Some(text) => since(text, until).map_err(|m| ApiError::bad_request("bad_query", m))?,
    };
    let stats::Period { from, mut devices, mut aisles } = stats::period(&app.pool, from, until).await?;
    let runs_jobs: Vec<String> =
        app.rules().devices.iter().filter(|(_, kinds)| !kinds.is_empty()).map(|(id, _)| id.clone()).collect();
    let devices = runs_jobs
        .into_iter()
        .map(|id| DeviceStats { figures: devices.remove(&id).unwrap_or_else(Figures::default), device: id })
        .collect();
    let aisles = app
        .rules()
        .layout
        .aisles()
        .keys()
        .map(|&n| AisleStats { aisle: n, figures: aisles.remove(&n).unwrap_or_default() })
        .collect();
    Ok(Json(Stats { since: from_ms(from), until: from_ms(until), devices, aisles }))
}

/// The start of the period for `text` (an RFC 3339 time or a duration back from `now`),
/// or why it is refused.
fn since(text: &str, now: i64) -> Result<i64, String> {
    let from = match duration_ms(text) {
        Some(back) => now.checked_sub(back).ok_or_else(|| format!("since {text:?} reaches too far back"))?,
        None => {
            let at = OffsetDateTime::parse(text, &time::format_description::well_known::Rfc3339).map_err(
                |_| {
                    format!(
                        "since {text:?} is neither an RFC 3339 time nor a duration such as 30m, 1h, 8h or 2d"
                    )
                },
            )?;
            to_ms(at)
        }
    };
    if from > now {
        return Err(format!("since {text:?} is in the future"));
    }
    if now - from > MAX_BACK_MS {
        return Err(format!("since {text:?} is more than 366 days back"));
    }
    Ok(from)
}

/// `90s`, `30m`, `8h`, `2d` in milliseconds; None for anything else.
fn duration_ms(text: &str) -> Option<i64> {
    let unit = match text.chars().last()? {
        's' => 1_000,
        'm' => 60_000,
        'h' => 3_600_000,
        'd' => 86_400_000,
        _ => return None,
    };
    let digits = &text[..text.len() - 1];
    if digits.is_empty() || !digits.chars().all(|c| c.is_ascii_digit()) {
        return None;
    }
    digits.parse::<i64>().ok()?.checked_mul(unit)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_and_times() {
        let now = 1000 * 86_400_000;
        assert_eq!(since("1h", now), Ok(now - 3_600_000));
        assert_eq!(since("8h", now), Ok(now - 8 * 3_600_000));
        assert_eq!(since("90s", now), Ok(now - 90_000));
        assert_eq!(since("366d", now), Ok(now - MAX_BACK_MS));
        assert!(since("367d", now).unwrap_err().contains("366 days"));
        assert!(since("h", now).is_err());
        assert!(since("-1h", now).is_err());
        assert!(since("1.5h", now).is_err());
        assert!(since("99999999999999999999h", now).is_err());
        assert!(since("yesterday", now).unwrap_err().contains("RFC 3339"));
        let real_now = now_ms();
        let t = OffsetDateTime::now_utc() - time::Duration::hours(2);
        let text = t.format(&time::format_description::well_known::Rfc3339).unwrap();
        assert!(since(&text, real_now).is_ok());
        let future = OffsetDateTime::now_utc() + time::Duration::hours(2);
        let text = future.format(&time::format_description::well_known::Rfc3339).unwrap();
        assert!(since(&text, real_now).unwrap_err().contains("future"));
    }
}
