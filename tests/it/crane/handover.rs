//! A hand-over cut at each of its steps, by a stop of rackd (restarted on the same
//! database) or by a link loss while rackd runs: the crane gets each task exactly once,
//! the cut task is followed as its own job, and nothing else is handed over until it has
//! finished. The simulator counts every breach of the interface; there must be none.

use std::time::Duration;

use rackd::protocols::mc3e::TransportKind;
use rackd::sim::crane::{CraneSim, Hold};
use rackd::wire::task_id_for;
use serde_json::{Value, json};
use time::OffsetDateTime;
use time::format_description::well_known::Rfc3339;

use super::*;
use crate::support::eventually_every;
use crate::support::{TestApp, spawn_on, wait_for_more};

/// Where the hand-over of the first job is cut.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Cut {
    /// Task words written, the strobe never raised.
    TaskWords,
    /// STB = 1, the crane has not latched (held before step 2).
    BeforeLatch,
    /// STB = 1 and the crane latched: ACK = 1.
    Latched,
    /// STB lowered, the crane's ACK still 1 (held before step 4).
    StrobeDown,
    /// STB lowered and the crane started.
    Started,
}

/// Waits (bounded) until `ok` holds.
async fn until(what: &str, secs: u64, ok: impl Fn() -> bool) {
    eventually_every(Duration::from_millis(5), what, Duration::from_secs(secs), async || ok()).await;
}

/// When the job entered `state`, from its history.
async fn entered(app: &TestApp, id: i64, state: &str) -> OffsetDateTime {
    let (_, h) = app.get(&format!("/api/v1/jobs/{id}/history")).await;
    let at = h.as_array().unwrap().iter().find(|e| e["state"] == state).map(|e| e["at"].clone());
    let at = at.unwrap_or_else(|| panic!("job {id} never {state}: {h}"));
    OffsetDateTime::parse(at.as_str().unwrap(), &Rfc3339).unwrap()
}

/// Both jobs completed, each task received once, one after the other, no breach.
async fn assert_one_after_the_other(app: &TestApp, sim: &CraneSim, first: i64, second: i64) {
    for id in [first, second] {
        let job = wait_job(app, id, &["completed", "failed", "cancelled"], 15).await;
        assert_eq!(job["state"], "completed", "{job}");
        assert_eq!(sim.received(task_id_for(id)), 1, "job {id}'s task received once");
        let h = history(app, id).await;
        assert_eq!(h.iter().filter(|(s, _)| s == "completed").count(), 1, "{h:?}");
    }
    let span =
        |id| async move { (entered(app, id, "dispatched").await, entered(app, id, "completed").await) };
    let (a, b) = (span(first).await, span(second).await);
    assert!(a.1 <= b.0 || b.1 <= a.0, "the two tasks overlapped: {a:?} {b:?}");
    assert_eq!(sim.violations(), 0, "{:?}", sim.violation_log());
    assert_eq!(sim.refused(), 0);
}

fn transfer() -> Value {
    json!({"kind": "move", "from": cloc(1, 2, 3, 1), "to": cloc(2, 5, 2, 2)})
}

fn travel() -> Value {
    json!({"kind": "travel", "to": cloc(1, 9, 4, 1)})
}

/// Cuts the hand-over at `cut`, with a crane that echoes the task words as it takes them,
/// then with a slow one that shows them only as it starts the task, a step after it
/// cleared ACK.
async fn restart_at(cut: Cut) {
    for late_start in [false, true] {
        restart_once(cut, late_start).await;
    }
}

async fn restart_once(cut: Cut, late_start: bool) {
    let (app, sim) = crane_app(TransportKind::Tcp, 20, |d| d.handshake_timeout_ms = 3000).await;
    sim.set_late_start(late_start);
    let device = device_for(&sim, TransportKind::Tcp, |d| d.handshake_timeout_ms = 3000);
    wait_device(&app, "online", 5, |s| s["online"] == true).await;
    match cut {
        Cut::TaskWords => sim.cut_link_after(9, 2),
        Cut::BeforeLatch => {
            sim.hold(Some(Hold::BeforeAck));
            sim.cut_link_after(21, 1);
        }
        Cut::Latched => sim.cut_link_after(21, 1),
        Cut::StrobeDown => {
            sim.hold(Some(Hold::BeforeStart));
            sim.cut_link_after(21, 0);
        }
        Cut::Started => sim.cut_link_after(21, 0),
    }
    let first = submit(&app, transfer(), "first").await;
    let task = task_id_for(first);
    until("cut", 5, || sim.link_cut()).await;
    match cut {
        Cut::Latched => until("latched", 5, || sim.word(225) == 1).await,
        Cut::Started => until("started", 5, || sim.word(208) == task).await,
        _ => {}
    }
    let (db, _dir) = app.stop().await;
    let (stb, ack) = (sim.word(21), sim.word(225));
    let want = match cut {
        Cut::TaskWords | Cut::Started => (0, 0),
        Cut::BeforeLatch => (1, 0),
        Cut::Latched => (1, 1),
        Cut::StrobeDown => (0, 1),
    };
    assert_eq!((stb, ack), want, "{cut:?}: STB and ACK when rackd stopped");
    if matches!(cut, Cut::Latched | Cut::StrobeDown) {
        let echo = if late_start { 0 } else { task };
        assert_eq!(sim.word(208), echo, "{cut:?}, late start {late_start}: D208");
    }
    assert_eq!(sim.word(8), task, "{cut:?}: D8 holds the first task");
    sim.set_link(true);
    let app = spawn_on(db, |c| with_crane(c, device)).await;
    let second = submit(&app, travel(), "second").await;
    if matches!(cut, Cut::BeforeLatch | Cut::StrobeDown) {
        // The crane is frozen mid-hand-over: rackd must wait for it and hand over nothing.
        wait_for_more("polls of the frozen crane", POLLS, 5, || sim.requests_seen()).await;
        let (_, job) = app.get(&format!("/api/v1/jobs/{second}")).await;
        assert_eq!(job["state"], "queued", "{cut:?}: nothing while a hand-over is under way: {job}");
        assert_eq!(sim.word(21), stb, "{cut:?}: the strobe is not touched while the crane is frozen");
        sim.hold(None);
    }
    assert_one_after_the_other(&app, &sim, first, second).await;
    let h = history(&app, first).await;
    assert_eq!(h.iter().filter(|(s, _)| s == "dispatched").count(), 1, "{cut:?}: {h:?}");
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_restart_after_the_task_words_hands_the_task_over_once() {
    restart_at(Cut::TaskWords).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_restart_with_the_strobe_up_before_the_crane_latched_continues_the_hand_over() {
    restart_at(Cut::BeforeLatch).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_restart_after_the_crane_latched_finishes_the_hand_over_as_the_same_job() {
    restart_at(Cut::Latched).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_restart_with_the_strobe_down_and_ack_still_up_follows_the_task() {
    restart_at(Cut::StrobeDown).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_restart_after_the_crane_started_follows_the_task() {
    restart_at(Cut::Started).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_link_lost_after_the_crane_latched_finishes_the_hand_over_when_it_returns() {
    let (app, sim) = crane_app(TransportKind::Tcp, 20, |_| {}).await;
    wait_device(&app, "online", 5, |s| s["online"] == true).await;
    sim.cut_link_after(21, 1);
    let first = submit(&app, transfer(), "first").await;
    let second = submit(&app, travel(), "second").await;
    until("latched", 5, || sim.word(225) == 1).await;
    wait_device(&app, "offline", 5, |s| s["online"] == false).await;
    assert_eq!(sim.word(21), 1, "the strobe stays up while rackd cannot tell what the crane did");
    sim.set_link(true);
    assert_one_after_the_other(&app, &sim, first, second).await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unanswered_strobe_is_withdrawn_and_the_job_held_back_until_the_crane_is_idle() {
    let (app, sim) = crane_app(TransportKind::Tcp, 20, |d| d.handshake_timeout_ms = 300).await;
    wait_device(&app, "online", 5, |s| s["online"] == true).await;
    sim.hold(Some(Hold::BeforeAck));
    let first = submit(&app, transfer(), "first").await;
    until("strobe up", 5, || sim.word(21) == 1).await;
    let second = submit(&app, travel(), "second").await;
    // No ACK within 300 ms: rackd withdraws its strobe (the crane cannot have latched).
    until("strobe withdrawn", 5, || sim.word(21) == 0).await;
    wait_for_more("polls while the task is possibly latched", POLLS, 5, || sim.requests_seen()).await;
    for id in [first, second] {
        let (_, job) = app.get(&format!("/api/v1/jobs/{id}")).await;
        assert_eq!(job["state"], "queued", "{job}");
    }
    assert_eq!(sim.received(task_id_for(second)), 0, "nothing else while the first is pending");
    sim.hold(None);
    assert_one_after_the_other(&app, &sim, first, second).await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_strobe_up_for_a_task_that_is_no_job_blocks_work_until_a_person_clears_it() {
    let (app, sim) = crane_app(TransportKind::Tcp, 10, |_| {}).await;
    let device = device_for(&sim, TransportKind::Tcp, |_| {});
    let (db, _dir) = app.stop().await;
    // Someone else's words and strobe (rackd's own words after a database restore, say).
    for (k, w) in [999, 1, 0, 0, 0, 0, 2, 6, 2, 1].into_iter().enumerate() {
        sim.set_word(8 + k as u32, w);
    }
    sim.set_word(21, 1);
    until("latched", 5, || sim.word(225) == 1).await;
    let app = spawn_on(db, |c| with_crane(c, device)).await;
    let id = submit(&app, travel(), "waits").await;
    let status = wait_device(&app, "blocked", 5, |s| {
        s["last_error"].as_str().is_some_and(|e| e.contains("strobe (D21) was found up"))
    })
    .await;
    assert_eq!(status["online"], true, "{status}");
    wait_for_more("polls of the blocked crane", POLLS, 5, || sim.requests_seen()).await;
    let (_, job) = app.get(&format!("/api/v1/jobs/{id}")).await;
    assert_eq!(job["state"], "queued", "{job}");
    assert_eq!((sim.word(21), sim.action()), (1, 0), "the strobe is left as found; nothing started");
    // A person clears the strobe: the crane runs the foreign task, then rackd's.
    sim.set_word(21, 0);
    let job = wait_job(&app, id, &["completed", "failed", "cancelled"], 10).await;
    assert_eq!(job["state"], "completed", "{job}");
    assert_eq!((sim.received(999), sim.received(task_id_for(id))), (1, 1));
    assert_eq!(sim.violations(), 0, "{:?}", sim.violation_log());
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_crane_that_shows_its_task_only_a_step_after_the_hand_over_gets_one_task_at_a_time() {
    let (app, sim) = crane_app(TransportKind::Udp, 30, |_| {}).await;
    sim.set_late_start(true);
    let first = submit(&app, transfer(), "first").await;
    let second = submit(&app, travel(), "second").await;
    assert_one_after_the_other(&app, &sim, first, second).await;
    app.stop().await;
}
