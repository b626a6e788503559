//! `/api/v1/devices/{id}/tags`: a tags device's values, and writing one (operator role).
//!
//! Status codes: 404 for an unknown device or tag; 409 `not_a_tags_device` when the device
//! exists but is of another kind (the request is fine, the device has no tags); 422 for a
//! value of the wrong type (`invalid_tag_value`), outside the tag's range
//! (`tag_out_of_range`) or a read-only tag (`tag_read_only`); 503 `device_offline` when the
//! device is offline (nothing is sent); 502 `plc_error` when the PLC refuses or the link
//! fails, 504 `plc_timeout` when it does not answer. The PLC's own error text is sent: it
//! is what an operator needs at the machine, and holds nothing of rackd's internals.

use axum::extract::State;
use axum::http::StatusCode;
use serde::Deserialize;
use utoipa::ToSchema;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::device;
use crate::api::error::{ApiError, ErrorBody};
use crate::api::extract::{Caller, Json, Path};
use crate::api::state::AppState;
use crate::devices::tags::{TagsHandle, WriteError};
use crate::protocols::PlcError;
use crate::store::writer::Record;
use crate::wire::tags::{Tag, TagValue, ValueError};

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(list_tags)).routes(routes!(write_tag))
}

/// A tag write.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
#[schema(example = json!({"value": true}))]
pub struct TagWrite {
    /// The new value: `true`/`false` for bool tags, a whole number for u16, i16, u32 and
    /// i32, a finite number for f32; within the tag's `min`..=`max`.
    #[schema(value_type = TagValue)]
    pub value: serde_json::Value,
}

fn tags_of(app: &AppState, id: &str) -> Result<TagsHandle, ApiError> {
    let handle = device(app, id)?;
    handle.tags.clone().ok_or_else(|| {
        let kind = handle.status().kind.as_str();
        ApiError::conflict("not_a_tags_device", format!("device {id:?} is a {kind} device: it has no tags"))
    })
}

impl From<WriteError> for ApiError {
    fn from(e: WriteError) -> Self {
        let message = e.to_string();
        match e {
            WriteError::UnknownTag(_) => ApiError::not_found(message),
            WriteError::ReadOnly(_) => ApiError::invalid("tag_read_only", message),
            WriteError::Invalid { error: ValueError::Range { .. }, .. } => {
                ApiError::invalid("tag_out_of_range", message)
            }
            WriteError::Invalid { .. } => ApiError::invalid("invalid_tag_value", message),
            WriteError::Offline(_) => {
                ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "device_offline", message)
            }
            WriteError::Plc(PlcError::Timeout { .. })
            | WriteError::ReadBack(PlcError::Timeout { .. })
            | WriteError::TimedOut(_) => ApiError::new(StatusCode::GATEWAY_TIMEOUT, "plc_timeout", message),
            WriteError::Plc(_) | WriteError::ReadBack(_) => {
                ApiError::new(StatusCode::BAD_GATEWAY, "plc_error", message)
            }
            WriteError::Stopped => ApiError::unavailable(e),
        }
    }
}

/// Every tag of a tags device with its latest value, quality and change count.
#[utoipa::path(get, path = "/devices/{id}/tags", tag = "devices",
    params(("id" = String, Path, description = "Device id")),
    responses(
        (status = 200, description = "The device's tags, by name", body = Vec<Tag>),
        (status = 404, description = "No such device", body = ErrorBody),
        (status = 409, description = "The device is not a tags device (`not_a_tags_device`)",
            body = ErrorBody),
    ))]
async fn list_tags(State(app): State<AppState>, Path(id): Path<String>) -> Result<Json<Vec<Tag>>, ApiError> {
    Ok(Json(tags_of(&app, &id)?.tags()))
}

/// Write a tag (operator role): the value is checked against the tag's type, range and
/// `writable`, written to the PLC between two polls, read back, and the tag as read back is
/// the answer. An offline device refuses at once.
#[utoipa::path(post, path = "/devices/{id}/tags/{tag}", tag = "devices", request_body = TagWrite,
    params(
        ("id" = String, Path, description = "Device id"),
        ("tag" = String, Path, description = "Tag name, such as `beacon.red`"),
    ),
    responses(
        (status = 200, description = "Written; the tag as read back", body = Tag),
        (status = 404, description = "No such device or tag", body = ErrorBody),
        (status = 409, description = "The device is not a tags device (`not_a_tags_device`)",
            body = ErrorBody),
        (status = 422, description = "`invalid_tag_value` (wrong type), `tag_out_of_range`, `tag_read_only`, \
`invalid_body`", body = ErrorBody),
        (status = 502, description = "`plc_error`: the PLC refused the write or the link failed",
            body = ErrorBody),
        (status = 503, description = "`device_offline`: nothing was sent", body = ErrorBody),
        (status = 504, description = "`plc_timeout`: the PLC did not answer", body = ErrorBody),
    ))]
async fn write_tag(
    State(app): State<AppState>,
    Path((id, tag)): Path<(String, String)>,
    by: Caller,
    body: Result<Json<TagWrite>, ApiError>,
) -> Result<Json<Tag>, ApiError> {
    // Unknown device or tag first: a 404 says more than a complaint about the body.
    let handle = tags_of(&app, &id)?;
    if !handle.has(&tag) {
        return Err(WriteError::UnknownTag(tag).into());
    }
    let Json(body) = body?;
    let written = handle.write(&tag, &body.value).await;
    audit(&app, &by, &id, &tag, &body.value, &written).await;
    Ok(Json(written?))
}

/// Audits a tag write that reached the PLC, or may have (`tag` on `device:ID/TAG`, the
/// value and any doubt in the reason), after the fact: the PLC, not the store, holds the
/// value. A write refused before anything was sent, or refused by the PLC, changed nothing
/// and is not audited.
async fn audit(
    app: &AppState,
    by: &Caller,
    id: &str,
    tag: &str,
    value: &serde_json::Value,
    written: &Result<Tag, WriteError>,
) {
    let reason = match written {
        Ok(_) => format!("value {value}"),
        Err(e @ (WriteError::ReadBack(_) | WriteError::TimedOut(_))) => format!("value {value}; {e}"),
        Err(_) => return,
    };
    let record =
        Record::Audit { action: "tag".into(), target: format!("device:{id}/{tag}"), reason: Some(reason) };
    if let Err(e) = app.writer.record_as(record, by.who()).await {
        tracing::error!(device = %id, tag = %tag, error = %e, "tag write: the audit entry was not stored");
    }
}
