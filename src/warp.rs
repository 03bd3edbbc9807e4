//! Stage 7 — the warp: intermediate image to final image.
//!
//! Owns the final [`Image`] (premultiplied RGBA f32, row 0 at the top) and the
//! bilinear affine [`warp`] shared by every shear-warp path: each output pixel is
//! mapped back through the inverse of the factorization's 2-D warp into the
//! intermediate image and resampled bilinearly. Only the output span of each row
//! whose preimage meets the intermediate image's valid rectangle is resampled;
//! the rest is cleared.

use rayon::prelude::*;

use crate::composite::Intermediate;
use crate::error::{Error, Result};
use crate::view::Factorization;

/// A rendered image: premultiplied RGBA in [0, 1] (over black when displayed).
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub data: Vec<[f32; 4]>,
}

impl Image {
    /// A transparent image.
    pub fn new(width: usize, height: usize) -> Self {
        Image { width, height, data: vec![[0.0; 4]; width * height] }
    }

    /// Resizes (and clears) when the size differs.
    pub fn prepare(&mut self, width: usize, height: usize) {
        if self.width != width || self.height != height {
            *self = Image::new(width, height);
        }
    }

    /// Pixel at `(x, y)`.
    pub fn at(&self, x: usize, y: usize) -> [f32; 4] {
        self.data[y * self.width + x]
    }

    /// 8-bit RGB over a black background.
    pub fn to_rgb8(&self) -> image::RgbImage {
        let mut out = image::RgbImage::new(self.width as u32, self.height as u32);
        for (px, c) in out.pixels_mut().zip(&self.data) {
            *px = image::Rgb([to8(c[0]), to8(c[1]), to8(c[2])]);
        }
        out
    }

    /// Writes a PNG.
    pub fn save_png(&self, path: &std::path::Path) -> Result<()> {
        self.to_rgb8().save_with_format(path, image::ImageFormat::Png).map_err(|e| Error::file(path, format!("cannot write PNG: {e}")))
    }

    /// Fraction of pixels with any coverage.
    pub fn coverage(&self) -> f64 {
        self.data.iter().filter(|c| c[3] > 0.0).count() as f64 / self.data.len().max(1) as f64
    }
}

#[inline]
fn to8(c: f32) -> u8 {
    (c.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// Span `[lo, hi]` of `u` where `lo_b < a·u + b < hi_b`, intersected with `[lo, hi]`.
fn clip_span(lo: f64, hi: f64, a: f64, b: f64, lo_b: f64, hi_b: f64) -> (f64, f64) {
    if a.abs() < 1e-12 {
        return if b > lo_b && b < hi_b { (lo, hi) } else { (1.0, 0.0) };
    }
    let (x0, x1) = ((lo_b - b) / a, (hi_b - b) / a);
    (lo.max(x0.min(x1)), hi.min(x0.max(x1)))
}

/// Warps `inter` into `out` (already sized): output pixel `(u, v)` takes the
/// bilinear sample of `inter` at the intermediate position of the sheared point
/// `inverse_warp(u, v)` plus `origin` (the intermediate pixel of sheared `(0, 0)`).
pub fn warp(inter: &Intermediate, f: &Factorization, origin: [f64; 2], out: &mut Image) {
    let (inv, it) = f.inverse_warp();
    let w = out.width;
    let Some(r) = inter.valid else {
        out.data.par_iter_mut().for_each(|c| *c = [0.0; 4]);
        return;
    };
    out.data.par_chunks_mut(w).enumerate().for_each(|(v, row)| {
        let vf = v as f64;
        // p(u) = inv00·u + inv01·v + it0 + origin0, same for q
        let (pa, pb) = (inv[0][0], inv[0][1] * vf + it[0] + origin[0]);
        let (qa, qb) = (inv[1][0], inv[1][1] * vf + it[1] + origin[1]);
        let (lo, hi) = clip_span(0.0, (w - 1) as f64, pa, pb, r.p0 as f64 - 1.0, r.p1 as f64 + 1.0);
        let (lo, hi) = clip_span(lo, hi, qa, qb, r.q0 as f64 - 1.0, r.q1 as f64 + 1.0);
        let (u0, u1) = if lo <= hi { (lo.ceil().max(0.0) as usize, (hi.floor() as usize).min(w - 1)) } else { (1, 0) };
        if u0 > u1 {
            row.fill([0.0; 4]);
            return;
        }
        row[..u0].fill([0.0; 4]);
        row[u1 + 1..].fill([0.0; 4]);
        // every tap of this span lies in the valid rectangle or its cleared ring
        let iw = inter.size[0];
        let (ih, rgba) = (inter.size[1], &inter.rgba);
        for (u, px) in row.iter_mut().enumerate().take(u1 + 1).skip(u0) {
            let p = pa * u as f64 + pb;
            let q = qa * u as f64 + qb;
            let (x0, y0) = (p.floor(), q.floor());
            let (fx, fy) = ((p - x0) as f32, (q - y0) as f32);
            // clamp only guards against rounding at the span ends
            let x0 = (x0 as usize).min(iw - 2);
            let y0 = (y0 as usize).min(ih - 2);
            let i = y0 * iw + x0;
            let (c00, c10, c01, c11) = (rgba[i], rgba[i + 1], rgba[i + iw], rgba[i + iw + 1]);
            for c in 0..4 {
                let top = c00[c] + (c10[c] - c00[c]) * fx;
                let bot = c01[c] + (c11[c] - c01[c]) * fx;
                px[c] = top + (bot - top) * fy;
            }
        }
    });
}
