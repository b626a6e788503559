//! What operators set, kept across restarts: pauses of devices and aisles, and the audit
//! log of every change made through the API (submissions, cancels, priorities, retries,
//! pauses, locks, the inventory, alarm acknowledgements, tag writes) with who, from which
//! address, when and why.
//!
//! The writer writes both (with the action's other effects, in one commit); the API and
//! the start-up read them through the pool.

use serde::Serialize;
use time::OffsetDateTime;
use utoipa::ToSchema;

use super::paging::Query;
use super::{Reader, read};
use crate::domain::time::from_ms;
use crate::domain::{Pause, Target};

/// One operator action, as audited.
#[derive(Clone, Debug, PartialEq, Serialize, ToSchema)]
#[schema(example = json!({"id": 7, "at": "2026-11-21T08:00:00.000Z", "by": "ops-desk", "client": "10.20.1.14", "action": "pause",
    "target": "device:crane1", "reason": "fork inspection"}))]
pub struct AuditEntry {
    /// The entry's number.
    pub id: i64,
    /// When.
    #[serde(with = "time::serde::rfc3339")]
    #[schema(value_type = String, format = DateTime)]
    pub at: OffsetDateTime,
    /// The API key's name (`anonymous` when no keys are configured; `rackd` for what rackd
    /// recorded of itself).
    pub by: String,
    /// The address of the client that sent the request (its TCP peer, IPv4 or IPv6),
    /// when known; null for entries written before rackd recorded it.
    pub client: Option<String>,
    /// `submit`, `cancel`, `priority`, `retry`, `pause`, `resume`, `lock`, `unlock`,
    /// `inventory`, `acknowledge` or `tag`.
    pub action: String,
    /// What it applied to: `job:ID`, `jobs:FIRST-LAST` (a batch), `device:ID`, `aisle:N`,
    /// `location:A/R/B/L/P`, `alarm:ID` or `device:ID/TAG` (a tag written).
    pub target: String,
    /// Why, as the operator gave it.
    pub reason: Option<String>,
}

/// A `controls` row (the same on both engines).
#[derive(sqlx::FromRow)]
struct ControlRow {
    target: String,
    by: String,
    reason: Option<String>,
    at: i64,
}

/// An `audit` row (the same on both engines).
#[derive(sqlx::FromRow)]
struct AuditRow {
    id: i64,
    at: i64,
    by: String,
    client: Option<String>,
    action: String,
    target: String,
    reason: Option<String>,
}

impl From<AuditRow> for AuditEntry {
    fn from(r: AuditRow) -> AuditEntry {
        AuditEntry {
            id: r.id,
            at: from_ms(r.at),
            by: r.by,
            client: r.client,
            action: r.action,
            target: r.target,
            reason: r.reason,
        }
    }
}

/// Every paused device and aisle, with who paused it (at start, to restore).
pub async fn paused(db: impl Into<Reader<'_>>) -> Result<Vec<(Target, Pause)>, sqlx::Error> {
    let sql = "SELECT target, by, reason, at FROM controls WHERE paused = TRUE ORDER BY target";
    let rows: Vec<ControlRow> = read!(db.into(), p => sqlx::query_as(sql).fetch_all(p).await)?;
    Ok(rows
        .into_iter()
        .filter_map(|r| {
            Some((Target::parse(&r.target)?, Pause { by: r.by, reason: r.reason, at: from_ms(r.at) }))
        })
        .collect())
}

/// Audit entries, newest first, older than `before_id` if given: a page read on the key
/// (see [`super::paging`]).
pub async fn audit(
    db: impl Into<Reader<'_>>,
    before_id: Option<i64>,
    limit: u32,
) -> Result<Vec<AuditEntry>, sqlx::Error> {
    let rows: Vec<AuditRow> = audit_query(before_id, limit).fetch_all(db.into()).await?;
    Ok(rows.into_iter().map(AuditEntry::from).collect())
}

/// The statement [`audit`] runs.
pub fn audit_query(before_id: Option<i64>, limit: u32) -> Query {
    let mut q = Query::new("SELECT id, at, by, client, action, target, reason FROM audit WHERE TRUE");
    if let Some(id) = before_id {
        q.push(" AND id < ").int(id);
    }
    q.push(" ORDER BY id DESC LIMIT ").int(limit as i64);
    q
}
