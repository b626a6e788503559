//! The limit on failed authentications, per client address: after `[auth] max_failures`
//! unknown keys from one address within `failure_window_secs`, every request of that address
//! to a keyed route is answered 429 `too_many_failures`, with `Retry-After` (whole seconds),
//! until the window has passed; then it starts again from zero.
//!
//! Decisions where the issue is silent:
//! - **What counts**: each *different* unknown key an address presents. Guessing needs new
//!   keys; the same unknown key again is a stale key (a dashboard that kept an old key asks
//!   half a dozen routes at each load, a WMS with a revoked key retries), and counting it
//!   every time would lock out, for a minute, the right key typed next, or every client
//!   behind the same NAT. A request with no key at all does not count (a dashboard opened
//!   without one gets 401s and asks for it), nor does a known key whose role is too low
//!   (403): the key is right. Keys are remembered as 64-bit fingerprints, never in clear.
//! - **The window** is fixed, from the address's first failure: simple to explain ("10 wrong
//!   keys in a minute, then wait for the minute to end") and to answer with a
//!   `Retry-After`. A success does not wipe the count (a holder of a viewer key could
//!   otherwise go on guessing an admin's between two good requests), and it is per address:
//!   one address's failures never touch another's.
//! - **The address** is the TCP peer's. Clients behind one NAT or one reverse proxy on the
//!   same machine share it, so one of them sending a stale key holds up the others: raise
//!   `max_failures` there, or set it to 0 to turn the limit off. `X-Forwarded-For` is not
//!   read (anyone can send it; rackd has no trusted-proxy setting).
//! - **Bounded memory**: the table holds at most [`MOST`] addresses. When a new address
//!   would pass that, entries whose window has ended go first, then the older half by first
//!   failure. A flood from ever new addresses (spoofing needs a TCP handshake, so real
//!   addresses) costs at most that much memory, and at worst lets an address that stopped
//!   failing long ago start afresh.
//! - Without a peer address (a server built without one) nothing is counted.
//! - Time is tokio's, so tests move it on paused time.
//! - The limit is the running key ring's ([`FailureLimit`]), passed with each call: a
//!   reload that changes it holds from the next request on, and the table's counts stay
//!   (a window of the old length ends at the new length from its first failure).

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::Mutex;
use std::time::Duration;

use tokio::time::Instant;

use crate::auth::FailureLimit;

/// The most addresses the table holds. Each takes about 40 bytes and 8 per key counted
/// (`auth.max_failures` is at most [`crate::auth::MOST_FAILURES`]): at most about 7 MiB.
pub const MOST: usize = 8192;

/// The failures of each address within its window.
#[derive(Debug, Default)]
pub struct Failures {
    table: Mutex<HashMap<IpAddr, Window>>,
}

/// One address's window: when its first failure was, and the fingerprints of the unknown
/// keys since.
#[derive(Clone, Debug)]
struct Window {
    first: Instant,
    keys: Vec<u64>,
}

impl Window {
    fn new(first: Instant, key: u64) -> Window {
        Window { first, keys: vec![key] }
    }
}

/// A key's fingerprint: enough to tell keys apart, useless to find one.
pub fn fingerprint(key: &str) -> u64 {
    use std::hash::{BuildHasher, BuildHasherDefault};
    BuildHasherDefault::<std::collections::hash_map::DefaultHasher>::default().hash_one(key)
}

impl Failures {
    fn table(&self) -> std::sync::MutexGuard<'_, HashMap<IpAddr, Window>> {
        self.table.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// How long `ip` must still wait under `limit`, if it has used up its failures.
    pub fn blocked(&self, ip: IpAddr, limit: FailureLimit) -> Option<Duration> {
        if limit.max == 0 {
            return None;
        }
        let now = Instant::now();
        let table = self.table();
        let w = table.get(&ip)?;
        let ends = w.first + limit.window;
        (w.keys.len() >= limit.max as usize && now < ends).then(|| ends - now)
    }

    /// Notes that `ip` presented the unknown key of fingerprint `key` ([`fingerprint`]),
    /// under `limit`.
    pub fn failed(&self, ip: IpAddr, key: u64, limit: FailureLimit) {
        if limit.max == 0 {
            return;
        }
        let now = Instant::now();
        let window = limit.window;
        let mut table = self.table();
        if let Some(w) = table.get_mut(&ip) {
            if now >= w.first + window {
                *w = Window::new(now, key);
            } else if !w.keys.contains(&key) && w.keys.len() < limit.max as usize {
                w.keys.push(key);
            }
            return;
        }
        if table.len() >= MOST {
            table.retain(|_, w| now < w.first + window);
        }
        if table.len() >= MOST {
            // The older half goes, by first failure: one pass, amortised over the next
            // MOST / 2 new addresses.
            let mut firsts: Vec<Instant> = table.values().map(|w| w.first).collect();
            let middle = firsts.len() / 2;
            let (_, cut, _) = firsts.select_nth_unstable(middle);
            let cut = *cut;
            table.retain(|_, w| w.first > cut);
        }
        table.insert(ip, Window::new(now, key));
    }

    /// Addresses in the table (for tests).
    pub fn len(&self) -> usize {
        self.table().len()
    }

    /// Whether the table is empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const A: IpAddr = IpAddr::V4(std::net::Ipv4Addr::new(10, 0, 0, 1));
    const B: IpAddr = IpAddr::V4(std::net::Ipv4Addr::new(10, 0, 0, 2));

    fn limit(max: u32, secs: u64) -> FailureLimit {
        FailureLimit { max, window: Duration::from_secs(secs) }
    }

    #[tokio::test(start_paused = true)]
    async fn an_address_is_held_up_for_the_rest_of_its_window_then_starts_afresh() {
        let (f, l) = (Failures::default(), limit(3, 60));
        f.failed(A, fingerprint("guess-1"), l);
        f.failed(A, fingerprint("guess-2"), l);
        assert_eq!(f.blocked(A, l), None, "two of three");
        tokio::time::advance(Duration::from_secs(10)).await;
        f.failed(A, fingerprint("guess-3"), l);
        assert_eq!(f.blocked(A, l), Some(Duration::from_secs(50)), "the window runs from the first failure");
        assert_eq!(f.blocked(B, l), None, "another address is not touched");
        tokio::time::advance(Duration::from_secs(49)).await;
        assert_eq!(f.blocked(A, l), Some(Duration::from_secs(1)));
        tokio::time::advance(Duration::from_secs(1)).await;
        assert_eq!(f.blocked(A, l), None, "the window has passed");
        f.failed(A, fingerprint("guess-4"), l);
        assert_eq!(f.blocked(A, l), None, "and the count starts again");
    }

    #[tokio::test(start_paused = true)]
    async fn the_same_unknown_key_again_counts_once() {
        let (f, l) = (Failures::default(), limit(3, 60));
        for _ in 0..50 {
            f.failed(A, fingerprint("stale"), l);
        }
        assert_eq!(f.blocked(A, l), None, "a stale key retried is not a guess");
        f.failed(A, fingerprint("other-1"), l);
        f.failed(A, fingerprint("other-2"), l);
        assert!(f.blocked(A, l).is_some());
    }

    #[tokio::test(start_paused = true)]
    async fn failures_spread_over_more_than_a_window_never_block() {
        let (f, l) = (Failures::default(), limit(2, 60));
        for n in 0..10u64 {
            f.failed(A, n, l);
            tokio::time::advance(Duration::from_secs(61)).await;
        }
        assert_eq!(f.blocked(A, l), None);
    }

    #[tokio::test(start_paused = true)]
    async fn a_flood_of_addresses_keeps_the_table_bounded_and_the_newest() {
        let (f, l) = (Failures::default(), limit(1, 60));
        let ip = |i: u32| IpAddr::V4(std::net::Ipv4Addr::from(0x0a00_0000 + i));
        for i in 0..(MOST as u32 * 5) {
            f.failed(ip(i), 7, l);
            if i % 1000 == 0 {
                tokio::time::advance(Duration::from_millis(1)).await;
            }
        }
        assert!(f.len() <= MOST, "{}", f.len());
        assert!(f.blocked(ip(MOST as u32 * 5 - 1), l).is_some(), "the newest address is still held up");
        assert!(f.blocked(ip(0), l).is_none(), "the oldest went first");
    }

    #[test]
    fn no_limit_when_max_is_zero() {
        let (f, l) = (Failures::default(), limit(0, 60));
        for n in 0..100 {
            f.failed(A, n, l);
        }
        assert_eq!(f.blocked(A, l), None);
        assert!(f.is_empty());
    }
}
