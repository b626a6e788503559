//! Waiting for something to happen, with a deadline: one [`eventually`] in place of a
//! hand-written loop in every test.
//!
//! The probe is asked again every [`EVERY`] (or as often as the caller says) until it answers, and the test fails after
//! `within` with what it waited for and the probe's last answer. Time is tokio's, so a test
//! on paused time waits on its own clock.

use std::fmt::{Debug, Display};
use std::time::Duration;

/// How often the probe is asked again.
pub const EVERY: Duration = Duration::from_millis(10);

/// What a probe answers: done (with a value), or not yet (with what it saw, for the message).
pub trait Outcome<T> {
    /// `Ok` when the wait is over; `Err` with the last thing seen otherwise.
    fn done(self) -> Result<T, String>;
}

impl Outcome<()> for bool {
    fn done(self) -> Result<(), String> {
        if self { Ok(()) } else { Err("false".to_owned()) }
    }
}

impl<T> Outcome<T> for Option<T> {
    fn done(self) -> Result<T, String> {
        self.ok_or_else(|| "nothing yet".to_owned())
    }
}

impl<T, E: Debug> Outcome<T> for Result<T, E> {
    fn done(self) -> Result<T, String> {
        self.map_err(|e| format!("{e:?}"))
    }
}

/// Asks `probe` until it answers done, at most for `within`; panics after that, naming
/// `what` and the probe's last answer.
pub async fn eventually<T, O: Outcome<T>>(
    what: impl Display,
    within: Duration,
    probe: impl AsyncFnMut() -> O,
) -> T {
    eventually_every(EVERY, what, within, probe).await
}

/// [`eventually`], asking every `every`: more often for a probe that watches a fast
/// machine word change, less often for one that costs more than a request.
pub async fn eventually_every<T, O: Outcome<T>>(
    every: Duration,
    what: impl Display,
    within: Duration,
    probe: impl AsyncFnMut() -> O,
) -> T {
    try_eventually_every(every, what, within, probe).await.unwrap_or_else(|message| panic!("{message}"))
}

/// [`eventually_every`] for a caller with something to do before it fails (a screenshot,
/// say): the failure's message instead of a panic.
pub async fn try_eventually_every<T, O: Outcome<T>>(
    every: Duration,
    what: impl Display,
    within: Duration,
    mut probe: impl AsyncFnMut() -> O,
) -> Result<T, String> {
    let deadline = tokio::time::Instant::now() + within;
    loop {
        let last = match probe().await.done() {
            Ok(value) => return Ok(value),
            Err(last) => last,
        };
        if tokio::time::Instant::now() >= deadline {
            return Err(format!("waited {within:?} for {what}; last seen: {last}"));
        }
        tokio::time::sleep(every).await;
    }
}

/// [`eventually`] for a test without a runtime (one that runs `rackd` as a process):
/// the same probe, on the thread's own clock.
pub fn eventually_blocking<T, O: Outcome<T>>(
    what: impl Display,
    within: Duration,
    mut probe: impl FnMut() -> O,
) -> T {
    let deadline = std::time::Instant::now() + within;
    loop {
        let last = match probe().done() {
            Ok(value) => return value,
            Err(last) => last,
        };
        assert!(std::time::Instant::now() < deadline, "waited {within:?} for {what}; last seen: {last}");
        std::thread::sleep(EVERY);
    }
}

#[tokio::test(start_paused = true)]
async fn eventually_waits_for_the_probe_and_says_what_it_saw() {
    let mut asked = 0;
    let got = eventually("the third ask", Duration::from_secs(1), async || {
        asked += 1;
        (asked == 3).then_some(asked)
    })
    .await;
    assert_eq!(got, 3);

    let failed =
        tokio::spawn(eventually("a count of 5", Duration::from_millis(100), async || Err::<(), _>("only 4")));
    let message = *failed.await.unwrap_err().into_panic().downcast::<String>().unwrap();
    assert!(message.contains("a count of 5") && message.contains("only 4"), "{message}");
}
