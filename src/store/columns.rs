//! Every table's columns, in one place: the writer's set-based statements and `db copy`
//! name them from here.

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
