//! What a group produced, written set-based: one statement per table and kind of change,
//! each carrying all its rows in one JSON parameter (see [`crate::store::engine`]), so a
//! group of one job and a group of ten thousand cost the same number of statements.
//!
//! One exception, measured: on SQLite the intake path's tables (jobs, history, events, and
//! the audit log, which every submission reaches) are written with multi-row `VALUES` and
//! bound parameters, because SQLite parses a JSON row
//! three to four times slower than it reads bound values. SQLite allows 32766 bound values
//! per statement, so a group of up to 2047 new jobs still takes one statement per table,
//! and one more per 2047 jobs beyond. Each of those statements is built on the writer's
//! thread while SQLite's thread runs the one before it (measured: a group of batches spent
//! 18% less time in these inserts than when each statement was built, then run).

use std::sync::LazyLock;

use serde::Serialize;

use super::Conn;
use super::apply::{Group, History};
use crate::domain::Job;
use crate::store::columns::{ALARMS, AUDIT, CONTROLS, EVENTS, JOBS, JobOut, LOCATIONS};
use crate::store::controls::AuditEntry;
use crate::store::counts::{self, Row as CountRow};
use crate::store::engine::Engine;
use crate::store::events::StoredEvent;
use crate::store::on;

const JOB_UPDATE: [&str; 9] = [
    "state",
    "priority",
    "forced",
    "failure_kind",
    "failure_code",
    "failure_text",
    "updated_at",
    "attempt",
    "spec",
];

/// The statements, per engine, built once.
struct Statements {
    insert_jobs: String,
    update_jobs: String,
    history: String,
    events: String,
    locations: String,
    audit: String,
    raise: String,
    update_alarms: String,
    pause: String,
    resume: String,
    counts: String,
}

impl Statements {
    fn new(e: Engine) -> Statements {
        Statements {
            insert_jobs: e.insert_json("jobs", &JOBS),
            update_jobs: e.update_json("jobs", &["id"], &JOB_UPDATE),
            history: e.insert_json("job_history", &["job_id", "state", "cause", "at"]),
            events: e.insert_json("events", &EVENTS),
            locations: e.update_json("locations", &LOCATIONS[..5], &LOCATIONS[5..]),
            audit: e.insert_json("audit", &AUDIT),
            raise: e.insert_json("alarms", &ALARMS),
            update_alarms: e.update_json(
                "alarms",
                &["id"],
                &["cleared_at", "acknowledged_by", "acknowledged_at"],
            ),
            // `WHERE TRUE` lets SQLite tell the upsert's ON CONFLICT from a join's ON.
            pause: format!(
                "{} WHERE TRUE ON CONFLICT (target) DO UPDATE SET paused = excluded.paused, by = excluded.by, \
                 reason = excluded.reason, at = excluded.at",
                e.insert_json("controls", &CONTROLS)
            ),
            resume: format!(
                "DELETE FROM controls WHERE target IN (SELECT target FROM ({}) AS k)",
                e.json_rows("controls", &["target"])
            ),
            counts: counts::add_json(e),
        }
    }
}

static SQLITE: LazyLock<Statements> = LazyLock::new(|| Statements::new(Engine::Sqlite));
static POSTGRES: LazyLock<Statements> = LazyLock::new(|| Statements::new(Engine::Postgres));

#[derive(Serialize)]
struct EventOut<'a> {
    seq: i64,
    at: i64,
    #[serde(rename = "type")]
    kind: &'a str,
    data: &'a str,
}

#[derive(Serialize)]
struct AuditOut<'a> {
    id: i64,
    at: i64,
    by: &'a str,
    action: &'a str,
    target: &'a str,
    reason: Option<&'a str>,
    client: Option<&'a str>,
}

#[derive(Serialize)]
struct PauseOut<'a> {
    target: &'a str,
    paused: bool,
    by: &'a str,
    reason: Option<&'a str>,
    at: i64,
}

/// SQLite's limit on bound parameters in one statement.
const SQLITE_PARAMETERS: usize = 32766;

/// Pushes the multi-row `INSERT OR FAIL` (see [`Engine::or_fail`]) of `rows` into
/// `$target` (`"table (columns)"`) onto the builder `$q`, binding each row's `[values]`;
/// debug builds check that the values match the `$columns` the chunks were cut for.
macro_rules! values {
    ($q:expr, $target:expr, $columns:expr, $rows:expr, |$r:ident| [$($value:expr),+ $(,)?]) => {{
        debug_assert_eq!([$(stringify!($value)),+].len(), $columns, "{}", $target);
        let q: &mut sqlx::QueryBuilder<sqlx::Sqlite> = $q;
        q.push(concat!("INSERT OR FAIL INTO ", $target, " "));
        q.push_values($rows, |mut b, $r| {
            $(b.push_bind($value);)+
        });
    }};
}

/// A builder for statements of `rows` rows of `values` values in all, its text and
/// arguments allocated at their final size: grown value by value, a statement of 2047 jobs
/// copied its 32752 arguments and its text over and over (seen in a profile of the writer).
fn sized(rows: usize, values: usize) -> sqlx::QueryBuilder<sqlx::Sqlite> {
    use sqlx::Arguments;
    // `INSERT OR FAIL INTO table (columns) VALUES ` per statement (under 200 characters),
    // then `(?, ?, …), ` per row: three characters per value, four per row.
    let sql = String::with_capacity(3 * 200 + rows * 4 + values * 3);
    let mut arguments = sqlx::sqlite::SqliteArguments::default();
    arguments.reserve(values, 0);
    sqlx::QueryBuilder::with_arguments(sql, arguments)
}

/// The most new jobs one insert statement takes on SQLite.
pub(super) const JOBS_PER_STATEMENT: usize = SQLITE_PARAMETERS / JOB_VALUES;

/// Values per row of the intake path's three tables on SQLite.
const JOB_VALUES: usize = 16;
const HISTORY_VALUES: usize = 4;
const EVENT_VALUES: usize = 4;
const AUDIT_VALUES: usize = 7;
const COUNT_VALUES: usize = 3;

/// One statement of the intake path on SQLite: as many rows of one table as SQLite's limit
/// on bound parameters allows (2047 jobs, 8191 history entries or events).
pub(super) enum Chunk<'g> {
    Jobs(Vec<(&'g Job, &'g String)>),
    History(&'g [History]),
    Events(&'g [StoredEvent]),
    Audit(&'g [AuditEntry]),
    /// A group's change to `job_counts` (a few rows: one per device and state it moved).
    Counts(&'g [CountRow<'g>]),
}

impl Chunk<'_> {
    /// The most rows a statement of `values` values per row takes.
    fn most(values: usize) -> usize {
        SQLITE_PARAMETERS / values
    }

    /// Whether the chunk is a full one, whose text recurs (a shorter one's length is new in
    /// most groups: it is prepared for its one use and not kept in the statement cache).
    pub(super) fn full(&self) -> bool {
        let (rows, values) = match self {
            Chunk::Jobs(rows) => (rows.len(), JOB_VALUES),
            Chunk::History(rows) => (rows.len(), HISTORY_VALUES),
            Chunk::Events(rows) => (rows.len(), EVENT_VALUES),
            Chunk::Audit(rows) => (rows.len(), AUDIT_VALUES),
            Chunk::Counts(rows) => (rows.len(), COUNT_VALUES),
        };
        rows == Chunk::most(values)
    }

    /// The rows and values of the chunk.
    fn size(&self) -> (usize, usize) {
        match self {
            Chunk::Jobs(rows) => (rows.len(), rows.len() * JOB_VALUES),
            Chunk::History(rows) => (rows.len(), rows.len() * HISTORY_VALUES),
            Chunk::Events(rows) => (rows.len(), rows.len() * EVENT_VALUES),
            Chunk::Audit(rows) => (rows.len(), rows.len() * AUDIT_VALUES),
            Chunk::Counts(rows) => (rows.len(), rows.len() * COUNT_VALUES),
        }
    }

    /// The chunk's statement, its values bound.
    pub(super) fn statement(&self) -> sqlx::QueryBuilder<sqlx::Sqlite> {
        let (rows, values) = self.size();
        let mut q = sized(rows, values);
        self.push(&mut q);
        q
    }

    /// Pushes the chunk's statement onto `q`.
    fn push(&self, q: &mut sqlx::QueryBuilder<sqlx::Sqlite>) {
        match self {
            Chunk::Jobs(rows) => {
                let rows = rows.iter().map(|(job, request)| JobOut::new(job, Some(request)));
                values!(
                    q,
                    "jobs (id, reference, kind, priority, barcode, spec, request, device, state, forced, \
                     failure_kind, failure_code, failure_text, created_at, updated_at, attempt)",
                    JOB_VALUES,
                    rows,
                    |r| [
                        r.id,
                        r.reference,
                        r.kind,
                        r.priority,
                        r.barcode,
                        r.spec,
                        r.request,
                        r.device,
                        r.state,
                        r.forced,
                        r.failure_kind,
                        r.failure_code,
                        r.failure_text,
                        r.created_at,
                        r.updated_at,
                        r.attempt,
                    ]
                )
            }
            Chunk::History(rows) => {
                values!(q, "job_history (job_id, state, cause, at)", HISTORY_VALUES, *rows, |r| [
                    r.job_id,
                    r.state,
                    r.cause.as_str(),
                    r.at,
                ])
            }
            Chunk::Events(rows) => {
                values!(q, "events (seq, at, type, data)", EVENT_VALUES, *rows, |r| [
                    r.seq,
                    r.at,
                    r.kind.as_str(),
                    r.data.as_str(),
                ])
            }
            Chunk::Audit(rows) => {
                values!(q, "audit (id, at, by, action, target, reason, client)", AUDIT_VALUES, *rows, |r| [
                    r.id,
                    crate::domain::time::to_ms(r.at),
                    r.by.as_str(),
                    r.action.as_str(),
                    r.target.as_str(),
                    r.reason.as_deref(),
                    r.client.as_deref(),
                ])
            }
            Chunk::Counts(rows) => {
                q.push("INSERT INTO job_counts (device, state, n) ");
                q.push_values(*rows, |mut b, r| {
                    b.push_bind(r.device).push_bind(r.state).push_bind(r.n);
                });
                q.push(" ").push(counts::UPSERT);
            }
        }
    }
}

/// The most rows of one table a group may write for its intake statements to go to
/// SQLite together, as one execution kept prepared (see [`intake`]).
const SMALL: usize = 64;

/// How far a group's intake rows (see [`intake`]) have gone to SQLite.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Written {
    /// The first id of a created job not written yet.
    job: i64,
    /// History entries written.
    history: usize,
    /// Events written.
    events: usize,
}

impl Written {
    /// The next full statement of rows not written yet, if one is ready, and `self` moved
    /// past it; for a group of submissions only ([`super::stream`]), whose history entries
    /// come in the order of their jobs, each entry after its job's row (`job_history`
    /// refers to `jobs`).
    pub(super) fn next_full<'g>(&mut self, group: &'g Group) -> Option<Chunk<'g>> {
        let most = JOBS_PER_STATEMENT;
        let jobs: Vec<(&Job, &String)> = group
            .created
            .range(self.job..)
            .take(most)
            .filter_map(|(id, request)| Some((group.jobs.get(id)?, request)))
            .collect();
        if jobs.len() == most {
            self.job = jobs[most - 1].0.id + 1;
            return Some(Chunk::Jobs(jobs));
        }
        let most = Chunk::most(HISTORY_VALUES);
        if let Some(rows) = group.history.get(self.history..self.history + most)
            && rows.last().is_some_and(|h| h.job_id < self.job)
        {
            self.history += most;
            return Some(Chunk::History(rows));
        }
        let most = Chunk::most(EVENT_VALUES);
        if let Some(rows) = group.out.events.get(self.events..self.events + most) {
            self.events += most;
            return Some(Chunk::Events(rows));
        }
        None
    }
}

/// On SQLite, writes the jobs, history entries and events `group` created (those not
/// `written` already), its audit entries and `counts` (its change to `job_counts`), with
/// multi-row `VALUES` and bound values (see the module doc), and returns how far they are
/// written: all of them.
///
/// A group of at most [`SMALL`] rows in each table sends its statements together, as one
/// execution whose text recurs and is kept prepared: single POSTs make groups of a few
/// dozen jobs, and each statement sent alone was a hand-off to SQLite's thread and back,
/// most of them parsed afresh. A larger group sends its statements one by one, each built
/// while SQLite's thread runs the one before it, so the writer's thread and SQLite's work
/// at once.
pub(super) async fn intake(
    c: &mut sqlx::SqliteConnection,
    group: &Group,
    written: Written,
    counts: &[CountRow<'_>],
    count: &mut usize,
) -> Result<Written, sqlx::Error> {
    let all = Written {
        job: group.created.last_key_value().map_or(written.job, |(id, _)| id + 1),
        history: group.history.len(),
        events: group.out.events.len(),
    };
    let created: Vec<(&Job, &String)> = group
        .created
        .range(written.job..)
        .filter_map(|(id, request)| Some((group.jobs.get(id)?, request)))
        .collect();
    let chunks: Vec<Chunk> = created
        .chunks(Chunk::most(JOB_VALUES))
        .map(|rows| Chunk::Jobs(rows.to_vec()))
        .chain(group.history[written.history..].chunks(Chunk::most(HISTORY_VALUES)).map(Chunk::History))
        .chain(group.out.events[written.events..].chunks(Chunk::most(EVENT_VALUES)).map(Chunk::Events))
        .chain(group.audit.chunks(Chunk::most(AUDIT_VALUES)).map(Chunk::Audit))
        .chain((!counts.is_empty()).then_some(Chunk::Counts(counts)))
        .collect();
    if chunks.is_empty() {
        return Ok(all);
    }
    if chunks.len() <= 5 && chunks.iter().all(|c| c.size().0 <= SMALL) {
        let values = chunks.iter().map(|c| c.size().1).sum();
        let mut q = sized(chunks.iter().map(|c| c.size().0).sum(), values);
        for (i, chunk) in chunks.iter().enumerate() {
            if i > 0 {
                q.push("; ");
            }
            chunk.push(&mut q);
        }
        *count += chunks.len();
        q.build().persistent(true).execute(&mut *c).await?;
        return Ok(all);
    }
    let mut next = chunks.first().map(Chunk::statement);
    for (i, chunk) in chunks.iter().enumerate() {
        let Some(mut statement) = next.take() else { break };
        *count += 1;
        let run = statement.build().persistent(chunk.full()).execute(&mut *c);
        let (done, built) = meanwhile(run, || chunks.get(i + 1).map(Chunk::statement)).await;
        done?;
        next = built;
    }
    Ok(all)
}

/// Polls `f` once.
pub(super) async fn poll_once<F: std::future::Future + Unpin>(f: &mut F) -> std::task::Poll<F::Output> {
    std::future::poll_fn(|cx| std::task::Poll::Ready(std::pin::Pin::new(&mut *f).poll(cx))).await
}

/// Awaits `run` with `work` done meanwhile on this thread: `run` is polled once first (a
/// statement is then on its way to SQLite's thread), `work` runs, then `run` is awaited.
async fn meanwhile<F: std::future::Future, T>(run: F, work: impl FnOnce() -> T) -> (F::Output, T) {
    let mut run = std::pin::pin!(run);
    let first = poll_once(&mut run).await;
    let done = work();
    let output = match first {
        std::task::Poll::Ready(output) => output,
        std::task::Poll::Pending => run.await,
    };
    (output, done)
}

/// Runs `sql` with `rows` as its JSON parameter, unless there are none.
async fn write<T: Serialize>(
    db: &mut Conn,
    count: &mut usize,
    sql: &'static str,
    rows: &[T],
) -> Result<(), sqlx::Error> {
    if rows.is_empty() {
        return Ok(());
    }
    *count += 1;
    let json = serde_json::to_string(rows).map_err(|e| sqlx::Error::Encode(e.into()))?;
    on!(Conn, db, c => sqlx::query(sql).bind(json).execute(&mut *c).await.map(drop))?;
    Ok(())
}

/// Writes everything `group` produced, inside the caller's transaction; on SQLite, of its
/// intake rows only those not `written` already (see [`super::stream`]).
pub(super) async fn save(
    db: &mut Conn,
    group: &Group,
    written: Written,
    count: &mut usize,
) -> Result<(), sqlx::Error> {
    let sql: &'static Statements = match db.engine() {
        Engine::Sqlite => &SQLITE,
        Engine::Postgres => &POSTGRES,
    };
    // The intake path's tables, and the counts of jobs: bound values on SQLite, JSON on
    // PostgreSQL.
    let counts = group.out.counts.job_rows();
    match db {
        Conn::Sqlite(c) => {
            intake(c, group, written, &counts, count).await?;
        }
        Conn::Postgres(_) => {
            let created: Vec<JobOut> = group
                .created
                .iter()
                .filter_map(|(id, request)| Some(JobOut::new(group.jobs.get(id)?, Some(request))))
                .collect();
            let events: Vec<EventOut> = group
                .out
                .events
                .iter()
                .map(|e| EventOut { seq: e.seq, at: e.at, kind: &e.kind, data: &e.data })
                .collect();
            write(db, count, &sql.insert_jobs, &created).await?;
            write(db, count, &sql.history, &group.history).await?;
            write(db, count, &sql.events, &events).await?;
            let audit: Vec<AuditOut> = group
                .audit
                .iter()
                .map(|a| AuditOut {
                    id: a.id,
                    at: crate::domain::time::to_ms(a.at),
                    by: &a.by,
                    action: &a.action,
                    target: &a.target,
                    reason: a.reason.as_deref(),
                    client: a.client.as_deref(),
                })
                .collect();
            write(db, count, &sql.audit, &audit).await?;
            write(db, count, &sql.counts, &counts).await?;
        }
    }
    let changed: Vec<JobOut> =
        group.changed.iter().filter_map(|id| Some(JobOut::new(group.jobs.get(id)?, None))).collect();
    write(db, count, &sql.update_jobs, &changed).await?;
    let locations: Vec<_> = group.touched.iter().filter_map(|l| group.locations.get(l)).collect();
    write(db, count, &sql.locations, &locations).await?;
    let raised: Vec<_> = group.raised.iter().filter_map(|id| group.alarms.get(id)).collect();
    write(db, count, &sql.raise, &raised).await?;
    let changed: Vec<_> = group.alarms_changed.iter().filter_map(|id| group.alarms.get(id)).collect();
    write(db, count, &sql.update_alarms, &changed).await?;
    let (mut paused, mut resumed) = (Vec::new(), Vec::new());
    for (target, pause) in &group.controls {
        match pause {
            Some(p) => paused.push(PauseOut {
                target,
                paused: true,
                by: &p.by,
                reason: p.reason.as_deref(),
                at: crate::domain::time::to_ms(p.at),
            }),
            None => resumed.push(serde_json::json!({ "target": target })),
        }
    }
    write(db, count, &sql.pause, &paused).await?;
    write(db, count, &sql.resume, &resumed).await?;
    if let Some((before, through, hard)) = group.prune {
        let sql = "DELETE FROM events WHERE seq < (SELECT MAX(seq) FROM events) \
                   AND ((at < $1 AND seq <= $2) OR at < $3)";
        *count += 2;
        on!(Conn, db, c => sqlx::query(sql).bind(before).bind(through).bind(hard).execute(&mut *c).await.map(drop))?;
        let sql = "DELETE FROM webhook_deliveries WHERE at < $1";
        on!(Conn, db, c => sqlx::query(sql).bind(before).execute(&mut *c).await.map(drop))?;
    }
    save_webhooks(db, count, &group.webhooks).await?;
    save_sequences(db, count, group).await?;
    if !group.archived.is_empty() {
        // Ids are our own integers: written into the text, as a list.
        let ids: Vec<String> = group.archived.iter().map(|(id, _, _)| id.to_string()).collect();
        let ids = ids.join(",");
        for sql in [
            format!("DELETE FROM job_history WHERE job_id IN ({ids})"),
            format!("DELETE FROM jobs WHERE id IN ({ids})"),
        ] {
            *count += 1;
            let sql = sqlx::AssertSqlSafe(sql);
            on!(Conn, db, c => sqlx::query(sql).execute(&mut *c).await.map(drop))?;
        }
    }
    // Last: on PostgreSQL it takes the rollups' advisory lock, which must be the last lock
    // any writer's transaction waits for (a node holding it never waits for a job's row
    // another node holds while waiting for it).
    let mut rollups = match db {
        Conn::Sqlite(c) => crate::store::rollups::write::Db::Sqlite(c),
        Conn::Postgres(c) => crate::store::rollups::write::Db::Postgres(c),
    };
    *count += crate::store::rollups::write::save(&mut rollups, &group.out.moves).await?;
    Ok(())
}

/// The sequences the group created or changed, and the members it added.
async fn save_sequences(db: &mut Conn, count: &mut usize, group: &Group) -> Result<(), sqlx::Error> {
    static ROWS: LazyLock<[String; 2]> = LazyLock::new(|| {
        [Engine::Sqlite, Engine::Postgres].map(|e| {
            // `WHERE TRUE` lets SQLite tell the upsert's ON CONFLICT from a join's ON.
            format!(
                "{} WHERE TRUE ON CONFLICT (name) DO UPDATE SET station = excluded.station, last = excluded.last, \
                 completed_at = excluded.completed_at, cancelled_at = excluded.cancelled_at, \
                 updated_at = excluded.updated_at",
                e.insert_json(
                    "sequences",
                    &["name", "station", "last", "completed_at", "cancelled_at", "created_at", "updated_at"],
                )
            )
        })
    });
    static MEMBERS: LazyLock<[String; 2]> = LazyLock::new(|| {
        [Engine::Sqlite, Engine::Postgres]
            .map(|e| e.insert_json("sequence_members", &["name", "position", "job"]))
    });
    #[derive(Serialize)]
    struct MemberOut<'a> {
        name: &'a str,
        position: u32,
        job: i64,
    }
    let at = usize::from(db.engine() == Engine::Postgres);
    let rows: Vec<_> =
        group.sequences_changed.iter().filter_map(|n| group.sequences.get(n)).map(|s| &s.row).collect();
    write(db, count, &ROWS[at], &rows).await?;
    let members: Vec<MemberOut> = group
        .new_members
        .iter()
        .map(|(name, position, job)| MemberOut { name, position: *position, job: *job })
        .collect();
    write(db, count, &MEMBERS[at], &members).await
}

/// Webhook subscriptions' rows (the last of each name in the group) and their deliveries.
async fn save_webhooks(
    db: &mut Conn,
    count: &mut usize,
    progress: &[crate::store::webhooks::Progress],
) -> Result<(), sqlx::Error> {
    use crate::store::webhooks::{DELIVERY_COLUMNS, DeliveryOut, UPSERT};
    static DELIVERIES: LazyLock<[String; 2]> = LazyLock::new(|| {
        [Engine::Sqlite, Engine::Postgres].map(|e| e.insert_json("webhook_deliveries", &DELIVERY_COLUMNS))
    });
    let mut last = std::collections::BTreeMap::new();
    for p in progress {
        last.insert(p.row.name.as_str(), &p.row);
    }
    for r in last.into_values() {
        *count += 1;
        on!(Conn, db, c => sqlx::query(UPSERT)
            .bind(&r.name)
            .bind(r.cursor)
            .bind(r.paused)
            .bind(&r.paused_reason)
            .bind(r.last_ok_at)
            .bind(&r.last_error)
            .bind(r.last_error_at)
            .bind(r.failing_since)
            .bind(r.updated_at)
            .execute(&mut *c)
            .await
            .map(drop))?;
    }
    let rows: Vec<DeliveryOut<'_>> = progress
        .iter()
        .flat_map(|p| p.deliveries.iter().map(|d| DeliveryOut { name: &p.row.name, delivery: d }))
        .collect();
    let sql = match db {
        Conn::Sqlite(_) => DELIVERIES[0].as_str(),
        Conn::Postgres(_) => DELIVERIES[1].as_str(),
    };
    write(db, count, sql, &rows).await
}
