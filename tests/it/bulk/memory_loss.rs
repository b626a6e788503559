//! A shelf PLC power-cycles with 60 of rackd's tasks in its slots: each is lost and locks
//! its location, and the later job on each location waits behind the lock. After checking
//! the aisle an operator sees what one bulk action would do (a dry run that changes
//! nothing), then unlocks and retries them all at once: every job completes once, in the
//! order it was accepted on its location.

use std::time::Duration;

use rackd::store::Engine;
use rackd::wire::task_id_for;
use rstest::rstest;
use serde_json::{Value, json};

use super::{audit, job, now, shelf_on, wait_jobs};
use crate::support::*;

/// Location `k` of 60 in aisle 1: rows 1-2, bays 1-10, levels 1-3.
fn place(k: u16) -> Value {
    loc(1 + k % 2, 1 + (k / 2) % 10, 1 + k / 20, 1)
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn after_a_power_cycle_one_bulk_action_unlocks_and_retries_sixty_lost_tasks(#[case] engine: Engine) {
    // Tasks take 3 s: the 60 stores sit in the 60 slots when the PLC loses its memory.
    let (app, sim) = shelf_on(engine, 3_000, &[1]).await;
    assert_eq!(sim.slots(), 60);
    let stores: Vec<Value> = (0..60)
        .map(|k| json!({"kind": "store", "barcode": format!("BOX-{k}"), "to": place(k), "reference": format!("S{k}")}))
        .collect();
    let retrieves: Vec<Value> = (0..60).map(|k| json!({"kind": "retrieve", "from": place(k)})).collect();
    let (status, batch) = app
        .post("/api/v1/jobs/batch", &json!({"jobs": stores.into_iter().chain(retrieves).collect::<Vec<_>>()}))
        .await;
    assert_eq!(status, 201, "{batch}");
    let ids: Vec<i64> = batch["jobs"].as_array().unwrap().iter().map(|j| j["id"].as_i64().unwrap()).collect();
    let (store_ids, retrieve_ids) = ids.split_at(60);
    wait_jobs(&app, store_ids, 20, "the 60 stores in their slots", |j| {
        j["state"] == "dispatched" || j["state"] == "running"
    })
    .await;
    let before = now();
    sim.power_cycle();
    sim.set_task_time(Duration::from_millis(5));
    wait_jobs(&app, store_ids, 20, "the 60 stores lost", |j| j["state"] == "failed").await;
    for id in store_ids {
        let j = job(&app, *id).await;
        assert_eq!(j["failure"]["kind"], "lost", "{j}");
    }
    // Each retrieve waited behind its store; once the store is lost, behind its lock (the
    // dispatcher says so at its next round after the failure's commit).
    wait_jobs(&app, retrieve_ids, 10, "the retrieves behind the locks", |j| {
        j["state"] == "queued" && j["waiting"]["reason"] == "location_locked"
    })
    .await;
    let audited = audit(&app, 100).await;

    // The dry run: what would be done, and nothing done.
    let body = json!({"device": "shelf1", "failure": "lost", "since": before, "unlock": true,
        "reason": "aisle 1 checked after the power cut"});
    let mut dry = body.clone();
    dry["dry_run"] = json!(true);
    let (status, plan) = app.post("/api/v1/jobs/retry", &dry).await;
    assert_eq!(status, 200, "{plan}");
    assert_eq!(plan["dry_run"], true);
    let planned: Vec<i64> =
        plan["jobs"].as_array().unwrap().iter().map(|j| j["id"].as_i64().unwrap()).collect();
    assert_eq!(planned, store_ids, "the lost jobs, in id order");
    assert!(plan["jobs"].as_array().unwrap().iter().all(|j| j["state"] == "failed"), "{plan}");
    let unlocked = plan["unlocked"].as_array().unwrap();
    assert_eq!(unlocked.len(), 60, "{plan}");
    assert!(unlocked.iter().all(|u| store_ids.contains(&u["lock"]["job"].as_i64().unwrap())), "{plan}");
    assert_eq!(job(&app, store_ids[0]).await["state"], "failed", "a dry run changes nothing");
    let (_, locked) = app.get("/api/v1/locations?aisle=1").await;
    let locks = locked.as_array().unwrap().iter().filter(|l| !l["lock"].is_null()).count();
    assert_eq!(locks, 60, "still locked after the dry run");
    assert_eq!(audit(&app, 100).await, audited, "a dry run is not audited");

    // One action: unlocked and retried in one commit.
    let (status, done) = app.post("/api/v1/jobs/retry", &body).await;
    assert_eq!(status, 200, "{done}");
    assert_eq!(done["dry_run"], false);
    assert_eq!(done["jobs"].as_array().unwrap().len(), 60);
    assert!(done["jobs"].as_array().unwrap().iter().all(|j| j["attempt"] == 2), "{done}");
    assert_eq!(done["unlocked"].as_array().unwrap().len(), 60);

    let all = wait_ended(&app, 120, 120).await;
    for j in &all {
        assert_eq!(j["state"], "completed", "{j}");
        let (_, history) = app.get(&format!("/api/v1/jobs/{}/history", j["id"])).await;
        let ends = history.as_array().unwrap().iter().filter(|h| h["state"] == "completed").count();
        assert_eq!(ends, 1, "job {} completed once: {history}", j["id"]);
    }
    for (store, retrieve) in store_ids.iter().zip(retrieve_ids) {
        let (s, r) = (task_id_for(*store), task_id_for(*retrieve));
        assert_eq!(sim.received(s), 2, "store {store}: lost once, then sent once more");
        assert_eq!(sim.received(r), 1, "retrieve {retrieve} sent once");
        // Each location's jobs ran in the order they were accepted: the store reached the
        // PLC (again) before the retrieve did.
        assert!(sim.received_at(s).unwrap() < sim.received_at(r).unwrap(), "store {store} before {retrieve}");
    }
    assert_eq!(sim.finished(), (120, 0), "no task failed: no retrieve ran before its store");
    assert!(sim.inventory().is_empty(), "{:?}", sim.inventory());
    assert_eq!(sim.violations(), 0);

    let entries = audit(&app, 200).await;
    let reason = "bulk unlock and retry of 60 jobs: aisle 1 checked after the power cut";
    let retried = entries.iter().filter(|(a, _, r)| a == "retry" && r == reason).count();
    let unlocks = entries.iter().filter(|(a, _, r)| a == "unlock" && r == reason).count();
    assert_eq!((retried, unlocks), (60, 60), "each job and location audited: {entries:?}");
    app.stop().await;
}
