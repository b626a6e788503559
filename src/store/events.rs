//! The event log: every job, device, alarm and location change, in one gapless sequence.
//!
//! Events are appended by the writer only (see [`super::writer`]), inside the same
//! transaction as the change they describe, so the log never tells of a change that was
//! rolled back and never misses one that was committed. `seq` is numbered by the one
//! writer, from the highest committed number, and a group that rolls back gives its numbers
//! back, so numbers have no gaps on either engine. Pruning (retention) always keeps the
//! newest event, so a restart never reuses a number.

use super::paging::Query;
use super::{Reader, read};

use crate::domain::time::from_ms;

/// One event as stored.
#[derive(Clone, Debug, PartialEq, sqlx::FromRow)]
pub struct StoredEvent {
    /// Position in the log, from 1, without gaps.
    pub seq: i64,
    /// When it was committed (Unix ms).
    pub at: i64,
    /// `job.updated`, `device.updated`, `alarm.raised`, `alarm.cleared`, `location.updated`.
    #[sqlx(rename = "type")]
    pub kind: String,
    /// The event's data, JSON.
    pub data: String,
}

impl StoredEvent {
    /// The event as subscribers receive it: `{"seq", "time", "type", "data"}`.
    ///
    /// Built by hand from the stored JSON so that the writer serializes each event once,
    /// however many subscribers it goes to.
    pub fn to_json(&self) -> String {
        json(self.seq, self.at, &self.kind, &self.data)
    }
}

/// `{"seq", "time", "type", "data"}` from its parts; `data` must already be JSON.
pub fn json(seq: i64, at: i64, kind: &str, data: &str) -> String {
    let time = from_ms(at).format(&time::format_description::well_known::Rfc3339).unwrap_or_default();
    let kind = serde_json::to_string(kind).unwrap_or_default();
    format!(r#"{{"seq":{seq},"time":"{time}","type":{kind},"data":{data}}}"#)
}

/// Up to `limit` events after `since`, oldest first.
pub async fn after(
    db: impl Into<Reader<'_>>,
    since: i64,
    limit: u32,
) -> Result<Vec<StoredEvent>, sqlx::Error> {
    after_query(since, limit).fetch_all(db.into()).await
}

/// The statement [`after`] runs: a range of the key.
pub fn after_query(since: i64, limit: u32) -> Query {
    let mut q = Query::new("SELECT seq, at, type, data FROM events WHERE seq > ");
    q.int(since).push(" ORDER BY seq LIMIT ").int(limit as i64);
    q
}

/// The newest `limit` events of type `kind`, newest first.
pub async fn latest(
    db: impl Into<Reader<'_>>,
    kind: &str,
    limit: u32,
) -> Result<Vec<StoredEvent>, sqlx::Error> {
    let sql = "SELECT seq, at, type, data FROM events WHERE type = $1 ORDER BY seq DESC LIMIT $2";
    read!(db.into(), p => sqlx::query_as(sql).bind(kind).bind(limit as i64).fetch_all(p).await)
}

/// The first and last sequence numbers in the log (0, 0 when it is empty): two seeks on the
/// key (SQLite reads the whole table for a `MIN` and a `MAX` in one query).
pub async fn bounds(db: impl Into<Reader<'_>>) -> Result<(i64, i64), sqlx::Error> {
    read!(db.into(), p => sqlx::query_as(BOUNDS).fetch_one(p).await)
}

/// The statement [`bounds`] runs.
pub const BOUNDS: &str =
    "SELECT COALESCE((SELECT MIN(seq) FROM events), 0), COALESCE((SELECT MAX(seq) FROM events), 0)";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn event_json_is_valid_and_ordered() {
        let text = json(7, 1_700_000_000_123, "job.updated", r#"{"id":1}"#);
        assert_eq!(
            text,
            r#"{"seq":7,"time":"2023-11-14T22:13:20.123Z","type":"job.updated","data":{"id":1}}"#
        );
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["data"]["id"], 1);
    }
}
