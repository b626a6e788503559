//! The wall clock stepped an hour forward and an hour back (NTP after a long outage) while
//! the shelf and the crane run jobs: nothing is reordered, no alarm fires, the KPIs count
//! every job, and a standby does not take over (issue 53 item 4; what rackd does with the
//! wall clock is in `rackd::domain::time`).
//!
//! The clock is stepped with rackd's seam ([`rackd::domain::time::step_wall_clock`]),
//! which is process-wide: each test here runs [`alone`], in a process of its own (this
//! binary again, running that one test), so the other tests of the binary never see the
//! step.

mod standby;
mod steps;

use std::process::Command;

/// The variable that tells this binary, run again, that it runs `test` alone.
const ALONE: &str = "RACKD_TEST_ALONE";

/// An hour, in ms.
const HOUR: i64 = 3_600_000;

/// Runs `body` on a fresh runtime in a process of its own: this test binary started again
/// for the test `test` only (its path without the crate, `clock::steps::on_sqlite`).
/// Fails if that process fails, or ran no test (a name that no longer matches).
pub fn alone(test: &str, body: impl AsyncFnOnce()) {
    if std::env::var(ALONE).as_deref() == Ok(test) {
        let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
        rt.block_on(body());
        return;
    }
    let out = Command::new(std::env::current_exe().unwrap())
        .args([test, "--exact", "--nocapture", "--test-threads=1"])
        .env(ALONE, test)
        .output()
        .expect("the test binary starts again");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{test} failed in its own process:\n{stdout}\n{stderr}");
    assert!(stdout.contains("1 passed"), "{test} did not run in its own process:\n{stdout}");
}
