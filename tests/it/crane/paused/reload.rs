//! A reload stops (or restarts) the crane's task only at a safe point: asked to stop at
//! any step of a hand-over (the task words written, the strobe up, the strobe lowered),
//! the task carries the hand-over to its end first, and a crane that never answers the
//! strobe has it withdrawn and the hold that follows run out before the task ends.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use rackd::devices::DeviceRequest;
use rackd::domain::{JobState, Reported};
use rackd::wire::task_id_for;
use tokio::time::Instant;

use super::{Rig, Write, at, travel};

const MS: fn(u64) -> Duration = Duration::from_millis;
/// D8: the first of rackd's task words.
const WORDS: u32 = 8;
/// D21: rackd's strobe.
const STB: u32 = 21;
/// D225: the crane's ACK.
const ACK: u32 = 225;

/// Asks the device task to stop from the link, at the instant rackd's write that `when`
/// picks reaches the crane (the task is inside the hand-over then); returns when it asked.
fn stop_at(rig: &Rig, when: impl Fn(&Write) -> bool + Send + 'static) -> Arc<Mutex<Option<Instant>>> {
    let asked = Arc::new(Mutex::new(None));
    let (requests, at) = (rig.requests.clone(), asked.clone());
    rig.on_write(Box::new(move |_, write| {
        let mut at = at.lock().unwrap();
        if at.is_none() && when(write) {
            requests.try_send(DeviceRequest::Stop).expect("the inbox has room");
            *at = Some(Instant::now());
        }
    }));
    asked
}

/// Which of rackd's writes a step is.
type Step = fn(&Write) -> bool;

#[tokio::test(start_paused = true)]
async fn a_stop_during_a_hand_over_waits_for_its_end_at_each_step() {
    let steps: [(&str, Step); 3] = [
        ("the task words written", |w| w.start == WORDS),
        ("the strobe up", |w| w.start == STB && w.words == [1]),
        ("the strobe lowered", |w| w.start == STB && w.words == [0]),
    ];
    for (step, when) in steps {
        let mut rig = Rig::start(MS(50), |_| {});
        rig.until("came online", MS(500), |s| s.online).await;
        let asked = stop_at(&rig, when);
        let id = rig.queue(travel(at(1, 4, 3, 1)));
        let stopped = rig.until_stopped(Duration::from_secs(5)).await;
        let asked = asked.lock().unwrap().expect("the stop was asked");
        assert!(stopped >= asked, "{step}");
        // The hand-over ran to its end: both strobe and ACK down, the crane holds the task,
        // which it took once; the job is the crane's.
        assert_eq!((rig.word(STB), rig.word(ACK)), (0, 0), "{step}: the hand-over is over");
        assert_eq!(rig.writes_to(STB).len(), 2, "{step}: strobe up once, down once");
        assert_eq!(rig.engine_says(|e| e.received.get(&task_id_for(id)).copied()), Some(1), "{step}");
        assert_eq!(rig.engine_says(|e| e.refused), 0, "{step}");
        assert!(rig.reports(id).contains(&Reported::Taken), "{step}: {:?}", rig.reports(id));
        // Nothing was written after the end of the hand-over.
        let last = rig.writes_to(STB).last().unwrap().0;
        let later = rig.memory.writes.lock().unwrap().iter().filter(|w| w.at > last).count();
        assert_eq!(later, 0, "{step}: written after the hand-over");
    }
}

#[tokio::test(start_paused = true)]
async fn a_stop_while_the_crane_does_not_answer_waits_for_the_withdrawal_and_the_hold() {
    let mut rig = Rig::start(MS(50), |_| {});
    let timeout = MS(1000);
    rig.until("came online", MS(500), |s| s.online).await;
    rig.engine(|e| e.handshake_on = false);
    let asked = stop_at(&rig, |w| w.start == STB && w.words == [1]);
    let id = rig.queue(travel(at(2, 5, 5, 1)));
    let stopped = rig.until_stopped(Duration::from_secs(10)).await;
    let asked = asked.lock().unwrap().expect("the stop was asked");
    // The step-2 wait (a timeout), the strobe withdrawn, then the hold of a possibly latched
    // task (another timeout) before the crane counts as idle again: not before, and well
    // within the stop's grace (three timeouts and two polls).
    assert!(stopped - asked >= 2 * timeout, "stopped {:?} after the stop was asked", stopped - asked);
    assert!(
        stopped - asked <= 3 * timeout + MS(200),
        "stopped {:?} after the stop was asked",
        stopped - asked
    );
    assert_eq!(rig.word(STB), 0, "the strobe was withdrawn before the task ended");
    assert_eq!(rig.writes_to(STB).len(), 2, "no second attempt");
    assert_eq!(rig.job(id).state, JobState::Queued, "the job waits for the next start");
    assert_eq!(rig.engine_says(|e| e.received.get(&task_id_for(id)).copied()), None);
}
