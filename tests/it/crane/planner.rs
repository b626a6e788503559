//! The crane planner against the real crane simulator, in a double-deep aisle: a far box
//! behind a near one is fetched after a relocation rackd makes; a store far behind a box is
//! refused at intake; a store in front of a box an open job wants waits for that job; a put
//! into a box fails without being sent.

use std::time::Duration;

use rackd::config::Config;
use rackd::config::devices::CraneConfig;
use rackd::protocols::mc3e::TransportKind;
use rackd::sim::crane::{CraneSim, CraneSimOptions};
use rackd::store::Engine;
use rackd::wire::task_id_for;
use serde_json::{Value, json};
use time::format_description::well_known::Rfc3339;

use super::{cloc, crane, device_for, submit, wait_job, with_crane};
use crate::support::eventually;
use crate::support::{TestApp, spawn_with, split};

/// A crane app whose aisle 2 is double-deep.
async fn deep_app(edit: impl FnOnce(&mut CraneConfig)) -> (TestApp, CraneSim) {
    let sim = crane(TransportKind::Tcp, 5).await;
    let device = device_for(&sim, TransportKind::Tcp, edit);
    let app = spawn_with(Engine::Sqlite, |c: &mut Config| {
        with_crane(c, device);
        c.site.aisles.iter_mut().filter(|a| a.aisle == 2).for_each(|a| a.depth = 2);
    })
    .await;
    (app, sim)
}

/// Loads boxes at these crane locations.
async fn stock(app: &TestApp, at: &[Value]) {
    let entries: Vec<Value> = at
        .iter()
        .map(|l| {
            let mut e = l.clone();
            e["occupied"] = json!(true);
            e
        })
        .collect();
    let body = json!({"locations": entries, "reason": "test stock"});
    let (status, answer) =
        split(app.client.put(app.url("/api/v1/locations")).json(&body).send().await.unwrap()).await;
    assert_eq!(status, 200, "{answer}");
}

async fn occupied(app: &TestApp, l: &Value) -> bool {
    let (_, all) = app.get("/api/v1/locations?aisle=2&occupied=true").await;
    all.as_array().unwrap().iter().any(|s| ["row", "bay", "level", "position"].iter().all(|k| s[*k] == l[*k]))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_far_box_behind_a_near_one_comes_out_after_a_relocation() {
    let (app, sim) = deep_app(|_| {}).await;
    let (near, far) = (cloc(1, 5, 2, 1), cloc(1, 5, 2, 2));
    stock(&app, &[near.clone(), far.clone()]).await;
    let id = submit(&app, json!({"kind": "retrieve", "from": far}), "R-FAR").await;
    let done = wait_job(&app, id, &["completed", "failed"], 20).await;
    assert_eq!(done["state"], "completed", "{done}");
    let (_, moves) = app.get("/api/v1/jobs?kind=move").await;
    let moves = moves["jobs"].as_array().unwrap().clone();
    assert_eq!(moves.len(), 1, "one relocation: {moves:?}");
    let relocation = &moves[0];
    assert_eq!((relocation["serves"].as_i64(), &relocation["from"]), (Some(id), &near), "{relocation}");
    assert_eq!(relocation["state"], "completed", "{relocation}");
    assert!(relocation["id"].as_i64().unwrap() > id);
    let to = relocation["to"].clone();
    assert_eq!(to["position"], 2, "far first: {to}");
    assert!(!occupied(&app, &near).await && !occupied(&app, &far).await);
    assert!(occupied(&app, &to).await, "the near box is where it was moved: {to}");
    for job in [id, relocation["id"].as_i64().unwrap()] {
        assert_eq!(sim.received(task_id_for(job)), 1, "job {job} handed over once");
    }
    assert_eq!(sim.violations(), 0, "{:?}", sim.violation_log());
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_store_far_behind_a_box_is_refused_unless_the_box_leaves_first() {
    let (app, sim) = deep_app(|_| {}).await;
    stock(&app, &[cloc(1, 7, 1, 1)]).await;
    let (status, err) = app.post("/api/v1/jobs", &json!({"kind": "store", "to": cloc(1, 7, 1, 2)})).await;
    assert_eq!(status, 409, "{err}");
    assert_eq!(err["error"]["code"], "near_occupied", "{err}");
    let batch = json!({"jobs": [
        {"kind": "store", "to": cloc(1, 8, 1, 2)},
        {"kind": "store", "to": cloc(1, 7, 1, 2)},
    ]});
    let (status, err) = app.post("/api/v1/jobs/batch", &batch).await;
    assert_eq!(status, 409, "{err}");
    assert!(err["error"]["message"].as_str().unwrap().starts_with("jobs[1]:"), "{err}");
    // A retrieve of the near box first makes the same store fine: it runs after it.
    let batch = json!({"jobs": [
        {"kind": "retrieve", "from": cloc(1, 7, 1, 1)},
        {"kind": "store", "to": cloc(1, 7, 1, 2)},
    ]});
    let (status, both) = app.post("/api/v1/jobs/batch", &batch).await;
    assert_eq!(status, 201, "{both}");
    for job in both["jobs"].as_array().unwrap() {
        let id = job["id"].as_i64().unwrap();
        assert_eq!(wait_job(&app, id, &["completed", "failed"], 20).await["state"], "completed");
    }
    let (_, moves) = app.get("/api/v1/jobs?kind=move").await;
    assert!(moves["jobs"].as_array().unwrap().is_empty(), "no relocation was needed: {moves}");
    assert_eq!(sim.violations(), 0);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_store_in_front_of_a_box_an_open_job_wants_waits_for_it() {
    let (app, sim) = deep_app(|_| {}).await;
    let (near, far) = (cloc(1, 9, 2, 1), cloc(1, 9, 2, 2));
    stock(&app, std::slice::from_ref(&far)).await;
    // The store is older and its put is on the way, but putting it first would wall the
    // far box in and cost a relocation of the box just stored.
    let batch = json!({"jobs": [
        {"kind": "store", "to": near},
        {"kind": "retrieve", "from": far},
    ]});
    let (status, both) = app.post("/api/v1/jobs/batch", &batch).await;
    assert_eq!(status, 201, "{both}");
    let ids: Vec<i64> = both["jobs"].as_array().unwrap().iter().map(|j| j["id"].as_i64().unwrap()).collect();
    let mut ended = Vec::new();
    for id in &ids {
        let done = wait_job(&app, *id, &["completed", "failed"], 20).await;
        assert_eq!(done["state"], "completed", "{done}");
        ended.push(time::OffsetDateTime::parse(done["updated_at"].as_str().unwrap(), &Rfc3339).unwrap());
    }
    // As times, not text: a time on the whole second is written without a fraction.
    assert!(ended[1] < ended[0], "the retrieve ended before the store: {ended:?}");
    let (_, moves) = app.get("/api/v1/jobs?kind=move").await;
    assert!(moves["jobs"].as_array().unwrap().is_empty(), "no relocation was needed: {moves}");
    assert!(occupied(&app, &near).await && !occupied(&app, &far).await);
    assert_eq!(sim.violations(), 0, "{:?}", sim.violation_log());
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_put_into_a_box_fails_without_being_sent() {
    let (app, sim) = deep_app(|_| {}).await;
    stock(&app, &[cloc(2, 3, 4, 1)]).await;
    let id = submit(&app, json!({"kind": "store", "to": cloc(2, 3, 4, 1)}), "S-INTO-BOX").await;
    let failed = wait_job(&app, id, &["failed", "completed"], 10).await;
    assert_eq!(failed["state"], "failed", "{failed}");
    assert_eq!(failed["failure"]["kind"], "unsupported", "{failed}");
    assert!(failed["failure"]["text"].as_str().unwrap().contains("holds a box"), "{failed}");
    tokio::time::sleep(Duration::from_millis(100)).await;
    assert_eq!(sim.received(task_id_for(id)), 0, "nothing was sent");
    assert_eq!(sim.violations(), 0);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_store_left_to_rackd_goes_far_first_and_tells_where() {
    let (app, sim) = deep_app(|_| {}).await;
    let first = submit(&app, json!({"kind": "store", "aisle": 2}), "PUT-1").await;
    let (_, queued) = app.get(&format!("/api/v1/jobs/{first}")).await;
    assert_eq!(queued["zones"], json!([{"aisle": 2}]), "{queued}");
    let done = wait_job(&app, first, &["completed", "failed"], 20).await;
    assert_eq!(done["state"], "completed", "{done}");
    // Nearest the inbound station (row 2, bay 0, level 1), far before near.
    assert_eq!(done["to"], cloc(1, 1, 1, 2), "{done}");
    assert!(occupied(&app, &cloc(1, 1, 1, 2)).await);
    let told = super::history(&app, first).await;
    assert!(told.iter().any(|(_, cause)| cause.contains("putaway: rackd chose 2-1-1-1-2")), "{told:?}");
    // Zones and a class narrow the choice; the rest of the aisle is left alone.
    let zoned = json!({"kind": "store", "zones": [{"aisle": 2, "row": 2, "level": 3}], "class": "C"});
    let second = submit(&app, zoned, "PUT-2").await;
    let done = wait_job(&app, second, &["completed", "failed"], 20).await;
    assert_eq!(done["state"], "completed", "{done}");
    let to = &done["to"];
    assert_eq!(
        (to["row"].as_u64(), to["level"].as_u64(), to["position"].as_u64()),
        (Some(2), Some(3), Some(2)),
        "{done}"
    );
    assert!(to["bay"].as_u64().unwrap() >= 13, "class C: the far third of the aisle: {done}");
    assert_eq!(done["class"], "C");
    assert_eq!(sim.received(task_id_for(first)), 1);
    assert_eq!(sim.violations(), 0);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_store_left_to_rackd_is_checked_at_intake() {
    let (app, _sim) = deep_app(|_| {}).await;
    let cases = [
        (json!({"kind": "store", "aisle": 1}), "served by no crane"),
        (json!({"kind": "store", "aisle": 9}), "served by no crane"),
        (json!({"kind": "store", "aisle": 2, "to": cloc(1, 1, 1, 1)}), "not `to` and `aisle`"),
        (json!({"kind": "store", "class": "A"}), "`class` needs `aisle` or `zones`"),
        (json!({"kind": "store", "zones": []}), "at least one zone"),
        (json!({"kind": "store", "zones": [{"aisle": 2}, {"aisle": 1}]}), "same aisle"),
        (json!({"kind": "store", "zones": [{"aisle": 2, "level": 9}]}), "level 9 is outside 1..=8"),
        (json!({"kind": "retrieve", "from": cloc(1, 1, 1, 1), "aisle": 2}), "takes no `aisle`"),
        (json!({"kind": "store", "aisle": 2, "class": "D"}), ""),
        (json!({"kind": "store"}), "needs `to`"),
    ];
    for (body, says) in cases {
        let (status, err) = app.post("/api/v1/jobs", &body).await;
        assert_eq!(status, 422, "{body}: {err}");
        assert_eq!(
            err["error"]["code"],
            if says.is_empty() { "invalid_body" } else { "invalid_job" },
            "{err}"
        );
        assert!(err["error"]["message"].as_str().unwrap().contains(says), "{body}: {err}");
    }
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_mixed_workload_raises_no_business_alarm_and_both_inventories_agree() {
    // The crane knows its own rack (it raises 7069/7070 and 7091..7098 when asked the
    // impossible); rackd is told the same contents. Every job that would be impossible as
    // sent goes through the planner instead.
    let boxes = [[1, 3, 2, 1], [1, 3, 2, 2], [2, 5, 1, 1], [2, 5, 1, 2], [1, 8, 4, 2], [2, 2, 2, 1]];
    let options = CraneSimOptions {
        transport: TransportKind::Tcp,
        motion: Some(rackd::wire::motion::Motion::default()),
        time_scale: 1000.0,
        inventory: Some(boxes.to_vec()),
        ..Default::default()
    };
    let sim = CraneSim::start("127.0.0.1:0", options).await.unwrap();
    let device = device_for(&sim, TransportKind::Tcp, |_| {});
    let app = spawn_with(Engine::Sqlite, |c: &mut Config| {
        with_crane(c, device);
        c.site.aisles.iter_mut().filter(|a| a.aisle == 2).for_each(|a| a.depth = 2);
    })
    .await;
    let cells: Vec<Value> = boxes.iter().map(|[r, b, l, s]| cloc(*r, *b, *l, *s)).collect();
    stock(&app, &cells).await;
    let jobs = json!({"jobs": [
        {"kind": "retrieve", "from": cloc(1, 3, 2, 2)},
        {"kind": "store", "aisle": 2},
        {"kind": "retrieve", "from": cloc(2, 5, 1, 2)},
        {"kind": "store", "to": cloc(1, 8, 4, 1)},
        {"kind": "store", "zones": [{"aisle": 2, "bay": 3}]},
        {"kind": "move", "from": cloc(2, 2, 2, 1), "to": cloc(2, 9, 1, 2)},
        {"kind": "retrieve", "from": cloc(2, 5, 1, 1)},
    ]});
    let (status, posted) = app.post("/api/v1/jobs/batch", &jobs).await;
    assert_eq!(status, 201, "{posted}");
    for job in posted["jobs"].as_array().unwrap() {
        let id = job["id"].as_i64().unwrap();
        let done = wait_job(&app, id, &["completed", "failed", "cancelled"], 30).await;
        assert_eq!(done["state"], "completed", "{done}");
    }
    let stats = sim.stats();
    assert!(stats.alarms.is_empty(), "no business alarm: {stats}");
    assert_eq!(sim.violations(), 0, "{:?}", sim.violation_log());
    let (_, moves) = app.get("/api/v1/jobs?kind=move").await;
    let relocations = moves["jobs"].as_array().unwrap().iter().filter(|j| !j["serves"].is_null()).count();
    assert_eq!(
        relocations, 1,
        "only 1-3-2-2 needs one (2-5-1-2 waits for the retrieve of its near box): {moves}"
    );
    let (_, full) = app.get("/api/v1/locations?aisle=2&occupied=true").await;
    let mut rackd: Vec<[u16; 4]> = full
        .as_array()
        .unwrap()
        .iter()
        .map(|l| ["row", "bay", "level", "position"].map(|k| l[k].as_u64().unwrap() as u16))
        .collect();
    let mut crane = sim.inventory().unwrap();
    rackd.sort_unstable();
    crane.sort_unstable();
    assert_eq!(rackd, crane, "rackd's location model and the crane's own rack agree");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_store_whose_zones_are_full_waits_and_says_so() {
    let (app, _sim) = deep_app(|_| {}).await;
    stock(&app, &[cloc(1, 3, 1, 1), cloc(1, 3, 1, 2)]).await;
    let zone = json!({"kind": "store", "zones": [{"aisle": 2, "row": 1, "bay": 3, "level": 1}]});
    let id = submit(&app, zone, "FULL-ZONE").await;
    let waiting = eventually("the store to wait for no_place", Duration::from_secs(10), async || {
        let (_, job) = app.get(&format!("/api/v1/jobs/{id}")).await;
        if job["waiting"]["reason"] == "no_place" { Ok(job) } else { Err(job) }
    })
    .await;
    assert_eq!(waiting["state"], "queued", "{waiting}");
    let (_, listed) = app.get("/api/v1/jobs?waiting=no_place").await;
    assert_eq!(listed["jobs"].as_array().unwrap().len(), 1, "{listed}");
    // The near box goes out: the far place is still walled in until it does, then the
    // near one is free; the store takes it.
    let out = submit(&app, json!({"kind": "retrieve", "from": cloc(1, 3, 1, 1)}), "OUT").await;
    assert_eq!(wait_job(&app, out, &["completed", "failed"], 10).await["state"], "completed");
    let done = wait_job(&app, id, &["completed", "failed"], 10).await;
    assert_eq!((done["state"].clone(), done["to"].clone()), (json!("completed"), cloc(1, 3, 1, 1)), "{done}");
    app.stop().await;
}
