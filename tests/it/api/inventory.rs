//! `PUT /api/v1/locations`: an inventory loaded and corrected over the real server, all or
//! nothing, audited, with its events; refused where a job in flight holds a location.

use std::time::Duration;

use rackd::store::Engine;
use rstest::rstest;
use serde_json::{Value, json};

use super::demo::{SLOW_CRANE, cloc, demo_app, submit, wait_job};
use crate::support::ws::{Got, Ws};
use crate::support::{TestApp, assert_error, spawn_app, split};

async fn put(app: &TestApp, body: &Value) -> (u16, Value) {
    split(app.client.put(app.url("/api/v1/locations")).json(body).send().await.unwrap()).await
}

fn at(row: u16, bay: u16, level: u16, position: u16, stock: Value) -> Value {
    let mut entry = json!({"aisle": 1, "row": row, "bay": bay, "level": level, "position": position});
    entry.as_object_mut().unwrap().extend(stock.as_object().unwrap().clone());
    entry
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_inventory_loads_corrects_and_tells(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    let mut ws = Ws::connect(&app.base, "").await;
    // The snapshot first: a change committed before it is read is in it, not sent after it.
    assert_eq!(ws.json().await["type"], "snapshot");
    let body = json!({"locations": [
        at(1, 2, 3, 1, json!({"occupied": true, "barcode": "BOX-1"})),
        at(1, 2, 3, 2, json!({"occupied": true})),
    ], "reason": "stocktake"});
    let (status, now) = put(&app, &body).await;
    assert_eq!(status, 200, "{now}");
    assert_eq!((now[0]["occupied"].clone(), now[0]["barcode"].clone()), (json!(true), json!("BOX-1")));
    assert_eq!((now[1]["occupied"].clone(), now[1]["barcode"].clone()), (json!(true), Value::Null));
    let (_, occupied) = app.get("/api/v1/locations?aisle=1&occupied=true").await;
    assert_eq!(occupied.as_array().unwrap().len(), 2, "{occupied}");
    // Each change is an event and an audit entry; an entry that changes nothing is neither.
    let mut told = 0;
    while told < 2 {
        match ws.next(Duration::from_secs(5)).await {
            Got::Json(m) if m["type"] == "location.updated" => told += 1,
            Got::Json(_) => {}
            other => panic!("expected two location.updated events, got {other:?}"),
        }
    }
    let correction = json!({"locations": [
        at(1, 2, 3, 1, json!({"occupied": true, "barcode": "BOX-1"})),
        at(1, 2, 3, 2, json!({"occupied": false})),
    ]});
    assert_eq!(put(&app, &correction).await.0, 200);
    let (_, audit) = app.get("/api/v1/audit").await;
    let entries: Vec<&Value> =
        audit["entries"].as_array().unwrap().iter().filter(|e| e["action"] == "inventory").collect();
    assert_eq!(entries.len(), 3, "two loads and one correction: {audit}");
    assert!(entries.iter().any(|e| e["reason"] == "inventory: a box, BOX-1 (stocktake)"), "{audit}");
    app.stop().await;
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn a_bad_entry_refuses_the_whole_inventory(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    let good = at(1, 1, 1, 1, json!({"occupied": true}));
    for (bad, needle) in [
        (at(1, 1, 1, 9, json!({"occupied": true})), "locations[1]"),
        (at(1, 1, 1, 2, json!({"occupied": false, "barcode": "X"})), "no barcode"),
        (at(1, 1, 1, 2, json!({"occupied": true, "barcode": "é"})), "printable ASCII"),
        (good.clone(), "listed twice"),
    ] {
        let got = put(&app, &json!({"locations": [good, bad]})).await;
        assert_error(&got, 422, "invalid_inventory");
        assert!(got.1["error"]["message"].as_str().unwrap().contains(needle), "{got:?}");
    }
    assert_error(&put(&app, &json!({"locations": []})).await, 422, "invalid_inventory");
    let (_, occupied) = app.get("/api/v1/locations?occupied=true").await;
    assert_eq!(occupied, json!([]), "nothing of a refused inventory is written");
    app.stop().await;
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_location_a_job_in_flight_holds_is_refused(#[case] engine: Engine) {
    let (app, _sims) = demo_app(engine, SLOW_CRANE, |_| {}).await;
    let id = submit(&app, json!({"kind": "store", "barcode": "B1", "to": cloc(1, 5, 2, 1)})).await;
    wait_job(&app, id, 20, |j| j["state"] != "queued").await;
    let mut held = cloc(1, 5, 2, 1);
    held["occupied"] = json!(false);
    let mut free = cloc(1, 6, 2, 1);
    free["occupied"] = json!(true);
    let got = put(&app, &json!({"locations": [free, held]})).await;
    assert_error(&got, 409, "location_reserved");
    let (_, location) = app.get("/api/v1/locations?aisle=2&occupied=true").await;
    assert!(
        location.as_array().unwrap().iter().all(|l| l["bay"] != 6),
        "the free location of a refused inventory stays as it was: {location}"
    );
    app.stop().await;
}
