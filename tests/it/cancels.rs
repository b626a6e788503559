//! Two cancels of one job that overlap, on the real crane and shelf simulators (issue 50):
//! while one cancel is between its device's "not held" and its commit, another cancel of
//! the same job ends first (refused through the API, or dropped with its request, as a
//! client's timeout drops it). The job must never reach the machine: it ends `cancelled`
//! and the simulator never receives its task.
//!
//! The order is made, not waited for: the device is paused while both cancels take their
//! holds, the held-back cancel is a future the test polls once (its hold taken, its
//! question sent to the device task) and again only at the end, and the device is resumed
//! once the first cancel has ended. Two requests to the device task after the resume, each
//! answered between two of its rounds, say that every round that could hand the job over
//! has run, so nothing is left to chance or to a sleep.

use rackd::devices::DeviceHandle;
use rackd::domain::{JobState, Who};
use rackd::protocols::mc3e::TransportKind;
use rackd::service::dispatch::Actor;
use rackd::sim::crane::CraneSim;
use rackd::sim::shelf::ShelfSim;
use rackd::wire::task_id_for;
use rstest::rstest;
use serde_json::{Value, json};

use crate::crane::{cloc, crane_app};
use crate::shelf::{shelf_app, sim};
use crate::support::{TestApp, eventually, loc};

/// The machine under the cancels.
#[derive(Clone, Copy, Debug)]
enum Machine {
    Crane,
    Shelf,
}

/// How the first cancel ends.
#[derive(Clone, Copy, Debug)]
enum End {
    /// A bulk cancel through the API that lists a job no longer queued: 409.
    Refused,
    /// A bulk cancel whose request is dropped while its device decides.
    Dropped,
}

/// A running simulator, to count what it received.
enum Sim {
    Crane(CraneSim),
    Shelf(ShelfSim),
}

impl Sim {
    /// How many times the task of job `id` reached the machine.
    fn received(&self, id: i64) -> u32 {
        match self {
            Sim::Crane(sim) => sim.received(task_id_for(id)),
            Sim::Shelf(sim) => sim.received(task_id_for(id)),
        }
    }
}

/// rackd driving `machine`'s simulator, its device's id, and a store for it.
async fn start(machine: Machine) -> (TestApp, Sim, &'static str, Value) {
    match machine {
        Machine::Crane => {
            let (app, sim) = crane_app(TransportKind::Tcp, 20, |_| {}).await;
            let job = json!({"kind": "store", "barcode": "PAL-1", "to": cloc(1, 5, 3, 2)});
            (app, Sim::Crane(sim), "crane1", job)
        }
        Machine::Shelf => {
            let (app, sim) = shelf_app(sim(50), |_| {}).await;
            let job = json!({"kind": "store", "barcode": "BOX-1", "to": loc(1, 2, 3, 1)});
            (app, Sim::Shelf(sim), "shelf1", job)
        }
    }
}

/// Submits `body`; the job's id.
async fn submit(app: &TestApp, body: &Value) -> i64 {
    let (status, job) = app.post("/api/v1/jobs", body).await;
    assert_eq!(status, 201, "{job}");
    job["id"].as_i64().unwrap()
}

/// The job's state.
async fn state(app: &TestApp, id: i64) -> Value {
    app.get(&format!("/api/v1/jobs/{id}")).await.1["state"].clone()
}

/// Returns once `device`'s task has run every round it began before this call.
async fn rounds_done(device: &DeviceHandle) {
    for _ in 0..2 {
        device.holding(Vec::new()).await.expect("the device task runs");
    }
}

#[rstest]
#[case::crane_refused(Machine::Crane, End::Refused)]
#[case::crane_dropped(Machine::Crane, End::Dropped)]
#[case::shelf_refused(Machine::Shelf, End::Refused)]
#[case::shelf_dropped(Machine::Shelf, End::Dropped)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_cancel_that_ends_first_never_lets_a_cancelled_job_reach_the_machine(
    #[case] machine: Machine,
    #[case] end: End,
) {
    let (app, sim, id, body) = start(machine).await;
    let path = format!("/api/v1/devices/{id}");
    eventually("the device online", std::time::Duration::from_secs(10), async || {
        app.get(&path).await.1["online"] == true
    })
    .await;
    // In-process handles: the dispatcher holds the writer, so they go before the server stops.
    let devices = app.reload().devices();
    let device = devices.get(id).expect("the device runs").clone();
    let dispatcher = app.reload().dispatcher().clone();

    // Paused, the device takes nothing: the cancels take their holds first.
    let (status, _) = app.post(&format!("{path}/pause"), &json!({})).await;
    assert_eq!(status, 200);
    let job = submit(&app, &body).await;
    assert_eq!(state(&app, job).await, "queued");

    // The cancel that is held back: its hold taken and its question sent, not polled again
    // until the end, so it stays between its device's answer and its commit.
    let who = Who { name: "wms".into(), client: None };
    let mut held = Box::pin(dispatcher.cancel(job, &devices, &who));
    assert!(futures::poll!(held.as_mut()).is_pending());

    // The first cancel ends meanwhile.
    match end {
        End::Refused => {
            let mut other = body.clone();
            other["to"] = match machine {
                Machine::Crane => cloc(1, 6, 3, 2),
                Machine::Shelf => loc(1, 2, 4, 1),
            };
            let ended = submit(&app, &other).await;
            let (status, _) = app.post(&format!("/api/v1/jobs/{ended}/cancel"), &json!({})).await;
            assert_eq!(status, 200, "a queued job of a paused device is cancelled at once");
            let (status, refused) = app.post("/api/v1/jobs/cancel", &json!({"jobs": [job, ended]})).await;
            assert_eq!(status, 409, "a listed job that is not queued refuses the bulk cancel: {refused}");
        }
        End::Dropped => {
            let actor = Actor { by: "operator".into(), client: None, reason: None };
            let mut bulk = Box::pin(dispatcher.bulk_cancel(vec![job], &devices, false, &actor));
            assert!(futures::poll!(bulk.as_mut()).is_pending());
            rounds_done(&device).await;
            drop(bulk);
        }
    }

    // Resumed, the device takes whatever it may; every round that could take the job runs.
    let (status, _) = app.post(&format!("{path}/resume"), &json!({})).await;
    assert_eq!(status, 200);
    rounds_done(&device).await;

    let answer = held.await;
    drop((dispatcher, devices, device));
    assert_eq!(
        sim.received(job),
        0,
        "job {job} reached the {machine:?} after the other cancel ended; the held cancel answered {answer:?}"
    );
    let cancelled = answer.expect("the held cancel commits");
    assert_eq!(cancelled.state, JobState::Cancelled);
    assert_eq!(state(&app, job).await, "cancelled");

    // The device goes on with other work: nothing else is held.
    let mut next = body.clone();
    next["to"] = match machine {
        Machine::Crane => cloc(2, 7, 3, 1),
        Machine::Shelf => loc(1, 3, 3, 1),
    };
    let later = submit(&app, &next).await;
    eventually("the next job to complete", std::time::Duration::from_secs(20), async || {
        state(&app, later).await == "completed"
    })
    .await;
    assert_eq!(sim.received(later), 1);
    assert_eq!(sim.received(job), 0, "job {job} never reached the {machine:?}");
    app.stop().await;
}
