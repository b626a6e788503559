//! `/api/v1/alarms`: device alarms, active and past; acknowledging one; the history as CSV.
//!
//! An alarm's `text` is the plain sentence (what happened, where), `action` what to do,
//! and `detail` the protocol's or device's own words. Acknowledging says a person has seen
//! it: it does not clear it (only the device does) and the first acknowledgement stands
//! (a second one is a 409), recorded in the audit log and published as `alarm.updated`.

use axum::extract::State;
use axum::http::header;
use axum::response::IntoResponse;
use serde::{Deserialize, Serialize};
use time::OffsetDateTime;
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::{router::OpenApiRouter, routes};

use super::control::actor;
use super::error::{ApiError, ErrorBody};
use super::extract::{Caller, Json, OptionalJson, Path, Query, page};
use super::state::AppState;
use crate::domain::time::{now_ms, to_ms};
use crate::store::alarms::{self, Alarm, AlarmFilter};
use crate::store::writer::Record;

/// The most rows one CSV export holds.
pub const EXPORT_LIMIT: u32 = 100_000;

/// Alarms an export reads from the store at a time: what it holds in memory at once,
/// whatever the period holds.
const EXPORT_PAGE: u32 = 1000;

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(list_alarms))
        .routes(routes!(acknowledge_alarm))
        .routes(routes!(export_alarms))
}

/// An acknowledgement's optional note.
#[derive(Debug, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"note": "crane reset after the e-stop; area checked"}))]
pub struct AcknowledgeRequest {
    /// A note for the audit log (at most 500 characters).
    pub note: Option<String>,
}

/// Acknowledge an alarm: who and when are recorded on it and in the audit log, and an
/// `alarm.updated` event is published. It stays active until the device clears it.
#[utoipa::path(post, path = "/alarms/{id}/acknowledge", tag = "alarms",
    request_body(content = Option<AcknowledgeRequest>),
    params(("id" = i64, Path, description = "Alarm id")),
    responses(
        (status = 200, description = "The alarm, acknowledged", body = Alarm),
        (status = 400, description = "The id is not a number", body = ErrorBody),
        (status = 404, description = "No such alarm", body = ErrorBody),
        (status = 409, description = "Already acknowledged", body = ErrorBody),
        (status = 422, description = "Note too long or unknown field", body = ErrorBody),
    ))]
async fn acknowledge_alarm(
    State(app): State<AppState>,
    Path(id): Path<i64>,
    by: Caller,
    OptionalJson(body): OptionalJson<AcknowledgeRequest>,
) -> Result<Json<Alarm>, ApiError> {
    let actor = actor(by, body.note)?;
    tracing::info!(alarm = id, by = %actor.by, "alarm acknowledged through the API");
    let who = actor.who();
    let record = Record::Acknowledge { alarm: id, by: actor.by, note: actor.reason };
    app.writer.record_as(record, who).await?;
    let alarm = alarms::get(&app.pool, id).await?;
    Ok(Json(alarm.ok_or_else(|| ApiError::not_found(format!("alarm {id} does not exist")))?))
}

/// The period of an export.
#[derive(Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct ExportParams {
    /// Alarms raised at or after this time (RFC 3339; default: the beginning).
    #[serde(default, with = "time::serde::rfc3339::option")]
    #[param(value_type = Option<String>, format = DateTime)]
    since: Option<OffsetDateTime>,
    /// Alarms raised before this time (RFC 3339; default: now).
    #[serde(default, with = "time::serde::rfc3339::option")]
    #[param(value_type = Option<String>, format = DateTime)]
    until: Option<OffsetDateTime>,
}

/// The alarm history as CSV (RFC 4180: fields with commas, quotes or line breaks quoted,
/// quotes doubled), oldest first, at most 100 000 rows. Header:
/// `id,device,kind,code,class,text,detail,raised_at,cleared_at,acknowledged_by,acknowledged_at`.
#[utoipa::path(get, path = "/alarms/export.csv", tag = "alarms", params(ExportParams),
    responses(
        (status = 200, description = "The alarms raised in the period", content_type = "text/csv", body = String),
        (status = 400, description = "Bad time, or `until` before `since`", body = ErrorBody),
    ))]
async fn export_alarms(
    State(app): State<AppState>,
    Query(p): Query<ExportParams>,
) -> Result<impl IntoResponse, ApiError> {
    let from = p.since.map_or(i64::MIN, to_ms);
    let to = p.until.map_or_else(|| now_ms().saturating_add(1), to_ms);
    // A `since` in the future with no `until` is an empty period, not a mistake.
    if p.until.is_some() && to < from {
        return Err(ApiError::bad_request("bad_query", "`until` is before `since`"));
    }
    // The first page before the answer: a store that fails fails the request (a 5xx),
    // rather than an answer cut short.
    let first = alarms::raised_between(&app.pool, from, to, 0, EXPORT_PAGE).await?;
    let mut head = format!("{CSV_HEADER}\r\n");
    lines(&first, &mut head);
    let pages =
        Pages { pool: app.pool.clone(), from, to, last: first.last().map(|a| a.id), sent: first.len() };
    let rest = futures::stream::unfold(pages, Pages::next);
    let body = futures::StreamExt::chain(futures::stream::once(async { Ok(bytes::Bytes::from(head)) }), rest);
    let headers = [
        (header::CONTENT_TYPE, "text/csv; charset=utf-8"),
        (header::CONTENT_DISPOSITION, "attachment; filename=\"alarms.csv\""),
    ];
    Ok((headers, axum::body::Body::from_stream(body)))
}

/// The rest of an export after its first page, a page at a time (see [`EXPORT_PAGE`]).
struct Pages {
    pool: crate::store::Pool,
    from: i64,
    to: i64,
    /// The last alarm sent; None once the period is done.
    last: Option<i64>,
    /// Alarms sent so far.
    sent: usize,
}

impl Pages {
    /// The next page's lines, if any; a store that fails now ends the answer short (the
    /// client sees the transfer broken off), and is logged.
    async fn next(mut self) -> Option<(Result<bytes::Bytes, std::io::Error>, Pages)> {
        let after = self.last.filter(|_| self.sent.is_multiple_of(EXPORT_PAGE as usize))?;
        let limit = EXPORT_PAGE.min(EXPORT_LIMIT.saturating_sub(self.sent as u32));
        if limit == 0 {
            return None;
        }
        match alarms::raised_between(&self.pool, self.from, self.to, after, limit).await {
            Ok(page) if page.is_empty() => None,
            Ok(page) => {
                let mut out = String::new();
                lines(&page, &mut out);
                (self.last, self.sent) = (page.last().map(|a| a.id), self.sent + page.len());
                Some((Ok(bytes::Bytes::from(out)), self))
            }
            Err(e) => {
                tracing::error!(error = %e, "the alarm export could not read the store; its answer ends short");
                self.last = None;
                Some((Err(std::io::Error::other("the store failed")), self))
            }
        }
    }
}

/// The export's header line.
pub const CSV_HEADER: &str =
    "id,device,kind,code,class,text,detail,raised_at,cleared_at,acknowledged_by,acknowledged_at";

/// Alarms as CSV lines (CRLF, as RFC 4180 writes them), appended to `out`.
fn lines(alarms: &[Alarm], out: &mut String) {
    let at = |t: Option<OffsetDateTime>| {
        t.and_then(|t| t.format(&time::format_description::well_known::Rfc3339).ok()).unwrap_or_default()
    };
    for a in alarms {
        let fields = [
            a.id.to_string(),
            a.device.clone(),
            a.kind.as_str().to_owned(),
            a.code.to_string(),
            a.class.as_str().to_owned(),
            a.text.clone(),
            a.detail.clone().unwrap_or_default(),
            at(Some(a.raised_at)),
            at(a.cleared_at),
            a.acknowledged_by.clone().unwrap_or_default(),
            at(a.acknowledged_at),
        ];
        let line: Vec<String> = fields.iter().map(|f| field(f)).collect();
        out.push_str(&line.join(","));
        out.push_str("\r\n");
    }
}

/// One CSV field: quoted (quotes doubled) when it holds a comma, a quote or a line break.
fn field(value: &str) -> String {
    if value.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", value.replace('"', "\"\""))
    } else {
        value.to_owned()
    }
}

/// Filters and paging for the alarm list.
#[derive(Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct AlarmParams {
    /// Only active (true) or only cleared (false) alarms.
    active: Option<bool>,
    /// Only this device's alarms.
    device: Option<String>,
    /// Continue after this cursor (the `next_cursor` of the previous page).
    cursor: Option<String>,
    /// Alarms per page, 1..=1000 (default 100).
    #[param(minimum = 1, maximum = 1000)]
    limit: Option<u32>,
}

/// A page of alarms.
#[derive(Serialize, ToSchema)]
pub struct AlarmPage {
    /// Alarms, newest first.
    pub alarms: Vec<Alarm>,
    /// Pass as `cursor` for the next (older) page; absent on the last page.
    pub next_cursor: Option<String>,
}

/// Device alarms, newest first: device, code, class, text, raised and cleared times.
///
/// A crane's alarm (its D205 code, with the catalogue's text and class) is raised when the
/// crane reports it and cleared when the crane no longer does; a `link` alarm (code 0) is
/// raised while a device does not answer.
#[utoipa::path(get, path = "/alarms", tag = "alarms", params(AlarmParams),
    responses(
        (status = 200, description = "A page of alarms", body = AlarmPage),
        (status = 400, description = "Bad filter or cursor", body = ErrorBody),
    ))]
async fn list_alarms(
    State(app): State<AppState>,
    Query(p): Query<AlarmParams>,
) -> Result<Json<AlarmPage>, ApiError> {
    let (limit, before_id) = page(p.limit, p.cursor, 1)?;
    let filter = AlarmFilter { active: p.active, device: p.device, before_id, limit };
    let alarms = alarms::list(&app.pool, &filter).await?;
    let next_cursor =
        (alarms.len() == limit as usize).then(|| alarms.last().map(|a| a.id.to_string())).flatten();
    Ok(Json(AlarmPage { alarms, next_cursor }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_with_commas_quotes_or_line_breaks_are_quoted() {
        assert_eq!(field("plain"), "plain");
        assert_eq!(field("a,b"), "\"a,b\"");
        assert_eq!(field("say \"hi\""), "\"say \"\"hi\"\"\"");
        assert_eq!(field("two\nlines"), "\"two\nlines\"");
        assert_eq!(field(""), "");
    }
}
