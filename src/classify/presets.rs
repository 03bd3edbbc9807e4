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

/// True when the volume looks like CT in Hounsfield units (air near −1000).
pub fn looks_like_ct(v: &Volume) -> bool {
    let (lo, hi) = v.value_range();
    lo <= -900.0 && lo >= -3100.0 && hi > 0.0
}

/// Otsu's threshold over a 256-bin histogram: the density that best separates
/// background from object. A sensible default iso value for MRI and unknown data.
pub fn otsu_threshold(v: &Volume) -> f32 {
    let (lo, hi) = v.value_range();
    if hi <= lo {
        return lo;
    }
    let h = v.histogram(256);
    let t = otsu_bins(&h, 0, 256).unwrap_or(0);
    lo + (hi - lo) * (t as f32 + 1.0) / 256.0
}

/// Otsu's split of histogram bins `[a, b)`: the last bin of the lower class.
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
    let (lo, hi) = v.value_range();
    if hi <= lo {
        return vec![];
    }
    let h = v.histogram(256);
    let to_density = |t: usize| lo + (hi - lo) * t as f32 / 256.0;
    multi_otsu(&h, 4).into_iter().map(to_density).collect()
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
    let hi = v.value_range().1;
    let names = ["low", "mid", "high"];
    let ts = histogram_thresholds(v);
    let ts = if ts.is_empty() { vec![otsu_threshold(v)] } else { ts };
    ts.iter().zip(names).map(|(&t, name)| Tissue { name, ..generic(t, hi) }).collect()
}

/// A generic preset for non-CT data: threshold at `t`, grey iso surface, and a
/// ramp that makes everything above `t` semi-transparent.
pub fn generic(t: f32, hi: f32) -> Tissue {
    let rgb = [0.92, 0.9, 0.85];
    let top = if hi > t { hi } else { t + 1.0 };
    Tissue { name: "auto", threshold: t, rgb, tf: tf(&[(t, 0.0), (t + (top - t) * 0.5, 0.25), (top, 0.6)], &[(t, rgb)]) }
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
    fn otsu_separates_two_populations() {
        let v = Volume::from_fn([10, 10, 10], [1.0; 3], |x, _, _| if x < 5 { 10.0 } else { 200.0 }).unwrap();
        let t = otsu_threshold(&v);
        assert!(t > 10.0 && t <= 200.0, "{t}");
    }
}
