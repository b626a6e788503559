//! Repeated device errors, logged without flooding.
//!
//! An unreachable PLC fails every attempt for as long as it is away: five polls a second
//! at the default period, each a WARN line, forever. Per device, rackd logs instead:
//! - the first failure in full (WARN);
//! - while failures go on, one summary line per interval (WARN) with how many there were
//!   since the last line, how long the outage lasts and the last error;
//! - when the device works again, one line (INFO) with the outage's count and length.
//!
//! Decisions where the spec is silent:
//! - One limiter per device, whatever the error: a device failing in alternating ways is one
//!   outage to the person reading the log, and a count per message would flood again.
//! - At most one WARN line per device per interval, also across outages: a device that
//!   flaps (fails, answers, fails again within the interval) does not log a pair of lines
//!   per flap. An outage that starts less than an interval after the last line is
//!   announced only when the interval is over (its failures are counted in that line);
//!   if it ends sooner, its end is logged at DEBUG and its failures are carried into the
//!   next line.
//! - The interval is [`SUMMARY_EVERY`], one minute: enough to see that an outage goes on,
//!   few enough lines that three offline devices fill no disk.
//!
//! The device's id is not a field here: the device task runs in a `device` span that
//! carries it (see `devices::start`), as every line the task logs does.

use std::fmt::Display;
use std::time::Duration;

use tokio::time::Instant;

/// The longest a device stays silent while it keeps failing.
pub const SUMMARY_EVERY: Duration = Duration::from_secs(60);

/// A device's repeated-failure log.
#[derive(Debug)]
pub struct Repeats {
    every: Duration,
    outage: Option<Outage>,
    /// When the last WARN or INFO line of this limiter was written.
    last_line: Option<Instant>,
    /// Failures not yet counted in a line.
    unreported: u64,
}

#[derive(Debug)]
struct Outage {
    since: Instant,
    failures: u64,
    announced: bool,
    last_error: String,
}

impl Default for Repeats {
    fn default() -> Self {
        Repeats::every(SUMMARY_EVERY)
    }
}

impl Repeats {
    /// A limiter that writes at most one WARN line per `every`.
    pub fn every(every: Duration) -> Self {
        Repeats { every, outage: None, last_line: None, unreported: 0 }
    }

    /// One failure: `what` failed with `error`.
    pub fn failed(&mut self, what: &str, error: &dyn Display) {
        let now = Instant::now();
        let outage = self.outage.get_or_insert_with(|| Outage {
            since: now,
            failures: 0,
            announced: false,
            last_error: String::new(),
        });
        outage.failures += 1;
        outage.last_error = format!("{what}: {error}");
        self.unreported += 1;
        if self.last_line.is_some_and(|at| now - at < self.every) {
            return;
        }
        let outage_s = (now - outage.since).as_secs();
        if outage.announced {
            tracing::warn!(
                failures = self.unreported,
                outage_s,
                last_error = %outage.last_error,
                "still failing: {} more failures in the last {} s",
                self.unreported,
                self.last_line.map_or(0, |at| (now - at).as_secs()),
            );
        } else {
            let earlier = self.unreported - 1;
            if earlier > 0 {
                tracing::warn!(error = %error, earlier_failures = earlier, outage_s, "{what}");
            } else {
                tracing::warn!(error = %error, "{what}");
            }
            outage.announced = true;
        }
        self.unreported = 0;
        self.last_line = Some(now);
    }

    /// The device worked: ends an outage, if there is one.
    pub fn recovered(&mut self) {
        let Some(outage) = self.outage.take() else { return };
        let now = Instant::now();
        let outage_s = (now - outage.since).as_secs_f64();
        if outage.announced {
            tracing::info!(
                failures = outage.failures,
                outage_s = format_args!("{outage_s:.1}"),
                "working again after {} failures over {outage_s:.1} s",
                outage.failures,
            );
            self.unreported = 0;
            self.last_line = Some(now);
        } else {
            tracing::debug!(failures = outage.failures, "working again after a short outage");
        }
    }

    /// Whether an outage is under way.
    pub fn failing(&self) -> bool {
        self.outage.is_some()
    }
}

#[cfg(test)]
mod tests;
