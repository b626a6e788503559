//! Read-only ranges of a simulated PLC's memory: items a master may read but not write,
//! as a real PLC's inputs are refreshed from the field and not from the network.
//!
//! A range is a key (the area: a Modbus table, an MC device, an S7 memory area) and a
//! half-open range of items in the unit the simulator keeps that area in (items of a Modbus
//! table, points of an MC device, bits of an S7 area or a MEWTOCOL contact area). Ranges
//! never overlap: [`ReadOnly::add`] refuses one that would, so a preset with two ranges
//! over the same items is refused at start instead of silently merged.
//!
//! Only the server's master path consults the list; the simulator's own writes (the field,
//! a test bench) pass by it.

use std::fmt::Debug;
use std::ops::Range;

/// The read-only ranges of one memory, and how many master writes they refused.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ReadOnly<K> {
    ranges: Vec<(K, Range<u64>)>,
    refused: u64,
}

impl<K> Default for ReadOnly<K> {
    fn default() -> Self {
        ReadOnly { ranges: Vec::new(), refused: 0 }
    }
}

/// A range that would overlap one already read-only.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("items {}..{} overlap the read-only items {}..{}", .new.start, .new.end, .existing.start, .existing.end)]
pub struct Overlap {
    /// The range asked for.
    pub new: Range<u64>,
    /// The range it overlaps.
    pub existing: Range<u64>,
}

fn overlaps(a: &Range<u64>, b: &Range<u64>) -> bool {
    a.start < b.end && b.start < a.end
}

impl<K: PartialEq + Clone + Debug> ReadOnly<K> {
    /// Makes `items` of `key` read-only; an empty range or one overlapping an earlier range
    /// is refused.
    pub fn add(&mut self, key: K, items: Range<u64>) -> Result<(), Overlap> {
        if let Some((_, existing)) = self.ranges.iter().find(|(k, r)| *k == key && overlaps(r, &items)) {
            return Err(Overlap { new: items, existing: existing.clone() });
        }
        if !items.is_empty() {
            self.ranges.push((key, items));
        }
        Ok(())
    }

    /// Whether a master write of `items` of `key` touches a read-only item; counts it as
    /// refused when it does.
    pub fn refuses(&mut self, key: &K, items: Range<u64>) -> bool {
        let hit = self.ranges.iter().any(|(k, r)| k == key && overlaps(r, &items));
        self.refused += u64::from(hit);
        hit
    }

    /// Master writes refused so far.
    pub fn refused(&self) -> u64 {
        self.refused
    }

    /// The ranges, in the order they were added.
    pub fn ranges(&self) -> &[(K, Range<u64>)] {
        &self.ranges
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_writes_touching_a_range_and_counts_them() {
        let mut ro = ReadOnly::default();
        ro.add("4x", 100..110).unwrap();
        ro.add("3x", 100..110).unwrap();
        assert!(!ro.refuses(&"4x", 90..100), "ends just before");
        assert!(ro.refuses(&"4x", 109..111), "last item");
        assert!(!ro.refuses(&"0x", 100..101), "another area");
        assert_eq!(ro.refused(), 1);
    }

    #[test]
    fn overlapping_ranges_are_refused() {
        let mut ro = ReadOnly::default();
        ro.add('D', 0..10).unwrap();
        assert_eq!(ro.add('D', 9..12), Err(Overlap { new: 9..12, existing: 0..10 }));
        ro.add('D', 10..12).unwrap();
        ro.add('W', 0..10).unwrap();
        assert_eq!(ro.ranges().len(), 3);
    }
}
