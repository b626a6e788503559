//! The ids a link gives its attempts (Modbus transaction ids, PPI PDU references), and
//! whether an id in a reply is one of them.
//!
//! Ids are consecutive 16-bit numbers from a random start (so a rackd after a restart does
//! not reuse the ids its previous life had in flight), which tells the ids of this link's
//! recent requests without keeping them: an id among the last [`RECENT`] given is ours,
//! and a reply carrying it (but not the current request's) is a late answer to an earlier
//! request, *stale*; any other id was never asked by this link, *foreign* (another master
//! on the line, or a rackd before a restart). The verdicts and counters say which, so a
//! late reply does not send an engineer looking for a device that is not there.

/// How many of the last ids given count as this link's own.
const RECENT: u32 = 4096;

/// The ids given so far.
#[derive(Debug)]
pub(crate) struct RecentIds {
    next: u16,
    given: u32,
}

impl RecentIds {
    /// No id given yet; the first is random.
    pub fn new() -> Self {
        Self::from(rand::random())
    }

    /// No id given yet; the first is `first`.
    pub fn from(first: u16) -> Self {
        RecentIds { next: first, given: 0 }
    }

    /// The id of the next attempt.
    pub fn next(&mut self) -> u16 {
        let id = self.next;
        self.next = self.next.wrapping_add(1);
        self.given = self.given.saturating_add(1);
        id
    }

    /// Whether `id` is one of the last [`RECENT`] given.
    pub fn ours(&self, id: u16) -> bool {
        let back = u32::from(self.next.wrapping_sub(id));
        back >= 1 && back <= self.given.min(RECENT)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_last_ids_given_are_ours_across_the_wrap() {
        let mut ids = RecentIds::from(65_534);
        assert!(!ids.ours(65_534) && !ids.ours(65_533), "none given yet");
        let given: Vec<u16> = (0..4).map(|_| ids.next()).collect();
        assert_eq!(given, [65_534, 65_535, 0, 1]);
        assert!(given.iter().all(|&id| ids.ours(id)));
        assert!(!ids.ours(2), "not given yet");
        assert!(!ids.ours(65_533), "before the first");
        for _ in 0..RECENT {
            ids.next();
        }
        assert!(!ids.ours(1), "long ago");
    }
}
