//! A sequence whose members sit in two crane aisles reaches its station in position order:
//! a missing position holds the later ones, and each member goes only after the one ahead
//! of it completed, later still by the difference of their aisles' transit times.

use std::time::Duration;

use rackd::store::Engine;
use rackd::wire::task_id_for;
use serde_json::json;

use super::{at, entered, two_cranes};
use crate::crane::{POLLS, wait_job};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_sequence_across_two_aisles_reaches_its_station_in_order() {
    // A box from aisle 2 takes 0.4 s more to reach station 1 than one from aisle 3.
    let transit = |aisle: u16| if aisle == 2 { 0.4 } else { 0.0 };
    let (app, sim2, sim3) = two_cranes(Engine::Sqlite, (transit(2), transit(3))).await;
    let aisles: [u16; 6] = [2, 3, 3, 2, 3, 2];
    let member = |p: usize| {
        json!({"kind": "retrieve", "reference": format!("ORD-1-{p}"), "from": at(aisles[p - 1], 2 * p as u16, 2),
            "sequence": {"name": "ORD-1", "position": p, "station": 1, "last": p == 6}})
    };
    // Positions 6 down to 2 first: nothing may go while position 1 is not posted.
    let later: Vec<_> = (2..=6).rev().map(member).collect();
    let (status, posted) = app.post("/api/v1/jobs/batch", &json!({"jobs": later})).await;
    assert_eq!(status, 201, "{posted}");
    let mut ids = [0i64; 7];
    for job in posted["jobs"].as_array().unwrap() {
        ids[job["sequence"]["position"].as_u64().unwrap() as usize] = job["id"].as_i64().unwrap();
    }
    // Long enough for several dispatch rounds of both cranes.
    tokio::time::sleep(Duration::from_millis(POLLS * 20)).await;
    let (_, seq) = app.get("/api/v1/sequences/ORD-1").await;
    assert_eq!((seq["state"].as_str(), seq["next_position"].as_u64()), (Some("complete"), Some(1)), "{seq}");
    assert_eq!(seq["holding"]["reason"], "sequence", "{seq}");
    assert_eq!(seq["holding"]["text"], "position 1 is not posted yet", "{seq}");
    let (_, two) = app.get(&format!("/api/v1/jobs/{}", ids[2])).await;
    assert_eq!(
        (two["state"].as_str(), two["waiting"]["reason"].as_str()),
        (Some("queued"), Some("sequence")),
        "{two}"
    );
    let reached: u32 =
        ids[2..].iter().map(|&id| sim2.received(task_id_for(id)) + sim3.received(task_id_for(id))).sum();
    assert_eq!(reached, 0, "nothing reached a crane before position 1");

    let (status, one) = app.post("/api/v1/jobs", &member(1)).await;
    assert_eq!(status, 201, "{one}");
    ids[1] = one["id"].as_i64().unwrap();
    for &id in &ids[1..] {
        assert_eq!(wait_job(&app, id, &["completed", "failed"], 30).await["state"], "completed");
    }
    let mut arrived_before = i64::MIN;
    for p in 1..=6 {
        let (started, done) = (
            entered(&app, ids[p], "dispatched").await.unwrap(),
            entered(&app, ids[p], "completed").await.unwrap(),
        );
        let arrival = done + (transit(aisles[p - 1]) * 1000.0) as i64;
        assert!(
            arrival >= arrived_before,
            "position {p} reached the station at {arrival}, before position {} ({arrived_before})",
            p - 1
        );
        if p > 1 {
            let ahead = entered(&app, ids[p - 1], "completed").await.unwrap();
            let lead = ((transit(aisles[p - 2]) - transit(aisles[p - 1])) * 1000.0) as i64;
            assert!(
                started >= ahead + lead.max(0),
                "position {p} went at {started}, position {} completed at {ahead} (lead {lead} ms)",
                p - 1
            );
        }
        arrived_before = arrival;
        let sim = if aisles[p - 1] == 2 { &sim2 } else { &sim3 };
        assert_eq!(sim.received(task_id_for(ids[p])), 1, "position {p} handed over once");
    }
    let (_, seq) = app.get("/api/v1/sequences/ORD-1").await;
    assert_eq!((seq["state"].as_str(), &seq["next_position"]), (Some("done"), &json!(null)), "{seq}");
    let metrics = app.client.get(app.url("/metrics")).send().await.unwrap().text().await.unwrap();
    let inversions: Vec<&str> =
        metrics.lines().filter(|l| l.starts_with("rackd_sequence_inversions_total{")).collect();
    assert!(!inversions.is_empty() && inversions.iter().all(|l| l.ends_with(" 0")), "{inversions:?}");
    for sim in [&sim2, &sim3] {
        assert_eq!(sim.violations(), 0, "{:?}", sim.violation_log());
    }
    app.stop().await;
}
