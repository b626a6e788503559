//! Durability: jobs survive a restart, and a graceful stop loses no acknowledged job.

use rackd::store::Engine;
use rstest::rstest;
use serde_json::json;

use crate::support::*;

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn jobs_survive_a_restart_on_the_same_file(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    let (_, a) = app.post("/api/v1/jobs", &store("R1")).await;
    let (_, b) = app.post("/api/v1/jobs", &store("R2")).await;
    app.post(&format!("/api/v1/jobs/{}/cancel", b["id"]), &json!({})).await;
    let (_, before) = app.get("/api/v1/jobs").await;
    let (db, dir) = app.stop().await;

    let app = spawn_on(db, |_| {}).await;
    let (_, after) = app.get("/api/v1/jobs").await;
    assert_eq!(before, after);
    let (_, history) = app.get(&format!("/api/v1/jobs/{}/history", b["id"])).await;
    assert_eq!(history.as_array().unwrap().len(), 2);
    let (status, c) = app.post("/api/v1/jobs", &store("R3")).await;
    assert_eq!(status, 201);
    assert!(c["id"].as_i64() > a["id"].as_i64());
    let (status, _) = app.post("/api/v1/jobs", &store("R1")).await;
    assert_eq!(status, 200, "references are remembered across restarts");
    app.stop().await;
    drop(dir);
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn a_graceful_stop_keeps_every_acknowledged_job(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    let base = app.base.clone();
    let client = app.client.clone();
    let posts: Vec<_> = (0..200)
        .map(|i| {
            let (client, url) = (client.clone(), format!("{base}/api/v1/jobs"));
            tokio::spawn(async move {
                let r = client.post(url).json(&store(&format!("G{i}"))).send().await.ok()?;
                (r.status() == 201).then_some(i)
            })
        })
        .collect();
    tokio::time::sleep(std::time::Duration::from_millis(5)).await;
    let (db, dir) = app.stop().await;
    let mut acknowledged = Vec::new();
    for p in posts {
        acknowledged.extend(p.await.unwrap());
    }
    let app = spawn_on(db, |_| {}).await;
    for i in &acknowledged {
        let (_, page) = app.get(&format!("/api/v1/jobs?reference=G{i}")).await;
        assert_eq!(page["jobs"].as_array().unwrap().len(), 1, "acknowledged job G{i} lost");
    }
    app.stop().await;
    drop(dir);
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn health_readiness_and_metrics(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    assert_eq!(app.get("/healthz").await, (200, json!({"status": "ok"})));
    assert_eq!(app.get("/readyz").await, (200, json!({"status": "ok"})));
    app.post("/api/v1/jobs", &store("M1")).await;
    let text = app.client.get(app.url("/metrics")).send().await.unwrap().text().await.unwrap();
    assert!(
        text.contains(r#"rackd_http_requests_total{method="POST",route="/api/v1/jobs",status="201"} 1"#),
        "{text}"
    );
    // No device serves the demo's aisles in this test: the job is counted unrouted.
    assert!(text.contains(r#"rackd_jobs{device="",state="queued"} 1"#), "{text}");
    assert!(text.contains("rackd_intake_seconds_count 1"), "{text}");
    let docs = app.client.get(app.url("/docs/")).send().await.unwrap();
    assert_eq!(docs.status(), 200);
    assert!(docs.text().await.unwrap().contains("swagger"), "the docs page is served from the binary");
    let init =
        app.client.get(app.url("/docs/swagger-initializer.js")).send().await.unwrap().text().await.unwrap();
    assert!(init.contains(r#""validatorUrl": "none""#), "no spec sent to validator.swagger.io: {init}");
    assert!(!init.contains("swagger.io"), "{init}");
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn the_page_has_a_favicon_from_the_binary(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    for path in ["/favicon.ico", "/favicon.svg"] {
        let r = app.client.get(app.url(path)).send().await.unwrap();
        assert_eq!(r.status(), 200, "{path}");
        assert_eq!(r.headers()["content-type"], "image/svg+xml");
        assert!(r.text().await.unwrap().starts_with("<svg"));
    }
    let page = app.client.get(app.url("/")).send().await.unwrap().text().await.unwrap();
    assert!(page.contains(r#"<link rel="icon" href="/favicon.svg""#));
}
