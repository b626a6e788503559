//! Each list's statement, exactly as the store runs it (see src/store/paging.rs), is read
//! on an index that matches its filter and gives its order: the engine's own plan names the
//! index, reads no table whole and sorts nothing. On SQLite `EXPLAIN QUERY PLAN`; on
//! PostgreSQL `EXPLAIN (FORMAT JSON)` with sequential scans, bitmap scans and sorts
//! switched off, so that the plan it shows is an ordered index scan whenever the schema has
//! one, whatever the (empty) tables' statistics say; without one it still shows the scan
//! or the sort, and the test fails. Plans, not timings: nothing here is timed.

use rackd::domain::{JobKind, JobState};
use rackd::store::alarms::{self, AlarmFilter};
use rackd::store::jobs::{self, JobFilter};
use rackd::store::paging::{Param, Query};
use rackd::store::{Engine, Pool, controls, events};
use rstest::rstest;

use super::open;

/// How a plan may read: the index names (SQLite: words of its plan lines) one of which
/// it must use, and whether it may sort what it read: only the unfinished jobs, and the
/// one job a reference names (PostgreSQL sorts the at most one row its unique index gives).
struct Expect {
    what: &'static str,
    uses: &'static [&'static str],
    sorts: bool,
}

const fn uses(what: &'static str, uses: &'static [&'static str]) -> Expect {
    Expect { what, uses, sorts: false }
}

/// The plan of `sql` with `params`: SQLite's lines, or PostgreSQL's nodes as
/// `Node Type` and `Index Name`, one per line (sorts switched off unless `sorts`).
async fn plan(pool: &Pool, sql: &str, params: &[Param], sorts: bool) -> Vec<String> {
    match pool {
        Pool::Sqlite(p) => {
            let text = format!("EXPLAIN QUERY PLAN {sql}");
            let mut q = sqlx::query_as::<_, (i64, i64, i64, String)>(sqlx::AssertSqlSafe(text));
            for param in params {
                q = match param {
                    Param::Int(n) => q.bind(*n),
                    Param::Text(s) => q.bind(s.clone()),
                };
            }
            q.fetch_all(p).await.unwrap().into_iter().map(|r| r.3).collect()
        }
        Pool::Postgres(p) => {
            let mut c = p.acquire().await.unwrap();
            let off = "SET enable_seqscan = off; SET enable_bitmapscan = off";
            sqlx::raw_sql(off).execute(&mut *c).await.unwrap();
            if !sorts {
                sqlx::raw_sql("SET enable_sort = off").execute(&mut *c).await.unwrap();
            }
            let text = format!("EXPLAIN (FORMAT JSON) {sql}");
            let mut q = sqlx::query_scalar::<_, serde_json::Value>(sqlx::AssertSqlSafe(text));
            for param in params {
                q = match param {
                    Param::Int(n) => q.bind(*n),
                    Param::Text(s) => q.bind(s.clone()),
                };
            }
            let json = q.fetch_one(&mut *c).await.unwrap();
            sqlx::raw_sql("RESET ALL").execute(&mut *c).await.unwrap();
            let mut nodes = Vec::new();
            walk(&json[0]["Plan"], &mut nodes);
            nodes
        }
    }
}

fn walk(node: &serde_json::Value, out: &mut Vec<String>) {
    let kind = node["Node Type"].as_str().unwrap_or("?");
    out.push(format!("{kind} {}", node["Index Name"].as_str().unwrap_or("")).trim().to_owned());
    for child in node["Plans"].as_array().into_iter().flatten() {
        walk(child, out);
    }
}

/// Asserts that the plan of `query` reads as `expect` says.
async fn check(pool: &Pool, sql: &str, params: &[Param], expect: &Expect) {
    let lines = plan(pool, sql, params, expect.sorts).await;
    let what = expect.what;
    let used = lines.iter().any(|l| expect.uses.iter().any(|name| l.contains(name)));
    assert!(used, "{what}: none of {:?} in the plan {lines:#?}\n{sql}", expect.uses);
    for line in &lines {
        // SQLite: `SCAN t` reads the table whole (`SCAN t USING INDEX i` the index whole,
        // allowed for a partial index the case names: it holds only the active alarms).
        let scan = line.starts_with("SCAN ")
            && line != "SCAN CONSTANT ROW"
            && !expect.uses.iter().any(|name| line.ends_with(&format!("USING INDEX {name}")));
        assert!(!scan && !line.starts_with("Seq Scan"), "{what}: a full scan: {lines:#?}\n{sql}");
        let sort = line.contains("TEMP B-TREE") || line.ends_with("Sort");
        assert!(expect.sorts || !sort, "{what}: a sort: {lines:#?}\n{sql}");
    }
}

async fn check_query(pool: &Pool, query: &Query, expect: &Expect) {
    check(pool, query.sql(), query.params(), expect).await;
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn every_job_filter_pages_on_an_index_in_id_order(#[case] engine: Engine) {
    let (pool, _db, _dir) = open(engine).await;
    let page = |f: JobFilter| JobFilter { after_id: Some(1000), limit: 50, ..f };
    let state = Some(JobState::Completed);
    let kind = Some(JobKind::Light);
    let device = Some("shelf1".to_owned());
    let (from, to) = (Some(1_800_000_000_000), Some(1_800_086_400_000));
    let d = JobFilter::default;
    const STATE: &[&str] = &["jobs_state"];
    const PERIOD: &[&str] = &["INTEGER PRIMARY KEY", "jobs_pkey"];
    const REFERENCE: Expect = uses("reference", &["sqlite_autoindex_jobs_1", "jobs_reference_key"]);
    let cases = [
        (page(JobFilter { state, ..d() }), uses("state", STATE)),
        (page(JobFilter { kind, ..d() }), uses("kind", &["jobs_kind"])),
        (page(JobFilter { device: device.clone(), ..d() }), uses("device", &["jobs_device"])),
        (page(JobFilter { reference: Some("WMS-1".into()), ..d() }), Expect { sorts: true, ..REFERENCE }),
        (page(JobFilter { created_from: from, ..d() }), uses("created_from", PERIOD)),
        (page(JobFilter { created_to: to, ..d() }), uses("created_to", PERIOD)),
        (page(JobFilter { created_from: from, created_to: to, ..d() }), uses("period", PERIOD)),
        (page(JobFilter { state, kind, ..d() }), uses("state and kind", &["jobs_state", "jobs_kind"])),
        (
            page(JobFilter { state, device: device.clone(), ..d() }),
            uses("state and device", &["jobs_device_state"]),
        ),
        (
            page(JobFilter { kind, device: device.clone(), ..d() }),
            uses("kind and device", &["jobs_kind", "jobs_device"]),
        ),
        (
            page(JobFilter { state, kind, device: device.clone(), ..d() }),
            uses("state, kind and device", &["jobs_device_state", "jobs_state", "jobs_kind"]),
        ),
        (
            page(JobFilter { state, created_from: from, created_to: to, ..d() }),
            uses("state in a period", &["jobs_state", "INTEGER PRIMARY KEY", "jobs_pkey"]),
        ),
        (
            page(JobFilter { kind, device, created_from: from, ..d() }),
            uses(
                "kind and device in a period",
                &["jobs_kind", "jobs_device", "INTEGER PRIMARY KEY", "jobs_pkey"],
            ),
        ),
        (JobFilter { state, limit: 50, ..d() }, uses("state, first page", STATE)),
        (JobFilter { created_from: from, limit: 1000, ..d() }, uses("the dashboard's last hour", PERIOD)),
    ];
    for (filter, expect) in &cases {
        check_query(&pool, &jobs::list_query(filter), expect).await;
    }
    // The period's bounds are sought on jobs_created.
    let period = jobs::list_query(&page(JobFilter { created_from: from, created_to: to, ..d() }));
    let lines = plan(&pool, period.sql(), period.params(), false).await;
    assert_eq!(lines.iter().filter(|l| l.contains("jobs_created")).count(), 2, "{lines:#?}");

    // A device's unfinished jobs (the dispatcher's at start), on device and state together.
    check_query(
        &pool,
        &jobs::unfinished_query("shelf1"),
        &uses("a device's unfinished", &["jobs_device_state"]),
    )
    .await;
    // The failed jobs a bulk retry or unlock selects: in id order on the failed jobs' entries.
    let lost = Some(rackd::domain::FailureKind::Lost);
    for (device, kind, since, expect) in [
        (Some("shelf1"), lost, from, uses("a device's failed", &["jobs_device_state"])),
        (Some("shelf1"), None, None, uses("a device's failed, any kind", &["jobs_device_state"])),
        (None, lost, from, uses("failed of a kind", STATE)),
        (None, None, from, uses("failed since", STATE)),
    ] {
        check_query(&pool, &jobs::failed_query(device, kind, since, 10_001), &expect).await;
    }
    // A job's history, and the snapshot's unfinished jobs (sorted: they are not the history).
    check_query(&pool, &jobs::history_query(7), &uses("history", &["job_history_job"])).await;
    let unfinished = Expect { what: "unfinished", uses: STATE, sorts: true };
    check_query(&pool, &jobs::active_query(5000), &unfinished).await;
    pool.close().await;
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn alarms_audit_and_the_event_log_page_on_an_index(#[case] engine: Engine) {
    let (pool, _db, _dir) = open(engine).await;
    let page = |f: AlarmFilter| AlarmFilter { before_id: Some(1000), limit: 50, ..f };
    let d = AlarmFilter::default;
    let device = Some("crane1".to_owned());
    const KEY: &[&str] = &["INTEGER PRIMARY KEY", "alarms_pkey"];
    let cases = [
        (page(d()), uses("every alarm", KEY)),
        (page(AlarmFilter { active: Some(true), ..d() }), uses("active", &["alarms_open"])),
        (AlarmFilter { active: Some(true), limit: 50, ..d() }, uses("active, first page", &["alarms_open"])),
        (page(AlarmFilter { active: Some(false), ..d() }), uses("cleared", KEY)),
        (page(AlarmFilter { device: device.clone(), ..d() }), uses("device", &["alarms_device"])),
        (
            page(AlarmFilter { device: device.clone(), active: Some(true), ..d() }),
            uses("a device's active", &["alarms_device_open"]),
        ),
        (
            page(AlarmFilter { device, active: Some(false), ..d() }),
            uses("a device's cleared", &["alarms_device"]),
        ),
    ];
    for (filter, expect) in &cases {
        check_query(&pool, &alarms::list_query(filter), expect).await;
    }
    // The CSV export, a page of its period at a time: the bounds sought on alarms_raised.
    let export = alarms::raised_query(1_700_000_000_000, 1_700_086_400_000, 1000, 1000);
    check_query(&pool, &export, &uses("the export", KEY)).await;
    let lines = plan(&pool, export.sql(), export.params(), false).await;
    assert_eq!(lines.iter().filter(|l| l.contains("alarms_raised")).count(), 2, "{lines:#?}");
    let audit = uses("audit", &["INTEGER PRIMARY KEY", "audit_pkey"]);
    check_query(&pool, &controls::audit_query(Some(1000), 100), &audit).await;
    let replay = uses("replay", &["INTEGER PRIMARY KEY", "events_pkey"]);
    check_query(&pool, &events::after_query(1000, 500), &replay).await;
    check(&pool, events::BOUNDS, &[], &uses("the log's bounds", &["SEARCH events", "events_pkey"])).await;
    pool.close().await;
}
