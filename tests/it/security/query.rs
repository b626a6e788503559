//! Issue 51, "the API refuses what it would ignore": a query parameter an operation does
//! not take is refused with 400 `bad_query` naming it, on every operation (the list
//! is the OpenAPI document's, `src/api/query.rs`); `dry_run` is taken in the query and in
//! the body alike by every operation that has one, and the two may not disagree. Before,
//! `POST /api/v1/jobs/retry?dry_run=true` retried for real and a reload's
//! `{"dry_run": true}` body was ignored.

use std::time::Duration;

use rackd::config::{AisleConfig, Config};
use rackd::domain::time::from_ms;
use rackd::domain::{JobSpec, JobState, LightColor, Location, NewJob, Priority};
use rackd::store::import::{self, Ended};
use rackd::store::{self, Engine};
use serde_json::{Value, json};

use crate::support::{TestApp, assert_error, fresh_database, spawn_app, spawn_from_file, spawn_on, split};

/// A POST with a JSON body (keyless mode takes changes as JSON only).
async fn post(app: &TestApp, path: &str, body: &str) -> (u16, Value) {
    let request = app.client.post(app.url(path)).header("content-type", "application/json");
    split(request.body(body.to_owned()).send().await.unwrap()).await
}

/// A server whose store holds job 1, a light that failed (and the store's folder).
async fn with_a_failed_job() -> (TestApp, Option<tempfile::TempDir>) {
    let (db, dir) = fresh_database(Engine::Sqlite).await;
    let pool = store::open(&db, Duration::from_secs(5)).await.unwrap();
    let new = NewJob {
        spec: JobSpec::Light {
            location: Location { aisle: 1, row: 1, bay: 1, level: 1, position: 1 },
            color: LightColor::Green,
            on: true,
        },
        reference: Some("L-1".into()),
        priority: Priority::default(),
        barcode: None,
        device: None,
        serves: None,
        terms: Default::default(),
    };
    let at = rackd::domain::time::now_ms() - 60_000;
    let mut job = new.accepted(1, at);
    job.state = JobState::Failed;
    job.updated_at = from_ms(at + 1000);
    let history =
        vec![(JobState::Queued, "accepted".into(), at), (JobState::Failed, "lost".into(), at + 1000)];
    import::ended_jobs(&pool, &[Ended { request: new.canonical(), job, history }]).await.unwrap();
    pool.close().await;
    (spawn_on(db, |_| {}).await, dir)
}

#[tokio::test]
async fn a_bulk_action_takes_dry_run_in_the_query_too() {
    let (app, _dir) = with_a_failed_job().await;
    let (status, answer) = post(&app, "/api/v1/jobs/retry?dry_run=true", r#"{"jobs": [1]}"#).await;
    assert_eq!(status, 200, "{answer}");
    assert_eq!(answer["dry_run"], true, "?dry_run=true is a dry run: {answer}");
    let (_, job) = app.get("/api/v1/jobs/1").await;
    assert_eq!(job["state"], "failed", "nothing was retried: {job}");

    // The body says it as well, or says nothing; the two may not disagree.
    let (status, answer) =
        post(&app, "/api/v1/jobs/retry?dry_run=true", r#"{"jobs": [1], "dry_run": true}"#).await;
    assert_eq!((status, &answer["dry_run"]), (200, &json!(true)), "{answer}");
    let got = post(&app, "/api/v1/jobs/retry?dry_run=true", r#"{"jobs": [1], "dry_run": false}"#).await;
    assert_error(&got, 400, "conflicting_dry_run");
    let got = post(&app, "/api/v1/jobs/cancel?dry_run=false", r#"{"jobs": [1], "dry_run": true}"#).await;
    assert_error(&got, 400, "conflicting_dry_run");
    let (_, job) = app.get("/api/v1/jobs/1").await;
    assert_eq!(job["state"], "failed", "{job}");
    app.stop().await;
}

#[tokio::test]
async fn an_unknown_query_parameter_is_refused_and_named_on_every_operation() {
    let app = spawn_app(Engine::Sqlite).await;
    // A typo of `dry_run` on an action, of `state` on a list, anything on a route that
    // takes no query: each refused, nothing done.
    let got = post(&app, "/api/v1/jobs/cancel?dryrun=true", r#"{"aisle": 1}"#).await;
    assert_error(&got, 400, "bad_query");
    let message = got.1["error"]["message"].as_str().unwrap();
    assert!(message.contains("`dryrun`") && message.contains("dry_run"), "{message}");
    let got = split(app.client.get(app.url("/api/v1/jobs?stat=failed")).send().await.unwrap()).await;
    assert_error(&got, 400, "bad_query");
    assert!(got.1["error"]["message"].as_str().unwrap().contains("`stat`"), "{got:?}");
    for path in ["/api/v1/devices?x=1", "/healthz?verbose=1", "/api/v1/jobs/1?fields=id", "/metrics?name=x"] {
        let got = split(app.client.get(app.url(path)).send().await.unwrap()).await;
        assert_error(&got, 400, "bad_query");
        let message = got.1["error"]["message"].as_str().unwrap();
        assert!(message.contains("takes no query parameter"), "{path}: {message}");
    }
    // What an operation documents is taken as before.
    let (status, _) = app.get("/api/v1/jobs?state=failed&limit=5").await;
    assert_eq!(status, 200);
    let (status, _) = app.get("/api/v1/alarms?active=true").await;
    assert_eq!(status, 200);
    app.stop().await;
}

#[tokio::test]
async fn a_reload_takes_dry_run_in_the_body_too() {
    let (app, file) = spawn_from_file("").await;
    let running = app.get("/api/v1/config").await.1;
    let mut config = Config::load(&file).unwrap();
    config.site.aisles.push(AisleConfig { aisle: 9, rows: 1, bays: 1, levels: 1, positions: 1, depth: 1 });
    std::fs::write(&file, toml::to_string(&config).unwrap()).unwrap();

    let (status, answer) = post(&app, "/api/v1/config/reload", r#"{"dry_run": true}"#).await;
    assert_eq!(status, 200, "{answer}");
    assert_eq!(answer["dry_run"], true, "a dry run asked in the body: {answer}");
    assert_eq!(answer["aisles"]["added"], json!([9]), "{answer}");
    assert_eq!(app.get("/api/v1/config").await.1, running, "nothing was applied");
    let got = post(&app, "/api/v1/config/reload?dry_run=false", r#"{"dry_run": true}"#).await;
    assert_error(&got, 400, "conflicting_dry_run");
    assert_error(&post(&app, "/api/v1/config/reload", r#"{"dryrun": true}"#).await, 422, "invalid_body");
    assert_eq!(app.get("/api/v1/config").await.1, running, "nothing was applied");
    app.stop().await;
}

#[test]
fn every_operation_documents_an_unknown_query_parameter() {
    let doc = serde_json::to_value(rackd::api::openapi()).unwrap();
    for (path, item) in doc["paths"].as_object().unwrap() {
        for (method, operation) in item.as_object().unwrap() {
            let bad = &operation["responses"]["400"]["description"];
            let says =
                bad.as_str().is_some_and(|d| d.contains("a query parameter the operation does not take"));
            assert!(says, "{method} {path}: {bad}");
        }
    }
}
