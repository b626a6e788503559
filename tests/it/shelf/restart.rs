//! rackd stopped abruptly mid-run and started again on the same database: every job ends
//! exactly once, and the PLC received each task once.

use std::path::Path;
use std::time::Duration;

use rackd::app::Application;
use rackd::config::Config;
use rackd::store::Engine;
use serde_json::json;

use super::device_for;
use super::workload::{Model, mixed_jobs, rackd_store};
use crate::support::*;

/// Runs rackd on its own runtime in its own thread; sending on the returned channel drops
/// that runtime, killing every task of it mid-step, as a crash would.
fn start_crashable(config: Config) -> (String, std::sync::mpsc::Sender<()>, std::thread::JoinHandle<()>) {
    let (addr_tx, addr_rx) = std::sync::mpsc::channel();
    let (kill_tx, kill_rx) = std::sync::mpsc::channel::<()>();
    let thread = std::thread::spawn(move || {
        let runtime =
            tokio::runtime::Builder::new_multi_thread().worker_threads(1).enable_all().build().unwrap();
        let app = runtime.block_on(Application::build(&config, false)).unwrap();
        addr_tx.send(format!("http://{}", app.local_addr())).unwrap();
        runtime.spawn(app.run_until(std::future::pending()));
        let _ = kill_rx.recv();
        runtime.shutdown_background();
    });
    (addr_rx.recv().unwrap(), kill_tx, thread)
}

fn config(db: &Path, device: rackd::config::devices::ShelfConfig) -> Config {
    let mut c = Config::demo();
    c.server.listen = "127.0.0.1:0".parse().unwrap();
    c.database.path = db.to_owned();
    c.devices = vec![device.into()];
    c
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_crash_mid_run_loses_and_repeats_nothing() {
    let sim = rackd::sim::shelf::ShelfSim::start("127.0.0.1:0", super::sim(3)).await.unwrap();
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("rackd.db");
    let device = device_for(&sim, |_| {});

    let (base, kill, thread) = start_crashable(config(&db, device.clone()));
    let client = reqwest::Client::new();
    let mut model = Model::default();
    let jobs = mixed_jobs(300, 23, &mut model);
    for chunk in jobs.chunks(100) {
        let r = client
            .post(format!("{base}/api/v1/jobs/batch"))
            .json(&json!({"jobs": chunk}))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 201);
    }
    // Let part of the work finish, then pull the plug.
    let started = async || sim.finished().0 >= 60;
    eventually_every(Duration::from_millis(5), "60 tasks done", Duration::from_secs(60), started).await;
    kill.send(()).unwrap();
    tokio::task::spawn_blocking(move || thread.join()).await.unwrap().unwrap();
    let (done_at_crash, _) = sim.finished();
    assert!(done_at_crash < 300, "the crash came mid-run");

    let app = spawn_on(rackd::store::Database::Sqlite(db.clone()), |c| c.devices = vec![device.into()]).await;
    let done = wait_ended(&app, 300, 120).await;
    super::assert_each_completed_once(&app, &sim, &done).await;
    assert_eq!(rackd_store(&app).await.0, sim.inventory());
    assert_eq!(sim.inventory(), model.boxes);
    assert_eq!(sim.violations(), 0);
}

/// rackd wrote a task into a slot (the body while the id is 0, then the id) and stopped
/// before the id write's reply came back, so the job is still `queued`: on restart the slot
/// is found to hold the job's task, the job follows the slot, and the PLC gets it once.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_slot_written_just_before_a_stop_is_found_on_restart_and_not_written_again() {
    use rackd::domain::{JobSpec, Location};

    let sim = rackd::sim::shelf::ShelfSim::start("127.0.0.1:0", super::sim(50)).await.unwrap();
    let device = device_for(&sim, |_| {});
    let app = spawn_with(Engine::Sqlite, |c| c.devices = vec![device.clone().into()]).await;
    let (status, _) = app.post("/api/v1/devices/shelf1/pause", &json!({})).await;
    assert_eq!(status, 200);
    let (status, job) = app.post("/api/v1/jobs", &store("cut")).await;
    assert_eq!(status, 201, "{job}");
    let id = job["id"].as_i64().unwrap();
    let (db, _dir) = app.stop().await;
    // What rackd writes, in its order: the body while the id is 0, then the id alone.
    let plc = rackd::protocols::link::connect(&device.link).await.unwrap();
    let at = plc.parse_address(device.slot_base()).unwrap();
    let spec = JobSpec::Store { to: Location { aisle: 1, row: 1, bay: 2, level: 3, position: 1 } };
    let priority = job["priority"].as_u64().unwrap() as u8;
    let body = rackd::wire::slot::encode_body(&spec, priority, Some("BOX-1")).unwrap();
    plc.write_words(&plc.word_address(&at, 1), &body).await.unwrap();
    let task = rackd::wire::task_id_for(id);
    plc.write_words(&at, &[task]).await.unwrap();
    assert_eq!(sim.received(task), 1, "the PLC took the task");

    let app = spawn_on(db, |c| c.devices = vec![device.into()]).await;
    let done = wait_ended(&app, 1, 10).await;
    super::assert_each_completed_once(&app, &sim, &done).await;
    assert_eq!(sim.violations(), 0);
    app.stop().await;
}

/// Tasks the PLC finished while rackd was down are recorded as completed at the restart,
/// and the PLC is not taken for one that lost its memory: it remembered them.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tasks_finished_while_rackd_was_down_are_completed_not_taken_for_a_lost_memory() {
    let sim = rackd::sim::shelf::ShelfSim::start("127.0.0.1:0", super::sim(800)).await.unwrap();
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("rackd.db");
    let device = device_for(&sim, |_| {});
    let (base, kill, thread) = start_crashable(config(&db, device.clone()));
    let client = reqwest::Client::new();
    let light = |bay| json!({"kind": "light", "location": loc(1, bay, 1, 1), "color": "green", "on": true});
    let jobs: Vec<_> = (1..=4).map(light).collect();
    let r =
        client.post(format!("{base}/api/v1/jobs/batch")).json(&json!({"jobs": jobs})).send().await.unwrap();
    assert_eq!(r.status(), 201);
    let ids: Vec<u16> = (1..=4).map(rackd::wire::task_id_for).collect();
    let every = Duration::from_millis(5);
    let sent = async || ids.iter().all(|&t| sim.received(t) == 1);
    eventually_every(every, "the tasks to reach the PLC", Duration::from_secs(30), sent).await;
    kill.send(()).unwrap();
    tokio::task::spawn_blocking(move || thread.join()).await.unwrap().unwrap();
    let finished = async || sim.finished().0 >= 4;
    eventually_every(every, "the PLC to finish", Duration::from_secs(30), finished).await;

    let app = spawn_on(rackd::store::Database::Sqlite(db.clone()), |c| c.devices = vec![device.into()]).await;
    let done = wait_ended(&app, 4, 30).await;
    super::assert_each_completed_once(&app, &sim, &done).await;
    let (_, alarms) = app.get("/api/v1/alarms").await;
    let alarms = alarms["alarms"].as_array().unwrap();
    assert!(!alarms.iter().any(|a| a["kind"] == "memory_lost"), "{alarms:?}");
    assert_eq!(sim.violations(), 0);
}
