//! `GET /api/v1/devices/{id}/capture?seconds=N` (operators): the device's flight recorder
//! as a pcapng file, for Wireshark (`docs/commissioning/capture.md`); and
//! `GET /api/v1/alarms/{id}/capture`: the one frozen when the alarm was raised
//! (`service::captures`).
//!
//! Decisions:
//! - Operators, not viewers: the bytes show every value the machine holds and rackd writes,
//!   more than the dashboard does. Each download is audited (`capture` on `device:ID`,
//!   with the span and the frames the recorder held) before its first byte.
//! - Without `seconds`, everything the recorder holds (its `capture_seconds`, at most
//!   `capture_bytes`); with it, the last N seconds (1 to 86,400).
//! - A device whose recorder is off (`capture_bytes = 0`) answers 409 `capture_off`.
//! - The file holds frames and rackd's notes on them only (`crate::capture`): no key, no
//!   secret, no setting.
//! - **A download cannot take rackd down** (issue 51). The file is built part by part
//!   ([`body`]): 256 KiB of the ring's records copied under the recorder's lock, decoded
//!   and written on a thread of the download's own, handed to the response's body, then
//!   the next part, no sooner than the client takes the one before. So a build holds about
//!   a megabyte whatever the ring's size, and the device's own requests wait on the
//!   recorder for one copy at most. At most `server.capture_downloads` (2) are built at
//!   once, so builds take at most that many cores' time; one more is answered 429
//!   `capture_busy` with `Retry-After`. A client that stops reading keeps its place until
//!   `server.idle_timeout_ms` closes its connection.
//! - **The build's thread runs at nice 10**: on a busy machine the devices' tasks and the
//!   API come first. `bench capture` (50 downloads of a 64 MiB ring on 2 cores, the device
//!   on Modbus TCP's 2 ms timeout floor): 58 timeouts at nice 0, 12 at nice 10, none with a
//!   20 ms floor (docs/development/benchmarks/capture.md). The price: beside a CPU hog a
//!   download is slow (a debug build's 20 MB took minutes beside `stress-ng`).
//! - An alarm's file is streamed from the disk as it is read, 64 KiB at a time. It is the
//!   file of that incident, named after the alarm's raise as well as its id
//!   (`service::captures`): the alarm is read first, and a file of an alarm that had the
//!   same id in another database is never served.

mod body;

use std::time::Duration;

use axum::extract::State;
use axum::http::header;
use axum::response::IntoResponse;
use serde::Deserialize;
use utoipa::IntoParams;

use super::device;
use crate::api::error::{ApiError, ErrorBody};
use crate::api::extract::{Caller, Path, Query};
use crate::api::state::AppState;
use crate::store::writer::Record;

/// `?seconds=`.
#[derive(Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct CaptureParams {
    /// Only the last N seconds (1 to 86,400); everything the recorder holds without it.
    seconds: Option<u64>,
}

/// The pcapng file type (Wireshark's own).
pub const PCAPNG: &str = "application/x-pcapng";

/// The device's recent traffic as a pcapng file: every frame rackd sent and read, with
/// microsecond times, the link's real endpoints, and per packet a comment with the job,
/// the retry and rackd's verdict. Streamed as it is built; at most
/// `server.capture_downloads` are built at once. Audited.
#[utoipa::path(get, path = "/devices/{id}/capture", tag = "devices",
    params(("id" = String, Path, description = "Device id"), CaptureParams),
    responses(
        (status = 200, description = "The capture", content_type = "application/x-pcapng", body = Vec<u8>),
        (status = 403, description = "Not an operator's key", body = ErrorBody),
        (status = 404, description = "No such device", body = ErrorBody),
        (status = 409, description = "The device's recorder is off (`capture_off`: `capture_bytes = 0`)", body = ErrorBody),
        (status = 422, description = "`seconds` out of 1..=86400 (`invalid_seconds`)", body = ErrorBody),
        (status = 429, description = "`capture_busy`: `server.capture_downloads` captures are being built; \
try again in `Retry-After` seconds", body = ErrorBody),
    ))]
pub async fn device_capture(
    State(app): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    Query(p): Query<CaptureParams>,
) -> Result<impl IntoResponse, ApiError> {
    if p.seconds.is_some_and(|s| !(1..=86_400).contains(&s)) {
        return Err(ApiError::invalid("invalid_seconds", "seconds: from 1 to 86400"));
    }
    let handle = device(&app, &id)?;
    let Some(recorder) = handle.recorder else {
        return Err(ApiError::conflict(
            "capture_off",
            format!("device {id:?} records nothing (capture_bytes = 0)"),
        ));
    };
    let place = body::take(&app.capture_builds)?;
    let reader = recorder.reader(p.seconds.map(Duration::from_secs));
    let span = p.seconds.map_or("all it holds".to_owned(), |s| format!("the last {s} s"));
    let audit = Record::Audit {
        action: "capture".into(),
        target: format!("device:{id}"),
        reason: Some(format!("{span}, of {} frames held", reader.held())),
    };
    app.writer.record_as(audit, caller.who()).await?;
    let body = body::build(reader, place).map_err(ApiError::unavailable)?;
    let name = format!("attachment; filename=\"{id}-{}.pcapng\"", stamp());
    Ok(([(header::CONTENT_TYPE, PCAPNG.to_owned()), (header::CONTENT_DISPOSITION, name)], body))
}

/// The capture frozen when alarm `id` was raised (a device's `hardware` or `link` alarm:
/// its last `retention.alarm_capture_seconds` of traffic), streamed from the disk. Audited.
#[utoipa::path(get, path = "/alarms/{id}/capture", tag = "alarms",
    params(("id" = i64, Path, description = "Alarm id")),
    responses(
        (status = 200, description = "The capture", content_type = "application/x-pcapng", body = Vec<u8>),
        (status = 403, description = "Not an operator's key", body = ErrorBody),
        (status = 404, description = "No such alarm, or no capture for it (none was kept: another class, a \
device without a recorder, one kept for the same alarm of the device within \
`retention.alarm_capture_interval_secs`; or deleted: older than the retention, or the oldest past \
`retention.captures_max_bytes`)", body = ErrorBody),
    ))]
pub async fn alarm_capture(
    State(app): State<AppState>,
    caller: Caller,
    Path(id): Path<i64>,
) -> Result<impl IntoResponse, ApiError> {
    let alarm = crate::store::alarms::get(&app.pool, id).await?;
    let Some(alarm) = alarm else { return Err(ApiError::not_found(format!("alarm {id} does not exist"))) };
    // The file of this incident: named after the alarm's raise as well as its id.
    let raised_ms = crate::domain::time::to_ms(alarm.raised_at);
    let file = crate::service::captures::file_of(&app.captures, id, raised_ms);
    let opened = match tokio::fs::File::open(&file).await {
        Ok(opened) => opened,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(ApiError::not_found(format!("alarm {id} has no capture")));
        }
        Err(e) => return Err(ApiError::unavailable(e)),
    };
    let audit = Record::Audit { action: "capture".into(), target: format!("alarm:{id}"), reason: None };
    app.writer.record_as(audit, caller.who()).await?;
    let name = format!("attachment; filename=\"alarm-{id}.pcapng\"");
    Ok(([(header::CONTENT_TYPE, PCAPNG.to_owned()), (header::CONTENT_DISPOSITION, name)], body::file(opened)))
}

/// Now as `20261127T081500Z`, for file names.
pub fn stamp() -> String {
    let now = crate::domain::time::now();
    let format = time::macros::format_description!("[year][month][day]T[hour][minute][second]Z");
    now.format(&format).unwrap_or_default()
}
