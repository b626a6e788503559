//! Submitting, reading, cancelling and re-prioritising jobs.

use rackd::store::Engine;
use rstest::rstest;
use serde_json::json;

use crate::support::*;

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn every_kind_is_accepted_with_its_fields(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    let bodies = [
        json!({"kind": "store", "to": loc(1, 1, 1, 1), "barcode": "A1"}),
        json!({"kind": "retrieve", "from": loc(2, 10, 6, 4)}),
        json!({"kind": "move", "from": loc(1, 1, 1, 1), "to": loc(2, 1, 1, 1), "priority": 0}),
        json!({"kind": "clear", "location": loc(1, 5, 2, 2)}),
        json!({"kind": "light", "location": loc(1, 5, 2, 2), "color": "red", "on": true}),
        json!({"kind": "travel", "to": loc(1, 0, 1, 1)}),
    ];
    for body in bodies {
        let (status, job) = app.post("/api/v1/jobs", &body).await;
        assert_eq!(status, 201, "{body} -> {job}");
        assert_eq!(job["kind"], body["kind"]);
        assert_eq!(job["state"], "queued");
        assert_eq!(job["priority"], body.get("priority").cloned().unwrap_or(json!(10)));
        for field in ["from", "to", "location", "color", "on"] {
            assert_eq!(job.get(field), body.get(field), "{field} of {body}");
        }
        let (status, read) = app.get(&format!("/api/v1/jobs/{}", job["id"])).await;
        assert_eq!((status, &read), (200, &job));
    }
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn wrong_fields_for_a_kind_are_rejected(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    let cases = [
        (json!({"kind": "store"}), "needs `to`"),
        (json!({"kind": "store", "to": loc(1, 1, 1, 1), "from": loc(1, 1, 1, 2)}), "takes no `from`"),
        (json!({"kind": "retrieve", "to": loc(1, 1, 1, 1)}), "takes no `to`"),
        (json!({"kind": "move", "from": loc(1, 1, 1, 1)}), "needs `to`"),
        (json!({"kind": "clear", "location": loc(1, 1, 1, 1), "color": "red"}), "takes no `color`"),
        (json!({"kind": "light", "location": loc(1, 1, 1, 1), "on": true}), "needs `color`"),
        (json!({"kind": "travel", "to": loc(1, 1, 1, 1), "on": false}), "takes no `on`"),
        (json!({"kind": "store", "to": loc(3, 1, 1, 1)}), "row 3"),
        (
            json!({"kind": "store", "to": {"aisle": 9, "row": 1, "bay": 1, "level": 1, "position": 1}}),
            "aisle 9",
        ),
        (json!({"kind": "store", "to": loc(1, 11, 1, 1)}), "bay 11"),
        (json!({"kind": "store", "to": loc(1, 1, 7, 1)}), "level 7"),
        (json!({"kind": "store", "to": loc(1, 1, 1, 0)}), "position 0"),
        (json!({"kind": "store", "to": loc(1, 1, 1, 1), "priority": 21}), "priority"),
        (json!({"kind": "store", "to": loc(1, 1, 1, 1), "priority": -1}), "priority"),
        (json!({"kind": "store", "to": loc(1, 1, 1, 1), "barcode": "X".repeat(21)}), "barcode"),
        (json!({"kind": "store", "to": loc(1, 1, 1, 1), "barcode": "ü"}), "barcode"),
        (json!({"kind": "store", "to": loc(1, 1, 1, 1), "device": "nope"}), "not configured"),
        (json!({"kind": "move", "from": loc(1, 1, 1, 1), "to": loc(1, 1, 1, 1)}), "two different"),
    ];
    for (body, words) in cases {
        let got = app.post("/api/v1/jobs", &body).await;
        assert_error(&got, 422, "invalid_job");
        let message = got.1["error"]["message"].as_str().unwrap();
        assert!(message.contains(words), "{body}: {message:?} lacks {words:?}");
    }
    let (_, page) = app.get("/api/v1/jobs").await;
    assert_eq!(page["jobs"].as_array().unwrap().len(), 0, "nothing stored");
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn a_reference_makes_posts_idempotent(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    let (s1, first) = app.post("/api/v1/jobs", &store("WMS-1")).await;
    let (s2, again) = app.post("/api/v1/jobs", &store("WMS-1")).await;
    assert_eq!((s1, s2), (201, 200));
    assert_eq!(first, again);
    let mut different = store("WMS-1");
    different["priority"] = json!(3);
    assert_error(&app.post("/api/v1/jobs", &different).await, 409, "reference_conflict");
    let (_, page) = app.get("/api/v1/jobs?reference=WMS-1").await;
    assert_eq!(page["jobs"].as_array().unwrap().len(), 1);
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn concurrent_posts_with_one_reference_store_one_job(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    let body = store("SAME");
    let posts = (0..20).map(|_| app.post("/api/v1/jobs", &body));
    let answers = futures::future::join_all(posts).await;
    let created = answers.iter().filter(|(s, _)| *s == 201).count();
    assert_eq!(created, 1, "{answers:?}");
    assert!(answers.iter().all(|(s, j)| (*s == 201 || *s == 200) && j["id"] == answers[0].1["id"]));
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn batches_are_all_or_nothing(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    let good = |r: &str| store(r);
    let (status, body) = app.post("/api/v1/jobs/batch", &json!({"jobs": [good("B1"), good("B2")]})).await;
    assert_eq!(status, 201, "{body}");
    assert_eq!(body["jobs"].as_array().unwrap().len(), 2);

    let bad = json!({"kind": "store", "to": loc(1, 99, 1, 1)});
    let got = app.post("/api/v1/jobs/batch", &json!({"jobs": [good("B3"), bad]})).await;
    assert_error(&got, 422, "invalid_job");
    assert!(got.1["error"]["message"].as_str().unwrap().starts_with("jobs[1]"));

    let mut changed = good("B1");
    changed["barcode"] = json!("OTHER");
    let got = app.post("/api/v1/jobs/batch", &json!({"jobs": [good("B4"), changed]})).await;
    assert_error(&got, 409, "reference_conflict");

    let (_, page) = app.get("/api/v1/jobs").await;
    let refs: Vec<_> = page["jobs"].as_array().unwrap().iter().map(|j| j["reference"].clone()).collect();
    assert_eq!(refs, vec![json!("B1"), json!("B2")], "B3 and B4 were not stored");

    let (status, body) = app.post("/api/v1/jobs/batch", &json!({"jobs": [good("B1"), good("B2")]})).await;
    assert_eq!(status, 200, "a repeated batch changes nothing: {body}");

    // A stored job and a new one, answered in request order, each as reading it answers.
    let (status, body) = app.post("/api/v1/jobs/batch", &json!({"jobs": [good("B1"), good("B5")]})).await;
    assert_eq!(status, 201, "{body}");
    let jobs = body["jobs"].as_array().unwrap();
    assert_eq!((jobs[0]["reference"].clone(), jobs[1]["reference"].clone()), (json!("B1"), json!("B5")));
    for job in jobs {
        let (_, read) = app.get(&format!("/api/v1/jobs/{}", job["id"])).await;
        assert_eq!(&read, job);
    }

    let too_many: Vec<_> = (0..1001).map(|i| good(&format!("M{i}"))).collect();
    assert_error(&app.post("/api/v1/jobs/batch", &json!({"jobs": too_many})).await, 422, "invalid_batch");
    assert_error(&app.post("/api/v1/jobs/batch", &json!({"jobs": []})).await, 422, "invalid_batch");
    let full: Vec<_> = (0..1000).map(|i| good(&format!("F{i}"))).collect();
    let (status, body) = app.post("/api/v1/jobs/batch", &json!({"jobs": full})).await;
    assert_eq!((status, body["jobs"].as_array().unwrap().len()), (201, 1000));
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn cancel_and_priority_follow_the_state(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    let (_, job) = app.post("/api/v1/jobs", &store("C1")).await;
    let id = job["id"].as_i64().unwrap();
    let (status, changed) = app.patch(&format!("/api/v1/jobs/{id}"), &json!({"priority": 0})).await;
    assert_eq!((status, changed["priority"].clone()), (200, json!(0)));
    assert_error(
        &app.patch(&format!("/api/v1/jobs/{id}"), &json!({"priority": 21})).await,
        422,
        "invalid_body",
    );

    let (status, cancelled) = app.post(&format!("/api/v1/jobs/{id}/cancel"), &json!({})).await;
    assert_eq!((status, cancelled["state"].clone()), (200, json!("cancelled")));
    assert_error(&app.post(&format!("/api/v1/jobs/{id}/cancel"), &json!({})).await, 409, "job_ended");
    assert_error(
        &app.patch(&format!("/api/v1/jobs/{id}"), &json!({"priority": 1})).await,
        409,
        "invalid_state",
    );
    assert_error(&app.post("/api/v1/jobs/999/cancel", &json!({})).await, 404, "not_found");

    let (status, history) = app.get(&format!("/api/v1/jobs/{id}/history")).await;
    assert_eq!(status, 200);
    let states: Vec<_> = history.as_array().unwrap().iter().map(|h| h["state"].clone()).collect();
    assert_eq!(states, vec![json!("queued"), json!("queued"), json!("cancelled")]);
    assert_eq!(history[1]["cause"], "priority 10 -> 0");
    assert_error(&app.get("/api/v1/jobs/999/history").await, 404, "not_found");
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn list_filters_by_state_kind_reference_and_time(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    app.post("/api/v1/jobs", &store("L1")).await;
    let (_, light) = app
        .post("/api/v1/jobs", &json!({"kind": "light", "reference": "L2", "location": loc(1, 1, 1, 1), "color": "green", "on": false}))
        .await;
    app.post(&format!("/api/v1/jobs/{}/cancel", light["id"]), &json!({})).await;
    let count = |v: &serde_json::Value| v["jobs"].as_array().unwrap().len();
    assert_eq!(count(&app.get("/api/v1/jobs?state=cancelled").await.1), 1);
    assert_eq!(count(&app.get("/api/v1/jobs?state=queued").await.1), 1);
    assert_eq!(count(&app.get("/api/v1/jobs?kind=light").await.1), 1);
    assert_eq!(count(&app.get("/api/v1/jobs?kind=move").await.1), 0);
    assert_eq!(count(&app.get("/api/v1/jobs?reference=L2").await.1), 1);
    assert_eq!(count(&app.get("/api/v1/jobs?device=shelf1").await.1), 0);
    assert_eq!(count(&app.get("/api/v1/jobs?created_from=2000-01-01T00:00:00Z").await.1), 2);
    assert_eq!(count(&app.get("/api/v1/jobs?created_to=2000-01-01T00:00:00Z").await.1), 0);
    assert_error(&app.get("/api/v1/jobs?created_from=yesterday").await, 400, "bad_query");
    assert_error(&app.get("/api/v1/jobs?colour=red").await, 400, "bad_query");
    assert_error(&app.get("/api/v1/jobs?cursor=abc").await, 400, "bad_cursor");
}
