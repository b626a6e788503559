//! What operators set, kept across restarts: pauses of devices and aisles, and the audit
//! log of every operator action (pause, resume, lock, unlock, retry) with who, when, why.
//!
//! The writer thread writes both (with the action's other effects, in one commit); the
//! API and the start-up read them through the pool.

use rusqlite::{Transaction, params};
use serde::Serialize;
use sqlx::SqliteExecutor;
use time::OffsetDateTime;
use utoipa::ToSchema;

use crate::domain::time::{from_ms, to_ms};
use crate::domain::{Pause, Target};

/// One operator action, as audited.
#[derive(Clone, Debug, PartialEq, Serialize, ToSchema)]
#[schema(example = json!({"id": 7, "at": "2026-11-21T08:00:00.000Z", "by": "ops-desk", "action": "pause",
    "target": "device:crane1", "reason": "fork inspection"}))]
pub struct AuditEntry {
    /// The entry's number.
    pub id: i64,
    /// When.
    #[serde(with = "time::serde::rfc3339")]
    #[schema(value_type = String, format = DateTime)]
    pub at: OffsetDateTime,
    /// The API key's name (`anonymous` when no keys are configured).
    pub by: String,
    /// `pause`, `resume`, `lock`, `unlock` or `retry`.
    pub action: String,
    /// What it applied to: `device:ID`, `aisle:N`, `location:A/R/B/L/P` or `job:ID`.
    pub target: String,
    /// Why, as the operator gave it.
    pub reason: Option<String>,
}

/// Every paused device and aisle, with who paused it (at start, to restore).
pub async fn paused(db: impl SqliteExecutor<'_>) -> Result<Vec<(Target, Pause)>, sqlx::Error> {
    let rows: Vec<(String, String, Option<String>, i64)> =
        sqlx::query_as("SELECT target, by, reason, at FROM controls WHERE paused = 1 ORDER BY target")
            .fetch_all(db)
            .await?;
    Ok(rows
        .into_iter()
        .filter_map(|(target, by, reason, at)| {
            Some((Target::parse(&target)?, Pause { by, reason, at: from_ms(at) }))
        })
        .collect())
}

/// Audit entries, newest first, older than `before_id` if given.
pub async fn audit(
    db: impl SqliteExecutor<'_>,
    before_id: Option<i64>,
    limit: u32,
) -> Result<Vec<AuditEntry>, sqlx::Error> {
    let rows: Vec<(i64, i64, String, String, String, Option<String>)> = sqlx::query_as(
        "SELECT id, at, by, action, target, reason FROM audit WHERE (?1 IS NULL OR id < ?1) ORDER BY id DESC LIMIT ?2",
    )
    .bind(before_id)
    .bind(limit)
    .fetch_all(db)
    .await?;
    Ok(rows
        .into_iter()
        .map(|(id, at, by, action, target, reason)| AuditEntry {
            id,
            at: from_ms(at),
            by,
            action,
            target,
            reason,
        })
        .collect())
}

// What follows runs in the job writer's thread, inside its transaction.

/// Records that `target` is paused (`Some`) or resumed (`None`).
pub(crate) fn set(tx: &Transaction<'_>, target: &Target, pause: Option<&Pause>) -> rusqlite::Result<()> {
    match pause {
        Some(p) => tx
            .prepare_cached(
                "INSERT INTO controls (target, paused, by, reason, at) VALUES (?1, 1, ?2, ?3, ?4) \
                 ON CONFLICT (target) DO UPDATE SET paused = 1, by = ?2, reason = ?3, at = ?4",
            )?
            .execute(params![target.key(), p.by, p.reason, to_ms(p.at)])?,
        None => {
            tx.prepare_cached("DELETE FROM controls WHERE target = ?1")?.execute(params![target.key()])?
        }
    };
    Ok(())
}

/// Appends an audit entry.
pub(crate) fn append(
    tx: &Transaction<'_>,
    by: &str,
    action: &str,
    target: &str,
    reason: Option<&str>,
    now: i64,
) -> rusqlite::Result<AuditEntry> {
    tx.prepare_cached("INSERT INTO audit (at, by, action, target, reason) VALUES (?1, ?2, ?3, ?4, ?5)")?
        .execute(params![now, by, action, target, reason])?;
    Ok(AuditEntry {
        id: tx.last_insert_rowid(),
        at: from_ms(now),
        by: by.to_owned(),
        action: action.to_owned(),
        target: target.to_owned(),
        reason: reason.map(str::to_owned),
    })
}
