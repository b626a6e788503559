//! A deadline at risk reorders a crane's queue against travel: the far job due soon goes
//! before the near ones the travel planner would take first.

use rackd::protocols::mc3e::TransportKind;
use serde_json::json;

use super::entered;
use crate::crane::{cloc, crane_app, wait_job};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_deadline_at_risk_goes_before_the_near_jobs() {
    let (app, sim) = crane_app(TransportKind::Tcp, 5, |_| {}).await;
    let (status, _) = app.post("/api/v1/devices/crane1/pause", &json!({})).await;
    assert_eq!(status, 200);
    // Near the station, no deadline; far away, due in 40 s: after a near job's cycle it
    // would end well past its deadline less the 30 s margin (the motion model's seconds).
    let due = time::OffsetDateTime::now_utc() + time::Duration::seconds(40);
    let due = due.format(&time::format_description::well_known::Rfc3339).unwrap();
    let batch = json!({"jobs": [
        {"kind": "retrieve", "reference": "NEAR-1", "from": cloc(1, 1, 1, 1)},
        {"kind": "retrieve", "reference": "NEAR-2", "from": cloc(1, 2, 1, 1)},
        {"kind": "retrieve", "reference": "FAR", "from": cloc(1, 19, 8, 1), "deadline": due},
    ]});
    let (status, posted) = app.post("/api/v1/jobs/batch", &batch).await;
    assert_eq!(status, 201, "{posted}");
    let ids: Vec<i64> =
        posted["jobs"].as_array().unwrap().iter().map(|j| j["id"].as_i64().unwrap()).collect();
    assert_eq!(app.post("/api/v1/devices/crane1/resume", &json!({})).await.0, 200);
    for &id in &ids {
        assert_eq!(wait_job(&app, id, &["completed", "failed"], 30).await["state"], "completed");
    }
    let mut started = Vec::new();
    for &id in &ids {
        started.push(entered(&app, id, "dispatched").await.unwrap());
    }
    assert!(
        started[2] < started[0] && started[2] < started[1],
        "the far job due soon went first: {started:?}"
    );
    assert!(started[0] < started[1], "then by travel, the nearest first: {started:?}");
    let (_, far) = app.get(&format!("/api/v1/jobs/{}", ids[2])).await;
    assert_eq!(far["late_by_s"], json!(null), "{far}");
    assert_eq!(sim.violations(), 0, "{:?}", sim.violation_log());
    app.stop().await;
}
