//! Classification presets: CT tissue presets in Hounsfield units and histogram-
//! based thresholds for volumes without a known scale (MRI, raw data).
//!
//! Owns [`Tissue`] (a named lower threshold with a matching iso colour and
//! alpha-blending transfer function), the CT presets, and [`otsu_threshold`].

use crate::classify::TransferFunction;
use crate::data::volume::Volume;

/// A named tissue preset.
#[derive(Clone, Debug, PartialEq)]
pub struct Tissue {
    /// Name on the command line.
    pub name: &'static str,
    /// Lower density threshold: below it the tissue preset is transparent.
    pub threshold: f32,
    /// Colour of the iso-surface preview.
    pub rgb: [f32; 3],
    /// Transfer function for the full alpha-blended render.
    pub tf: TransferFunction,
}

impl Tissue {
    /// The iso (threshold) transfer function of this preset.
    pub fn iso_tf(&self) -> TransferFunction {
        TransferFunction::threshold(self.threshold, self.rgb)
    }
}

/// CT tissue presets in Hounsfield units, by increasing lower threshold.
///
/// | name | lower threshold (HU) | shows |
/// |---|---|---|
/// | `skin` | −500 | the air/skin boundary: the outer surface of the body |
/// | `fat` | −200 | fat (≈ −100 HU) and everything denser |
/// | `soft` | −20 | soft tissue (≈ 20–60 HU: muscle, brain, organs) and denser, not fat |
/// | `bone` | 300 | bone (400–1500 HU) |
pub fn ct_tissues() -> Vec<Tissue> {
    let skin_rgb = [0.93, 0.76, 0.65];
    let fat_rgb = [0.98, 0.88, 0.55];
    let soft_rgb = [0.85, 0.42, 0.38];
    let bone_rgb = [1.0, 0.98, 0.9];
    vec![
        Tissue {
            name: "skin",
            threshold: -500.0,
            rgb: skin_rgb,
            tf: tf(
                &[(-500.0, 0.0), (-300.0, 0.08), (200.0, 0.08), (300.0, 0.0), (400.0, 0.0), (700.0, 0.9)],
                &[(-500.0, skin_rgb), (200.0, soft_rgb), (400.0, bone_rgb)],
            ),
        },
        Tissue {
            name: "fat",
            threshold: -200.0,
            rgb: fat_rgb,
            tf: tf(
                &[(-200.0, 0.0), (-100.0, 0.15), (-50.0, 0.02), (250.0, 0.02), (300.0, 0.0), (400.0, 0.0), (700.0, 0.9)],
                &[(-200.0, fat_rgb), (0.0, soft_rgb), (400.0, bone_rgb)],
            ),
        },
        Tissue {
            name: "soft",
            threshold: -20.0,
            rgb: soft_rgb,
            tf: tf(
                &[(-20.0, 0.0), (40.0, 0.12), (250.0, 0.12), (300.0, 0.0), (400.0, 0.0), (700.0, 0.9)],
                &[(-20.0, soft_rgb), (400.0, bone_rgb)],
            ),
        },
        Tissue {
            name: "bone",
            threshold: 300.0,
            rgb: bone_rgb,
            tf: tf(&[(300.0, 0.0), (700.0, 0.6), (1500.0, 1.0)], &[(300.0, [0.9, 0.8, 0.6]), (1000.0, bone_rgb)]),
        },
    ]
}

fn tf(op: &[(f32, f32)], col: &[(f32, [f32; 3])]) -> TransferFunction {
    // the presets are static data; validation can only fail on a typo here, which the tests catch
    TransferFunction::new(op.to_vec(), col.to_vec()).unwrap_or_else(|e| panic!("invalid built-in preset: {e}"))
}

/// The CT preset called `name`.
pub fn ct_tissue(name: &str) -> Option<Tissue> {
    ct_tissues().into_iter().find(|t| t.name == name)
}

/// A volume's value range, and the sentinel (no-data value such as
/// ±FLT_MAX) that dominates it, if one does.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DataRange {
    /// Smallest and largest value.
    pub lo: f32,
    pub hi: f32,
    /// The range of the values other than the sentinel (`(lo, hi)` without one).
    pub bulk: (f32, f32),
    /// A value at one end of the range, far from all the others: the rest of
    /// the data span less than 1/1000 of the full range (or the value is
    /// beyond ±1e30). Thresholds and histograms ignore it.
    pub sentinel: Option<f32>,
    /// Voxels holding the sentinel.
    pub sentinel_voxels: u64,
}

impl DataRange {
    /// The range presets and histograms use: [`DataRange::bulk`].
    pub fn working(&self) -> (f32, f32) {
        self.bulk
    }

    /// What a report should say about the sentinel, if there is one.
    pub fn sentinel_note(&self) -> Option<String> {
        let n = crate::fmt::fmt_density;
        self.sentinel.map(|s| {
            format!(
                "{} voxels hold {}, far from the other values ({} … {}): a no-data sentinel? It dominates the range; the \
                 presets ignore it, but the renderer's classification table spans it, so replace it for a faithful render",
                self.sentinel_voxels,
                n(s),
                n(self.bulk.0),
                n(self.bulk.1)
            )
        })
    }
}

/// The value range of `v` and any sentinel that dominates it (see [`DataRange`]).
pub fn data_range(v: &Volume) -> DataRange {
    let (lo, hi) = v.value_range();
    let plain = DataRange { lo, hi, bulk: (lo, hi), sentinel: None, sentinel_voxels: 0 };
    if hi <= lo {
        return plain;
    }
    let span = hi as f64 - lo as f64;
    // the range of the values other than the lowest, and other than the highest
    let st = v.stats();
    let (lo2, hi2, n_lo, n_hi) = (st.lo2, st.hi2, st.n_lo, st.n_hi);
    // the end value `s` is a sentinel when the rest has a spread of its own and
    // lies far from it
    let far = |rest_lo: f32, rest_hi: f32, s: f32| {
        rest_lo < rest_hi
            && ((rest_hi as f64 - rest_lo as f64) < 1e-3 * span || (s.abs() >= 1e30 && rest_lo.abs().max(rest_hi.abs()) < 1e30))
    };
    if far(lo2, hi, lo) {
        return DataRange { bulk: (lo2, hi), sentinel: Some(lo), sentinel_voxels: n_lo, ..plain };
    }
    if far(lo, hi2, hi) {
        return DataRange { bulk: (lo, hi2), sentinel: Some(hi), sentinel_voxels: n_hi, ..plain };
    }
    plain
}

/// True when the volume looks like CT in Hounsfield units (air near −1000),
/// judged on the range without a sentinel.
pub fn looks_like_ct(v: &Volume) -> bool {
    let (lo, hi) = data_range(v).working();
    (-3100.0..=-900.0).contains(&lo) && hi > 0.0
}

/// `lo + (hi − lo)·f` without overflow (f64), as a finite f32.
fn lerp(lo: f32, hi: f32, f: f64) -> f32 {
    ((lo as f64) + (hi as f64 - lo as f64) * f).clamp(f32::MIN as f64, f32::MAX as f64) as f32
}

/// Bins of the histogram the presets are found in.
pub const HISTOGRAM_BINS: usize = 256;

/// A 256-bin histogram over `[lo, hi]`, ignoring values outside it (a sentinel).
fn histogram_in(v: &Volume, bins: usize, lo: f32, hi: f32) -> Vec<u64> {
    v.stats().histogram_in(v.data(), bins, lo, hi)
}

/// Otsu's threshold over a 256-bin histogram: the density that best separates
/// background from object. A sensible default iso value for MRI and unknown data.
/// Finite for any finite data (a sentinel is left out).
pub fn otsu_threshold(v: &Volume) -> f32 {
    let (lo, hi) = data_range(v).working();
    if hi <= lo {
        return lo;
    }
    let h = histogram_in(v, HISTOGRAM_BINS, lo, hi);
    let t = otsu_bins(&h, 0, 256).unwrap_or(0);
    lerp(lo, hi, (t as f64 + 1.0) / 256.0)
}

/// Otsu's split of histogram bins `[a, b)`: the last bin of the lower class.
#[allow(clippy::needless_range_loop)] // `t` is both the bin index and its value
fn otsu_bins(h: &[u64], a: usize, b: usize) -> Option<usize> {
    let total: f64 = h[a..b].iter().sum::<u64>() as f64;
    let sum_all: f64 = (a..b).map(|i| i as f64 * h[i] as f64).sum();
    let (mut w0, mut sum0, mut best, mut best_t) = (0.0, 0.0, -1.0, None);
    for t in a..b {
        w0 += h[t] as f64;
        sum0 += t as f64 * h[t] as f64;
        let w1 = total - w0;
        if w0 == 0.0 || w1 == 0.0 {
            continue;
        }
        let (m0, m1) = (sum0 / w0, (sum_all - sum0) / w1);
        let between = w0 * w1 * (m0 - m1) * (m0 - m1);
        if between > best {
            best = between;
            best_t = Some(t);
        }
    }
    best_t
}

/// Suggested lower thresholds for a volume without a known scale (MRI): the
/// three thresholds of multi-level Otsu (four classes with the largest
/// between-class variance, found exactly by dynamic programming over a 256-bin
/// histogram), ascending. Fewer when the volume has fewer distinct levels.
pub fn histogram_thresholds(v: &Volume) -> Vec<f32> {
    let (lo, hi) = data_range(v).working();
    if hi <= lo {
        return vec![];
    }
    let h = histogram_in(v, HISTOGRAM_BINS, lo, hi);
    let to_density = |t: usize| lerp(lo, hi, t as f64 / 256.0);
    let mut t: Vec<f32> = multi_otsu(&h, 4).into_iter().map(to_density).collect();
    // bins closer than an f32 step collapse: keep distinct thresholds only
    t.dedup();
    t
}

/// Class boundaries (the first bin of classes 1..k) maximising Σ w·μ² over `k`
/// non-empty classes of consecutive bins.
fn multi_otsu(h: &[u64], k: usize) -> Vec<usize> {
    let n = h.len();
    let mut pw = vec![0f64; n + 1];
    let mut ps = vec![0f64; n + 1];
    for i in 0..n {
        pw[i + 1] = pw[i] + h[i] as f64;
        ps[i + 1] = ps[i] + i as f64 * h[i] as f64;
    }
    // a class [a, b) must hold voxels
    let gain = |a: usize, b: usize| {
        let w = pw[b] - pw[a];
        if w > 0.0 { Some((ps[b] - ps[a]).powi(2) / w) } else { None }
    };
    let k = k.min(h.iter().filter(|&&c| c > 0).count()).max(1);
    // best[c][b]: best score of c classes covering bins [0, b); from[c][b]: start of the last class
    let mut best = vec![vec![f64::NEG_INFINITY; n + 1]; k + 1];
    let mut from = vec![vec![0usize; n + 1]; k + 1];
    best[0][0] = 0.0;
    for c in 1..=k {
        for b in 1..=n {
            for a in (c - 1)..b {
                if best[c - 1][a] == f64::NEG_INFINITY {
                    continue;
                }
                if let Some(g) = gain(a, b) {
                    let v = best[c - 1][a] + g;
                    if v > best[c][b] {
                        best[c][b] = v;
                        from[c][b] = a;
                    }
                }
            }
        }
    }
    if best[k][n] == f64::NEG_INFINITY {
        return vec![];
    }
    let mut cuts = vec![];
    let mut b = n;
    for c in (1..=k).rev() {
        let a = from[c][b];
        if c > 1 {
            cuts.push(a);
        }
        b = a;
    }
    cuts.reverse();
    cuts
}

/// Tissue presets for a volume: the CT presets for Hounsfield data, else
/// histogram presets ("low", "mid", "high") from [`histogram_thresholds`].
pub fn tissues_for(v: &Volume) -> Vec<Tissue> {
    if looks_like_ct(v) {
        return ct_tissues();
    }
    let hi = data_range(v).working().1;
    let names = ["low", "mid", "high"];
    let ts = histogram_thresholds(v);
    let ts = if ts.is_empty() { vec![otsu_threshold(v)] } else { ts };
    ts.iter().zip(names).map(|(&t, name)| Tissue { name, ..generic(t, hi) }).collect()
}

/// A generic preset for non-CT data: threshold at `t`, grey iso surface, and a
/// ramp that makes everything above `t` semi-transparent.
pub fn generic(t: f32, hi: f32) -> Tissue {
    let rgb = [0.92, 0.9, 0.85];
    // in f64: t and hi may be anywhere in the f32 range (±FLT_MAX sentinels)
    let top = if hi > t {
        hi
    } else {
        let u = t + 1.0;
        if u.is_finite() { u } else { t }
    };
    Tissue { name: "auto", threshold: t, rgb, tf: tf(&[(t, 0.0), (lerp(t, top, 0.5), 0.25), (top, 0.6)], &[(t, rgb)]) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ct_presets_are_valid_and_ordered() {
        let t = ct_tissues();
        assert_eq!(t.len(), 4);
        assert!(t.windows(2).all(|w| w[0].threshold < w[1].threshold));
        for x in &t {
            assert_eq!(x.tf.lower_threshold(), Some(x.threshold), "{}", x.name);
            assert_eq!(x.tf.opacity_at(x.threshold - 1.0), 0.0);
        }
        assert!(ct_tissue("bone").is_some() && ct_tissue("nope").is_none());
    }

    #[test]
    fn histogram_thresholds_find_three_populations() {
        let v = Volume::from_fn([40, 10, 10], [1.0; 3], |x, _, _| [0.0, 50.0, 120.0, 220.0][x / 10]).unwrap();
        let t = histogram_thresholds(&v);
        assert_eq!(t.len(), 3, "{t:?}");
        assert!(t[0] > 0.0 && t[0] <= 50.0 && t[1] > 50.0 && t[1] <= 120.0 && t[2] > 120.0 && t[2] <= 220.0, "{t:?}");
        let tissues = tissues_for(&v);
        assert_eq!(tissues.iter().map(|t| t.name).collect::<Vec<_>>(), ["low", "mid", "high"]);
    }

    #[test]
    fn extreme_and_sentinel_ranges_give_valid_presets() {
        for (a, b) in [(-f32::MAX, f32::MAX), (0.0, f32::MAX), (-f32::MAX, 0.0), (1e37, 3e38), (-1e-38, 1e-38), (5.0, 5.0)] {
            let v = Volume::from_fn([8, 4, 4], [1.0; 3], |x, y, _| if x < 4 { a } else { b - b.abs() * 0.1 * y as f32 }).unwrap();
            let t = tissues_for(&v);
            assert!(!t.is_empty());
            for x in &t {
                assert!(x.threshold.is_finite(), "{a} {b}: {x:?}");
            }
            assert!(t.windows(2).all(|w| w[0].threshold < w[1].threshold), "{t:?}");
            assert!(otsu_threshold(&v).is_finite());
            let _ = generic(a, b);
            let _ = generic(b, a);
        }
        // a FLT_MAX no-data value around CT data
        let v = Volume::from_fn([16, 8, 8], [1.0; 3], |x, y, _| if x == 0 { -f32::MAX } else { [-1000.0, 40.0, 900.0][y % 3] }).unwrap();
        let r = data_range(&v);
        assert_eq!(r.sentinel, Some(-f32::MAX));
        assert_eq!(r.bulk, (-1000.0, 900.0));
        assert_eq!(r.sentinel_voxels, 64);
        assert!(looks_like_ct(&v));
        // ordinary data have none, nor have two-valued masks
        let m = Volume::from_fn([4, 4, 4], [1.0; 3], |x, _, _| (x % 2) as f32).unwrap();
        assert_eq!(data_range(&m).sentinel, None);
    }

    #[test]
    fn otsu_separates_two_populations() {
        let v = Volume::from_fn([10, 10, 10], [1.0; 3], |x, _, _| if x < 5 { 10.0 } else { 200.0 }).unwrap();
        let t = otsu_threshold(&v);
        assert!(t > 10.0 && t <= 200.0, "{t}");
    }
}
