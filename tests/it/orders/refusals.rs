//! What the API refuses and what it shows of sequences, deadlines and dependencies, on both
//! engines; the site has no device, so every job stays queued.

use rackd::config::{StationConfig, Transit};
use rackd::store::Engine;
use rstest::rstest;
use serde_json::{Value, json};

use crate::support::{TestApp, assert_error, loc, spawn_with};

fn retrieve(reference: &str, bay: u16, sequence: Value) -> Value {
    json!({"kind": "retrieve", "reference": reference, "from": loc(1, bay, 1, 1), "sequence": sequence})
}

async fn post(app: &TestApp, body: &Value) -> (u16, Value) {
    app.post("/api/v1/jobs", body).await
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sequences_deadlines_and_dependencies_are_checked_and_shown(#[case] engine: Engine) {
    let app = spawn_with(engine, |c| {
        c.site.stations =
            vec![StationConfig { id: 3, name: None, transit: vec![Transit { aisle: 1, seconds: 5.0 }] }];
    })
    .await;
    // Fields a job does not take, and values out of range: 422, nothing stored.
    let store = json!({"kind": "store", "to": loc(1, 1, 1, 1), "sequence": {"name": "S", "position": 1}});
    assert_error(&post(&app, &store).await, 422, "invalid_job");
    assert_error(
        &post(&app, &retrieve("R0", 1, json!({"name": "S", "position": 0}))).await,
        422,
        "invalid_job",
    );
    assert_error(
        &post(&app, &retrieve("R0", 1, json!({"name": "S", "position": 1, "station": 9}))).await,
        422,
        "invalid_job",
    );
    assert_error(
        &post(&app, &retrieve("R0", 1, json!({"name": " ", "position": 1}))).await,
        422,
        "invalid_job",
    );
    let late = json!({"kind": "store", "to": loc(1, 1, 1, 1), "deadline": "tomorrow at two"});
    assert_error(&post(&app, &late).await, 422, "invalid_job");

    // A sequence of station 3: a position once, one station, nothing after the last.
    let first = post(&app, &retrieve("ORD-1", 1, json!({"name": "ORD", "position": 1, "station": 3}))).await;
    assert_eq!(first.0, 201, "{first:?}");
    assert_eq!(first.1["sequence"], json!({"name": "ORD", "position": 1}), "{first:?}");
    let again = post(&app, &retrieve("ORD-1", 1, json!({"name": "ORD", "position": 1, "station": 3}))).await;
    assert_eq!((again.0, &again.1["id"]), (200, &first.1["id"]), "the same request again is the same job");
    assert_error(
        &post(&app, &retrieve("ORD-1", 1, json!({"name": "ORD", "position": 4}))).await,
        409,
        "reference_conflict",
    );
    assert_error(
        &post(&app, &retrieve("ORD-1b", 2, json!({"name": "ORD", "position": 1}))).await,
        409,
        "sequence_conflict",
    );
    let other_station = json!({"kind": "travel", "reference": "ORD-x", "to": {"aisle": 2, "row": 1, "bay": 2, "level": 1, "position": 1},
        "sequence": {"name": "ORD", "position": 5, "station": 4}});
    assert_error(&post(&app, &other_station).await, 422, "invalid_job");
    let last = post(&app, &retrieve("ORD-3", 3, json!({"name": "ORD", "position": 3, "last": true}))).await;
    assert_eq!(last.0, 201, "{last:?}");
    assert_error(
        &post(&app, &retrieve("ORD-4", 4, json!({"name": "ORD", "position": 4}))).await,
        409,
        "sequence_conflict",
    );

    let (status, seq) = app.get("/api/v1/sequences/ORD").await;
    assert_eq!(status, 200, "{seq}");
    assert_eq!(
        (seq["station"].as_u64(), seq["state"].as_str(), seq["complete"].as_bool()),
        (Some(3), Some("complete"), Some(true)),
        "{seq}"
    );
    assert_eq!(seq["next_position"], 1, "1 is due (then 2, not posted yet, holds 3): {seq}");
    let positions: Vec<u64> =
        seq["members"].as_array().unwrap().iter().map(|m| m["position"].as_u64().unwrap()).collect();
    assert_eq!(positions, vec![1, 3], "{seq}");
    assert_eq!(seq["holding"]["reason"], "no_device", "the due member waits for a device: {seq}");
    assert_error(&app.get("/api/v1/sequences/nothing").await, 404, "not_found");
    assert_error(&app.post("/api/v1/sequences/nothing/complete", &json!({})).await, 404, "not_found");

    // Re-prioritised, then cancelled as a whole.
    let (status, seq) = app.patch("/api/v1/sequences/ORD", &json!({"priority": 2})).await;
    assert_eq!(status, 200, "{seq}");
    let (_, job) = app.get(&format!("/api/v1/jobs/{}", last.1["id"])).await;
    assert_eq!(job["priority"], 2, "{job}");
    let (status, seq) = app.post("/api/v1/sequences/ORD/cancel", &json!({})).await;
    assert_eq!(status, 200, "{seq}");
    assert_eq!(seq["state"], "cancelled", "{seq}");
    assert!(seq["members"].as_array().unwrap().iter().all(|m| m["state"] == "cancelled"), "{seq}");
    assert_error(
        &post(&app, &retrieve("ORD-9", 9, json!({"name": "ORD", "position": 9}))).await,
        409,
        "sequence_conflict",
    );

    // Open sequences complete on request; a complete one takes nobody.
    assert_eq!(post(&app, &retrieve("OPEN-1", 5, json!({"name": "OPEN", "position": 1}))).await.0, 201);
    let (status, seq) = app.post("/api/v1/sequences/OPEN/complete", &json!({})).await;
    assert_eq!(
        (status, seq["state"].as_str(), seq["complete"].as_bool()),
        (200, Some("complete"), Some(true)),
        "{seq}"
    );
    assert_eq!(app.post("/api/v1/sequences/OPEN/complete", &json!({})).await.0, 200, "idempotent");
    assert_error(
        &post(&app, &retrieve("OPEN-2", 6, json!({"name": "OPEN", "position": 2}))).await,
        409,
        "sequence_conflict",
    );

    // Dependencies: an unknown reference, a circle, a job naming itself.
    let after = |reference: &str, bay: u16, on: &[&str]| json!({"kind": "clear", "reference": reference, "location": loc(2, bay, 2, 1), "after": on});
    assert_error(&post(&app, &after("D1", 1, &["nobody"])).await, 422, "unknown_dependency");
    assert_error(&post(&app, &after("D1", 1, &["D1"])).await, 422, "dependency_cycle");
    let circle = json!({"jobs": [after("D2", 2, &["D3"]), after("D3", 3, &["D4"]), after("D4", 4, &["D2"])]});
    assert_error(&app.post("/api/v1/jobs/batch", &circle).await, 422, "dependency_cycle");
    // Forward in one batch, and on a stored job: fine.
    let chain = json!({"jobs": [after("D5", 5, &["D6", "ORD-1"]), after("D6", 6, &[])]});
    let (status, chain) = app.post("/api/v1/jobs/batch", &chain).await;
    assert_eq!(status, 201, "{chain}");
    assert_eq!(chain["jobs"][0]["after"], json!(["D6", "ORD-1"]), "{chain}");

    // A deadline already passed: the job is accepted, and late.
    let past = json!({"kind": "clear", "reference": "LATE", "location": loc(2, 9, 1, 1), "deadline": "2020-01-01T00:00:00Z"});
    let (status, job) = post(&app, &past).await;
    assert_eq!(status, 201, "{job}");
    assert_eq!(job["deadline"], "2020-01-01T00:00:00Z", "{job}");
    assert!(job["late_by_s"].as_i64().is_some_and(|s| s > 3600), "{job}");
    let metrics = app.client.get(app.url("/metrics")).send().await.unwrap().text().await.unwrap();
    let late: Vec<&str> = metrics.lines().filter(|l| l.starts_with("rackd_jobs_late ")).collect();
    assert_eq!(late, vec!["rackd_jobs_late 1"], "{metrics}");
    assert!(metrics.lines().any(|l| l.starts_with("rackd_deadline_slack_seconds -")), "{metrics}");
    app.stop().await;
}
