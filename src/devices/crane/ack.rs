//! Acknowledging the crane's completion states (20 done, 30 force-completed, 40 cancelled).
//!
//! The spec leaves the values of D22 (WCS) and D223 (crane) open. The reading chosen by
//! default ([`Ack::Handshake`]): the crane sets D223 (to the completion state) and
//! D203 to 20/30/40; rackd records the outcome, then sets D22 = 1; the crane clears D223
//! (and its task words); rackd clears D22. [`Ack::Echo`] is the other plausible
//! reading: rackd writes D223's value back into D22 and follows it to 0. In both, rackd
//! writes the acknowledgement only after the outcome is stored, so a crash in between
//! records the outcome again (a no-op) instead of losing it.
//!
//! A write of D22 whose reply never came may have landed or not. rackd then takes D22 as
//! unknown: it writes the word wanted again at the next poll, and hands no task over
//! until a write of 0 was answered; a 1 left standing would acknowledge the next task's
//! completion before rackd saw it, which rackd would take for a lost task (found by the
//! seeded wire simulation, `crane::wire`).

use crate::config::devices::Ack;

impl Ack {
    /// What to write to D22, if anything, given the crane's D223 and the D22 rackd last
    /// wrote (`None`: a write of it went unanswered, so it is not known: the word wanted is
    /// written again). Only call it once any completion shown has been recorded.
    pub fn next_word(self, completion: u16, written: Option<u16>) -> Option<u16> {
        let want = match self {
            Ack::Handshake => u16::from(completion != 0),
            Ack::Echo => completion,
        };
        (Some(want) != written).then_some(want)
    }
}

/// What a completion state means for the job.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// 20: done.
    Done,
    /// 30: completed by hand on the crane's panel.
    Forced,
    /// 40: cancelled.
    Cancelled,
}

impl Outcome {
    /// The outcome the crane shows: the action state (D203) if it is 20/30/40, else the
    /// completion word (D223) if it is.
    pub fn of(action: u16, completion: u16) -> Option<Outcome> {
        [action, completion].into_iter().find_map(|w| match w {
            20 => Some(Outcome::Done),
            30 => Some(Outcome::Forced),
            40 => Some(Outcome::Cancelled),
            _ => None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn handshake_sets_then_clears() {
        let r = Ack::Handshake;
        assert_eq!(r.next_word(20, Some(0)), Some(1));
        assert_eq!(r.next_word(20, Some(1)), None);
        assert_eq!(r.next_word(0, Some(1)), Some(0));
        assert_eq!(r.next_word(0, Some(0)), None);
        assert_eq!(r.next_word(0, None), Some(0), "a write of it went unanswered: written again");
    }

    #[test]
    fn echo_mirrors_the_completion_word() {
        let r = Ack::Echo;
        assert_eq!(r.next_word(30, Some(0)), Some(30));
        assert_eq!(r.next_word(30, Some(30)), None);
        assert_eq!(r.next_word(0, Some(30)), Some(0));
    }

    #[test]
    fn outcomes() {
        assert_eq!(Outcome::of(20, 20), Some(Outcome::Done));
        assert_eq!(Outcome::of(30, 0), Some(Outcome::Forced));
        assert_eq!(Outcome::of(0, 40), Some(Outcome::Cancelled));
        assert_eq!(Outcome::of(12, 0), None);
    }
}
