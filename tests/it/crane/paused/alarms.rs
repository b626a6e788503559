//! Alarms as the crane shows them, on paused time: shown in the status at the next poll,
//! a hardware alarm blocks new work and halts the task without failing it, a business alarm
//! cancels the task and fails the job with its code.

use std::time::Duration;

use rackd::domain::{AlarmClass, FailureKind, JobSpec, JobState, Reported};
use rackd::wire::alarms;
use tokio::time::Instant;

use super::{Rig, at, travel};

const MS: fn(u64) -> Duration = Duration::from_millis;
/// D205: the crane's alarm.
const ALARM: u32 = 205;

fn alarm_shown(code: u16) -> impl Fn(&rackd::devices::DeviceStatus) -> bool {
    move |s| s.crane.as_ref().is_some_and(|c| c.alarm_code == Some(code))
}

#[tokio::test(start_paused = true)]
async fn a_hardware_alarm_shows_at_the_next_poll_and_blocks_new_work_until_cleared() {
    let mut rig = Rig::start(MS(50), |_| {});
    let poll = MS(100);
    rig.until("came online", MS(500), |s| s.online).await;
    rig.set_word(ALARM, 7002);
    let raised = Instant::now();
    let shown = rig.until("showed the alarm", poll + MS(1), alarm_shown(7002)).await;
    assert!(shown - raised <= poll);
    {
        let status = rig.status.borrow();
        let crane = status.crane.as_ref().unwrap();
        assert_eq!(crane.alarm_class, Some(AlarmClass::Hardware));
        assert_eq!(crane.alarm_text.as_deref(), Some(alarms::lookup(7002).text.as_str()));
        assert!(status.online, "an alarm is not a lost link");
    }
    let id = rig.queue(travel(at(1, 4, 2, 1)));
    rig.polls(100).await;
    assert_eq!(rig.job(id).state, JobState::Queued, "no new work under a hardware alarm");
    assert!(rig.writes_to(8).is_empty() && rig.writes_to(21).is_empty(), "nothing handed over");
    rig.set_word(ALARM, 0);
    rig.until("cleared the alarm", poll + MS(1), |s| {
        s.crane.as_ref().is_some_and(|c| c.alarm_code.is_none())
    })
    .await;
    rig.until_job(id, JobState::Completed, Duration::from_secs(5)).await;
}

#[tokio::test(start_paused = true)]
async fn a_hardware_alarm_mid_task_halts_the_crane_and_fails_nothing() {
    let mut rig = Rig::start(MS(50), |_| {});
    let id = rig.queue(JobSpec::Retrieve { from: at(2, 11, 7, 1) });
    rig.until_job(id, JobState::Running, Duration::from_secs(2)).await;
    rig.set_word(ALARM, 7011);
    let halted = rig.word(203);
    rig.until("showed the alarm", MS(101), alarm_shown(7011)).await;
    // 100 polls: 10 s, 200 of the crane's 50 ms steps.
    rig.polls(100).await;
    assert_eq!(rig.word(203), halted, "the crane stands still");
    assert_eq!(rig.job(id).state, JobState::Running, "a hardware alarm fails nothing by itself");
    assert_eq!(rig.engine_says(|e| e.cancels), 0, "no cancel for a hardware alarm");
    rig.set_word(ALARM, 0);
    rig.until_job(id, JobState::Completed, Duration::from_secs(5)).await;
}

#[tokio::test(start_paused = true)]
async fn a_business_alarm_cancels_the_task_and_fails_the_job_with_its_code() {
    let rig = Rig::start(MS(50), |_| {});
    let code = alarms::business_codes().next().expect("a business alarm");
    let id = rig.queue(JobSpec::Store { to: at(1, 4, 2, 1) });
    rig.until_job(id, JobState::Running, Duration::from_secs(2)).await;
    rig.set_word(ALARM, code);
    // The cancel is handed over at the next poll; the crane ends the task in 40 and the job
    // fails with the alarm once that is seen.
    rig.until_job(id, JobState::Failed, Duration::from_secs(2)).await;
    let failure = rig.job(id).failure.expect("a failure");
    assert_eq!((failure.kind, failure.code), (FailureKind::Alarm, Some(i64::from(code))));
    assert_eq!(failure.text, alarms::lookup(code).text);
    assert_eq!(rig.engine_says(|e| e.cancels), 1);
    assert!(rig.reports(id).contains(&Reported::Cancelling), "{:?}", rig.reports(id));
    assert_eq!(rig.word(ALARM), 0, "the crane cleared the alarm with the cancel");
}
