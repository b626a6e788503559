//! Every bad input gets JSON with a code, a message and the right status; nothing 500s.

use proptest::prelude::*;
use proptest::strategy::ValueTree;
use rackd::store::Engine;
use rstest::rstest;
use serde_json::json;

use crate::support::*;

async fn raw(
    app: &TestApp,
    method: reqwest::Method,
    path: &str,
    content_type: Option<&str>,
    body: Vec<u8>,
) -> (u16, serde_json::Value) {
    let mut req = app.client.request(method, app.url(path)).body(body);
    if let Some(ct) = content_type {
        req = req.header("content-type", ct);
    }
    split(req.send().await.unwrap()).await
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn bad_requests_get_json_errors(#[case] engine: Engine) {
    let app = spawn_with(engine, |c| c.server.body_limit_bytes = 64 * 1024).await;
    use reqwest::Method as M;
    let json_ct = Some("application/json");
    type Case<'a> = (M, &'a str, Option<&'a str>, Vec<u8>, u16, &'a str);
    let cases: Vec<Case> = vec![
        (M::POST, "/api/v1/jobs", json_ct, b"{\"kind\": \"store\",".to_vec(), 400, "malformed_json"),
        (M::POST, "/api/v1/jobs", json_ct, b"not json".to_vec(), 400, "malformed_json"),
        (M::POST, "/api/v1/jobs", Some("text/plain"), b"{}".to_vec(), 415, "unsupported_media_type"),
        (M::POST, "/api/v1/jobs", None, b"{}".to_vec(), 415, "unsupported_media_type"),
        (M::POST, "/api/v1/jobs", json_ct, b"{}".to_vec(), 422, "invalid_body"),
        (M::POST, "/api/v1/jobs", json_ct, b"[]".to_vec(), 422, "invalid_body"),
        (M::POST, "/api/v1/jobs", json_ct, br#"{"kind":"fly"}"#.to_vec(), 422, "invalid_body"),
        (
            M::POST,
            "/api/v1/jobs",
            json_ct,
            br#"{"kind":"store","to":{"aisle":1}}"#.to_vec(),
            422,
            "invalid_body",
        ),
        (M::POST, "/api/v1/jobs", json_ct, br#"{"kind":"store","extra":1}"#.to_vec(), 422, "invalid_body"),
        (
            M::POST,
            "/api/v1/jobs",
            json_ct,
            br#"{"kind":"store","to":{"aisle":-1,"row":1,"bay":1,"level":1,"position":1}}"#.to_vec(),
            422,
            "invalid_body",
        ),
        (M::POST, "/api/v1/jobs", json_ct, vec![b' '; 70 * 1024], 413, "body_too_large"),
        (M::POST, "/api/v1/jobs/batch", json_ct, br#"{"jobs":{}}"#.to_vec(), 422, "invalid_body"),
        (M::GET, "/api/v1/jobs/abc", None, vec![], 400, "bad_path"),
        (M::GET, "/api/v1/jobs/99999999999999999999999", None, vec![], 400, "bad_path"),
        (M::GET, "/api/v1/jobs/12345", None, vec![], 404, "not_found"),
        (M::GET, "/api/v1/jobs?limit=5000", None, vec![], 400, "bad_query"),
        (M::GET, "/api/v1/jobs?state=done", None, vec![], 400, "bad_query"),
        (M::GET, "/api/v1/nothing", None, vec![], 404, "not_found"),
        (M::GET, "/nothing.html", None, vec![], 404, "not_found"),
        // Without keys, a change not sent as JSON is refused before its method is looked
        // at, as a missing key is with keys (`security::keyless`).
        (M::DELETE, "/api/v1/jobs", None, vec![], 415, "unsupported_media_type"),
        (M::DELETE, "/api/v1/jobs", json_ct, vec![], 405, "method_not_allowed"),
        (M::PUT, "/api/v1/jobs/1", json_ct, b"{}".to_vec(), 405, "method_not_allowed"),
        (
            M::PATCH,
            "/api/v1/jobs/1",
            json_ct,
            br#"{"priority":1,"kind":"store"}"#.to_vec(),
            422,
            "invalid_body",
        ),
        (M::PATCH, "/api/v1/jobs/1", json_ct, br#"{"priority":1}"#.to_vec(), 404, "not_found"),
    ];
    for (method, path, ct, body, status, code) in cases {
        let got = raw(&app, method.clone(), path, ct, body).await;
        assert_error(&got, status, code);
        let _ = (method, path);
    }
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn a_body_is_read_alike_whatever_form_of_json_content_type_it_comes_with(#[case] engine: Engine) {
    // A plain `application/json` body is read without tracking where it goes wrong, and read
    // again with it only if it is refused: the answer still names the place.
    let app = spawn_app(engine).await;
    let bad = json!({"jobs": [store("ct-0"), {"kind": "fly"}]}).to_string().into_bytes();
    for ct in ["application/json", "Application/JSON", "application/json; charset=utf-8"] {
        let got = raw(&app, reqwest::Method::POST, "/api/v1/jobs/batch", Some(ct), bad.clone()).await;
        assert_error(&got, 422, "invalid_body");
        assert!(got.1["error"]["message"].as_str().unwrap().contains("jobs[1]"), "{ct}: {got:?}");
    }
    for (i, ct) in
        ["application/json", "Application/JSON", "application/json; charset=utf-8"].iter().enumerate()
    {
        let body = store(&format!("ct-{i}")).to_string().into_bytes();
        let (status, job) = raw(&app, reqwest::Method::POST, "/api/v1/jobs", Some(ct), body).await;
        assert_eq!(status, 201, "{ct}: {job}");
        assert_eq!(job["reference"], format!("ct-{i}"));
    }
    let got =
        raw(&app, reqwest::Method::POST, "/api/v1/jobs", Some("application/json;x"), b"{}".to_vec()).await;
    assert_error(&got, 415, "unsupported_media_type");
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn random_bodies_never_cause_a_server_error(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    let mut runner =
        proptest::test_runner::TestRunner::new(ProptestConfig { cases: 200, ..ProptestConfig::default() });
    let strategy = prop_oneof![
        proptest::collection::vec(any::<u8>(), 0..200),
        any::<String>().prop_map(String::into_bytes),
        arb_json().prop_map(|v| v.to_string().into_bytes()),
    ];
    let mut bodies = Vec::new();
    for _ in 0..200 {
        bodies.push(strategy.new_tree(&mut runner).unwrap().current());
    }
    for body in bodies {
        for path in ["/api/v1/jobs", "/api/v1/jobs/batch"] {
            let (status, value) =
                raw(&app, reqwest::Method::POST, path, Some("application/json"), body.clone()).await;
            assert!(status < 500, "{status} for {:?}", String::from_utf8_lossy(&body));
            if status >= 400 {
                assert!(value["error"]["code"].is_string(), "{value}");
            }
        }
    }
}

/// JSON that looks like a job, with values drawn from plausible and implausible ranges.
fn arb_json() -> impl Strategy<Value = serde_json::Value> {
    let num = prop_oneof![
        Just(json!(0)),
        Just(json!(1)),
        Just(json!(-1)),
        Just(json!(65536)),
        Just(json!(1.5)),
        Just(json!("1")),
        Just(json!(null))
    ];
    let loc = (num.clone(), num.clone(), num.clone(), num.clone(), num.clone())
        .prop_map(|(a, r, b, l, p)| json!({"aisle": a, "row": r, "bay": b, "level": l, "position": p}));
    let kind = prop_oneof![
        Just("store"),
        Just("retrieve"),
        Just("move"),
        Just("clear"),
        Just("light"),
        Just("travel"),
        Just("x")
    ];
    (kind, proptest::option::of(loc.clone()), proptest::option::of(loc), proptest::option::of(num), proptest::option::of(".{0,30}"))
        .prop_map(|(k, from, to, priority, barcode)| {
            json!({"kind": k, "from": from, "to": to, "priority": priority, "barcode": barcode, "reference": barcode})
        })
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn a_full_intake_queue_is_refused_at_once_with_retry_after(#[case] engine: Engine) {
    // The writer's queue holds one request; another connection holds the database's write
    // lock, so the writer is stuck on its first group and the queue fills.
    let app = spawn_with(engine, |c| {
        c.intake.queue = 1;
        c.intake.max_group = 1;
        c.database.busy_timeout_ms = 3_000;
    })
    .await;
    let blocker = crate::support::WriteLock::take(&app.db).await;
    let first = tokio::spawn({
        let (client, url) = (app.client.clone(), app.url("/api/v1/jobs"));
        async move { client.post(url).json(&store("Q-1")).send().await.unwrap().status().as_u16() }
    });
    let started = std::time::Instant::now();
    let mut refused = None;
    for k in 2..50 {
        let r = app
            .client
            .post(app.url("/api/v1/jobs"))
            .json(&store(&format!("Q-{k}")))
            .timeout(std::time::Duration::from_secs(10));
        let pending = tokio::spawn(r.send());
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
        if pending.is_finished() {
            let r = pending.await.unwrap().unwrap();
            if r.status() == 503 {
                refused = Some(r);
                break;
            }
        }
    }
    let r = refused.expect("a request was refused while the queue was full");
    assert!(started.elapsed() < std::time::Duration::from_secs(2), "refused at once, not after a timeout");
    assert_eq!(r.headers()["retry-after"], "1");
    let body: serde_json::Value = r.json().await.unwrap();
    assert_eq!(body["error"]["code"], "overloaded", "{body}");
    blocker.release().await;
    assert!([201, 503].contains(&first.await.unwrap()));
}
