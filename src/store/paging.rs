//! How the lists read a page: by an index that matches the filter and the order, so that a
//! page costs the same whatever the history holds (issue 39). The lists are jobs
//! ([`super::jobs::list`]), alarms ([`super::alarms::list`]) and the audit log
//! ([`super::controls::audit`]); a job's history and the event log's replay read one job's
//! entries or a range of sequence numbers, on the index or key they are ordered by already.
//!
//! Decisions:
//! - **Keyset pagination on the id.** A page is `WHERE <filters> AND id > cursor ORDER BY id
//!   LIMIT n` (alarms and the audit log: `id < cursor ... DESC`), never an `OFFSET`. Each
//!   filter has an index whose entries for one value are in id order (migration 0008):
//!   `jobs_state`, `jobs_kind`, `jobs_device`, `jobs_device_state` (device and state
//!   together), the unique index on `reference`; `alarms_device`, and the active alarms'
//!   partial indexes `alarms_open` and `alarms_device_open`. The database then seeks to the
//!   cursor within the filter's value and reads only the entries it returns.
//! - **Combinations** of the jobs' filters are read on one index, the other filters checked
//!   on each entry read: device and state together have `jobs_device_state` (the
//!   dispatcher needs it too), and with a kind as well read on it; state and kind read
//!   `jobs_state` or `jobs_kind`, kind and device `jobs_kind` or `jobs_device`, whichever
//!   the engine picks. A page of such a pair reads as many entries as the rows of the
//!   other filter it passes over (50 failed stores among 2 million jobs, 1 in 50 failed:
//!   about 2,500 entries, 1.2 ms), which depends on how common the other filter's value is,
//!   not on how long the history is. An index for each pair would cost every job two more
//!   index entries at intake, and each transition one more, for lists nobody has asked
//!   to be fast (measured in docs/development/benchmarks/history.md).
//! - **The period (`created_from`, `created_to`) is a range of ids.** Ids are given in
//!   acceptance order and `created_at` is the acceptance time, so the jobs of a period are
//!   the ids from the first job accepted at or after `created_from` to the last accepted
//!   before `created_to`: each bound is one seek on `jobs_created` (its ties in id order),
//!   and the page reads the id range on whichever index serves the other filters. The
//!   conditions on `created_at` stay too, written `+created_at` so that neither engine reads
//!   the page off `jobs_created` (which is not in id order, and would need a sort of the
//!   whole period): no job outside the period is ever listed. Should the system clock step
//!   back, a job accepted before the step but timed after a bound can fall outside its
//!   range and be left out of a period's list; the ids, and so the order and the cursor,
//!   stay exact.
//! - **Sorted, and why.** The snapshot's unfinished jobs (`state IN (...)`, newest first)
//!   are read on `jobs_state` and sorted, and a device's unfinished jobs (the dispatcher's
//!   at start) on `jobs_device_state`, sorted in Rust: both are the jobs not yet ended,
//!   never the history. The latter asks for no order at all: with one, `jobs_device`
//!   (device, id) gives the order without a sort, and SQLite without statistics read the
//!   device's whole history on it.
//! - **Not indexed, and why.** A standby's snapshot finds each device's last status among
//!   the newest `device.updated` events without an index on the event type: the log holds
//!   `events.retention_hours` of events, and every device tells its status at least every
//!   `contact_refresh_ms`, so the read stops early; an index there would cost every event
//!   (one per job change) an entry.
//! - **Memory does not follow the history.** A list's page is at most 1000 rows; the
//!   alarms' CSV export (up to 100,000 rows of a period) is read and sent 1000 at a time
//!   ([`super::alarms::raised_query`], its period sought as the jobs' is); a replay goes
//!   page by page. What is read whole is bounded by the site, not by its past: the
//!   layout's locations, the unfinished jobs, the active alarms. (The KPIs of
//!   [`super::stats`] still read their period: issue 39 moves them to rollups.)
//!
//! A list's statement is a [`Query`]: its text, with `$1`, `$2`, ... in the order they
//! appear (SQLite numbers named parameters by first appearance, PostgreSQL by number: the
//! same text works on both), and its parameters. The tests read the plan of each list's
//! statement as it is run (`tests/it/store/plans.rs`).

use sqlx::{FromRow, postgres::PgRow, sqlite::SqliteRow};

use super::{Reader, read};

/// A parameter of a [`Query`].
#[derive(Clone, Debug, PartialEq)]
pub enum Param {
    /// An integer.
    Int(i64),
    /// A text.
    Text(String),
}

/// A list's statement and its parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct Query {
    sql: String,
    params: Vec<Param>,
}

impl Query {
    /// A statement starting with `sql` (no parameters in it).
    pub(crate) fn new(sql: impl Into<String>) -> Query {
        Query { sql: sql.into(), params: Vec::new() }
    }

    /// Appends text with no parameter.
    pub(crate) fn push(&mut self, sql: &str) -> &mut Query {
        self.sql.push_str(sql);
        self
    }

    /// Appends `param`'s placeholder.
    pub(crate) fn bind(&mut self, param: Param) -> &mut Query {
        self.params.push(param);
        self.sql.push_str(&format!("${}", self.params.len()));
        self
    }

    /// Appends an integer's placeholder.
    pub(crate) fn int(&mut self, n: i64) -> &mut Query {
        self.bind(Param::Int(n))
    }

    /// Appends a text's placeholder.
    pub(crate) fn text(&mut self, s: &str) -> &mut Query {
        self.bind(Param::Text(s.to_owned()))
    }

    /// The statement's text.
    pub fn sql(&self) -> &str {
        &self.sql
    }

    /// Its parameters, `$1` first.
    pub fn params(&self) -> &[Param] {
        &self.params
    }

    /// Every row it reads, as `R`.
    pub(crate) async fn fetch_all<R>(&self, db: Reader<'_>) -> Result<Vec<R>, sqlx::Error>
    where
        R: for<'r> FromRow<'r, SqliteRow> + for<'r> FromRow<'r, PgRow> + Send + Unpin,
    {
        read!(db, p => {
            let mut q = sqlx::query_as::<_, R>(sqlx::AssertSqlSafe(self.sql.clone()));
            for param in &self.params {
                q = match param {
                    Param::Int(n) => q.bind(*n),
                    Param::Text(s) => q.bind(s.clone()),
                };
            }
            q.fetch_all(p).await
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn placeholders_are_numbered_in_the_order_they_appear() {
        let mut q = Query::new("SELECT id FROM jobs WHERE TRUE");
        q.push(" AND state = ").text("queued").push(" AND id > ").int(7).push(" LIMIT ").int(50);
        assert_eq!(q.sql(), "SELECT id FROM jobs WHERE TRUE AND state = $1 AND id > $2 LIMIT $3");
        assert_eq!(q.params(), [Param::Text("queued".into()), Param::Int(7), Param::Int(50)]);
    }
}
