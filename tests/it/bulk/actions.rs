//! Each bulk action by each of its filters and as a list: cancel the queued jobs of a
//! device or an aisle, retry the failed jobs of one kind since a time, unlock by cause;
//! one refused item refuses the whole action; bad requests say what is wrong.

use std::time::Duration;

use rackd::store::Engine;
use rstest::rstest;
use serde_json::{Value, json};
use time::format_description::well_known::Rfc3339;

use super::{audit, job, now, shelf_on, wait_jobs};
use crate::support::*;

fn ids(answer: &Value) -> Vec<i64> {
    answer["jobs"].as_array().unwrap().iter().map(|j| j["id"].as_i64().unwrap()).collect()
}

async fn submit(app: &TestApp, body: Value) -> i64 {
    let (status, j) = app.post("/api/v1/jobs", &body).await;
    assert_eq!(status, 201, "{j}");
    j["id"].as_i64().unwrap()
}

/// A location of aisle 2.
fn cloc(bay: u16) -> Value {
    json!({"aisle": 2, "row": 1, "bay": bay, "level": 1, "position": 1})
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cancel_takes_the_queued_jobs_of_a_device_or_an_aisle(#[case] engine: Engine) {
    // 3 s a task: the first job stays on the machine while the rest are decided on. The
    // shelf serves aisle 2 as well, here.
    let (app, sim) = shelf_on(engine, 3_000, &[1, 2]).await;
    let on_machine = submit(&app, json!({"kind": "store", "to": loc(1, 1, 1, 1)})).await;
    wait_jobs(&app, &[on_machine], 10, "the first job on the machine", |j| j["state"] != "queued").await;
    assert_eq!(app.post("/api/v1/devices/shelf1/pause", &json!({})).await.0, 200);
    let mut shelf = Vec::new();
    for bay in 2..=4 {
        shelf.push(submit(&app, json!({"kind": "store", "to": loc(1, bay, 1, 1)})).await);
    }
    let aisle_2 = [
        submit(&app, json!({"kind": "store", "to": cloc(1)})).await,
        submit(&app, json!({"kind": "store", "to": cloc(2)})).await,
    ];

    let (status, plan) = app.post("/api/v1/jobs/cancel", &json!({"device": "shelf1", "dry_run": true})).await;
    assert_eq!((status, plan["dry_run"].clone()), (200, json!(true)), "{plan}");
    let queued: Vec<i64> = shelf.iter().chain(&aisle_2).copied().collect();
    assert_eq!(ids(&plan), queued, "the device's queued jobs, not the one on the machine");
    assert!(plan["unlocked"].as_array().unwrap().is_empty());
    assert_eq!(job(&app, shelf[0]).await["state"], "queued", "a dry run cancels nothing");

    let (status, done) =
        app.post("/api/v1/jobs/cancel", &json!({"aisle": 2, "reason": "aisle 2 closed"})).await;
    assert_eq!(status, 200, "{done}");
    assert_eq!(ids(&done), aisle_2);
    assert!(done["jobs"].as_array().unwrap().iter().all(|j| j["state"] == "cancelled"), "{done}");
    assert_eq!(job(&app, shelf[0]).await["state"], "queued", "another aisle's jobs stay");

    // One job that is no longer queued refuses the whole list.
    let got = app.post("/api/v1/jobs/cancel", &json!({"jobs": [shelf[0], on_machine]})).await;
    assert_error(&got, 409, "bulk_refused");
    let message = got.1["error"]["message"].as_str().unwrap();
    assert!(
        message.contains(&format!("job {on_machine} is ")) && message.contains("not queued"),
        "{message}"
    );
    assert!(message.starts_with("nothing was done: 1 item cannot"), "{message}");
    assert_eq!(job(&app, shelf[0]).await["state"], "queued", "nothing was cancelled");

    let (status, done) =
        app.post("/api/v1/jobs/cancel", &json!({"device": "shelf1", "reason": "orders withdrawn"})).await;
    assert_eq!(status, 200, "{done}");
    assert_eq!(ids(&done), shelf);
    for id in &shelf {
        assert_eq!(job(&app, *id).await["state"], "cancelled");
    }
    let entries = audit(&app, 5).await;
    let want: Vec<(String, String, String)> = shelf
        .iter()
        .rev()
        .map(|id| ("cancel".into(), format!("job:{id}"), "bulk cancel of 3 jobs: orders withdrawn".into()))
        .collect();
    assert_eq!(entries[..3], want, "one entry per job, newest first");
    assert_eq!(entries[3].2, "bulk cancel of 2 jobs: aisle 2 closed");
    // Nothing to cancel any more: an empty answer, not an error.
    let (status, none) = app.post("/api/v1/jobs/cancel", &json!({"device": "shelf1"})).await;
    assert_eq!((status, ids(&none)), (200, vec![]));
    assert_eq!(sim.violations(), 0);
    app.stop().await;
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn retry_by_failure_kind_since_a_time_and_unlock_by_cause(#[case] engine: Engine) {
    let (app, sim) = shelf_on(engine, 2_000, &[1]).await;
    // Two stores lost in a power cycle, then two retrieves from empty places rejected.
    let lost = [
        submit(&app, json!({"kind": "store", "to": loc(1, 1, 1, 1)})).await,
        submit(&app, json!({"kind": "store", "to": loc(1, 2, 1, 1)})).await,
    ];
    wait_jobs(&app, &lost, 10, "both stores in their slots", |j| j["state"] != "queued").await;
    sim.power_cycle();
    sim.set_task_time(Duration::from_millis(0));
    wait_jobs(&app, &lost, 10, "both stores lost", |j| j["failure"]["kind"] == "lost").await;
    let first = submit(&app, json!({"kind": "retrieve", "from": loc(2, 5, 1, 1)})).await;
    wait_jobs(&app, &[first], 10, "the first retrieve rejected", |j| j["state"] == "failed").await;
    let failed_at = job(&app, first).await["updated_at"].as_str().unwrap().to_owned();
    let since = time::OffsetDateTime::parse(&failed_at, &Rfc3339).unwrap() + Duration::from_millis(1);
    let since = since.format(&Rfc3339).unwrap();
    let second = submit(&app, json!({"kind": "retrieve", "from": loc(2, 6, 1, 1)})).await;
    wait_jobs(&app, &[second], 10, "the second retrieve rejected", |j| j["state"] == "failed").await;
    assert_eq!(job(&app, second).await["failure"]["kind"], "rejected");

    let dry = |body: Value| {
        let mut body = body;
        body["dry_run"] = json!(true);
        body
    };
    let (_, plan) = app.post("/api/v1/jobs/retry", &dry(json!({"failure": "rejected"}))).await;
    assert_eq!(ids(&plan), [first, second]);
    let (_, plan) =
        app.post("/api/v1/jobs/retry", &dry(json!({"failure": "rejected", "since": since}))).await;
    assert_eq!(ids(&plan), [second], "{plan}");
    let (_, plan) =
        app.post("/api/v1/jobs/retry", &dry(json!({"device": "shelf1", "failure": "lost"}))).await;
    assert_eq!(ids(&plan), lost);
    assert!(plan["unlocked"].as_array().unwrap().is_empty(), "no unlock asked");

    // Unlock by cause: the places the lost jobs locked, not the rejected ones'.
    let cause = json!({"device": "shelf1", "failure": "lost", "reason": "bays 1-2 checked"});
    let (status, plan) = app.post("/api/v1/locations/unlock", &dry(cause.clone())).await;
    assert_eq!(status, 200, "{plan}");
    let unlocked: Vec<(Value, i64)> = plan["unlocked"]
        .as_array()
        .unwrap()
        .iter()
        .map(|u| (u["location"]["bay"].clone(), u["lock"]["job"].as_i64().unwrap()))
        .collect();
    assert_eq!(unlocked, [(json!(1), lost[0]), (json!(2), lost[1])]);
    let (status, done) = app.post("/api/v1/locations/unlock", &cause).await;
    assert_eq!((status, done["unlocked"].as_array().unwrap().len()), (200, 2), "{done}");
    let (_, locked) = app.get("/api/v1/locations?aisle=1").await;
    let locked: Vec<Value> = locked
        .as_array()
        .unwrap()
        .iter()
        .filter(|l| !l["lock"].is_null())
        .map(|l| l["lock"]["job"].clone())
        .collect();
    assert_eq!(locked, [json!(first), json!(second)], "the rejected jobs' locks stay");
    assert_eq!(job(&app, lost[0]).await["state"], "failed", "an unlock retries nothing");

    // Retried without unlock, a job waits on its own lock.
    let (status, done) = app
        .post("/api/v1/jobs/retry", &json!({"failure": "rejected", "since": since, "reason": "box found"}))
        .await;
    assert_eq!(status, 200, "{done}");
    assert_eq!(ids(&done), [second]);
    let j = &done["jobs"][0];
    assert_eq!((j["state"].clone(), j["attempt"].clone()), (json!("queued"), json!(2)), "{j}");
    assert_eq!(j["waiting"]["reason"], "location_locked", "{j}");
    assert_eq!(job(&app, first).await["state"], "failed");

    // One item no longer as it was refuses the whole action.
    let got = app.post("/api/v1/jobs/retry", &json!({"jobs": [first, second]})).await;
    assert_error(&got, 409, "bulk_refused");
    assert!(
        got.1["error"]["message"].as_str().unwrap().contains(&format!("job {second} is queued, not failed"))
    );
    assert_eq!(job(&app, first).await["state"], "failed", "nothing was retried");
    let got =
        app.post("/api/v1/locations/unlock", &json!({"locations": [loc(1, 1, 1, 1), loc(2, 5, 1, 1)]})).await;
    assert_error(&got, 409, "bulk_refused");
    assert!(
        got.1["error"]["message"].as_str().unwrap().contains("location 1/1/1/1/1 is not locked"),
        "{got:?}"
    );
    let (_, still) = app.get("/api/v1/locations?aisle=1").await;
    assert!(
        still.as_array().unwrap().iter().any(|l| l["lock"]["job"] == json!(first)),
        "nothing was unlocked"
    );

    let entries = audit(&app, 4).await;
    assert_eq!(
        entries[0],
        ("retry".into(), format!("job:{second}"), "bulk retry of 1 job: box found".into())
    );
    assert_eq!(entries[1].0, "unlock");
    assert_eq!(entries[1].2, "bulk unlock of 2 locations: bays 1-2 checked");
    assert_eq!(sim.violations(), 0);
    app.stop().await;
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn bad_bulk_requests_say_what_is_wrong(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    let queued = submit(&app, json!({"kind": "store", "to": loc(1, 1, 1, 1)})).await;
    for (path, body, code) in [
        ("/api/v1/jobs/retry", json!({}), "invalid_bulk"),
        ("/api/v1/jobs/retry", json!({"since": now()}), "invalid_bulk"),
        ("/api/v1/jobs/retry", json!({"jobs": [queued], "device": "shelf1"}), "invalid_bulk"),
        ("/api/v1/jobs/retry", json!({"device": "shelf1"}), "invalid_bulk"),
        ("/api/v1/jobs/retry", json!({"jobs": []}), "invalid_bulk"),
        ("/api/v1/jobs/retry", json!({"jobs": [queued, queued]}), "invalid_bulk"),
        ("/api/v1/jobs/retry", json!({"jobs": (1..=10_001).collect::<Vec<i64>>()}), "bulk_too_large"),
        ("/api/v1/jobs/retry", json!({"failure": "bogus"}), "invalid_body"),
        ("/api/v1/jobs/retry", json!({"failure": "lost", "since": "yesterday"}), "invalid_body"),
        ("/api/v1/jobs/cancel", json!({}), "invalid_bulk"),
        ("/api/v1/jobs/cancel", json!({"aisle": 99}), "invalid_bulk"),
        ("/api/v1/jobs/cancel", json!({"aisle": 1, "why": "x"}), "invalid_body"),
        ("/api/v1/jobs/cancel", json!({"aisle": 1, "reason": "x".repeat(501)}), "invalid_reason"),
        ("/api/v1/locations/unlock", json!({}), "invalid_bulk"),
        ("/api/v1/locations/unlock", json!({"locations": [loc(9, 1, 1, 1)]}), "invalid_bulk"),
        (
            "/api/v1/locations/unlock",
            json!({"locations": [loc(1, 1, 1, 1), loc(1, 1, 1, 1)]}),
            "invalid_bulk",
        ),
        (
            "/api/v1/locations/unlock",
            json!({"failure": "lost", "locations": [loc(1, 1, 1, 1)]}),
            "invalid_bulk",
        ),
    ] {
        assert_error(&app.post(path, &body).await, 422, code);
    }
    let got = app.post("/api/v1/jobs/retry", &json!({"jobs": [queued + 1000]})).await;
    assert_error(&got, 409, "bulk_refused");
    assert!(got.1["error"]["message"].as_str().unwrap().contains("does not exist"), "{got:?}");
    let raw = app
        .client
        .post(app.url("/api/v1/jobs/cancel"))
        .header("content-type", "application/json")
        .body("{")
        .send()
        .await
        .unwrap();
    assert_error(&split(raw).await, 400, "malformed_json");
    assert_error(&app.get("/api/v1/jobs/retry").await, 405, "method_not_allowed");
    // Nothing selected: nothing to do, nothing audited.
    let (status, none) = app.post("/api/v1/jobs/retry", &json!({"failure": "lost", "unlock": true})).await;
    assert_eq!((status, none), (200, json!({"dry_run": false, "jobs": [], "unlocked": []})));
    assert!(audit(&app, 10).await.iter().all(|(action, _, _)| action == "submit"));
    assert_eq!(job(&app, queued).await["state"], "queued");
    app.stop().await;
}
