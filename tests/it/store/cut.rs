//! A connection to PostgreSQL cut between a `COMMIT` and its answer, 100 times, while the
//! demo site's shelf and crane run jobs (issue 53). rackd reaches its database through a
//! proxy that cuts the job writer's connection at its `COMMIT` (the message holding the
//! writer's mark, `INSERT INTO rackd_commits`): half the time after delivering it (the server commits,
//! the answer is lost), half the time before (nothing commits). Each such group is settled
//! by reading what landed (`store/writer/unsure.rs`). Before, every cut group was failed
//! whether or not it had landed: a job created twice by the WMS's retry, or a dispatch
//! committed that no machine was sent.
//!
//! It asserts: every cut settled (`rackd_store_unsure_commits_total`), each one dropped
//! settled as not landed; every job the WMS got a 2xx for is in the store once and ends
//! completed; each task reached its machine once, with no busy-slot write and no breach of
//! the crane's handshake; the `store` alarm raised and cleared; work back within 2 s of
//! each cut (printed).

use std::sync::Arc;
use std::time::Duration;

use rackd::cli::demo::{self, Pace};
use rackd::config::Config;
use rackd::store::Database;
use serde_json::{Value, json};

use crate::api::demo::cloc;
use crate::api::waiting::wait_for_online;
use crate::support::machines::each_task_once_and_no_breach;
use crate::support::proxy::Proxy;
use crate::support::ws::Ws;
use crate::support::{TestApp, all_jobs, eventually, loc, postgres, spawn_on, split};

const CUTS: usize = 100;
const PACE: Pace = Pace { task_time: Duration::from_millis(150), crane_step: Duration::from_millis(10) };

/// Posts `job` as a WMS does: again on a 503 (the reference makes it idempotent) until it
/// gets a 2xx; answers the job's id.
async fn post(app: &TestApp, job: &Value) -> i64 {
    eventually("a 2xx for a job", Duration::from_secs(30), async || {
        let r = app.client.post(app.url("/api/v1/jobs")).json(job).send().await.unwrap();
        match split(r).await {
            (200 | 201, body) => Ok(body["id"].as_i64().unwrap()),
            (503, body) => Err(body),
            (status, body) => panic!("{status} {body}"),
        }
    })
    .await
}

/// The value of the metric line starting with `series`.
async fn metric(app: &TestApp, series: &str) -> u64 {
    let text = app.client.get(app.url("/metrics")).send().await.unwrap().text().await.unwrap();
    let line =
        text.lines().find(|l| l.starts_with(series)).unwrap_or_else(|| panic!("no {series} in {text}"));
    line.rsplit(' ').next().unwrap().parse::<f64>().unwrap() as u64
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn commits_whose_answer_was_lost_are_settled_by_what_landed() {
    let db = postgres::database().await;
    let (proxy, url) = Proxy::to_postgres(&db).await;
    let proxy = Arc::new(proxy);
    let mut site = Config::demo();
    let (shelf, crane, _tower) = demo::start_with(&mut site, PACE).await.expect("the demo simulators");
    let app = spawn_on(Database::Postgres(url), |c| {
        c.site = site.site.clone();
        c.devices = site.devices.clone();
    })
    .await;
    wait_for_online(&app, "shelf1").await;
    wait_for_online(&app, "crane1").await;

    // One cut at a time, delivered and dropped in turn, each once the last one was done.
    let cutter = {
        let proxy = proxy.clone();
        tokio::spawn(async move {
            for i in 0..CUTS {
                proxy.cut_at(b"INSERT INTO rackd_commits", 1, i % 2 == 0);
                while proxy.cuts().len() <= i {
                    tokio::time::sleep(Duration::from_millis(2)).await;
                }
            }
        })
    };

    // Jobs while the cuts go on: every shelf location once, and a few crane stores.
    let mut posted = Vec::new();
    let shelf_slots =
        (1..=2u16).flat_map(|row| (1..=10u16).flat_map(move |bay| (1..=6u16).map(move |l| (row, bay, l))));
    for (i, (row, bay, level)) in shelf_slots.enumerate() {
        if cutter.is_finished() && posted.len() >= 40 {
            break;
        }
        let shelf = json!({"kind": "store", "reference": format!("cut-s{i}"), "barcode": format!("S{i}"), "to": loc(row, bay, level, 1)});
        posted.push((post(&app, &shelf).await, 1));
        if i % 8 == 0 {
            let bay = 1 + (i / 8) as u16;
            let crane = json!({"kind": "store", "reference": format!("cut-c{i}"), "barcode": format!("C{i}"), "to": cloc(1, bay, 1, 1)});
            posted.push((post(&app, &crane).await, 2));
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    eventually("every cut done", Duration::from_secs(60), async || {
        if cutter.is_finished() { Ok(()) } else { Err(proxy.cuts().len()) }
    })
    .await;

    // Every job posted ends completed, each once in the store.
    let jobs = eventually("every job completed", Duration::from_secs(60), async || {
        let jobs = all_jobs(&app).await;
        let done =
            posted.iter().all(|(id, _)| jobs.iter().any(|j| j["id"] == *id && j["state"] == "completed"));
        if done {
            Ok(jobs)
        } else {
            Err(jobs.iter().filter(|j| j["state"] != "completed").cloned().collect::<Vec<_>>())
        }
    })
    .await;
    assert_eq!(jobs.len(), posted.len(), "a job is in the store twice, or one not posted is: {jobs:#?}");
    each_task_once_and_no_breach(&shelf, &crane, &posted);

    // Every cut settled, each dropped one as not landed.
    let cuts = proxy.cuts();
    let dropped = cuts.iter().filter(|(delivered, _)| !delivered).count() as u64;
    let settled = eventually("every cut settled", Duration::from_secs(10), async || {
        let landed = metric(&app, "rackd_store_unsure_commits_total{landed=\"true\"}").await;
        let lost = metric(&app, "rackd_store_unsure_commits_total{landed=\"false\"}").await;
        if (landed + lost) as usize == CUTS { Ok((landed, lost)) } else { Err((landed, lost)) }
    })
    .await;
    assert!(settled.1 >= dropped && settled.0 >= 1, "landed, not landed: {settled:?}; dropped {dropped}");

    // Back to work after each cut: the writer's next commit (settled, it goes on).
    let seen = proxy.seen();
    let mut gaps: Vec<Duration> =
        cuts.iter().filter_map(|(_, at)| seen.iter().find(|p| *p > at).map(|p| *p - *at)).collect();
    gaps.sort();
    let worst = gaps.last().copied().unwrap_or_default();
    println!(
        "{CUTS} cuts mid-commit: {} landed, {} not; next commit after a cut: median {:?}, worst {worst:?}",
        settled.0,
        settled.1,
        gaps.get(gaps.len() / 2).copied().unwrap_or_default()
    );
    // The goal is 2 s (the figure above: well under it alone); the bound here leaves room
    // for a loaded CI machine and still catches a writer that waits for a TCP timeout.
    assert!(worst < Duration::from_secs(5), "work resumed {worst:?} after a cut");

    // The store alarm: raised by the failed commits, cleared by the next one.
    let alarms = eventually("the store alarm raised and cleared", Duration::from_secs(20), async || {
        let (_, page) = app.get("/api/v1/alarms?device=store").await;
        let alarms = page["alarms"].as_array().cloned().unwrap_or_default();
        let store: Vec<Value> = alarms.into_iter().filter(|a| a["kind"] == "store").collect();
        if !store.is_empty() && store.iter().all(|a| !a["cleared_at"].is_null()) {
            Ok(store)
        } else {
            Err(store)
        }
    })
    .await;
    assert!(alarms.iter().all(|a| a["code"] == 3 || a["code"] == 2), "{alarms:#?}");
    app.stop().await;
}

/// A database that stops answering (a partition: the proxy forwards nothing, the
/// connections stay open) is told within a second and a bit, though no commit fails: the
/// writer's group is stalled (`store::writer`, `STALL`). Once it answers again, the group
/// commits and the store is told ok.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_database_that_stops_answering_is_told_at_once() {
    let db = postgres::database().await;
    let (proxy, url) = Proxy::to_postgres(&db).await;
    let app = spawn_on(Database::Postgres(url), |c| c.devices.clear()).await;
    let mut ws = Ws::connect(&app.base, "?topics=jobs").await;
    assert_eq!(ws.json().await["type"], "snapshot");

    proxy.block();
    let blocked = tokio::time::Instant::now();
    let job = json!({"kind": "store", "reference": "partition", "barcode": "P1", "to": loc(1, 1, 1, 1)});
    let posting = {
        let (client, url) = (app.client.clone(), app.url("/api/v1/jobs"));
        tokio::spawn(async move { client.post(url).json(&job).send().await.unwrap().status().as_u16() })
    };
    let told = store_message(&mut ws).await;
    let after = blocked.elapsed();
    println!("a database that stopped answering was told {after:?} after");
    assert_eq!((told["ok"].clone(), told["cause"].clone()), (json!(false), json!("unreachable")), "{told}");
    // A second (`STALL`), and room for a loaded machine's scheduling.
    assert!(after < Duration::from_secs(3), "told {after:?} after the database stopped answering");

    proxy.unblock();
    assert_eq!(posting.await.unwrap(), 201, "the job waited for the database and went in");
    assert_eq!(store_message(&mut ws).await["ok"], true);
    app.stop().await;
}

/// The next `store` message of `ws` (within 10 s), passing over events.
async fn store_message(ws: &mut Ws) -> Value {
    loop {
        let m = ws.json().await;
        if m["type"] == "store" {
            return m;
        }
    }
}
