//! Stage 6 — the intermediate image and the compositing arithmetic.
//!
//! Owns [`Intermediate`] (the base-plane image every shear-warp path renders into:
//! premultiplied RGBA plus the iso hit depth per pixel, and the rectangle that was
//! written this frame), the shading model ([`Shading`]: Blinn-Phong with a
//! headlight, two-sided) and front-to-back compositing ([`composite`]). Binary,
//! RLE and brute-force paths all call these same functions, so their images can be
//! compared sample for sample.

use crate::mask::Rect;

/// Blinn-Phong material for a headlight (light and eye along the view direction,
/// so the half vector is the light vector).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shading {
    pub ambient: f32,
    pub diffuse: f32,
    pub specular: f32,
    pub shininess: i32,
}

impl Default for Shading {
    fn default() -> Self {
        Shading { ambient: 0.15, diffuse: 0.75, specular: 0.3, shininess: 20 }
    }
}

impl Shading {
    /// Shaded colour of `rgb` for a surface with `|n · l| = ndl`.
    #[inline(always)]
    pub fn shade(&self, rgb: [f32; 3], ndl: f32) -> [f32; 3] {
        let d = self.ambient + self.diffuse * ndl;
        let s = self.specular * pow_int(ndl, self.shininess);
        [rgb[0] * d + s, rgb[1] * d + s, rgb[2] * d + s]
    }
}

/// `x^n` by repeated squaring, inline (`f32::powi` is a libcall on x86-64).
/// Negative `n` gives 1: shininess exponents are never negative.
#[inline(always)]
pub fn pow_int(x: f32, n: i32) -> f32 {
    let (mut r, mut b, mut e) = (1.0f32, x, n.max(0) as u32);
    while e > 0 {
        if e & 1 == 1 {
            r *= b;
        }
        b *= b;
        e >>= 1;
    }
    r
}

/// `|n · l|` for a voxel-space gradient `g`: `m` maps it to the eye-space z
/// component (the headlight's direction), `scale` to world units (for the length).
/// A zero gradient faces the viewer.
#[inline(always)]
pub fn headlight_ndl(g: [f32; 3], m: [f32; 3], scale: [f32; 3]) -> f32 {
    let dot = g[0] * m[0] + g[1] * m[1] + g[2] * m[2];
    let (a, b, c) = (g[0] * scale[0], g[1] * scale[1], g[2] * scale[2]);
    let len2 = a * a + b * b + c * c;
    if len2 > 1e-30 { (dot.abs() / len2.sqrt()).min(1.0) } else { 1.0 }
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

    #[test]
    fn pow_int_matches_powi() {
        for n in 0..40 {
            for x in [0.0f32, 0.3, 0.5, 0.9, 1.0] {
                let (a, b) = (pow_int(x, n), x.powi(n));
                assert!((a - b).abs() <= 1e-6 * b.abs().max(1e-30), "{x}^{n}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn headlight_facing_and_grazing() {
        let m = [0.0, 0.0, 1.0];
        let s = [1.0; 3];
        assert_eq!(headlight_ndl([0.0, 0.0, -3.0], m, s), 1.0);
        assert_eq!(headlight_ndl([2.0, 0.0, 0.0], m, s), 0.0);
        assert_eq!(headlight_ndl([0.0; 3], m, s), 1.0);
        let sh = Shading::default();
        assert!(sh.shade([1.0; 3], 1.0)[0] > sh.shade([1.0; 3], 0.2)[0]);
    }
}
