//! The 4-step heartbeat on paused time: the crane is lost exactly after the configured
//! timeout, found again at the first poll after it moves, and rackd's own word steps no
//! faster than `heartbeat_ms`; the crane's watchdog stays quiet while rackd runs.

use std::time::Duration;

use rackd::domain::JobState;
use tokio::time::Instant;

use super::{Rig, at, travel};

const MS: fn(u64) -> Duration = Duration::from_millis;

#[tokio::test(start_paused = true)]
async fn a_stalled_crane_is_lost_after_exactly_the_timeout_and_found_when_it_moves() {
    let mut rig = Rig::start(MS(50), |_| {});
    let (poll, timeout) = (MS(100), MS(10_000));
    rig.until("came online", MS(500), |s| s.online && s.crane.as_ref().is_some_and(|c| c.heartbeat_ok)).await;
    rig.polls(10).await;
    rig.engine(|e| e.heartbeat_on = false);
    let off = Instant::now();
    // Every poll sees the crane's word moved (heartbeat_ms = poll), so the last move rackd
    // saw is at the first poll from `off` on, and loss is judged at polls: lost at least
    // `timeout` after `off`, and at most one poll later.
    tokio::time::sleep_until(off + timeout - MS(1)).await;
    assert!(rig.status.borrow().online, "not lost 1 ms before the timeout");
    let lost = rig.until("lost the crane", timeout + poll + MS(1), |s| !s.online).await;
    assert!(lost >= off + timeout && lost <= off + timeout + poll, "lost after {:?}", lost - off);
    {
        let status = rig.status.borrow();
        assert_eq!(status.crane.as_ref().map(|c| c.heartbeat_ok), Some(false), "{status:?}");
        assert!(status.last_error.as_deref().is_some_and(|e| e.contains("heartbeat")), "{status:?}");
    }

    // No work for a lost crane, over 50 polls.
    let id = rig.queue(travel(at(2, 3, 1, 1)));
    rig.polls(50).await;
    assert_eq!(rig.job(id).state, JobState::Queued);
    assert!(rig.writes_to(8).is_empty(), "no task words written");
    assert_eq!(rig.engine_says(|e| e.received.len()), 0);

    // Back at the first poll after the crane answers (its next tick, 10 ms at most).
    rig.engine(|e| e.heartbeat_on = true);
    let on = Instant::now();
    let back = rig.until("found the crane again", MS(11) + poll, |s| s.online).await;
    assert!(back >= on && back <= on + MS(10) + poll, "back after {:?}", back - on);
    rig.until_job(id, JobState::Completed, Duration::from_secs(5)).await;
}

#[tokio::test(start_paused = true)]
async fn rackds_heartbeat_steps_no_faster_than_its_period() {
    let rig = Rig::start(MS(50), |d| {
        d.poll_ms = 10;
        d.heartbeat_ms = 250;
    });
    tokio::time::sleep(Duration::from_secs(5)).await;
    let writes = rig.writes_to(0);
    assert!((19..=21).contains(&writes.len()), "{} writes in 5 s", writes.len());
    for pair in writes.windows(2) {
        let gap = pair[1].0 - pair[0].0;
        // Never faster than the period; due at the first poll (10 ms) after it.
        assert!(gap >= MS(250) && gap <= MS(260), "D0 written {gap:?} apart");
        assert_ne!(pair[0].1, pair[1].1, "each write is the next step");
    }
}

#[tokio::test(start_paused = true)]
async fn the_cranes_watchdog_stays_quiet_while_rackd_runs_and_fires_once_it_stops() {
    let rig = Rig::start(MS(50), |_| {});
    let watchdog = MS(1000);
    rig.engine(|e| e.wcs_timeout = Some(watchdog));
    // Ten watchdog periods, looked at every millisecond.
    let start = Instant::now();
    while Instant::now() < start + 10 * watchdog {
        assert_eq!(rig.word(205), 0, "rackd's heartbeat keeps the watchdog quiet");
        tokio::time::sleep(MS(1)).await;
    }
    rig.stop_rackd();
    let last = rig.writes_to(0).last().expect("rackd wrote its heartbeat").0;
    while rig.word(205) != 7020 {
        assert!(Instant::now() <= last + watchdog + MS(10), "no 7020 by {:?}", Instant::now() - last);
        tokio::time::sleep(MS(1)).await;
    }
    // Raised at the first tick (10 ms) once D0 stood still for the watchdog's time.
    assert!(Instant::now() >= last + watchdog, "7020 after only {:?}", Instant::now() - last);
}
