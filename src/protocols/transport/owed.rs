//! What a link whose replies name no request may still receive, and what must happen before
//! its next request goes out: the one rule of every such link, whatever its protocol
//! (the argument is in the transport's module documentation, "Links whose replies name no
//! request").
//!
//! [`Owed`] is plain bookkeeping, kept by both link kinds ([`super::StreamLink`],
//! [`super::DatagramLink`]): a request sent and not answered, a timeout, a retry or a reply
//! that was not the request's leave a reply owed; [`Owed::before_send`] says whether the
//! link may send at once, must replace its carrier, or must wait for silence.

use std::time::Duration;

use tokio::time::Instant;

use crate::protocols::Replies;

/// How a link keeps a late reply from passing for the next request's answer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Guard {
    /// Replies name their request ([`Replies::Named`]): ids do it, the link does nothing.
    Ids,
    /// A new carrier carries nothing of the old: a TCP connection the device itself ends
    /// (Modbus TCP, MC 3E), a UDP socket on a new ephemeral port (the old one is kept
    /// bound until every reply owed to it is past, so no one else gets its port).
    Replace,
    /// Only silence does: a serial line, a TCP connection to a serial gateway (which hands
    /// whatever the line brings to whichever connection is open), a UDP socket on a fixed
    /// local port.
    Wait,
}

impl Guard {
    /// The guard of a link with these `replies`, on a carrier that a new one replaces
    /// exactly (`fresh`) or not.
    pub fn of(replies: Replies, fresh: bool) -> Guard {
        match (replies, fresh) {
            (Replies::Named, _) => Guard::Ids,
            (Replies::Unnamed, true) => Guard::Replace,
            (Replies::Unnamed, false) => Guard::Wait,
        }
    }
}

/// What the link must do before its next send.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Clear {
    /// Nothing is owed (or ids tell replies apart): send.
    Nothing,
    /// Open a new carrier first.
    Replace,
    /// Hold the line until it has been quiet for the reply lifetime.
    Wait,
}

/// The replies a link may still receive.
#[derive(Debug)]
pub(crate) struct Owed {
    guard: Guard,
    /// The carrier may bring frames that another process (a rackd before a restart, on a
    /// serial line, a gateway or a reused UDP port) asked for: only silence clears that.
    cold: bool,
    /// An attempt timed out, a retry went out, or a reply that was not the request's came:
    /// another may follow.
    unsettled: bool,
    /// A request went out and its answer was not taken (it timed out, failed, or its
    /// caller gave up on it).
    pending: bool,
    /// When anything was last sent or received.
    last_io: Instant,
    /// When the last request went out.
    last_send: Instant,
}

impl Owed {
    /// Nothing sent yet. A link starts `cold` when its carrier can bring another process's
    /// frames (every link under [`Guard::Wait`], and datagram links: a new ephemeral port
    /// may be one a rackd before a restart used); a new TCP connection cannot.
    pub fn new(guard: Guard, cold: bool) -> Owed {
        let now = Instant::now();
        Owed {
            guard,
            cold: cold && guard != Guard::Ids,
            unsettled: false,
            pending: false,
            last_io: now,
            last_send: now,
        }
    }

    /// The link's guard.
    pub fn guard(&self) -> Guard {
        self.guard
    }

    /// An attempt went out now; `retry` if it is not its request's first. On a carrier
    /// that only silence clears, a retry leaves the link unsettled even once answered: the
    /// answer taken may be the first attempt's, come late, and the retry's own may follow.
    /// Holding once more before the next request drains it, so a reply up to about twice
    /// the lifetime late is still not taken for another request's answer.
    pub fn sent(&mut self, retry: bool) {
        let now = Instant::now();
        self.unsettled |= retry && self.guard == Guard::Wait;
        self.pending = true;
        self.last_io = now;
        self.last_send = now;
    }

    /// Something arrived now.
    pub fn received(&mut self) {
        self.last_io = Instant::now();
    }

    /// The answer to the last request was taken.
    pub fn answered(&mut self) {
        self.pending = false;
    }

    /// A reply that was not the request's came, or an attempt timed out: more may follow.
    pub fn unsettle(&mut self) {
        self.unsettled = true;
    }

    /// Whether a reply may still come that the next request must not take.
    pub fn owes(&self) -> bool {
        self.cold || self.unsettled || self.pending
    }

    /// What must happen before the next send.
    pub fn before_send(&self) -> Clear {
        match self.guard {
            Guard::Ids => Clear::Nothing,
            _ if !self.owes() => Clear::Nothing,
            Guard::Replace if !self.cold => Clear::Replace,
            Guard::Replace | Guard::Wait => Clear::Wait,
        }
    }

    /// The carrier was replaced, or the line held quiet: nothing earlier can arrive.
    pub fn cleared(&mut self) {
        self.cold = false;
        self.unsettled = false;
        self.pending = false;
    }

    /// The carrier was lost and will be reopened: a new connection under
    /// [`Guard::Replace`] carries nothing late; a reopened line or gateway connection may.
    pub fn reopened(&mut self) {
        if self.guard == Guard::Replace {
            self.cleared();
        }
    }

    /// When the line counts as quiet: `lifetime` after the last thing sent or received.
    pub fn quiet_at(&self, lifetime: Duration) -> Instant {
        self.last_io + lifetime
    }

    /// When every reply owed to the last request is past: `lifetime` after it went out.
    pub fn past_at(&self, lifetime: Duration) -> Instant {
        self.last_send + lifetime
    }

    /// When anything was last sent or received.
    pub fn last_io(&self) -> Instant {
        self.last_io
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_clean_exchange_owes_nothing_and_a_troubled_one_clears_by_its_guard() {
        let mut owed = Owed::new(Guard::Replace, false);
        assert_eq!(owed.before_send(), Clear::Nothing, "a new TCP connection");
        owed.sent(false);
        owed.answered();
        assert_eq!(owed.before_send(), Clear::Nothing, "one request, one reply");
        owed.sent(false);
        assert_eq!(owed.before_send(), Clear::Replace, "not answered: its reply may come");
        owed.cleared();
        owed.sent(true);
        owed.answered();
        assert_eq!(owed.before_send(), Clear::Nothing, "a retry on a new carrier owes nothing once answered");
        owed.sent(false);
        owed.answered();
        owed.unsettle();
        assert_eq!(owed.before_send(), Clear::Replace, "a reply that was not the request's");
        owed.reopened();
        assert_eq!(owed.before_send(), Clear::Nothing, "a new connection carries nothing late");

        let mut line = Owed::new(Guard::Wait, true);
        assert_eq!(line.before_send(), Clear::Wait, "a line may bring a previous process's reply");
        line.cleared();
        line.sent(true);
        line.answered();
        assert_eq!(line.before_send(), Clear::Wait, "a retry answered: the other answer may follow");
        line.cleared();
        line.sent(false);
        line.reopened();
        assert_eq!(line.before_send(), Clear::Wait, "a reopened line may bring the late reply");

        let udp = Owed::new(Guard::Replace, true);
        assert_eq!(udp.before_send(), Clear::Wait, "a fresh port may be a previous process's");
        let mut ids = Owed::new(Guard::Ids, true);
        ids.sent(true);
        ids.unsettle();
        assert_eq!(ids.before_send(), Clear::Nothing, "ids tell replies apart");
    }
}
