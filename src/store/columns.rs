//! Every table's columns, in one place: the writer's set-based statements and `db copy`
//! name them from here; and a job's row as written (the writer, `store::import`).

use serde::Serialize;

use crate::domain::Job;

/// `jobs`.
pub(crate) const JOBS: [&str; 17] = [
    "id",
    "reference",
    "kind",
    "priority",
    "barcode",
    "spec",
    "request",
    "device",
    "state",
    "forced",
    "failure_kind",
    "failure_code",
    "failure_text",
    "device_ref",
    "created_at",
    "updated_at",
    "attempt",
];

/// `job_history`.
pub(crate) const JOB_HISTORY: [&str; 6] = ["id", "job_id", "state", "cause", "detail", "at"];

/// `locations`: the five key columns first.
pub(crate) const LOCATIONS: [&str; 15] = [
    "aisle",
    "row",
    "bay",
    "level",
    "position",
    "occupied",
    "barcode",
    "red",
    "green",
    "reserved_by",
    "updated_at",
    "locked_at",
    "locked_by",
    "lock_reason",
    "lock_job",
];

/// `events`.
pub(crate) const EVENTS: [&str; 4] = ["seq", "at", "type", "data"];

/// `alarms`.
pub(crate) const ALARMS: [&str; 12] = [
    "id",
    "device",
    "kind",
    "code",
    "class",
    "text",
    "detail",
    "action",
    "acknowledged_by",
    "acknowledged_at",
    "raised_at",
    "cleared_at",
];

/// `controls`.
pub(crate) const CONTROLS: [&str; 5] = ["target", "paused", "by", "reason", "at"];

/// `audit`.
pub(crate) const AUDIT: [&str; 7] = ["id", "at", "by", "action", "target", "reason", "client"];

/// `job_counts`: the key columns first.
pub(crate) const JOB_COUNTS: [&str; 3] = ["device", "state", "n"];

/// A job's row, as [`JOBS`] names its columns (`device_ref` is null: a new job has none).
#[derive(Serialize)]
pub(crate) struct JobOut<'a> {
    pub(crate) id: i64,
    pub(crate) reference: Option<&'a str>,
    pub(crate) kind: &'static str,
    pub(crate) priority: u8,
    pub(crate) barcode: Option<&'a str>,
    pub(crate) spec: String,
    pub(crate) request: Option<&'a str>,
    pub(crate) device: Option<&'a str>,
    pub(crate) state: &'static str,
    pub(crate) forced: bool,
    pub(crate) failure_kind: Option<&'static str>,
    pub(crate) failure_code: Option<i64>,
    pub(crate) failure_text: Option<&'a str>,
    pub(crate) created_at: i64,
    pub(crate) updated_at: i64,
    pub(crate) attempt: u32,
}

impl<'a> JobOut<'a> {
    /// `job`'s row; `request` is the request's JSON for a new job (its idempotency check).
    pub(crate) fn new(job: &'a Job, request: Option<&'a str>) -> JobOut<'a> {
        use crate::domain::time::to_ms;
        let f = job.failure.as_ref();
        JobOut {
            id: job.id,
            reference: job.reference.as_deref(),
            kind: job.kind.as_str(),
            priority: job.priority,
            barcode: job.barcode.as_deref(),
            spec: crate::store::jobs::StoredSpec::json(job),
            request,
            device: job.device.as_deref(),
            state: job.state.as_str(),
            forced: job.forced,
            failure_kind: f.map(|f| f.kind.as_str()),
            failure_code: f.and_then(|f| f.code),
            failure_text: f.map(|f| f.text.as_str()),
            created_at: to_ms(job.created_at),
            updated_at: to_ms(job.updated_at),
            attempt: job.attempt,
        }
    }
}
