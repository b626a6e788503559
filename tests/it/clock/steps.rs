//! One rackd on the demo site's shelf and crane: the wall clock stepped an hour forward
//! while a batch of jobs runs, an hour back while the next one runs, and a last batch
//! after. What "the right bucket" means is in `rackd::domain::time`: a job counts in the
//! bucket of its recorded end, and recorded ends never run backward, so every job is in
//! the period up to now and a job that ended before the step back is in a bucket no later
//! than those after it.

use std::time::Duration;

use rackd::domain::time::step_wall_clock;
use rackd::store::Engine;
use serde_json::{Value, json};

use super::{HOUR, alone};
use crate::api::demo::{FAST, cloc, submit, wait_job};
use crate::api::waiting::wait_for_online;
use crate::support::machines::each_task_once_and_no_breach;
use crate::support::{self, loc};

#[test]
fn on_sqlite() {
    alone("clock::steps::on_sqlite", async || stepped(Engine::Sqlite).await);
}

#[test]
fn on_postgres() {
    alone("clock::steps::on_postgres", async || stepped(Engine::Postgres).await);
}

fn ms(v: &Value) -> i64 {
    let t = time::OffsetDateTime::parse(v.as_str().unwrap(), &time::format_description::well_known::Rfc3339)
        .unwrap_or_else(|_| panic!("not a time: {v}"));
    rackd::domain::time::to_ms(t)
}

/// Submits two jobs to the shelf and two to the crane (`n` tells the batch apart),
/// answering their ids and aisles.
async fn batch(app: &support::TestApp, n: u16) -> Vec<(i64, u16)> {
    let mut posted = Vec::new();
    for i in 0..2u16 {
        let bay = n * 2 + i + 1;
        let shelf = json!({"kind": "store", "barcode": format!("S{bay}"), "to": loc(1, bay, 1, 1)});
        posted.push((submit(app, shelf).await, 1));
        let crane = json!({"kind": "store", "barcode": format!("C{bay}"), "to": cloc(1, bay, 1, 1)});
        posted.push((submit(app, crane).await, 2));
    }
    posted
}

async fn all_completed(app: &support::TestApp, posted: &[(i64, u16)]) -> Vec<Value> {
    let mut jobs = Vec::new();
    for (id, _) in posted {
        let job = wait_job(app, *id, 60, |j| j["state"] == "completed" || j["state"] == "failed").await;
        assert_eq!(job["state"], "completed", "{job}");
        jobs.push(job);
    }
    jobs
}

async fn stepped(engine: Engine) {
    let mut site = rackd::config::Config::demo();
    let (shelf, crane, _tower) = rackd::cli::demo::start_with(&mut site, FAST).await.unwrap();
    let app = support::spawn_with(engine, |c| {
        c.site = site.site.clone();
        c.devices = site.devices.clone();
    })
    .await;
    wait_for_online(&app, "crane1").await;
    wait_for_online(&app, "shelf1").await;

    // An hour forward while the first batch runs, an hour back while the second does.
    let first = batch(&app, 0).await;
    wait_job(&app, first[1].0, 30, |j| j["state"] == "running").await;
    step_wall_clock(HOUR);
    let mut jobs = all_completed(&app, &first).await;
    let second = batch(&app, 1).await;
    wait_job(&app, second[1].0, 30, |j| j["state"] == "running").await;
    // Every job accepted after the step back is stamped no earlier than this, accepted and
    // ended alike. (Which of the second batch's jobs end after the step cannot be told from
    // outside: a commit is stamped when its group starts, so the event order below is
    // what covers them.)
    let before_back = rackd::domain::time::now_ms();
    step_wall_clock(-HOUR);
    jobs.extend(all_completed(&app, &second).await);
    let third = batch(&app, 2).await;
    let after_back = all_completed(&app, &third).await;
    jobs.extend(after_back.iter().cloned());
    let posted: Vec<(i64, u16)> = [first, second, third].concat();
    each_task_once_and_no_breach(&shelf, &crane, &posted);

    // The event log: numbered without gaps, its times in the same order.
    let events = stamped_in_order(&app.db).await;
    assert!(events.windows(2).all(|w| w[1].seq == w[0].seq + 1), "the log has gaps");
    // A job's completion, by the log, is stamped no earlier than any before it.
    let completions: Vec<i64> = events
        .iter()
        .filter(|e| e.kind == "job.updated" && e.data.contains(r#""state":"completed""#))
        .map(|e| e.at)
        .collect();
    assert_eq!(completions.len(), posted.len(), "one completion each");
    let ends: Vec<i64> = jobs.iter().map(|j| ms(&j["updated_at"])).collect();
    for (job, end) in jobs.iter().zip(&ends) {
        assert!(ms(&job["created_at"]) <= *end, "ended before it was accepted: {job}");
    }
    for job in &after_back {
        assert!(
            ms(&job["created_at"]) >= before_back && ms(&job["updated_at"]) >= before_back,
            "a job accepted after the step back is stamped before it: {job}"
        );
    }

    // The jobs' pages by period: from the first one's acceptance, every job, each once, in
    // order; up to the last one's, every other one.
    // The earliest by time, not by text: "…03.55Z" is 550 ms and sorts after "…03.554Z".
    let first = jobs.iter().min_by_key(|j| ms(&j["created_at"])).unwrap();
    let from = first["created_at"].as_str().unwrap().to_owned();
    let last_created = jobs.iter().map(|j| ms(&j["created_at"])).max().unwrap();
    let mut ids = Vec::new();
    let mut cursor = String::new();
    loop {
        let path = format!("/api/v1/jobs?limit=5&created_from={}{cursor}", enc(&from));
        let (status, page) = app.get(&path).await;
        assert_eq!(status, 200, "{page}");
        ids.extend(page["jobs"].as_array().unwrap().iter().map(|j| j["id"].as_i64().unwrap()));
        match page["next_cursor"].as_str() {
            Some(next) => cursor = format!("&cursor={next}"),
            None => break,
        }
    }
    let mut want: Vec<i64> = posted.iter().map(|(id, _)| *id).collect();
    want.sort_unstable();
    assert_eq!(ids, want, "GET /api/v1/jobs?created_from={from}");
    let to = rackd::domain::time::from_ms(last_created)
        .format(&time::format_description::well_known::Rfc3339)
        .unwrap();
    let (status, page) = app.get(&format!("/api/v1/jobs?limit=100&created_to={}", enc(&to))).await;
    assert_eq!(status, 200, "{page}");
    let before: Vec<i64> =
        page["jobs"].as_array().unwrap().iter().map(|j| j["id"].as_i64().unwrap()).collect();
    assert_eq!(before.len(), want.len() - 1, "every job accepted before the last one: {before:?}");

    // No alarm of any kind, ever: neither the heartbeat nor a link.
    let (status, alarms) = app.get("/api/v1/alarms?limit=100").await;
    assert_eq!(status, 200, "{alarms}");
    assert_eq!(alarms["alarms"], json!([]), "no alarm through the steps");

    // The KPIs count every job, and no duration is negative. Three hours back: a job that
    // ended just before the step forward is an hour old by the clock, rightly.
    let (status, stats) = app.get("/api/v1/stats?since=3h").await;
    assert_eq!(status, 200, "{stats}");
    for device in ["shelf1", "crane1"] {
        let d = stats["devices"].as_array().unwrap().iter().find(|d| d["device"] == device).unwrap();
        assert_eq!((d["completed"].clone(), d["failed"].clone()), (json!(6), json!(0)), "{device}: {stats}");
        let u = d["utilisation"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&u), "{stats}");
        for k in d["durations"].as_array().unwrap() {
            assert!(k["mean_s"].as_f64().unwrap() >= 0.0 && k["p95_s"].as_f64().unwrap() >= 0.0, "{stats}");
        }
    }
    app.stop().await;
}

/// `text` as a query value.
fn enc(text: &str) -> String {
    text.replace('+', "%2B").replace(':', "%3A")
}

#[test]
fn a_restart_after_a_step_back() {
    alone("clock::steps::a_restart_after_a_step_back", async || restarted().await);
}

/// rackd stopped, the wall clock stepped an hour back, rackd started again (a new process
/// remembers no stamp: [`rackd::domain::time::forget_stamps`]): what it stamps after the
/// restart is no earlier than what the store held. Before, the new jobs were stamped an
/// hour before the old ones.
async fn restarted() {
    let dir = tempfile::tempdir().unwrap();
    let db = rackd::store::Database::Sqlite(dir.path().join("rackd.db"));
    let job = |bay: u16| json!({"kind": "store", "barcode": format!("R{bay}"), "to": loc(1, bay, 1, 1)});
    let no_devices = |c: &mut rackd::config::Config| c.devices.clear();
    let app = support::spawn_on(db.clone(), no_devices).await;
    let mut before = Vec::new();
    for bay in 1..=3 {
        before.push(submit(&app, job(bay)).await);
    }
    let (_, last) = app.get(&format!("/api/v1/jobs/{}", before[2])).await;
    app.stop().await;

    step_wall_clock(-HOUR);
    rackd::domain::time::forget_stamps();
    let app = support::spawn_on(db.clone(), no_devices).await;
    for bay in 4..=6 {
        let id = submit(&app, job(bay)).await;
        let (_, after) = app.get(&format!("/api/v1/jobs/{id}")).await;
        assert!(
            ms(&after["created_at"]) >= ms(&last["created_at"]),
            "stamped before the store's last: {after} after {last}"
        );
    }
    app.stop().await;

    stamped_in_order(&db).await;
}

/// The event log of `db`, checked stamped in the order of its numbers.
async fn stamped_in_order(db: &rackd::store::Database) -> Vec<rackd::store::events::StoredEvent> {
    let pool = rackd::store::open(db, Duration::from_secs(5)).await.unwrap();
    let events = rackd::store::events::after(&pool, 0, 100_000).await.unwrap();
    pool.close().await;
    for w in events.windows(2) {
        assert!(
            w[1].at >= w[0].at,
            "event {} is stamped before event {}: {} < {}",
            w[1].seq,
            w[0].seq,
            w[1].at,
            w[0].at
        );
    }
    events
}
