//! Stage 5 — compositing into the intermediate image: the traversals and the
//! policies they share.
//!
//! Owns [`Intermediate`] (the base-plane image every shear-warp path renders into:
//! premultiplied RGBA plus the iso hit depth per pixel, and the rectangle
//! ([`Rect`]) that was written this frame), the rendering [`Mode`], and the
//! policies written once: front-to-back "over" ([`composite`],
//! [`composite_premultiplied`]) and early ray termination ([`terminated`]); the
//! shading model is [`crate::classify::shading`]. The two traversals read the
//! frame plan ([`crate::view::plan`]) and nothing else about the view:
//! - [`raycast`]: the ray traversal (the binary rotator's rows and their brute
//!   force), post-classified and shaded per sample;
//! - [`slices`]: the slice traversal of the RLE path and its brute force,
//!   generic over what a sample is made of ([`slices::Sampler`]:
//!   pre-classified voxels, or post-classified densities and normals —
//!   Shear-Warp Deluxe P), with the intermediate samples between slices of
//!   a half-step plan (Deluxe I).

pub mod raycast;
pub mod slices;

pub use crate::classify::shading::Shading;

/// Rendering mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Mode {
    /// Iso-surface preview: the first sample at or above the iso value, shaded, opaque.
    Iso,
    /// Full alpha blending through the transfer function.
    Blend,
}

impl Mode {
    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Iso => "iso",
            Mode::Blend => "blend",
        }
    }
}

/// The early-ray-termination policy of every path: a pixel whose accumulated
/// opacity has reached `ert` composites nothing more. It is asked *before* each
/// sample, so the threshold means the same on the ray and slice traversals:
/// `ert ≤ 0` composites nothing, `ert = 1` stops only at full opacity (which
/// changes no pixel), and a NaN threshold composites nothing (the renderer
/// rejects it before a frame; this keeps every kernel in agreement anyway).
#[allow(clippy::neg_cmp_op_on_partial_ord)] // NaN on either side: terminated
#[inline(always)]
pub fn terminated(opacity: f32, ert: f32) -> bool {
    !(opacity < ert)
}

/// Front-to-back "over": adds a sample of colour `rgb` and opacity `alpha` behind
/// the premultiplied accumulation `acc`.
#[inline(always)]
pub fn composite(acc: &mut [f32; 4], rgb: [f32; 3], alpha: f32) {
    let t = (1.0 - acc[3]) * alpha;
    acc[0] += t * rgb[0];
    acc[1] += t * rgb[1];
    acc[2] += t * rgb[2];
    acc[3] += t;
}

/// Front-to-back "over" of an already premultiplied sample `s = [α·r, α·g, α·b, α]`
/// (the pre-classified paths blend premultiplied voxels, then composite the blend).
#[inline(always)]
pub fn composite_premultiplied(acc: &mut [f32; 4], s: [f32; 4]) {
    let t = 1.0 - acc[3];
    acc[0] += t * s[0];
    acc[1] += t * s[1];
    acc[2] += t * s[2];
    acc[3] += t * s[3];
}

/// Opacity bins of an [`OpacityTable`] row over `α ∈ [0, 1]`.
const ALPHA_BINS: usize = 1024;
/// Most rows of an [`OpacityTable`]: past it, the rows are spaced wider.
const MAX_ROWS: usize = 1024;

/// The opacity correction of the pre-classified paths' premultiplied samples,
/// each already corrected to one sample spacing, to a ray whose spacing is
/// `e ≥ 1` times that: `α' = 1 − (1 − α)^e`, the colour scaled with it (`c·α'/α`,
/// so premultiplied colour is attenuated once). Without a log2 and an exp2 per
/// sample: the table holds `g(α, e) = α'/α` (`e` at `α = 0`) at `α = i / 1024`
/// and on a fixed lattice of exponents `e = 1 + r·h`, and
/// [`OpacityTable::correct`] interpolates it bilinearly and multiplies the
/// sample by it. With `h` = 1/64 (exponents up to 17; 4 kB a row) its largest
/// error in `α'` is below 2e-5, one 200th of a 1/255 step (the unit test
/// measures it); past that the rows are spaced wider (at most 1024 of them),
/// `h` = 1/32 up to `e` = 33 (6.4e-5), 1/16 up to 65 (2.5e-4). `e = 1` (every ray of a
/// parallel view, the rays near a perspective view's axis) returns the sample
/// unchanged, bit for bit; so do `α = 0` and `α = 1`.
///
/// The frame plan owns one ([`crate::view::plan::FramePlan::correct_opacity`]),
/// grown to its largest exponent as frames need it ([`OpacityTable::cover`]),
/// so the RLE slices and their brute force correct with the same numbers.
#[derive(Clone, Debug, Default)]
pub struct OpacityTable {
    /// Rows per unit of exponent (`1/h`; 0 while empty).
    per_unit: f32,
    /// Rows held (0 or at least 2).
    rows: usize,
    /// `g` by row, `ALPHA_BINS + 1` entries a row.
    g: Vec<f32>,
}

impl OpacityTable {
    /// Makes the table hold every exponent in `[1, e_max]` (only the rows it
    /// lacks are computed: a table that already does is left as it is).
    pub fn cover(&mut self, e_max: f32) {
        let span = if e_max.is_finite() { (e_max - 1.0).max(0.0) as f64 } else { 0.0 };
        let mut per_unit = 64.0f64;
        while span * per_unit > (MAX_ROWS - 2) as f64 {
            per_unit *= 0.5;
        }
        let rows = (span * per_unit).ceil() as usize + 2;
        if per_unit as f32 != self.per_unit {
            (self.per_unit, self.rows) = (per_unit as f32, 0);
            self.g.clear();
        }
        for r in self.rows..rows {
            let e = 1.0 + r as f64 / per_unit;
            self.g.extend((0..=ALPHA_BINS).map(|i| {
                let a = i as f64 / ALPHA_BINS as f64;
                match (r, i) {
                    (0, _) => 1.0,
                    (_, 0) => e as f32,
                    _ => ((1.0 - (1.0 - a).powf(e)) / a) as f32,
                }
            }));
        }
        self.rows = self.rows.max(rows);
    }

    /// Sample `s` corrected to exponent `e` (in `[1, e_max]` of
    /// [`OpacityTable::cover`]).
    #[inline(always)]
    pub fn correct(&self, s: [f32; 4], e: f32) -> [f32; 4] {
        if e == 1.0 || self.rows < 2 {
            return s;
        }
        self.correct_row(s, self.row(e))
    }

    /// Where exponent `e` (in `[1, e_max]` of [`OpacityTable::cover`], which
    /// has been called) lies in the table: [`OpacityTable::correct_row`]
    /// with it is [`OpacityTable::correct`] with `e`, bit for bit, so a ray's
    /// row can be found once for all its samples.
    #[inline]
    pub fn row(&self, e: f32) -> RayRow {
        let (r, fe) = table_cell((e - 1.0) * self.per_unit);
        RayRow { at: (r.min(self.rows.max(2) - 2) * (ALPHA_BINS + 1)) as u32, fe }
    }

    /// Sample `s` corrected on the ray whose exponent is at `row`
    /// ([`OpacityTable::row`]). Exponent 1 (row 0, no fraction) returns `s`
    /// itself: that row is all ones.
    #[inline(always)]
    pub fn correct_row(&self, s: [f32; 4], row: RayRow) -> [f32; 4] {
        let a = s[3];
        if !(a > 0.0 && a < 1.0) {
            return s;
        }
        const W: usize = ALPHA_BINS + 1;
        let (i, fa) = table_cell(a * ALPHA_BINS as f32);
        let at = row.at as usize + i;
        let (g0, g1) = (&self.g[at..][..2], &self.g[at + W..][..2]);
        let lo = g0[0] + fa * (g0[1] - g0[0]);
        let hi = g1[0] + fa * (g1[1] - g1[0]);
        let g = lo + row.fe * (hi - lo);
        [s[0] * g, s[1] * g, s[2] * g, (a * g).min(1.0)]
    }
}

/// A ray's place in an [`OpacityTable`]: the offset of its exponent's lower
/// row and the fraction towards the next ([`OpacityTable::row`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RayRow {
    at: u32,
    fe: f32,
}

/// The lower corner of the table cell holding `x ≥ 0` (`x < 2²²`) and the
/// fraction past it, by rounding `x − ½` to an integer: adding 1.5·2²³ leaves
/// it in the low mantissa bits (the sum stays in `[2²³, 2²⁴)`, where f32 steps
/// by 1; a floor or a float-to-integer cast costs several instructions more).
#[inline(always)]
fn table_cell(x: f32) -> (usize, f32) {
    const MAGIC: f32 = 12_582_912.0;
    let b = x - 0.5 + MAGIC;
    ((b.to_bits() & 0x3f_ffff) as usize, x - (b - MAGIC))
}

/// The opacity `α` of one sample spacing corrected to `e` spacings,
/// `1 − (1 − α)^e`, to about 2e-7 (the raycast paths' straight-alpha samples;
/// `e = 1` and `α` of 0 or 1 return `α` bit for bit).
#[inline(always)]
pub fn correct_alpha(a: f32, e: f32) -> f32 {
    if e == 1.0 || !(a > 0.0 && a < 1.0) {
        return a;
    }
    1.0 - exp2_approx(e * log2_approx(1.0 - a))
}

/// `log2 x` for a normal `x > 0`, to about 1e-7 relative: the exponent from
/// the bits, the mantissa reduced to `[√½, √2)` and `2·atanh(t)/ln 2` with
/// `t = (m − 1)/(m + 1)` (`|t| ≤ 0.172`) to `t⁹`. Plain f32 arithmetic: the same
/// bits on every path and thread.
#[inline(always)]
fn log2_approx(x: f32) -> f32 {
    let bits = x.to_bits();
    let mut e = ((bits >> 23) & 0xff) as i32 - 127;
    let mut m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    if m > std::f32::consts::SQRT_2 {
        m *= 0.5;
        e += 1;
    }
    let t = (m - 1.0) / (m + 1.0);
    let t2 = t * t;
    let p = t * (2.0 + t2 * (2.0 / 3.0 + t2 * (2.0 / 5.0 + t2 * (2.0 / 7.0 + t2 * (2.0 / 9.0)))));
    e as f32 + p * std::f32::consts::LOG2_E
}

/// `2^y` for `y ≤ 0`, to about 2e-7 relative (0 below `2^−126`): `2^round(y)`
/// from the bits times the Taylor series of `e^(f·ln 2)`, `|f| ≤ 1/2`, to `f⁶`.
#[inline(always)]
fn exp2_approx(y: f32) -> f32 {
    // (NaN takes the first branch too)
    if y.is_nan() || y <= -126.0 {
        return 0.0;
    }
    // an integer within 1/2 of y (y ≤ 0; truncation of a positive number, not
    // a call to round, which the x86-64 baseline has no instruction for)
    let i = -((0.5 - y) as i32 as f32);
    let x = (y - i) * std::f32::consts::LN_2;
    let p = 1.0 + x * (1.0 + x * (0.5 + x * (1.0 / 6.0 + x * (1.0 / 24.0 + x * (1.0 / 120.0 + x * (1.0 / 720.0))))));
    p * f32::from_bits(((i as i32 + 127) as u32) << 23)
}

/// Inclusive rectangle `[p0, p1] × [q0, q1]` of grid columns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rect {
    pub p0: usize,
    pub p1: usize,
    pub q0: usize,
    pub q1: usize,
}

impl Rect {
    pub(crate) fn union(a: Option<Rect>, b: Option<Rect>) -> Option<Rect> {
        match (a, b) {
            (Some(a), Some(b)) => Some(Rect { p0: a.p0.min(b.p0), p1: a.p1.max(b.p1), q0: a.q0.min(b.q0), q1: a.q1.max(b.q1) }),
            (a, None) => a,
            (None, b) => b,
        }
    }
}

/// The intermediate (base-plane) image.
#[derive(Clone, Debug, Default)]
pub struct Intermediate {
    /// Size `[width, height]`.
    pub size: [usize; 2],
    /// Premultiplied RGBA, row-major.
    pub rgba: Vec<[f32; 4]>,
    /// Fractional slice index of the iso hit (NaN where no hit; iso mode only).
    pub depth: Vec<f32>,
    /// Pixels outside this rectangle are transparent; inside, every pixel was written.
    pub valid: Option<Rect>,
}

impl Intermediate {
    /// Bytes held (capacity of both planes).
    pub fn bytes(&self) -> usize {
        self.rgba.capacity() * 16 + self.depth.capacity() * 4
    }

    /// Resizes for a grid of `size` (reusing the allocation when it is big enough).
    pub fn prepare(&mut self, size: [usize; 2]) {
        let n = size[0] * size[1];
        if self.size != size {
            self.size = size;
            self.rgba.clear();
            self.rgba.resize(n, [0.0; 4]);
            self.depth.clear();
            self.depth.resize(n, f32::NAN);
        }
        self.valid = None;
    }

    /// Marks `rect` as this frame's valid rectangle and clears the one-pixel ring
    /// around it, so a bilinear tap anywhere in `[p0 − 1, p1 + 1] × [q0 − 1, q1 + 1]`
    /// reads either a rendered pixel or transparent black (never a stale one).
    pub fn seal(&mut self, rect: Option<Rect>) {
        self.valid = rect;
        let Some(r) = rect else { return };
        let [w, h] = self.size;
        let (x0, x1) = (r.p0.saturating_sub(1), (r.p1 + 1).min(w - 1));
        for q in [r.q0.wrapping_sub(1), r.q1 + 1] {
            if q < h {
                self.rgba[q * w + x0..=q * w + x1].fill([0.0; 4]);
            }
        }
        for q in r.q0..=r.q1 {
            if r.p0 > 0 {
                self.rgba[q * w + r.p0 - 1] = [0.0; 4];
            }
            if r.p1 + 1 < w {
                self.rgba[q * w + r.p1 + 1] = [0.0; 4];
            }
        }
    }

    /// Pixel `(p, q)`, transparent outside the valid rectangle.
    #[inline(always)]
    pub fn get(&self, p: isize, q: isize) -> [f32; 4] {
        match self.valid {
            Some(r) if p >= r.p0 as isize && p <= r.p1 as isize && q >= r.q0 as isize && q <= r.q1 as isize => {
                self.rgba[q as usize * self.size[0] + p as usize]
            }
            _ => [0.0; 4],
        }
    }

    /// Whether this image holds an iso-depth plane for a grid of `size`
    /// (what reading another frame's or pyramid's depths checks first).
    pub fn holds_depths_of(&self, size: [usize; 2]) -> bool {
        self.size == size && self.depth.len() == size[0] * size[1]
    }

    /// Iso depth at `(p, q)` (NaN outside the valid rectangle or without a hit).
    pub fn depth_at(&self, p: usize, q: usize) -> f32 {
        match self.valid {
            Some(r) if p >= r.p0 && p <= r.p1 && q >= r.q0 && q <= r.q1 => self.depth[q * self.size[0] + p],
            _ => f32::NAN,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compositing_is_over() {
        let mut acc = [0.0; 4];
        composite(&mut acc, [1.0, 0.0, 0.0], 0.5);
        composite(&mut acc, [0.0, 1.0, 0.0], 0.5);
        assert_eq!(acc, [0.5, 0.25, 0.0, 0.75]);
        composite(&mut acc, [0.0, 0.0, 1.0], 1.0);
        assert_eq!(acc[3], 1.0);
        composite(&mut acc, [1.0, 1.0, 1.0], 1.0);
        assert_eq!(acc, [0.5, 0.25, 0.25, 1.0]);
    }

    /// Two samples at one spacing through a homogeneous medium equal one at
    /// twice the spacing, colour included (premultiplied colour attenuated once).
    #[test]
    fn perspective_opacity_correction_is_the_spacing_law() {
        let mut table = OpacityTable::default();
        table.cover(3.0);
        let s = [0.3 * 0.6, 0.3 * 0.2, 0.0, 0.3];
        assert_eq!(table.correct(s, 1.0), s);
        let mut two = [0.0; 4];
        composite_premultiplied(&mut two, s);
        composite_premultiplied(&mut two, s);
        let one = table.correct(s, 2.0);
        for c in 0..4 {
            assert!((one[c] - two[c]).abs() < 2e-5, "{one:?} vs {two:?}");
        }
        assert_eq!(table.correct([0.5, 0.5, 0.5, 1.0], 1.7), [0.5, 0.5, 0.5, 1.0]);
        assert_eq!(table.correct([0.0; 4], 1.7), [0.0; 4]);
        // the table against the library's pow, over α (dense, and near 0 and 1)
        // and e (on and between its rows): at most 2e-5 off
        let alphas = (1..4000).map(|i| i as f32 / 4000.0).chain((1..60).flat_map(|i| {
            let t = 10f32.powf(-(i as f32) / 8.0);
            [t, 1.0 - t]
        }));
        let mut worst = 0f64;
        for a in alphas.filter(|&a| a > 0.0 && a < 1.0) {
            for e in [1.0001f32, 1.003, 1.01, 1.0234, 1.2, 1.5, 1.77, 2.0, 2.99, 3.0] {
                let want = 1.0 - (1.0 - a as f64).powf(e as f64);
                let got = table.correct([a, a, a, a], e);
                worst = worst.max((got[3] as f64 - want).abs());
            }
        }
        assert!(worst < 2e-5, "largest error in α' {worst}");
        // the raycast paths' correction against the library's pow
        for i in 1..1000 {
            let a = i as f32 / 1000.0;
            for e in [1.0001f32, 1.01, 1.2, 1.5, 2.0, 3.0] {
                let want = 1.0 - (1.0 - a as f64).powf(e as f64);
                let got = correct_alpha(a, e) as f64;
                assert!((got - want).abs() < 2e-7, "α {a}, e {e}: {got} vs {want}");
            }
        }
        // a wider span of exponents spaces the rows wider; a narrower one keeps them
        table.cover(1.5);
        assert_eq!((table.per_unit, table.rows), (64.0, 130));
        table.cover(30.0);
        assert!(table.per_unit == 32.0 && table.rows <= MAX_ROWS);
        for (a, e) in [(0.25f32, 20.0f32), (0.01, 1.01), (0.5, 1.0234)] {
            let want = 1.0 - (1.0 - a as f64).powf(e as f64);
            assert!((table.correct([a; 4], e)[3] as f64 - want).abs() < 7e-5);
        }
        assert!((log2_approx(1e-30) as f64 - (1e-30f64).log2()).abs() < 1e-4);
        assert_eq!(exp2_approx(-200.0), 0.0);
    }
}
