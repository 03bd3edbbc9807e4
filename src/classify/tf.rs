//! Classification: densities to colour and opacity.
//!
//! Owns the user-facing [`TransferFunction`] (piecewise-linear opacity and colour
//! over density), the iso (threshold) preset, and the [`Classifier`]: the one
//! function every render path evaluates per sample. The classifier is a uniform
//! table of [`TABLE_NODES`] nodes over the volume's density range, linearly
//! interpolated. It also answers the question the mask builders ask — "can any
//! density in `[lo, hi]` be non-transparent?" — *about the same function*, so the
//! masks are conservative for exactly what is rendered, even for transfer
//! functions that are not monotone (a band of opacity between two corner values
//! counts; the paper's "any corner is opaque" rule would miss it).

use crate::error::{Error, Result};

/// Nodes in the classification table.
pub const TABLE_NODES: usize = 4096;

/// Piecewise-linear opacity and colour over density.
///
/// Outside its first and last control points each curve is constant.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferFunction {
    /// `(density, opacity)` control points, sorted by density, opacity in [0, 1].
    pub opacity: Vec<(f32, f32)>,
    /// `(density, [r, g, b])` control points, sorted by density, colours in [0, 1].
    pub color: Vec<(f32, [f32; 3])>,
}

impl TransferFunction {
    /// Builds and validates a transfer function.
    pub fn new(opacity: Vec<(f32, f32)>, color: Vec<(f32, [f32; 3])>) -> Result<Self> {
        if opacity.is_empty() || color.is_empty() {
            return Err(Error::value("transfer function", "needs at least one opacity and one colour point"));
        }
        let sorted = |d: &[f32]| d.windows(2).all(|w| w[0] <= w[1]);
        let od: Vec<f32> = opacity.iter().map(|p| p.0).collect();
        let cd: Vec<f32> = color.iter().map(|p| p.0).collect();
        if !sorted(&od) || !sorted(&cd) {
            return Err(Error::value("transfer function", "control points must be sorted by density"));
        }
        let finite01 = |x: f32| x.is_finite() && (0.0..=1.0).contains(&x);
        if od.iter().chain(&cd).any(|d| !d.is_finite()) {
            return Err(Error::value("transfer function", "densities must be finite"));
        }
        if !opacity.iter().all(|p| finite01(p.1)) || !color.iter().all(|p| p.1.iter().all(|&c| finite01(c))) {
            return Err(Error::value("transfer function", "opacities and colours must lie in [0, 1]"));
        }
        Ok(TransferFunction { opacity, color })
    }

    /// A threshold (iso) transfer function: transparent below `t`, opacity 1 and
    /// colour `rgb` from `t` on (a one-table-node ramp at `t`).
    pub fn threshold(t: f32, rgb: [f32; 3]) -> Self {
        TransferFunction { opacity: vec![(t, 0.0), (t, 1.0)], color: vec![(t, rgb)] }
    }

    /// A linear opacity ramp from 0 at `lo` to `max_alpha` at `hi`, with colour `rgb`.
    pub fn ramp(lo: f32, hi: f32, max_alpha: f32, rgb: [f32; 3]) -> Self {
        TransferFunction { opacity: vec![(lo, 0.0), (hi, max_alpha)], color: vec![(lo, rgb)] }
    }

    /// Opacity at density `d` (exact piecewise-linear evaluation).
    pub fn opacity_at(&self, d: f32) -> f32 {
        eval_pl(&self.opacity, d, |p| p.1, |a, b, t| a + (b - a) * t)
    }

    /// Colour at density `d` (exact piecewise-linear evaluation).
    pub fn color_at(&self, d: f32) -> [f32; 3] {
        eval_pl(&self.color, d, |p| p.1, |a, b, t| [0, 1, 2].map(|c| a[c] + (b[c] - a[c]) * t))
    }

    /// The lowest density with non-zero opacity (`None` if all transparent).
    pub fn lower_threshold(&self) -> Option<f32> {
        let first = self.opacity.iter().position(|p| p.1 > 0.0)?;
        Some(if first == 0 { f32::NEG_INFINITY } else { self.opacity[first - 1].0 })
    }
}

fn eval_pl<P: Copy, V: Copy>(pts: &[(f32, P)], d: f32, val: impl Fn(&(f32, P)) -> V, lerp: impl Fn(V, V, f32) -> V) -> V {
    let n = pts.len();
    if d <= pts[0].0 {
        // at a step (two points at the same density) the upper value wins from the step on
        let last_at = pts.iter().rposition(|p| p.0 == pts[0].0).unwrap_or(0);
        return if d == pts[0].0 { val(&pts[last_at]) } else { val(&pts[0]) };
    }
    if d >= pts[n - 1].0 {
        return val(&pts[n - 1]);
    }
    // first point with density > d
    let hi = pts.partition_point(|p| p.0 <= d);
    let (a, b) = (&pts[hi - 1], &pts[hi]);
    let t = (d - a.0) / (b.0 - a.0);
    lerp(val(a), val(b), t)
}

/// Colour and opacity of one classified sample.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Rgba {
    pub r: f32,
    pub g: f32,
    pub b: f32,
    pub a: f32,
}

/// The classification table every render path evaluates.
#[derive(Clone, Debug)]
pub struct Classifier {
    d0: f32,
    inv_step: f32,
    step: f32,
    table: Vec<Rgba>,
    /// `next_nz[i]` = smallest node index ≥ i with non-zero opacity (or `TABLE_NODES`).
    next_nz: Vec<u32>,
    /// Opacity of each node before the per-view sample-spacing correction.
    raw_alpha: Vec<f32>,
    /// The sample-spacing ratio `table` is corrected for.
    ratio: f32,
    tf: TransferFunction,
}

impl Classifier {
    /// Tabulates `tf` over the density range `[lo, hi]` (normally the volume's).
    pub fn new(tf: &TransferFunction, lo: f32, hi: f32) -> Self {
        // in f64: the range may span the whole f32 range (±FLT_MAX sentinels),
        // where hi − lo overflows f32 but its 4095th part does not
        let (lo, hi) = if hi > lo && lo.is_finite() && hi.is_finite() {
            (lo, hi)
        } else {
            let up = lo + 1.0;
            (lo, if up > lo { up } else { lo + lo.abs() * f32::EPSILON * 2.0 })
        };
        let step = if (hi - lo).is_finite() {
            (hi - lo) / (TABLE_NODES - 1) as f32
        } else {
            ((hi as f64 - lo as f64) / (TABLE_NODES - 1) as f64) as f32
        };
        let table: Vec<Rgba> = (0..TABLE_NODES)
            .map(|i| {
                let d = lo + step * i as f32;
                let d = if d.is_finite() { d } else { (lo as f64 + step as f64 * i as f64).min(f32::MAX as f64) as f32 };
                let [r, g, b] = tf.color_at(d);
                Rgba { r, g, b, a: tf.opacity_at(d) }
            })
            .collect();
        let mut next_nz = vec![TABLE_NODES as u32; TABLE_NODES + 1];
        for i in (0..TABLE_NODES).rev() {
            next_nz[i] = if table[i].a > 0.0 { i as u32 } else { next_nz[i + 1] };
        }
        let raw_alpha = table.iter().map(|t| t.a).collect();
        Classifier { d0: lo, inv_step: 1.0 / step, step, table, next_nz, raw_alpha, ratio: 1.0, tf: tf.clone() }
    }

    /// Corrects the table's opacities for samples `ratio` times the reference
    /// spacing apart: `α' = 1 − (1 − α)^ratio` at every node (VolPack's opacity
    /// correction). Cheap to call every frame: the table is rebuilt only when the
    /// ratio changes. Zero stays zero, so [`Classifier::may_be_visible`] is unaffected.
    pub fn set_sample_ratio(&mut self, ratio: f32) {
        if ratio == self.ratio || !ratio.is_finite() || ratio <= 0.0 {
            return;
        }
        self.ratio = ratio;
        // ratio 1 restores the raw opacities exactly (1 − (1 − a) rounds), so the
        // table is a function of the ratio alone, never of the ratios before it
        for (t, &a) in self.table.iter_mut().zip(&self.raw_alpha) {
            t.a = if a >= 1.0 || ratio == 1.0 { a.min(1.0) } else { 1.0 - (1.0 - a).powf(ratio) };
        }
    }

    /// The sample-spacing ratio the opacities are corrected for.
    pub fn sample_ratio(&self) -> f32 {
        self.ratio
    }

    /// The transfer function this table was built from.
    pub fn transfer_function(&self) -> &TransferFunction {
        &self.tf
    }

    /// Table position of density `d` (clamped into the table).
    #[inline(always)]
    fn pos(&self, d: f32) -> f32 {
        ((d - self.d0) * self.inv_step).clamp(0.0, (TABLE_NODES - 1) as f32)
    }

    /// Colour and opacity at density `d`: linear interpolation between table nodes.
    #[inline(always)]
    pub fn classify(&self, d: f32) -> Rgba {
        let p = self.pos(d);
        let i = (p as usize).min(TABLE_NODES - 2);
        let t = p - i as f32;
        let (a, b) = (self.table[i], self.table[i + 1]);
        Rgba { r: a.r + (b.r - a.r) * t, g: a.g + (b.g - a.g) * t, b: a.b + (b.b - a.b) * t, a: a.a + (b.a - a.a) * t }
    }

    /// Opacity only (cheaper than [`Classifier::classify`]).
    #[inline(always)]
    pub fn alpha(&self, d: f32) -> f32 {
        let p = self.pos(d);
        let i = (p as usize).min(TABLE_NODES - 2);
        let t = p - i as f32;
        let (a, b) = (self.table[i].a, self.table[i + 1].a);
        a + (b - a) * t
    }

    /// True when some density in `[lo, hi]` may classify to non-zero opacity.
    ///
    /// Conservative for [`Classifier::alpha`]: if this is false, `alpha(d) == 0`
    /// for every `d` in `[lo, hi]`. The interpolated function is piecewise linear
    /// with nodes at the table entries, so its maximum over an interval is at a node
    /// inside it or at an end; we check every node from the one at or below `lo` to
    /// the one at or above `hi`, which covers both ends.
    #[inline]
    pub fn may_be_visible(&self, lo: f32, hi: f32) -> bool {
        let i0 = self.pos(lo).floor() as usize;
        let i1 = (self.pos(hi).ceil() as usize).min(TABLE_NODES - 1);
        (self.next_nz[i0] as usize) <= i1
    }

    /// Density of table node `i`.
    pub fn node_density(&self, i: usize) -> f32 {
        let d = self.d0 + self.step * i as f32;
        if d.is_finite() { d } else { (self.d0 as f64 + self.step as f64 * i as f64).clamp(f32::MIN as f64, f32::MAX as f64) as f32 }
    }

    /// The table node nearest to density `d` (clamped into the table): the
    /// pre-classified paths quantize each voxel's density to it.
    #[inline(always)]
    pub fn nearest_node(&self, d: f32) -> usize {
        ((self.pos(d) + 0.5) as usize).min(TABLE_NODES - 1)
    }

    /// Colour and opacity of table node `i` *before* the sample-spacing
    /// correction of [`Classifier::set_sample_ratio`].
    pub fn raw_node(&self, i: usize) -> Rgba {
        Rgba { a: self.raw_alpha[i], ..self.table[i] }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn piecewise_linear_evaluation() {
        let tf = TransferFunction::new(vec![(0.0, 0.0), (10.0, 1.0), (20.0, 0.0)], vec![(0.0, [1.0, 0.0, 0.0]), (20.0, [0.0, 0.0, 1.0])])
            .unwrap();
        assert_eq!(tf.opacity_at(-5.0), 0.0);
        assert_eq!(tf.opacity_at(5.0), 0.5);
        assert_eq!(tf.opacity_at(10.0), 1.0);
        assert_eq!(tf.opacity_at(25.0), 0.0);
        assert_eq!(tf.color_at(10.0), [0.5, 0.0, 0.5]);
        let th = TransferFunction::threshold(100.0, [1.0; 3]);
        assert_eq!(th.opacity_at(99.99), 0.0);
        assert_eq!(th.opacity_at(100.0), 1.0);
        assert_eq!(th.lower_threshold(), Some(100.0));
    }

    #[test]
    fn rejects_bad_transfer_functions() {
        assert!(TransferFunction::new(vec![(1.0, 0.0), (0.0, 1.0)], vec![(0.0, [1.0; 3])]).is_err());
        assert!(TransferFunction::new(vec![(0.0, 1.5)], vec![(0.0, [1.0; 3])]).is_err());
        assert!(TransferFunction::new(vec![(f32::NAN, 0.5)], vec![(0.0, [1.0; 3])]).is_err());
        assert!(TransferFunction::new(vec![], vec![(0.0, [1.0; 3])]).is_err());
    }

    #[test]
    fn may_be_visible_is_conservative_for_a_band() {
        // opacity only in a narrow band strictly between two corner values
        let tf = TransferFunction::new(vec![(100.0, 0.0), (101.0, 0.7), (102.0, 0.0)], vec![(0.0, [1.0; 3])]).unwrap();
        let c = Classifier::new(&tf, 0.0, 1000.0);
        assert!(c.may_be_visible(50.0, 300.0));
        assert!(!c.may_be_visible(0.0, 90.0));
        assert!(!c.may_be_visible(110.0, 1000.0));
        // brute check over many intervals
        for lo in (0..1000).step_by(7) {
            for w in [0.0f32, 0.3, 1.0, 2.5, 10.0] {
                let (lo, hi) = (lo as f32 * 0.37, lo as f32 * 0.37 + w);
                let any = (0..=200).any(|s| c.alpha(lo + (hi - lo) * s as f32 / 200.0) > 0.0);
                if any {
                    assert!(c.may_be_visible(lo, hi), "[{lo}, {hi}]");
                }
            }
        }
    }
}
