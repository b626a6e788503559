//! A mergeable sketch of durations: a histogram over fixed logarithmic bins, from which a
//! percentile is read with a known relative error.
//!
//! Bin 0 holds durations under a millisecond; bin `k >= 1` holds the durations `d` (ms)
//! with `GAMMA^(k-2) < d <= GAMMA^(k-1)`, `GAMMA = (1 + ALPHA) / (1 - ALPHA)`. A bin's value
//! is `2 GAMMA^(k-1) / (GAMMA + 1)`, within `ALPHA` (1%) of every duration in it, so a
//! percentile read from the sketch is within 1% of the same percentile (nearest rank) of
//! the durations themselves (the idea of DDSketch, Masson et al., VLDB 2019). Adding two
//! sketches adds their bins: a year's sketch is the sum of its days', exactly as if the
//! year's durations had been put in one.
//!
//! Written here rather than taken from a crate (`sketches-ddsketch`): the bins are kept in
//! the database for years, so their stored form must be ours and stable (a sparse list of
//! `[bin, count]`), not a crate's internal layout, which its next version may change. The
//! arithmetic is a dozen lines.

use serde::{Deserialize, Serialize};

/// The relative error of a value read from the sketch.
pub const ALPHA: f64 = 0.01;

/// The ratio between a bin's bounds.
const GAMMA: f64 = (1.0 + ALPHA) / (1.0 - ALPHA);

/// Durations (ms) by bin: the counts of the bins from `first` on, held densely (adding a
/// year of days' sketches is adding arrays); stored as a list of `[bin, count]` of the bins
/// that hold any, ascending.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(from = "Vec<(i32, u64)>", into = "Vec<(i32, u64)>")]
pub struct Sketch {
    first: i32,
    counts: Vec<u64>,
}

impl PartialEq for Sketch {
    /// The same durations, whatever room each has made for bins.
    fn eq(&self, other: &Sketch) -> bool {
        let held = |s: &Sketch| (s.first..).zip(s.counts.clone()).filter(|(_, n)| *n > 0).collect::<Vec<_>>();
        held(self) == held(other)
    }
}

impl From<Vec<(i32, u64)>> for Sketch {
    fn from(pairs: Vec<(i32, u64)>) -> Sketch {
        let mut s = Sketch::default();
        if let (Some(lo), Some(hi)) = (pairs.iter().map(|p| p.0).min(), pairs.iter().map(|p| p.0).max()) {
            s.cover(lo, hi);
        }
        for (bin, n) in pairs {
            s.counts[(bin - s.first) as usize] += n;
        }
        s
    }
}

impl From<Sketch> for Vec<(i32, u64)> {
    fn from(s: Sketch) -> Vec<(i32, u64)> {
        (s.first..).zip(s.counts).filter(|(_, n)| *n > 0).collect()
    }
}

impl Sketch {
    /// Makes room for the bins `lo..=hi`.
    fn cover(&mut self, lo: i32, hi: i32) {
        if self.counts.is_empty() {
            (self.first, self.counts) = (lo, vec![0; (hi - lo + 1) as usize]);
            return;
        }
        if lo < self.first {
            let mut grown = vec![0; (self.first - lo) as usize];
            grown.append(&mut self.counts);
            (self.first, self.counts) = (lo, grown);
        }
        let last = self.first + self.counts.len() as i32 - 1;
        if hi > last {
            self.counts.resize(self.counts.len() + (hi - last) as usize, 0);
        }
    }

    /// Adds one duration (ms).
    pub fn add(&mut self, ms: i64) {
        let b = bin(ms);
        self.cover(b, b);
        self.counts[(b - self.first) as usize] += 1;
    }

    /// Adds every duration of `other`.
    pub fn merge(&mut self, other: &Sketch) {
        if other.counts.is_empty() {
            return;
        }
        self.cover(other.first, other.first + other.counts.len() as i32 - 1);
        let at = (other.first - self.first) as usize;
        for (mine, n) in self.counts[at..].iter_mut().zip(&other.counts) {
            *mine += n;
        }
    }

    /// How many durations it holds.
    pub fn count(&self) -> u64 {
        self.counts.iter().sum()
    }

    /// The `q` quantile (0 < q <= 1) by nearest rank, in ms, within [`ALPHA`] of the true
    /// one; None when empty.
    pub fn quantile(&self, q: f64) -> Option<f64> {
        let count = self.count();
        if count == 0 {
            return None;
        }
        let rank = ((count as f64) * q).ceil().clamp(1.0, count as f64) as u64;
        let mut seen = 0;
        for (bin, n) in (self.first..).zip(&self.counts) {
            seen += n;
            if seen >= rank {
                return Some(value(bin));
            }
        }
        None
    }
}

/// The bin of a duration (ms).
fn bin(ms: i64) -> i32 {
    if ms < 1 {
        return 0;
    }
    1 + ((ms as f64).ln() / GAMMA.ln()).ceil() as i32
}

/// The value a bin stands for (ms).
fn value(bin: i32) -> f64 {
    if bin <= 0 {
        return 0.0;
    }
    2.0 * GAMMA.powi(bin - 1) / (GAMMA + 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The nearest-rank quantile of `values`.
    fn exact(values: &mut [i64], q: f64) -> f64 {
        values.sort_unstable();
        let rank = ((values.len() as f64) * q).ceil().clamp(1.0, values.len() as f64) as usize;
        values[rank - 1] as f64
    }

    #[test]
    fn every_quantile_is_within_alpha_of_the_exact_one() {
        // A spread of durations as jobs have them: 1 ms to 20 minutes, skewed (xorshift).
        let mut x: u64 = 0x9e37_79b9_7f4a_7c15;
        let mut values: Vec<i64> = (0..20_000)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                let u = (x % 1_000_000) as f64 / 1_000_000.0;
                (1.0 + 1_200_000.0 * u * u * u) as i64
            })
            .collect();
        let mut sketch = Sketch::default();
        for v in &values {
            sketch.add(*v);
        }
        for q in [0.01, 0.25, 0.5, 0.9, 0.95, 0.99, 1.0] {
            let (want, got) = (exact(&mut values, q), sketch.quantile(q).unwrap());
            assert!((got - want).abs() <= ALPHA * want + 1e-9, "q {q}: {got} against {want}");
        }
    }

    #[test]
    fn merged_sketches_are_the_sketch_of_all_values_and_survive_their_stored_form() {
        let (mut a, mut b, mut all) = (Sketch::default(), Sketch::default(), Sketch::default());
        for v in 0..500 {
            a.add(v * 7);
            all.add(v * 7);
            b.add(v * 13 + 1);
            all.add(v * 13 + 1);
        }
        a.merge(&b);
        assert_eq!(a, all);
        let (mut low, mut high) = (Sketch::default(), Sketch::default());
        low.add(3);
        high.add(90_000);
        high.merge(&low);
        low.add(90_000);
        assert_eq!(high, low, "merged either way round");
        let mut wide = Sketch::default();
        wide.merge(&high);
        wide.add(1);
        assert_ne!(wide, high);
        let stored = serde_json::to_string(&a).unwrap();
        assert!(stored.starts_with("[[0,1],[1,"), "{stored}");
        assert_eq!(serde_json::from_str::<Sketch>(&stored).unwrap(), all);
        assert_eq!(Sketch::default().quantile(0.95), None);
        let mut zero = Sketch::default();
        zero.add(0);
        assert_eq!(zero.quantile(0.5), Some(0.0));
    }
}
