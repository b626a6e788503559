//! Reservations as the event stream tells them: a location shows reserved once its job is
//! handed to the device, and free again, with the job's result, when the job ends.

use serde_json::json;

use super::{shelf_app, sim};
use crate::support::ws::Ws;
use crate::support::*;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn location_events_follow_a_jobs_reservation() {
    let (app, _sim) = shelf_app(sim(100), |_| {}).await;
    let mut ws = Ws::connect(&app.base, "?topics=locations").await;
    assert_eq!(ws.json().await["type"], "snapshot");
    let (status, job) =
        app.post("/api/v1/jobs", &json!({"kind": "store", "barcode": "RES-1", "to": loc(1, 4, 2, 3)})).await;
    assert_eq!(status, 201, "{job}");

    let events = ws.events(2).await;
    let at = |e: &serde_json::Value| {
        (e["data"]["bay"].clone(), e["data"]["level"].clone(), e["data"]["position"].clone())
    };
    for e in &events {
        assert_eq!(e["type"], "location.updated", "{e}");
        assert_eq!(at(e), (json!(4), json!(2), json!(3)), "{e}");
    }
    let (dispatched, completed) = (&events[0]["data"], &events[1]["data"]);
    assert_eq!(dispatched["reserved_by"], job["id"], "reserved on dispatch: {dispatched}");
    assert_eq!(dispatched["occupied"], false, "{dispatched}");
    assert!(completed["reserved_by"].is_null(), "released on completion: {completed}");
    assert_eq!((completed["occupied"].clone(), completed["barcode"].clone()), (json!(true), json!("RES-1")));
}
