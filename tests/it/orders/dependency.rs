//! A job whose `after` names another waits until that one completed, on another crane; a
//! dependency cancelled holds it until it is cancelled too.

use std::time::Duration;

use rackd::store::Engine;
use rackd::wire::task_id_for;
use serde_json::json;

use super::{at, entered, two_cranes};
use crate::crane::{POLLS, wait_job};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dependency_holds_a_job_until_the_other_completed() {
    let (app, sim2, sim3) = two_cranes(Engine::Sqlite, (0.0, 0.0)).await;
    // crane1 is paused: the job on aisle 3 must wait for it, though crane2 is idle.
    let (status, paused) = app.post("/api/v1/devices/crane1/pause", &json!({"reason": "test"})).await;
    assert_eq!(status, 200, "{paused}");
    let (status, first) = app
        .post("/api/v1/jobs", &json!({"kind": "retrieve", "reference": "DEP-A", "from": at(2, 4, 2)}))
        .await;
    assert_eq!(status, 201, "{first}");
    let body = json!({"kind": "retrieve", "reference": "DEP-B", "from": at(3, 5, 3), "after": ["DEP-A"]});
    let (status, second) = app.post("/api/v1/jobs", &body).await;
    assert_eq!(status, 201, "{second}");
    assert_eq!(second["after"], json!(["DEP-A"]), "{second}");
    let (a, b) = (first["id"].as_i64().unwrap(), second["id"].as_i64().unwrap());
    tokio::time::sleep(Duration::from_millis(POLLS * 20)).await;
    let (_, held) = app.get(&format!("/api/v1/jobs/{b}")).await;
    assert_eq!(held["state"], "queued", "{held}");
    assert_eq!(
        (held["waiting"]["reason"].as_str(), held["waiting"]["job"].as_i64()),
        (Some("dependency"), Some(a)),
        "{held}"
    );
    assert_eq!(sim3.received(task_id_for(b)), 0, "the dependent job reached crane2 before DEP-A completed");
    let (_, page) = app.get("/api/v1/jobs?waiting=dependency").await;
    assert_eq!(page["jobs"].as_array().unwrap().len(), 1, "{page}");

    let (status, resumed) = app.post("/api/v1/devices/crane1/resume", &json!({})).await;
    assert_eq!(status, 200, "{resumed}");
    assert_eq!(wait_job(&app, b, &["completed", "failed"], 30).await["state"], "completed");
    let (done, started) =
        (entered(&app, a, "completed").await.unwrap(), entered(&app, b, "dispatched").await.unwrap());
    assert!(started >= done, "DEP-B went at {started}, before DEP-A completed at {done}");

    // A dependency cancelled holds the job, which the WMS then cancels.
    app.post("/api/v1/devices/crane1/pause", &json!({})).await;
    let (_, c) = app
        .post("/api/v1/jobs", &json!({"kind": "retrieve", "reference": "DEP-C", "from": at(2, 6, 2)}))
        .await;
    let body =
        json!({"kind": "retrieve", "reference": "DEP-D", "from": at(3, 7, 3), "after": ["DEP-C", "DEP-A"]});
    let (_, d) = app.post("/api/v1/jobs", &body).await;
    let (c, d) = (c["id"].as_i64().unwrap(), d["id"].as_i64().unwrap());
    let (status, _) = app.post(&format!("/api/v1/jobs/{c}/cancel"), &json!({})).await;
    assert_eq!(status, 200);
    let reason = crate::support::eventually(
        "DEP-D held by its cancelled dependency",
        Duration::from_secs(5),
        async || {
            let (_, job) = app.get(&format!("/api/v1/jobs/{d}")).await;
            let text = job["waiting"]["text"].as_str().unwrap_or("").to_owned();
            if text.contains("cancelled") { Ok(job) } else { Err(job) }
        },
    )
    .await;
    assert_eq!(
        (reason["waiting"]["reason"].as_str(), reason["waiting"]["job"].as_i64()),
        (Some("dependency"), Some(c)),
        "{reason}"
    );
    tokio::time::sleep(Duration::from_millis(POLLS * 20)).await;
    assert_eq!(sim3.received(task_id_for(d)), 0, "a job ran though its dependency was cancelled");
    let (status, _) = app.post(&format!("/api/v1/jobs/{d}/cancel"), &json!({})).await;
    assert_eq!(status, 200);
    for sim in [&sim2, &sim3] {
        assert_eq!(sim.violations(), 0, "{:?}", sim.violation_log());
    }
    app.stop().await;
}
