//! Replaying a capture into a live rackd: the device's side of a recorded conversation,
//! played back over UDP or TCP, so that a site's problem reproduces in the lab
//! (`rackd sim replay FILE.pcapng`). Each request rackd sends is matched to a recorded one
//! and answered with what the device answered then, as late as it was then; requests
//! that do not follow the recording are logged with their bytes, counted and reported.
//!
//! The parts: [`dialect`] (what the replay knows of a protocol), [`script`] (a capture as
//! requests and their replies), [`matcher`] (which recorded request a live one is: pure
//! logic, tested alone), [`server`] (the sockets).
//!
//! # Matching
//! rackd's timing is never the recording's: it polls a few more or a few fewer times, and
//! its job may come a little earlier or later. Polls return different answers over time
//! for the same bytes (a crane's heartbeat D200 moves while rackd reads D200..D239 again
//! and again), so a read cannot be matched by its bytes alone, nor by counting; what it
//! must get is the device's answer *as of the same point of the conversation*. The points
//! that tie two runs together are rackd's writes: the device reacts to them, rackd makes
//! them in reaction to what it read.
//!
//! - **Writes in order.** The recorded writes are taken one after the other: a live write
//!   takes the first one not yet made (the write *due*). A write identical to the last
//!   one taken is a retry and gets the same answer again. A write identical to one passed
//!   over earlier (owed) takes it. A write found a little further on (at most the reorder
//!   tolerance, 100 ms by default, after the write due, in the recording's time) is taken
//!   out of order, and the writes passed stay owed: two writes made in the same poll cycle
//!   (a heartbeat answer and a task's words) may come either way round. A write found
//!   only further on is *skipped to*: a divergence.
//! - **A clock for reads.** Each write taken sets an anchor: its recorded time and the
//!   live time it came. The replay clock is the anchor's recorded time plus the live time
//!   since, and it stops at the write due: the device never shows what followed a write
//!   rackd has not made. A read gets the latest recorded occurrence of the same bytes at or
//!   before the clock (the device's state then; never an answer from its future), or
//!   failing that the first one before the write due. So a late ACK stays late: after the
//!   strobe, rackd reads ACK = 0 for as long after its strobe as the crane took in the
//!   recording; extra or missing polls only read the same state more or fewer times; and
//!   a rackd slower to send its task sees the idle crane until it does. A read found only
//!   after the write due, within the reorder tolerance of it, is answered as recorded
//!   there and leaves the clock alone (rackd checked the crane's ACK before it answered
//!   the heartbeat, this time); further on, it is skipped to (a divergence), moving the
//!   anchor there.
//! - **Writes already in place.** The replay keeps what rackd wrote live to each place (for
//!   writes that name one place and then data: MC batch writes, Modbus 5, 6, 15, 16). A
//!   recorded write due whose data the device already holds is taken as made once the
//!   clock reaches it, counted as `in_place`: rackd has nothing to write there and the
//!   device could not tell. So a heartbeat whose step rackd missed (it answered the
//!   crane's 0 with 1, then started a hand-over a poll earlier than at the site and never
//!   read the crane's 1) does not stop the clock at a D0 := 1 rackd already made: the
//!   crane's word moves on, and so does rackd. The decision: the device is taken to act on
//!   what it holds, not on being written the same value again.
//! - **Ids.** Bytes that legitimately differ between runs are left out of the comparison
//!   and copied into the answer: the Modbus transaction id (MBAP, TCP and UDP) and the MC
//!   4E serial number; a stale reply carries the live id of the request its recorded id
//!   belonged to. MC 3E has no id; anything else is compared byte for byte.
//! - **Replies as they were.** Every frame the device sent after a request until rackd's
//!   next one is its answer, sent with the recorded delay: a late reply stays late, a
//!   reply rackd dropped or took as stale is sent again as it was, and a request the
//!   device did not answer gets no answer.
//! - **Divergence.** A request matched nowhere in order is logged (a warning with the
//!   bytes got and the recorded write due, in hex) and counted; it is answered
//!   by skipping ahead when its bytes come later in the recording, else not at all.
//! - **After the recording.** Once every recorded write is made and the clock has passed
//!   the last request, a request gets the last answer to identical bytes (a poll of
//!   registers that no longer change), counted as repeated: rackd stays connected and the
//!   state it ended in can be looked at; bytes never recorded get no answer.
//!
//! What this cannot do: replay a conversation whose start was not recorded (rackd's own
//! start-up reads are expected first), or make rackd send what it did not (a job must be
//! posted as it was at the site); serial captures are refused (the replay serves UDP and
//! TCP).

pub mod dialect;
pub mod matcher;
pub mod script;
pub mod server;

use std::fmt;
use std::time::Duration;

pub use matcher::{Counters, Request, Taken};
pub use script::{Script, ScriptError};
pub use server::ReplayServer;

/// The default reorder tolerance: two writes this close in the recording may come either
/// way round.
pub const DEFAULT_REORDER: Duration = Duration::from_millis(100);

/// A request that did not follow the recording.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Divergence {
    /// When, since the replay's first request.
    pub at: Duration,
    /// The live request's bytes.
    pub got: Vec<u8>,
    /// The recorded write the replay was waiting for, if any.
    pub expected: Option<Vec<u8>>,
    /// Skipped to, or not answered.
    pub taken: Taken,
}

/// At most this many divergences are kept for the report (all are counted and logged).
pub const KEPT_DIVERGENCES: usize = 100;

/// What a replay did.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Report {
    /// Requests in the recording.
    pub recorded: usize,
    /// How the live requests were taken.
    pub counters: Counters,
    /// Recorded writes that rackd never made, passed over.
    pub passed_over: usize,
    /// Recorded writes not reached.
    pub not_reached: usize,
    /// The first divergences.
    pub divergences: Vec<Divergence>,
}

impl fmt::Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = &self.counters;
        writeln!(
            f,
            "replay of {} recorded requests: {} matched, {} reordered, {} repeated, {} skipped, {} unanswered ({} diverged)",
            self.recorded,
            c.matched,
            c.reordered,
            c.repeated,
            c.skipped,
            c.unanswered,
            c.diverged()
        )?;
        write!(
            f,
            "recorded writes not made: {} passed over, {} not reached; {} already held by the device",
            self.passed_over, self.not_reached, c.in_place
        )?;
        for d in &self.divergences {
            let expected = d.expected.as_deref().map_or("nothing".into(), hex_bytes);
            let taken = if d.taken == Taken::Skipped { "skipped ahead" } else { "not answered" };
            write!(
                f,
                "\ndivergence at {:.3} s ({taken}): got {}, expected {expected}",
                d.at.as_secs_f64(),
                hex_bytes(&d.got)
            )?;
        }
        Ok(())
    }
}

/// Bytes as spaced hex pairs, as a protocol's manual prints them.
pub fn hex_bytes(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02X}")).collect::<Vec<_>>().join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_report_names_counts_and_divergences() {
        let report = Report {
            recorded: 10,
            counters: Counters {
                matched: 7,
                reordered: 1,
                repeated: 2,
                skipped: 1,
                unanswered: 1,
                in_place: 1,
            },
            passed_over: 1,
            not_reached: 0,
            divergences: vec![Divergence {
                at: Duration::from_millis(1500),
                got: vec![0x50, 0x00],
                expected: None,
                taken: Taken::Unanswered,
            }],
        };
        assert_eq!(
            report.to_string(),
            "replay of 10 recorded requests: 7 matched, 1 reordered, 2 repeated, 1 skipped, 1 unanswered (2 diverged)\n\
             recorded writes not made: 1 passed over, 0 not reached; 1 already held by the device\n\
             divergence at 1.500 s (not answered): got 50 00, expected nothing"
        );
    }
}
