//! The open connections: what each is doing and since when ([`Conn`]), their count against
//! the cap, and the choice of the one to close when a new one arrives at the cap
//! ([`Table::admit`]).
//!
//! A connection's phase and the instant it entered it share one atomic word, so that the
//! request path (two changes a request) takes no lock; the table's lock is taken on accept,
//! on close and for an eviction, which reads every entry (at most the cap, and only at
//! the cap).

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::Notify;
use tokio::time::Instant;

/// What a connection is doing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub(super) enum Phase {
    /// Waiting for a request's headers: from the accept (the TLS handshake included) for
    /// the first request, from its first byte for a keep-alive one. Serves no one.
    Head = 0,
    /// A request is being served (from its parsed headers to its response's last byte
    /// handed to the socket).
    Busy = 1,
    /// Keep-alive, between two requests. Serves no one.
    Idle = 2,
    /// A WebSocket: out of HTTP, on its own pings and timeouts; never evicted.
    Upgraded = 3,
    /// Chosen to make room: closes at its task's next turn.
    Evicted = 4,
}

impl Phase {
    fn from_bits(bits: u64) -> Phase {
        match bits & 7 {
            0 => Phase::Head,
            1 => Phase::Busy,
            2 => Phase::Idle,
            3 => Phase::Upgraded,
            _ => Phase::Evicted,
        }
    }

    /// Whether closing it now loses nothing but a client's wait: it serves no one.
    fn evictable(self) -> bool {
        matches!(self, Phase::Head | Phase::Idle)
    }
}

/// One connection's state, shared by its socket, its requests' bodies and the table.
pub(super) struct Conn {
    epoch: Instant,
    /// Microseconds from `epoch` to the phase's start, shifted left 3, or-ed with the phase.
    word: AtomicU64,
    /// Microseconds from `epoch` (plus one; 0: none) since when a write has been waiting
    /// for the client to read.
    write_blocked: AtomicU64,
    /// Wakes the connection's task when it is evicted.
    pub(super) evicted: Notify,
}

impl Conn {
    fn new(epoch: Instant) -> Conn {
        let conn =
            Conn { epoch, word: AtomicU64::new(0), write_blocked: AtomicU64::new(0), evicted: Notify::new() };
        conn.word.store(conn.pack(Phase::Head, Instant::now()), Ordering::Relaxed);
        conn
    }

    fn micros(&self, at: Instant) -> u64 {
        at.saturating_duration_since(self.epoch).as_micros() as u64
    }

    fn instant(&self, micros: u64) -> Instant {
        self.epoch + Duration::from_micros(micros)
    }

    fn pack(&self, phase: Phase, at: Instant) -> u64 {
        (self.micros(at) << 3) | phase as u64
    }

    /// The phase, and when it started.
    pub(super) fn phase(&self) -> (Phase, Instant) {
        let word = self.word.load(Ordering::Acquire);
        (Phase::from_bits(word), self.instant(word >> 3))
    }

    /// Moves from one of `from` to `to`, now; false if the phase was another.
    fn shift(&self, from: &[Phase], to: Phase) -> bool {
        let mut word = self.word.load(Ordering::Acquire);
        loop {
            if !from.contains(&Phase::from_bits(word)) {
                return false;
            }
            let new = self.pack(to, Instant::now());
            match self.word.compare_exchange_weak(word, new, Ordering::AcqRel, Ordering::Acquire) {
                Ok(_) => return true,
                Err(now) => word = now,
            }
        }
    }

    /// Bytes of a request arrived: an idle connection now waits for headers.
    pub(super) fn heard(&self) {
        if Phase::from_bits(self.word.load(Ordering::Relaxed)) == Phase::Idle {
            self.shift(&[Phase::Idle], Phase::Head);
        }
    }

    /// A request's headers are in: it is being served.
    pub(super) fn serving(&self) {
        self.shift(&[Phase::Head, Phase::Idle], Phase::Busy);
    }

    /// Its response is handed over: back to waiting for the next request.
    pub(super) fn served(&self) {
        self.shift(&[Phase::Busy], Phase::Idle);
    }

    /// Switched protocols (a WebSocket).
    pub(super) fn upgraded(&self) {
        self.shift(&[Phase::Busy], Phase::Upgraded);
    }

    /// A write could not go out: the client is not reading.
    pub(super) fn write_blocked(&self) {
        if self.write_blocked.load(Ordering::Relaxed) == 0 {
            self.write_blocked.store(self.micros(Instant::now()) + 1, Ordering::Relaxed);
        }
    }

    /// A write went out.
    pub(super) fn write_moved(&self) {
        if self.write_blocked.load(Ordering::Relaxed) != 0 {
            self.write_blocked.store(0, Ordering::Relaxed);
        }
    }

    /// When the connection is to be closed if nothing changes, and why; `None`: not while
    /// it is as it is (a request being served, a WebSocket).
    pub(super) fn deadline(&self, limits: &super::Limits) -> Option<(Instant, Phase)> {
        let (phase, since) = self.phase();
        let own = match phase {
            Phase::Head => Some(since + limits.header_timeout),
            Phase::Idle => Some(since + limits.idle_timeout),
            Phase::Busy | Phase::Upgraded => None,
            Phase::Evicted => Some(since),
        };
        let blocked = match self.write_blocked.load(Ordering::Relaxed) {
            0 => None,
            at => Some(self.instant(at - 1) + limits.idle_timeout),
        };
        match (own, blocked) {
            (Some(a), Some(b)) => Some((a.min(b), phase)),
            (Some(a), None) | (None, Some(a)) => Some((a, phase)),
            (None, None) => None,
        }
    }
}

/// Evicted connections that may be closing at once: the open sockets stay under the cap
/// plus this, which is less than the descriptors kept in reserve (`files::RESERVE`).
pub(super) const CLOSING: usize = 32;

/// The open connections.
pub(super) struct Table {
    epoch: Instant,
    cap: usize,
    inner: Mutex<Inner>,
    /// Told when a connection closes (a permit is kept if no one waits).
    closed: Notify,
}

#[derive(Default)]
struct Inner {
    next: u64,
    open: HashMap<u64, Arc<Conn>>,
    /// Evicted and not closed yet.
    closing: usize,
}

/// What to do with a connection just accepted.
pub(super) enum Admit {
    /// Serve it.
    Serve(Slot, Arc<Conn>),
    /// Wait for an evicted connection to close, then ask again.
    Wait,
    /// Every connection is serving someone: close this one.
    Refuse,
}

/// A connection's place in the table, given back when its socket is dropped.
pub(super) struct Slot {
    table: Arc<Table>,
    id: u64,
}

impl Drop for Slot {
    fn drop(&mut self) {
        let mut inner = self.table.lock();
        if let Some(conn) = inner.open.remove(&self.id)
            && conn.phase().0 == Phase::Evicted
        {
            inner.closing -= 1;
        }
        drop(inner);
        self.table.closed.notify_one();
    }
}

impl Table {
    /// A table of at most `cap` connections.
    pub(super) fn new(cap: usize) -> Arc<Table> {
        Arc::new(Table { epoch: Instant::now(), cap, inner: Mutex::default(), closed: Notify::new() })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The most connections open at once.
    pub(super) fn cap(&self) -> usize {
        self.cap
    }

    /// Connections open now, not counting evicted ones still closing.
    pub(super) fn len(&self) -> usize {
        let inner = self.lock();
        inner.open.len() - inner.closing
    }

    /// Takes a new connection in, evicting the connection that has waited longest without
    /// being served when the table is full.
    pub(super) fn admit(self: &Arc<Self>) -> Admit {
        let mut inner = self.lock();
        if inner.open.len() - inner.closing >= self.cap {
            // A flood is taken in at the pace connections close, a few ahead of it.
            if inner.closing >= CLOSING {
                return Admit::Wait;
            }
            if !Self::evict_oldest(&mut inner) {
                return Admit::Refuse;
            }
        }
        let id = inner.next;
        inner.next += 1;
        let conn = Arc::new(Conn::new(self.epoch));
        inner.open.insert(id, conn.clone());
        Admit::Serve(Slot { table: self.clone(), id }, conn)
    }

    /// Out of file descriptors: evicts the oldest connection that serves no one; false if
    /// there is none.
    pub(super) fn relieve(&self) -> bool {
        let mut inner = self.lock();
        inner.closing > 0 || Self::evict_oldest(&mut inner)
    }

    /// Waits until a connection has closed since the last wait.
    pub(super) async fn a_close(&self) {
        self.closed.notified().await;
    }

    fn evict_oldest(inner: &mut Inner) -> bool {
        loop {
            let oldest = inner
                .open
                .values()
                .map(|c| (c.phase(), c))
                .filter(|((phase, _), _)| phase.evictable())
                .min_by_key(|((_, since), _)| *since)
                .map(|(_, c)| c.clone());
            let Some(conn) = oldest else { return false };
            // It may have started serving since it was read: then look again.
            if conn.shift(&[Phase::Head, Phase::Idle], Phase::Evicted) {
                inner.closing += 1;
                conn.evicted.notify_one();
                return true;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn serve(table: &Arc<Table>) -> (Slot, Arc<Conn>) {
        match table.admit() {
            Admit::Serve(slot, conn) => (slot, conn),
            _ => panic!("expected room"),
        }
    }

    #[tokio::test(start_paused = true)]
    async fn at_the_cap_the_longest_unserved_connection_makes_room_and_busy_ones_never_do() {
        let table = Table::new(3);
        let (slot_a, a) = serve(&table);
        tokio::time::advance(Duration::from_millis(1)).await;
        let (_slot_b, b) = serve(&table);
        tokio::time::advance(Duration::from_millis(1)).await;
        let (_slot_c, c) = serve(&table);
        // `a` is being served; of the two waiting for headers, `b` came first.
        a.serving();
        tokio::time::advance(Duration::from_millis(1)).await;
        let (_slot_d, d) = serve(&table);
        assert_eq!(b.phase().0, Phase::Evicted);
        assert_eq!(c.phase().0, Phase::Head);
        assert_eq!(table.len(), 3, "b is closing");
        drop(_slot_b);
        // `a` done, now idle: idle and waiting connections are taken oldest first.
        tokio::time::advance(Duration::from_millis(1)).await;
        a.served();
        let (_slot_f, f) = serve(&table);
        assert_eq!(c.phase().0, Phase::Evicted, "c waits since before a went idle");
        assert_eq!(d.phase().0, Phase::Head);
        drop(_slot_c);
        f.serving();
        // All three busy or upgraded: a newcomer is refused, none is evicted.
        a.serving();
        d.serving();
        d.upgraded();
        assert!(matches!(table.admit(), Admit::Refuse));
        assert!([&a, &f].iter().all(|c| c.phase().0 == Phase::Busy) && d.phase().0 == Phase::Upgraded);
        drop(slot_a);
        assert_eq!(table.len(), 2);
    }

    #[tokio::test(start_paused = true)]
    async fn a_flood_is_taken_in_a_few_evictions_ahead_of_the_closes() {
        let table = Table::new(2);
        let mut kept = Vec::new();
        for _ in 0..2 + CLOSING {
            kept.push(serve(&table));
            tokio::time::advance(Duration::from_millis(1)).await;
        }
        assert_eq!(table.len(), 2);
        assert!(matches!(table.admit(), Admit::Wait), "{CLOSING} closing already");
        let evicted = kept.iter().position(|(_, c)| c.phase().0 == Phase::Evicted).unwrap();
        kept.remove(evicted);
        serve(&table);
    }

    #[tokio::test(start_paused = true)]
    async fn deadlines_follow_the_phase() {
        let limits = super::super::Limits {
            header_timeout: Duration::from_secs(10),
            idle_timeout: Duration::from_secs(60),
            max_connections: 8,
        };
        let table = Table::new(1);
        let (_slot, conn) = serve(&table);
        let start = Instant::now();
        assert_eq!(conn.deadline(&limits), Some((start + limits.header_timeout, Phase::Head)));
        conn.serving();
        assert_eq!(conn.deadline(&limits), None);
        tokio::time::advance(Duration::from_secs(1)).await;
        conn.write_blocked();
        let blocked = Instant::now();
        tokio::time::advance(Duration::from_secs(1)).await;
        conn.write_blocked();
        assert_eq!(conn.deadline(&limits), Some((blocked + limits.idle_timeout, Phase::Busy)));
        conn.write_moved();
        conn.served();
        let idle = Instant::now();
        assert_eq!(conn.deadline(&limits), Some((idle + limits.idle_timeout, Phase::Idle)));
        tokio::time::advance(Duration::from_secs(5)).await;
        conn.heard();
        assert_eq!(conn.deadline(&limits), Some((Instant::now() + limits.header_timeout, Phase::Head)));
        conn.heard();
        conn.serving();
        conn.upgraded();
        conn.served();
        assert_eq!(conn.deadline(&limits), None, "a WebSocket stays");
    }
}
