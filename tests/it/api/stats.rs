//! `GET /api/v1/stats`: KPIs per device and per aisle from jobs run to completion on the
//! fast demo site, and a failed one.

use rackd::store::Engine;
use rstest::rstest;
use serde_json::{Value, json};

use super::demo::{FAST, cloc, demo_app, submit, wait_job};
use super::waiting::wait_for_online;
use crate::support::{assert_error, loc};

fn find<'a>(list: &'a Value, key: &str, value: Value) -> &'a Value {
    list.as_array()
        .unwrap()
        .iter()
        .find(|s| s[key] == value)
        .unwrap_or_else(|| panic!("no {key} {value} in {list}"))
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn per_device_and_per_aisle_from_the_history(#[case] engine: Engine) {
    let (app, sims) = demo_app(engine, FAST, |_| {}).await;
    wait_for_online(&app, "crane1").await;
    let mut ids = Vec::new();
    for bay in 1..=3 {
        ids.push(
            submit(&app, json!({"kind": "store", "barcode": format!("S{bay}"), "to": loc(1, bay, 1, 1)}))
                .await,
        );
    }
    for bay in 1..=2 {
        ids.push(
            submit(&app, json!({"kind": "store", "barcode": format!("C{bay}"), "to": cloc(1, bay, 1, 1)}))
                .await,
        );
    }
    for id in &ids {
        let job = wait_job(&app, *id, 30, |j| j["state"] == "completed" || j["state"] == "failed").await;
        assert_eq!(job["state"], "completed", "{job}");
    }
    // One that fails: a business alarm while the crane runs it (slow from now on, so the
    // job is seen running however busy the machine is).
    sims.crane.set_step(std::time::Duration::from_secs(1));
    let failed = submit(&app, json!({"kind": "store", "barcode": "F1", "to": cloc(2, 9, 1, 1)})).await;
    wait_job(&app, failed, 30, |j| j["state"] == "running").await;
    sims.crane.raise_alarm(7069);
    let job = wait_job(&app, failed, 10, |j| j["state"] == "failed").await;
    assert_eq!(job["failure"]["kind"], "alarm");

    let (status, stats) = app.get("/api/v1/stats").await;
    assert_eq!(status, 200, "{stats}");
    let since = time::OffsetDateTime::parse(
        stats["since"].as_str().unwrap(),
        &time::format_description::well_known::Rfc3339,
    )
    .unwrap();
    let until = time::OffsetDateTime::parse(
        stats["until"].as_str().unwrap(),
        &time::format_description::well_known::Rfc3339,
    )
    .unwrap();
    let span = (until - since).as_seconds_f64();
    assert!((3600.0..3660.0).contains(&span), "the default period is an hour from a whole minute: {stats}");
    assert_eq!(since.second(), 0, "{stats}");
    let devices: Vec<&str> =
        stats["devices"].as_array().unwrap().iter().map(|d| d["device"].as_str().unwrap()).collect();
    assert_eq!(devices, vec!["crane1", "shelf1"], "devices that run jobs, by id");
    let aisles: Vec<u64> =
        stats["aisles"].as_array().unwrap().iter().map(|a| a["aisle"].as_u64().unwrap()).collect();
    assert_eq!(aisles, vec![1, 2]);

    let shelf = find(&stats["devices"], "device", json!("shelf1"));
    assert_eq!(
        (shelf["completed"].clone(), shelf["failed"].clone(), shelf["failures"].clone()),
        (json!(3), json!(0), json!({}))
    );
    assert!((shelf["per_hour"].as_f64().unwrap() - 3.0 * 3600.0 / span).abs() < 1e-6, "{shelf}");
    let util = shelf["utilisation"].as_f64().unwrap();
    assert!(util > 0.0 && util < 0.05, "a few seconds of an hour: {shelf}");
    let d = &shelf["durations"][0];
    assert_eq!((d["kind"].clone(), d["count"].clone()), (json!("store"), json!(3)), "{shelf}");
    let (mean, p95) = (d["mean_s"].as_f64().unwrap(), d["p95_s"].as_f64().unwrap());
    assert!(mean >= 0.2 && p95 >= mean && p95 < 30.0, "a shelf task takes 200 ms: {shelf}");

    let crane = find(&stats["devices"], "device", json!("crane1"));
    assert_eq!((crane["completed"].clone(), crane["failed"].clone()), (json!(2), json!(1)), "{crane}");
    assert_eq!(crane["failures"], json!({"alarm": 1}));
    assert_eq!(crane["durations"][0]["count"], 2);
    assert_eq!(find(&stats["aisles"], "aisle", json!(1))["completed"], 3);
    let aisle2 = find(&stats["aisles"], "aisle", json!(2));
    assert_eq!((aisle2["completed"].clone(), aisle2["failed"].clone()), (json!(2), json!(1)));
    assert_eq!(aisle2["utilisation"], crane["utilisation"], "one crane serves the aisle");

    // The last shift: the same jobs over eight hours.
    let (_, shift) = app.get("/api/v1/stats?since=8h").await;
    let shelf = find(&shift["devices"], "device", json!("shelf1"));
    assert_eq!(shelf["completed"], 3);
    let per_hour = shelf["per_hour"].as_f64().unwrap();
    assert!(per_hour > 3.0 / 8.02 && per_hour <= 3.0 / 8.0, "{shelf}");
    let minute_ago = (time::OffsetDateTime::now_utc() - time::Duration::minutes(5))
        .format(&time::format_description::well_known::Rfc3339)
        .unwrap();
    let (status, recent) = app.get(&format!("/api/v1/stats?since={}", minute_ago.replace('+', "%2B"))).await;
    assert_eq!(status, 200, "{recent}");
    assert_eq!(find(&recent["devices"], "device", json!("shelf1"))["completed"], 3);

    // A year back: the same jobs.
    let (status, year) = app.get("/api/v1/stats?since=365d").await;
    assert_eq!(status, 200, "{year}");
    assert_eq!(find(&year["devices"], "device", json!("crane1"))["completed"], 2);

    // Rebuilt from the history while rackd runs: the same figures.
    let pool = rackd::store::open(&app.db, std::time::Duration::from_secs(5)).await.unwrap();
    rackd::store::rollups::rebuild::rebuild(&pool, |_, _| {}).await.unwrap();
    pool.close().await;
    let (_, again) = app.get("/api/v1/stats?since=8h").await;
    for (list, key) in [("devices", "device"), ("aisles", "aisle")] {
        for before in shift[list].as_array().unwrap() {
            let after = find(&again[list], key, before[key].clone());
            for figure in ["completed", "failed", "failures", "durations"] {
                assert_eq!(after[figure], before[figure], "{figure} of {before} and {after}");
            }
            let (b, a) = (before["utilisation"].as_f64().unwrap(), after["utilisation"].as_f64().unwrap());
            assert!((a - b).abs() <= b * 1e-3, "{before} and {after}");
        }
    }

    for bad in ["yesterday", "367d", "2999-01-01T00:00:00Z", "1.5h", ""] {
        assert_error(&app.get(&format!("/api/v1/stats?since={bad}")).await, 400, "bad_query");
    }
    assert_error(&app.get("/api/v1/stats?until=now").await, 400, "bad_query");
    app.stop().await;
}
