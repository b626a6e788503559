//! Webhook subscriptions as stored: each one's row (its cursor, whether it is paused, its
//! last success and failure) and the delivery log. Written by the writer only
//! ([`crate::store::writer::Record::Webhook`]): a subscription's row and the deliveries
//! that moved its cursor are one commit, so the cursor never says more was acknowledged
//! than the log shows. Read by the deliverer at start and by the API on any node.

use serde::Serialize;

use super::{Reader, read};

/// A subscription's row.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, sqlx::FromRow)]
pub struct Row {
    /// The subscription's name (`[[webhooks]] name`).
    pub name: String,
    /// The last event seq it is done with: acknowledged with a 2xx, or not of its types.
    pub cursor: i64,
    /// 0 while delivering; otherwise who paused it, as [`PausedBy::stored`] writes it (an
    /// administrator's 1, the receiver's 2).
    pub paused: i64,
    /// Why it is paused.
    pub paused_reason: Option<String>,
    /// When a delivery last succeeded (Unix ms).
    pub last_ok_at: Option<i64>,
    /// The last failure, as said to people (no response body beyond a short excerpt).
    pub last_error: Option<String>,
    /// When it happened (Unix ms).
    pub last_error_at: Option<i64>,
    /// Since when every try has failed (Unix ms); None after a success.
    pub failing_since: Option<i64>,
    /// When the row was written.
    pub updated_at: i64,
}

/// Who paused a subscription.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum PausedBy {
    /// An administrator (`POST /api/v1/webhooks/{name}/pause`): retention no longer holds
    /// its events, and no alarm says so.
    Admin,
    /// The receiver, or a proxy in front of it, answered 410 Gone: the `webhook` alarm
    /// (code 2) is raised, and retention goes on holding its events.
    Receiver,
}

impl PausedBy {
    /// Its value in the `paused` column.
    pub fn stored(self) -> i64 {
        match self {
            PausedBy::Admin => 1,
            PausedBy::Receiver => 2,
        }
    }
}

impl Row {
    /// Who paused it, if it is paused (a value of another version reads as an
    /// administrator's pause).
    pub fn paused_by(&self) -> Option<PausedBy> {
        match self.paused {
            0 => None,
            2 => Some(PausedBy::Receiver),
            _ => Some(PausedBy::Admin),
        }
    }
}

/// One try to deliver one event.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, sqlx::FromRow)]
pub struct Delivery {
    /// Its place in the log (assigned by the store; 0 until written).
    #[serde(skip)]
    pub id: i64,
    /// The subscription.
    #[serde(skip)]
    pub name: String,
    /// The event.
    pub seq: i64,
    /// 1 for the first try of this event since the deliverer took it up.
    pub attempt: i64,
    /// The receiver's HTTP status, when it answered.
    pub status: Option<i64>,
    /// `delivered` (2xx), `failed` (anything else: a status, a timeout, a refused
    /// connection), `gone` (410: the subscription is paused).
    pub outcome: String,
    /// From the request's start to its answer (or failure), in ms.
    pub latency_ms: i64,
    /// What went wrong.
    pub error: Option<String>,
    /// When the try ended (Unix ms).
    pub at: i64,
}

/// What the writer commits for one subscription: its row as it now stands and the tries
/// that brought it there.
#[derive(Clone, Debug, PartialEq)]
pub struct Progress {
    /// The row.
    pub row: Row,
    /// The tries since the last commit, oldest first.
    pub deliveries: Vec<Delivery>,
}

/// Every subscription's row, by name.
pub async fn rows(db: impl Into<Reader<'_>>) -> Result<Vec<Row>, sqlx::Error> {
    let sql = "SELECT name, cursor, paused, paused_reason, last_ok_at, last_error, last_error_at, \
               failing_since, updated_at FROM webhooks ORDER BY name";
    read!(db.into(), p => sqlx::query_as(sql).fetch_all(p).await)
}

/// Up to `limit` tries of subscription `name`, newest first, before the one with id
/// `before` (all when None).
pub async fn deliveries(
    db: impl Into<Reader<'_>>,
    name: &str,
    before: Option<i64>,
    limit: u32,
) -> Result<Vec<Delivery>, sqlx::Error> {
    let sql = "SELECT id, name, seq, attempt, status, outcome, latency_ms, error, at FROM webhook_deliveries \
               WHERE name = $1 AND id < $2 ORDER BY id DESC LIMIT $3";
    let before = before.unwrap_or(i64::MAX);
    read!(db.into(), p => sqlx::query_as(sql).bind(name).bind(before).bind(limit as i64).fetch_all(p).await)
}

/// The upsert of a subscription's row (`$1`..`$9` in the order of [`Row`]'s fields).
pub const UPSERT: &str = "INSERT INTO webhooks (name, cursor, paused, paused_reason, last_ok_at, last_error, \
     last_error_at, failing_since, updated_at) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9) \
     ON CONFLICT (name) DO UPDATE SET cursor = excluded.cursor, paused = excluded.paused, \
     paused_reason = excluded.paused_reason, last_ok_at = excluded.last_ok_at, \
     last_error = excluded.last_error, last_error_at = excluded.last_error_at, \
     failing_since = excluded.failing_since, updated_at = excluded.updated_at";

/// The columns of a delivery written (the JSON rows of [`Delivery`] with its name).
pub const DELIVERY_COLUMNS: [&str; 8] =
    ["name", "seq", "attempt", "status", "outcome", "latency_ms", "error", "at"];

/// A delivery as the writer's JSON insert takes it.
#[derive(Serialize)]
pub struct DeliveryOut<'a> {
    /// The subscription.
    pub name: &'a str,
    /// The rest.
    #[serde(flatten)]
    pub delivery: &'a Delivery,
}
