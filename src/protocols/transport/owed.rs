//! What a link whose replies name no request may still receive, and what must happen before
//! its next request goes out: the one rule of every such link, whatever its protocol
//! (the argument is in the transport's module documentation, "Links whose replies name no
//! request").
//!
//! [`Owed`] is plain bookkeeping, kept by both link kinds ([`super::StreamLink`],
//! [`super::DatagramLink`]): a request sent and not answered, a timeout, a retry or a reply
//! that was not the request's leave a reply owed, and a write never answered may still be
//! on its way to the device; [`Owed::before_send`] says whether the link may send at once,
//! must replace its carrier, or must wait for silence.

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

/// The replies a link may still receive, and the writes that may still reach the device.
#[derive(Debug)]
pub(crate) struct Owed {
    guard: Guard,
    /// Datagrams: frames may overtake each other on the way.
    reorders: bool,
    /// Nothing was sent yet: a process before this one (a rackd killed and started again,
    /// a `rackd plc` stopped mid-write) may have requests and replies under way, which only
    /// time clears (see [`Owed::new`]).
    cold: bool,
    /// An attempt timed out, a retry went out, or a reply that was not the request's came:
    /// another may follow.
    unsettled: bool,
    /// A request went out and its answer was not taken (it timed out, failed, or its
    /// caller gave up on it).
    pending: bool,
    /// The attempt sent last is a write's.
    writing: bool,
    /// A write attempt went out and was never answered: it may still reach the device (see
    /// [`Owed::before_send`]).
    write_owed: bool,
    /// When anything was last sent or received.
    last_io: Instant,
    /// When the last request went out.
    last_send: Instant,
}

impl Owed {
    /// Nothing sent yet: the link starts *cold*, and its first request waits until the
    /// carrier has been quiet for the lifetime. A process before this one may have left
    /// requests under way to the device (rackd killed mid-write and started again): one
    /// that lands after this process read the device would undo what it then decides (a
    /// slot read empty, a task handed over again while the old write of it is still on
    /// its way). Its replies may also reach this one, on a line, through a gateway or on a
    /// reused UDP port. Whatever the guard and the carrier, one lifetime at start clears
    /// both. `reorders` for datagrams, whose frames may overtake each other.
    pub fn new(guard: Guard, reorders: bool) -> Owed {
        let now = Instant::now();
        Owed {
            guard,
            reorders,
            cold: true,
            unsettled: false,
            pending: false,
            writing: false,
            write_owed: false,
            last_io: now,
            last_send: now,
        }
    }

    /// The link's guard.
    pub fn guard(&self) -> Guard {
        self.guard
    }

    /// An attempt went out now; `retry` if it is not its request's first, `write` if the
    /// request writes. On a carrier that only silence clears, a retry leaves the link
    /// unsettled even once answered: the answer taken may be the first attempt's, come
    /// late, and the retry's own may follow. Holding once more before the next request
    /// drains it, so a reply up to about twice the lifetime late is still not taken for
    /// another request's answer.
    pub fn sent(&mut self, retry: bool, write: bool) {
        let now = Instant::now();
        self.unsettled |= retry && self.guard == Guard::Wait;
        self.write_owed |= self.pending && self.writing;
        self.writing = write;
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

    /// What must happen before the next send: the `first` attempt of its request, or a
    /// retry.
    ///
    /// Besides the replies, a write that was never answered may still be on its way to
    /// the device: applied after a later request, it would put back what that request
    /// changed, or what the device changed meanwhile (a late "state 0" into a slot the PLC
    /// has started). On a carrier that keeps its order (a line, one TCP connection) it
    /// cannot come after a later request; across a new connection or a new UDP port, and
    /// on datagrams at all, it can. So before the next *request* (a retry of the same write
    /// may go at once: it writes the same), such a link holds the line until the write's
    /// lifetime is past, instead of replacing the carrier; a link whose replies carry ids
    /// does the same on datagrams.
    pub fn before_send(&self, first: bool) -> Clear {
        let late_write = first && (self.write_owed || (self.pending && self.writing));
        match self.guard {
            Guard::Ids if self.cold || (late_write && self.reorders) => Clear::Wait,
            Guard::Ids => Clear::Nothing,
            _ if !self.owes() && !late_write => Clear::Nothing,
            Guard::Replace if !self.cold && !late_write => Clear::Replace,
            Guard::Replace | Guard::Wait => Clear::Wait,
        }
    }

    /// The carrier was replaced: no reply sent to the old one can arrive; a write sent on
    /// it may still reach the device.
    pub fn replaced(&mut self) {
        self.write_owed |= self.pending && self.writing;
        self.unsettled = false;
        self.pending = false;
    }

    /// The line was held quiet for the lifetime: nothing earlier can arrive, either way.
    pub fn cleared(&mut self) {
        self.cold = false;
        self.unsettled = false;
        self.pending = false;
        self.write_owed = false;
    }

    /// The carrier was lost and will be reopened: a new connection under
    /// [`Guard::Replace`] carries no reply of the old; a reopened line (or a gateway's
    /// connection to it) may.
    pub fn reopened(&mut self) {
        if self.guard == Guard::Replace {
            self.replaced();
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
        assert_eq!(
            owed.before_send(true),
            Clear::Wait,
            "a process before this one may have left a write under way"
        );
        owed.cleared();
        owed.sent(false, false);
        owed.answered();
        assert_eq!(owed.before_send(true), Clear::Nothing, "one request, one reply");
        owed.sent(false, false);
        assert_eq!(owed.before_send(false), Clear::Replace, "not answered: its reply may come");
        owed.replaced();
        owed.sent(true, false);
        owed.answered();
        assert_eq!(
            owed.before_send(true),
            Clear::Nothing,
            "a retry on a new carrier owes nothing once answered"
        );
        owed.sent(false, false);
        owed.answered();
        owed.unsettle();
        assert_eq!(owed.before_send(true), Clear::Replace, "a reply that was not the request's");
        owed.reopened();
        assert_eq!(owed.before_send(true), Clear::Nothing, "a new connection carries nothing late");

        let mut line = Owed::new(Guard::Wait, false);
        assert_eq!(line.before_send(true), Clear::Wait, "a line may bring a previous process's reply");
        line.cleared();
        line.sent(true, false);
        line.answered();
        assert_eq!(line.before_send(true), Clear::Wait, "a retry answered: the other answer may follow");
        line.cleared();
        line.sent(false, false);
        line.reopened();
        assert_eq!(line.before_send(true), Clear::Wait, "a reopened line may bring the late reply");

        let udp = Owed::new(Guard::Replace, true);
        assert_eq!(udp.before_send(true), Clear::Wait, "a fresh port may be a previous process's");
        let mut ids = Owed::new(Guard::Ids, false);
        assert_eq!(ids.before_send(true), Clear::Wait, "ids or not, the start waits");
        ids.cleared();
        ids.sent(true, false);
        ids.unsettle();
        assert_eq!(ids.before_send(true), Clear::Nothing, "ids tell replies apart");
    }

    #[test]
    fn a_write_never_answered_is_waited_out_before_the_next_request_where_it_could_overtake() {
        // A write's first attempt is lost (or slow); its retry goes at once on a new port.
        let mut udp = Owed::new(Guard::Replace, true);
        udp.cleared();
        udp.sent(false, true);
        assert_eq!(udp.before_send(false), Clear::Replace, "the retry writes the same: at once");
        udp.replaced();
        udp.sent(true, true);
        udp.answered();
        assert_eq!(udp.before_send(true), Clear::Wait, "the first attempt may still land after the next");
        udp.cleared();
        assert_eq!(udp.before_send(true), Clear::Nothing, "its lifetime is past");
        // A read never answered is harmless once its reply cannot be taken.
        udp.sent(false, false);
        assert_eq!(udp.before_send(true), Clear::Replace);
        // With ids the replies are told apart, but a late write on datagrams is the same.
        let mut ids = Owed::new(Guard::Ids, true);
        ids.cleared();
        ids.sent(false, true);
        assert_eq!(ids.before_send(false), Clear::Nothing, "a retry of the write");
        ids.sent(true, true);
        ids.answered();
        assert_eq!(ids.before_send(true), Clear::Wait, "the next request waits the first attempt out");
        // One TCP connection keeps its order: nothing to wait for.
        let mut tcp = Owed::new(Guard::Ids, false);
        tcp.cleared();
        tcp.sent(false, true);
        tcp.sent(true, true);
        tcp.answered();
        assert_eq!(tcp.before_send(true), Clear::Nothing);
    }
}
