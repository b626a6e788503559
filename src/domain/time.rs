//! Times as stored (Unix milliseconds) and as shown (RFC 3339), and the one clock rackd
//! stamps them with.
//!
//! # Two clocks, and which one does what
//!
//! **Every timer runs on the monotonic clock** (`tokio::time::Instant`, `std::time::Instant`),
//! which a step of the wall clock (NTP after a long outage, an operator's `date -s`) does not
//! move: poll periods, request timeouts and retries, the crane's heartbeat (`devices::crane`:
//! lost after `heartbeat_timeout_ms` of a still D200, by `Instant`), the link alarm (failed
//! polls are counted, not timed), the hot standby's lease (`service::cluster`: the active
//! node's term and a standby's wait are both on the node's own monotonic clock; the
//! database's `clock_timestamp()` is only written to `renewed_at` and `seen_at` for display,
//! and nothing compares it with anything), the webhook retry backoff and its
//! `alarm_after_secs` (`service::webhooks::deliver`), the serve loop's deadlines and the
//! capture recorder's offsets. **The event log is ordered by `seq`**, numbered by the writer
//! in memory; no query orders events by time.
//!
//! **The wall clock is read through [`now_ms`]** (and [`now`]) for what needs a date:
//! - the writer's stamp on each commit group: jobs' `created_at`/`updated_at`, their history,
//!   events' `time`, alarms' `raised_at`/`cleared_at`, and the rollups' buckets (a job counts
//!   in the bucket of its recorded end);
//! - the end of a period read (`GET /api/v1/stats`, `GET /api/v1/alarms`), and a relative
//!   `since` (`since=8h`);
//! - what is shown: a device's `last_contact`, `last_error_at`, `memory_lost_at`,
//!   `heartbeat_stalled_since`, a pause's `at`, a node's `started_at`, a webhook's
//!   `last_ok_at`, `failing_since` and its signature's timestamp;
//! - how old is old, where a day is the unit: retention and the archive's days
//!   (`app::drive`), capture files' age (their mtimes are the OS's wall clock, so those read
//!   `SystemTime` directly), a certificate's expiry (`app::serve::certificate`: wall time
//!   by nature). A step of an hour moves these by an hour against days: accepted.
//!
//! # The stamp never runs backward
//!
//! Stored times are compared with the order of ids: a page of jobs or alarms by period
//! (`created_from`, `since`) is found as a range of ids, which holds only if a later id never
//! has an earlier time; a duration is a completion's stamp minus its dispatch's; a period
//! `[since, now]` must hold everything committed so far. So [`now_ms`] is the wall clock
//! **except that it never goes back**: when the wall clock steps back, the stamp runs on
//! from where it was at nine tenths of the monotonic clock's pace until the wall clock
//! catches up (a *smear*, as NTP's slew and Google's leap smear; an hour back is smeared in
//! ten hours). A step forward is taken at once: times stay in order, and the new time is
//! what NTP says is right.
//!
//! What "the right bucket" means, then: a job counts in the bucket of its own recorded end,
//! the stamp its completion was committed with. A job that ended just before a step back
//! keeps its bucket; those after it land in the same or later buckets, never earlier, and
//! `GET /api/v1/stats` over the last hours counts them all. A job that ran across a step
//! forward of an hour shows an hour longer (its stamps are all there is after a restart);
//! across a step back, up to a tenth shorter. The smear is per process: two cluster nodes
//! stamp with their own clocks, as they always did.
//!
//! # Across a restart
//!
//! The last stamp is kept in memory, so a process started after the wall clock stepped
//! back (rackd restarted, or the machine rebooted, during the hour NTP took back) would
//! stamp from the wall clock again, before what the store already holds. So the job writer
//! reads the newest stamp in the store when it starts and calls [`not_before`]: the stamp
//! then smears on from there, as in a process that never stopped.
//!
//! # The seam
//!
//! [`step_wall_clock`] moves this process's wall clock as NTP would, for tests: everything
//! that reads the wall clock for rackd reads it here. Left outside on purpose: a
//! certificate's expiry and capture files' age (the system's own clock is the one that
//! counts there), and `rackd plc poll`'s printed times (a command line tool, no store).
//! The seam is process-wide: a test that steps it runs in a process of its own
//! (`tests/it/clock`). [`forget_stamps`] forgets the last stamp, as a new process starts
//! without it, for a test of a restart in one process.

use std::sync::Mutex;
use std::sync::atomic::{AtomicI64, Ordering};
use std::time::Instant;

use time::OffsetDateTime;

/// What tests stepped this process's wall clock by, ms.
static STEPPED: AtomicI64 = AtomicI64::new(0);

/// The last stamp handed out, and the smear under way, if any.
static STAMP: Mutex<Stamp> = Mutex::new(Stamp { last: i64::MIN, smear: None });

/// Now, in Unix milliseconds: the wall clock, never going back (see the module doc).
pub fn now_ms() -> i64 {
    let wall = wall_ms();
    STAMP.lock().unwrap_or_else(|p| p.into_inner()).next(wall, Instant::now())
}

/// Now, as a date-time: [`now_ms`].
pub fn now() -> OffsetDateTime {
    from_ms(now_ms())
}

/// The wall clock as it reads, stepped or not: for what must agree with the system's own
/// times (files' mtimes), not for stamps.
pub fn wall_ms() -> i64 {
    let os = (OffsetDateTime::now_utc().unix_timestamp_nanos() / 1_000_000) as i64;
    os.saturating_add(STEPPED.load(Ordering::Relaxed))
}

/// Steps this process's wall clock by `ms` (negative: back), as NTP does after a long outage.
/// For tests: nothing in rackd calls it.
pub fn step_wall_clock(ms: i64) {
    STEPPED.fetch_add(ms, Ordering::Relaxed);
}

/// Stamps from now on are no earlier than `ms` (the newest stamp in the store, read as the
/// writer starts; see "Across a restart" in the module doc).
pub fn not_before(ms: i64) {
    let mut stamp = STAMP.lock().unwrap_or_else(|p| p.into_inner());
    if stamp.last < ms {
        stamp.last = ms;
        stamp.smear = None;
    }
}

/// Forgets the last stamp, as a process starts without it: for tests of a restart in one
/// process (see the module doc's seam).
pub fn forget_stamps() {
    *STAMP.lock().unwrap_or_else(|p| p.into_inner()) = Stamp { last: i64::MIN, smear: None };
}

/// A stored time as a date-time; out-of-range values clamp to the epoch.
pub fn from_ms(ms: i64) -> OffsetDateTime {
    OffsetDateTime::from_unix_timestamp_nanos(ms as i128 * 1_000_000).unwrap_or(OffsetDateTime::UNIX_EPOCH)
}

/// A date-time as stored.
pub fn to_ms(t: OffsetDateTime) -> i64 {
    (t.unix_timestamp_nanos() / 1_000_000) as i64
}

/// The stamp's state: the last one handed out, and where a smear started.
#[derive(Clone, Copy, Debug)]
struct Stamp {
    last: i64,
    /// The stamp and the monotonic instant a smear started from.
    smear: Option<(i64, Instant)>,
}

impl Stamp {
    /// The stamp for a wall clock reading `wall` at monotonic `mono`.
    fn next(&mut self, wall: i64, mono: Instant) -> i64 {
        if wall >= self.last {
            self.smear = None;
        } else {
            let (from, at) = *self.smear.get_or_insert((self.last, mono));
            let ran = mono.saturating_duration_since(at).as_millis() as i64;
            let smeared = from.saturating_add(ran.saturating_mul(9) / 10);
            if wall < smeared {
                self.last = self.last.max(smeared);
                return self.last;
            }
            self.smear = None;
        }
        self.last = wall;
        wall
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    const HOUR: i64 = 3_600_000;

    #[test]
    fn the_stamp_follows_the_wall_clock_and_takes_a_step_forward_at_once() {
        let mono = Instant::now();
        let mut s = Stamp { last: i64::MIN, smear: None };
        assert_eq!(s.next(1_000, mono), 1_000);
        assert_eq!(s.next(1_500, mono + Duration::from_millis(500)), 1_500);
        assert_eq!(s.next(1_500 + HOUR, mono + Duration::from_millis(600)), 1_500 + HOUR);
    }

    #[test]
    fn a_step_back_is_smeared_at_nine_tenths_until_the_wall_clock_catches_up() {
        let mono = Instant::now();
        let at = |ms: u64| mono + Duration::from_millis(ms);
        let mut s = Stamp { last: i64::MIN, smear: None };
        let t = 10 * HOUR;
        assert_eq!(s.next(t, at(0)), t);
        // Stepped back an hour: the stamp stays, then runs on at 9/10 of the pace.
        assert_eq!(s.next(t - HOUR, at(0)), t);
        assert_eq!(s.next(t - HOUR + 1, at(1)), t, "never back, even by the rounding");
        assert_eq!(s.next(t - HOUR + 1_000, at(1_000)), t + 900);
        assert_eq!(s.next(t - HOUR + 1_005, at(1_005)), t + 904);
        // Ten hours on, the wall clock has caught up and is followed again.
        let ten = 10 * HOUR as u64;
        assert_eq!(s.next(t + 9 * HOUR, at(ten)), t + 9 * HOUR);
        assert_eq!(s.smear, None);
        assert_eq!(s.next(t + 9 * HOUR + 1, at(ten + 1)), t + 9 * HOUR + 1);
    }

    #[test]
    fn a_step_forward_ends_a_smear() {
        let mono = Instant::now();
        let mut s = Stamp { last: i64::MIN, smear: None };
        assert_eq!(s.next(5 * HOUR, mono), 5 * HOUR);
        assert_eq!(s.next(4 * HOUR, mono + Duration::from_secs(1)), 5 * HOUR);
        assert_eq!(s.next(5 * HOUR + 2_000, mono + Duration::from_secs(2)), 5 * HOUR + 2_000);
        assert_eq!(s.smear, None);
    }

    #[test]
    fn stamps_never_run_backward_whatever_the_wall_clock_does() {
        let mono = Instant::now();
        let mut s = Stamp { last: i64::MIN, smear: None };
        let mut last = i64::MIN;
        let walls = [100, 90, 95, 3_000, 2_000, 2_001, 10, 5_000, 4_999];
        for (i, wall) in walls.into_iter().enumerate() {
            let got = s.next(wall, mono + Duration::from_millis(i as u64 * 7));
            assert!(got >= last, "{got} after {last}");
            last = got;
        }
    }
}
