//! The STB/ACK hand-over on paused time: each wait bounded by `handshake_timeout_ms`
//! exactly, the strobe withdrawn after an unanswered step 2 and the task then held back
//! (possibly latched) for another timeout, no hand-over while paused, and a task the crane
//! took during a hand-over that timed out followed rather than sent twice (its strobe is
//! never lowered a second time).

use std::time::Duration;

use rackd::domain::{JobState, Reported};
use rackd::wire::task_id_for;
use tokio::time::Instant;

use super::{Rig, at, travel};
use crate::support::eventually_every;

const MS: fn(u64) -> Duration = Duration::from_millis;
/// D21: rackd's strobe.
const STB: u32 = 21;

/// The instants rackd set the strobe to `value`.
fn strobes(rig: &Rig, value: u16) -> Vec<Instant> {
    rig.writes_to(STB).into_iter().filter(|(_, w)| w == &[value]).map(|(at, _)| at).collect()
}

#[tokio::test(start_paused = true)]
async fn a_crane_deaf_to_the_strobe_times_out_at_step_2_and_the_strobe_is_withdrawn() {
    let mut rig = Rig::start(MS(50), |_| {});
    let timeout = MS(1000);
    rig.until("came online", MS(500), |s| s.online).await;
    rig.engine(|e| e.handshake_on = false);
    let id = rig.queue(travel(at(2, 5, 5, 1)));
    rig.until("reported the timeout", 2 * timeout, |s| {
        s.last_error.as_deref().is_some_and(|e| e.contains("step 2"))
    })
    .await;
    // The strobe was withdrawn at the first poll after the step-2 wait gave up (ACK is
    // read every 10 ms, the poll period is 100 ms).
    let within = timeout + MS(110);
    let (up, down) = (strobes(&rig, 1)[0], strobes(&rig, 0)[0]);
    assert!(down - up >= timeout && down - up <= within, "strobe up for {:?}", down - up);
    assert!(rig.status.borrow().online, "a deaf crane is still online");
    assert_eq!(rig.job(id).state, JobState::Queued, "the job waits");

    // rackd tries again, each attempt bounded the same way, but only once the crane has
    // shown strictly idle for a handshake timeout after the withdrawal: until then the
    // task counts as possibly latched.
    eventually_every(MS(1), "rackd to try three times", 7 * timeout, async || strobes(&rig, 0).len() >= 3)
        .await;
    let (ups, downs) = (strobes(&rig, 1), strobes(&rig, 0));
    for (up, down) in ups.iter().zip(&downs) {
        assert!(*down - *up >= timeout && *down - *up <= within, "strobe up for {:?}", *down - *up);
    }
    for (down, next) in downs.iter().zip(&ups[1..]) {
        assert!(*next - *down >= timeout && *next - *down <= within, "held back for {:?}", *next - *down);
    }

    // Paused, rackd stops trying: the attempt under way ends with the strobe down (its ACK
    // reads are about 100 requests), and no other starts over 300 requests (10 s and more).
    rig.set_paused(true);
    let paused = Instant::now();
    rig.polls(300).await;
    let late: Vec<Instant> = strobes(&rig, 1).into_iter().filter(|at| *at > paused).collect();
    assert!(late.is_empty(), "hand-overs while paused at {late:?}");
    assert_eq!(rig.word(STB), 0, "the strobe is down");

    rig.engine(|e| e.handshake_on = true);
    rig.set_paused(false);
    rig.until_job(id, JobState::Completed, Duration::from_secs(5)).await;
    assert_eq!(rig.engine_says(|e| e.received.get(&task_id_for(id)).copied()), Some(1));
}

#[tokio::test(start_paused = true)]
async fn a_crane_that_never_lowers_ack_times_out_at_step_4_and_its_task_is_followed() {
    let mut rig = Rig::start(MS(50), |_| {});
    let timeout = MS(1000);
    rig.until("came online", MS(500), |s| s.online).await;
    // The crane takes the task (step 2) but goes deaf before it sees the strobe drop.
    rig.on_write(Box::new(|engine, write| {
        if write.start == STB && write.words == [0] {
            engine.handshake_on = false;
        }
    }));
    let id = rig.queue(travel(at(1, 8, 2, 1)));
    rig.until("reported the timeout", 2 * timeout, |s| {
        s.last_error.as_deref().is_some_and(|e| e.contains("step 4"))
    })
    .await;
    // Step 3 lowered the strobe once; the step-4 wait ended within its bound, and nothing
    // was written to the strobe since (the crane latched the task: it is followed).
    let downs = strobes(&rig, 0);
    assert_eq!(downs.len(), 1, "{downs:?}");
    assert!(Instant::now() - downs[0] >= timeout, "{:?}", Instant::now() - downs[0]);
    assert_eq!(rig.writes_to(STB).len(), 2, "{:?}", rig.writes_to(STB));
    assert_eq!(rig.word(225), 1, "the crane's ACK is still up");
    assert_eq!(rig.word(208), task_id_for(id), "the crane holds the task");

    // rackd follows the task the crane holds and hands over nothing else meanwhile.
    let before = rig.writes_to(8).len();
    rig.polls(50).await;
    assert_eq!(rig.writes_to(8).len(), before, "nothing handed over while the crane holds the task");
    rig.engine(|e| e.handshake_on = true);
    rig.until_job(id, JobState::Completed, Duration::from_secs(5)).await;
    assert_eq!(rig.engine_says(|e| e.received.get(&task_id_for(id)).copied()), Some(1), "sent once");
    assert_eq!(rig.engine_says(|e| e.refused), 0);
    assert!(rig.reports(id).contains(&Reported::Running), "{:?}", rig.reports(id));
}
