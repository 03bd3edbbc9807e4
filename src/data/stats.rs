//! The value statistics of a volume, computed once per volume.
//!
//! Owns [`ValueStats`]: the smallest and largest density, the runners-up and
//! how many voxels hold each end (what the sentinel test of
//! [`crate::classify::presets::data_range`] needs), and for integer voxels an
//! exact count of every value. Every histogram, range and preset a report or a
//! renderer asks for is derived from it, so a 108 MB scan is read once, in
//! parallel and in its own type, instead of once per question through f32
//! (2.4 s of a 512×512×413 chest CT's first frame before this existed).

use rayon::prelude::*;

use crate::data::voxels::VoxelData;

/// Voxels per parallel task.
const CHUNK: usize = 1 << 20;

/// What a volume's densities span (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct ValueStats {
    /// Smallest and largest density.
    pub lo: f32,
    pub hi: f32,
    /// The smallest density above `lo` and the largest below `hi` (`+∞` and
    /// `−∞` when every voxel holds the one value).
    pub lo2: f32,
    pub hi2: f32,
    /// Voxels holding `lo`, and `hi`.
    pub n_lo: u64,
    pub n_hi: u64,
    /// Integer voxels: the count of value `base + i` at `i`, over the type's range.
    counts: Option<(i32, Vec<u64>)>,
    /// A histogram given with the statistics ([`ValueStats::with_histogram`]):
    /// `[lo, hi]` and its bins.
    given: Option<(f32, f32, Vec<u64>)>,
}

impl ValueStats {
    /// The statistics of `data` (which must not be empty).
    pub fn of(data: &VoxelData) -> Self {
        match data {
            VoxelData::U8(v) => Self::from_counts(0, counts(v, 256, |x| x as usize)),
            VoxelData::U16(v) => Self::from_counts(0, counts(v, 65536, |x| x as usize)),
            VoxelData::I16(v) => Self::from_counts(-32768, counts(v, 65536, |x| (x as i32 + 32768) as usize)),
            VoxelData::F32(v) => Self::of_f32(v),
        }
    }

    fn from_counts(base: i32, c: Vec<u64>) -> Self {
        let used: Vec<usize> = c.iter().enumerate().filter(|(_, n)| **n > 0).map(|(i, _)| i).collect();
        let val = |i: usize| (base + i as i32) as f32;
        let (first, last) = (used.first().copied().unwrap_or(0), used.last().copied().unwrap_or(0));
        let lo2 = used.get(1).map_or(f32::INFINITY, |&i| val(i));
        let hi2 = if used.len() > 1 { val(used[used.len() - 2]) } else { f32::NEG_INFINITY };
        ValueStats { lo: val(first), hi: val(last), lo2, hi2, n_lo: c[first], n_hi: c[last], counts: Some((base, c)), given: None }
    }

    fn of_f32(v: &[f32]) -> Self {
        let (lo, hi) = v
            .par_chunks(CHUNK)
            .map(|c| c.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), &x| (l.min(x), h.max(x))))
            .reduce(|| (f32::INFINITY, f32::NEG_INFINITY), |a, b| (a.0.min(b.0), a.1.max(b.1)));
        type Acc = (f32, f32, u64, u64);
        let fold = |(l2, h2, nl, nh): Acc, &x: &f32| -> Acc {
            (if x == lo { l2 } else { l2.min(x) }, if x == hi { h2 } else { h2.max(x) }, nl + (x == lo) as u64, nh + (x == hi) as u64)
        };
        let zero = || (f32::INFINITY, f32::NEG_INFINITY, 0u64, 0u64);
        let (lo2, hi2, n_lo, n_hi) = v
            .par_chunks(CHUNK)
            .map(|c| c.iter().fold(zero(), fold))
            .reduce(zero, |a, b| (a.0.min(b.0), a.1.max(b.1), a.2 + b.2, a.3 + b.3));
        ValueStats { lo, hi, lo2, hi2, n_lo, n_hi, counts: None, given: None }
    }

    /// The statistics of the union of the voxels `self` and `other` were
    /// computed over (disjoint sets of voxels of one type): the same numbers
    /// [`ValueStats::of`] gives for the whole, without its voxels (how the
    /// bricks of a distributed volume agree on one classification).
    pub fn merge(&self, other: &ValueStats) -> ValueStats {
        if let (Some((b, c)), Some((b2, c2))) = (&self.counts, &other.counts)
            && b == b2
            && c.len() == c2.len()
        {
            return Self::from_counts(*b, c.iter().zip(c2).map(|(x, y)| x + y).collect());
        }
        let (lo, hi) = (self.lo.min(other.lo), self.hi.max(other.hi));
        // a part's runner-up: its own end when that end is not the whole's
        let lo2 = |s: &ValueStats| if s.lo == lo { s.lo2 } else { s.lo };
        let hi2 = |s: &ValueStats| if s.hi == hi { s.hi2 } else { s.hi };
        let n_lo = |s: &ValueStats| if s.lo == lo { s.n_lo } else { 0 };
        let n_hi = |s: &ValueStats| if s.hi == hi { s.n_hi } else { 0 };
        ValueStats {
            lo,
            hi,
            lo2: lo2(self).min(lo2(other)),
            hi2: hi2(self).max(hi2(other)),
            n_lo: n_lo(self) + n_lo(other),
            n_hi: n_hi(self) + n_hi(other),
            counts: None,
            given: None,
        }
    }

    /// Whether the statistics answer every histogram without the voxels
    /// (integer voxels: they hold the count of every value).
    pub fn has_counts(&self) -> bool {
        self.counts.is_some()
    }

    /// These statistics with `hist`, the histogram of `hist.len()` bins over
    /// `[lo, hi]` of the voxels they describe: [`ValueStats::histogram_in`]
    /// answers that question with it instead of reading the voxels (what a
    /// brick of a larger f32 volume is given: the whole volume's histogram).
    pub fn with_histogram(self, lo: f32, hi: f32, hist: Vec<u64>) -> ValueStats {
        ValueStats { given: Some((lo, hi, hist)), ..self }
    }

    /// The statistics as bytes ([`ValueStats::from_bytes`] reads them back;
    /// a histogram given with them is not part of them).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = Vec::new();
        for x in [self.lo, self.hi, self.lo2, self.hi2] {
            b.extend(x.to_le_bytes());
        }
        b.extend(self.n_lo.to_le_bytes());
        b.extend(self.n_hi.to_le_bytes());
        if let Some((base, c)) = &self.counts {
            b.extend(base.to_le_bytes());
            c.iter().for_each(|n| b.extend(n.to_le_bytes()));
        }
        b
    }

    /// Statistics from [`ValueStats::to_bytes`] (`None`: not such bytes).
    pub fn from_bytes(b: &[u8]) -> Option<ValueStats> {
        let f = |i: usize| Some(f32::from_le_bytes(b.get(4 * i..4 * i + 4)?.try_into().ok()?));
        let u = |at: usize| Some(u64::from_le_bytes(b.get(at..at + 8)?.try_into().ok()?));
        let (lo, hi, lo2, hi2, n_lo, n_hi) = (f(0)?, f(1)?, f(2)?, f(3)?, u(16)?, u(24)?);
        let counts = match b.len() {
            32 => None,
            n if n > 36 && (n - 36).is_multiple_of(8) => {
                let base = i32::from_le_bytes(b[32..36].try_into().ok()?);
                Some((base, b[36..].chunks_exact(8).map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes"))).collect()))
            }
            _ => return None,
        };
        Some(ValueStats { lo, hi, lo2, hi2, n_lo, n_hi, counts, given: None })
    }

    /// `bins` equal bins over `[lo, hi]`, ignoring values outside it; a value
    /// `x` falls in bin `⌊(x − lo)·bins / (hi − lo)⌋` (in f64), the last bin
    /// closed. Integer volumes answer from the counts without reading `data`.
    pub fn histogram_in(&self, data: &VoxelData, bins: usize, lo: f32, hi: f32) -> Vec<u64> {
        let bins = bins.max(1);
        let scale = if hi > lo { bins as f64 / (hi as f64 - lo as f64) } else { 0.0 };
        let bin = |x: f32| (((x as f64 - lo as f64) * scale) as usize).min(bins - 1);
        let inside = |x: f32| x >= lo && x <= hi;
        if let Some((glo, ghi, h)) = &self.given
            && (*glo, *ghi, h.len()) == (lo, hi, bins)
        {
            return h.clone();
        }
        match (&self.counts, data) {
            (Some((base, c)), _) => {
                let mut h = vec![0u64; bins];
                for (i, &n) in c.iter().enumerate().filter(|(_, n)| **n > 0) {
                    let x = (*base + i as i32) as f32;
                    if inside(x) {
                        h[bin(x)] += n;
                    }
                }
                h
            }
            (None, VoxelData::F32(v)) => v
                .par_chunks(CHUNK)
                .fold(
                    || vec![0u64; bins],
                    |mut h, c| {
                        for &x in c.iter().filter(|&&x| inside(x)) {
                            h[bin(x)] += 1;
                        }
                        h
                    },
                )
                .reduce(|| vec![0u64; bins], add),
            // integer data always has counts
            (None, d) => {
                let mut h = vec![0u64; bins];
                for x in (0..d.len()).map(|i| d.get(i)).filter(|&x| inside(x)) {
                    h[bin(x)] += 1;
                }
                h
            }
        }
    }
}

fn add(mut a: Vec<u64>, b: Vec<u64>) -> Vec<u64> {
    a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
    a
}

/// The count of every value of `v` (index `idx(x)` in `0..n`), in parallel.
fn counts<T: Copy + Sync>(v: &[T], n: usize, idx: impl Fn(T) -> usize + Sync) -> Vec<u64> {
    v.par_chunks(CHUNK)
        .fold(
            || vec![0u64; n],
            |mut h, c| {
                for &x in c {
                    h[idx(x)] += 1;
                }
                h
            },
        )
        .reduce(|| vec![0u64; n], add)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The statistics equal a plain scan, for every voxel type.
    #[test]
    fn stats_equal_a_plain_scan() {
        let mut rnd = crate::testing::xorshift(0x2545F4914F6CDD1D);
        let n = 3 * CHUNK + 12345;
        let sets = [
            VoxelData::U8((0..n).map(|_| (rnd() % 7) as u8 * 30 + 5).collect()),
            VoxelData::U16((0..n).map(|_| (rnd() % 4000) as u16).collect()),
            VoxelData::I16((0..n).map(|_| (rnd() % 3000) as i16 - 1024).collect()),
            VoxelData::F32((0..n).map(|_| (rnd() % 100000) as f32 * 0.37 - 500.0).collect()),
            VoxelData::I16(vec![-7; 10]),
            VoxelData::F32(vec![2.5; 10]),
        ];
        for d in &sets {
            let st = ValueStats::of(d);
            let all: Vec<f32> = (0..d.len()).map(|i| d.get(i)).collect();
            let lo = all.iter().copied().fold(f32::INFINITY, f32::min);
            let hi = all.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            assert_eq!((st.lo, st.hi), (lo, hi));
            assert_eq!(st.n_lo, all.iter().filter(|&&x| x == lo).count() as u64);
            assert_eq!(st.n_hi, all.iter().filter(|&&x| x == hi).count() as u64);
            assert_eq!(st.lo2, all.iter().copied().filter(|&x| x != lo).fold(f32::INFINITY, f32::min));
            assert_eq!(st.hi2, all.iter().copied().filter(|&x| x != hi).fold(f32::NEG_INFINITY, f32::max));
            for (bins, a, b) in [(256, lo, hi), (7, lo, hi), (64, lo + (hi - lo) * 0.25, hi - (hi - lo) * 0.3), (1, lo, lo)] {
                let scale = if b > a { bins as f64 / (b as f64 - a as f64) } else { 0.0 };
                let mut h = vec![0u64; bins];
                for &x in all.iter().filter(|&&x| x >= a && x <= b) {
                    h[(((x as f64 - a as f64) * scale) as usize).min(bins - 1)] += 1;
                }
                assert_eq!(st.histogram_in(d, bins, a, b), h, "{:?} {bins} bins", d.voxel_type());
            }
        }
    }
}
