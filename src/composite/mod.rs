//! Compositing into the intermediate image: the traversals and the
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

pub mod lean;
pub mod lean_cubic;
pub mod raycast;
pub mod slices;

pub use crate::classify::shading::Shading;
pub use crate::view::opacity::{OpacityTable, RayRow, correct_alpha};
pub use crate::view::plan::Rect;

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
    }
}
