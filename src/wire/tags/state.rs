//! What rackd knows of each tag, as the device status and the API show it.
//!
//! A tag's entry changes only when something about it changes (its value, its quality or
//! its error), never merely because it was polled again, so whoever watches device status
//! for changes (events) sees one change per real change. `changes` counts value changes so
//! a watcher can tell a new value from an old one seen late.

use std::sync::Arc;

use serde::Serialize;
use time::OffsetDateTime;
use utoipa::ToSchema;

use super::codec::{TagType, TagValue, WordOrder};
use super::spec::{ReadError, TagSpec};
use crate::protocols::PlcError;

/// How far a tag's value can be trusted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Quality {
    /// Not read yet.
    Unknown,
    /// The last read succeeded: `value` is what the PLC holds.
    Good,
    /// The last read failed (`error` says why): `value` is the last one read, if any.
    Bad,
}

/// One tag's configuration and latest value.
#[derive(Clone, Debug, PartialEq, Serialize, ToSchema)]
#[schema(example = json!({"address": "4x100", "type": "f32", "word_order": "high-first", "writable": true,
    "min": 0.0, "max": 2.5, "value": 1.25, "quality": "good", "error": null, "changes": 3,
    "changed_at": "2026-11-21T08:00:00.000Z"}))]
pub struct TagStatus {
    /// The address as configured.
    pub address: String,
    /// The value's type.
    #[serde(rename = "type")]
    pub ty: TagType,
    /// Word order (32-bit types only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub word_order: Option<WordOrder>,
    /// Whether the API may write it.
    pub writable: bool,
    /// Smallest value a write may set (numeric types).
    pub min: Option<f64>,
    /// Largest value a write may set (numeric types).
    pub max: Option<f64>,
    /// The latest value read (kept, with quality `bad`, while reads fail); null before the
    /// first good read.
    #[schema(value_type = Option<TagValue>)]
    pub value: Option<TagValue>,
    /// `good`, `bad` or `unknown`.
    pub quality: Quality,
    /// Why the last read failed.
    pub error: Option<String>,
    /// How many times the value changed since rackd started (the first read counts).
    pub changes: u64,
    /// When the value last changed.
    #[serde(with = "time::serde::rfc3339::option")]
    #[schema(value_type = Option<String>, format = DateTime)]
    pub changed_at: Option<OffsetDateTime>,
}

/// A tag with its name, as `GET /devices/{id}/tags` lists them.
#[derive(Clone, Debug, PartialEq, Serialize, ToSchema)]
#[schema(example = json!({"name": "beacon.red", "address": "0x1", "type": "bool", "writable": true,
    "min": null, "max": null, "value": true, "quality": "good", "error": null, "changes": 1,
    "changed_at": "2026-11-21T08:00:00.000Z"}))]
pub struct Tag {
    /// The tag's dotted name.
    pub name: String,
    /// Its configuration and latest value.
    #[serde(flatten)]
    pub status: TagStatus,
}

impl TagStatus {
    /// The status of a tag not read yet.
    pub fn new(spec: &TagSpec) -> Self {
        TagStatus {
            address: spec.address.clone(),
            ty: spec.ty,
            word_order: (spec.ty.words() == 2).then_some(spec.order),
            writable: spec.writable,
            min: spec.limits.map(|l| l.0),
            max: spec.limits.map(|l| l.1),
            value: None,
            quality: Quality::Unknown,
            error: None,
            changes: 0,
            changed_at: None,
        }
    }

    /// Records the outcome of reading the tag at `now`.
    pub fn settle(&mut self, read: Result<TagValue, TagFault>, now: OffsetDateTime) -> bool {
        let before = (self.value, self.quality, self.error.clone());
        match read {
            Ok(value) => {
                if self.value != Some(value) {
                    self.value = Some(value);
                    self.changes += 1;
                    self.changed_at = Some(now);
                }
                self.quality = Quality::Good;
                self.error = None;
            }
            Err(e) => {
                self.quality = Quality::Bad;
                self.error = Some(e.to_string());
            }
        }
        (self.value, self.quality, &self.error) != (before.0, before.1, &before.2)
    }
}

/// Why a poll brought no fresh value for a tag.
#[derive(Clone, Debug, thiserror::Error)]
pub enum TagFault {
    /// The reply held fewer items than were asked for.
    #[error("the reply held fewer items than asked for")]
    Short,
    /// The items read do not make a value of the tag's type.
    #[error(transparent)]
    Read(#[from] ReadError),
    /// The read of this tag failed (the device's own error code, or the link).
    #[error("{0}")]
    Plc(Arc<PlcError>),
    /// Not read: an earlier read of the same poll found the link down.
    #[error("not read: {0}")]
    NotRead(Arc<PlcError>),
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::tags::TagDef;

    #[test]
    fn only_real_changes_change_the_status() {
        let spec = TagSpec::resolve(crate::protocols::Protocol::ModbusTcp, "t", &TagDef::at("4x1")).unwrap();
        let mut s = TagStatus::new(&spec);
        assert_eq!((s.quality, s.value, s.word_order, s.max), (Quality::Unknown, None, None, Some(65535.0)));
        let t0 = OffsetDateTime::UNIX_EPOCH;
        let t1 = t0 + time::Duration::seconds(1);
        s.settle(Ok(TagValue::Int(5)), t0);
        assert_eq!((s.changes, s.changed_at, s.quality), (1, Some(t0), Quality::Good));
        let before = s.clone();
        s.settle(Ok(TagValue::Int(5)), t1);
        assert_eq!(s, before, "the same value again changes nothing");
        s.settle(Err(TagFault::Short), t1);
        assert_eq!((s.quality, s.value, s.changes), (Quality::Bad, Some(TagValue::Int(5)), 1));
        s.settle(Ok(TagValue::Int(6)), t1);
        assert_eq!(
            (s.quality, s.error.as_deref(), s.changes, s.changed_at),
            (Quality::Good, None, 2, Some(t1))
        );
        let json = serde_json::to_value(Tag { name: "t".into(), status: s }).unwrap();
        assert_eq!(
            (json["name"].as_str(), json["type"].as_str(), json["value"].as_i64()),
            (Some("t"), Some("u16"), Some(6))
        );
        assert!(json.get("word_order").is_none());
    }
}
