//! Stage 7 — the warp: intermediate image to final image.
//!
//! Owns the final [`Image`] (premultiplied RGBA f32, row 0 at the top) and the
//! bilinear affine [`warp`] shared by every shear-warp path: each output pixel is
//! mapped back through the inverse of the factorization's 2-D warp into the
//! intermediate image and resampled bilinearly. Only the output span of each row
//! whose preimage meets the intermediate image's valid rectangle is resampled;
//! the rest is cleared.

use glam::Vec4;
use rayon::prelude::*;

use crate::composite::Intermediate;
use crate::error::{Error, Result};
use crate::view::Factorization;

/// A rendered image: premultiplied RGBA in [0, 1] (over black when displayed).
/// Two images are equal when their sizes and pixels are.
#[derive(Clone, Debug)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub data: Vec<[f32; 4]>,
    /// Per row, the span `[u0, u1)` the last warp wrote; everything else in the row
    /// is transparent. Lets the next warp clear only what it no longer covers.
    spans: Vec<(u32, u32)>,
    /// Which renderer frame last wrote this image (0: none); lets a renderer skip
    /// a frame whose inputs did not change.
    pub(crate) stamp: u64,
}

impl Image {
    /// A transparent image.
    pub fn new(width: usize, height: usize) -> Self {
        Image { width, height, data: vec![[0.0; 4]; width * height], spans: vec![(0, 0); height], stamp: 0 }
    }

    /// Resizes (and clears) when the size differs.
    pub fn prepare(&mut self, width: usize, height: usize) {
        if self.width != width || self.height != height {
            *self = Image::new(width, height);
        }
    }

    /// An image made from pixel data (`data.len()` must be `width · height`).
    pub fn from_data(width: usize, height: usize, data: Vec<[f32; 4]>) -> Self {
        assert_eq!(data.len(), width * height, "pixel count");
        Image { width, height, data, spans: vec![(0, width as u32); height], stamp: 0 }
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

impl PartialEq for Image {
    fn eq(&self, o: &Self) -> bool {
        self.width == o.width && self.height == o.height && self.data == o.data
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
    let valid = inter.valid;
    out.data.par_chunks_mut(w).zip(out.spans.par_iter_mut()).enumerate().for_each(|(v, (row, span))| {
        let (old0, old1) = (span.0 as usize, span.1 as usize);
        let Some(r) = valid else {
            row[old0..old1].fill([0.0; 4]);
            *span = (0, 0);
            return;
        };
        let vf = v as f64;
        // p(u) = inv00·u + inv01·v + it0 + origin0, same for q
        let (pa, pb) = (inv[0][0], inv[0][1] * vf + it[0] + origin[0]);
        let (qa, qb) = (inv[1][0], inv[1][1] * vf + it[1] + origin[1]);
        let (lo, hi) = clip_span(0.0, (w - 1) as f64, pa, pb, r.p0 as f64 - 1.0, r.p1 as f64 + 1.0);
        let (lo, hi) = clip_span(lo, hi, qa, qb, r.q0 as f64 - 1.0, r.q1 as f64 + 1.0);
        let (u0, u1) = if lo <= hi { (lo.ceil().max(0.0) as usize, (hi.floor() as usize).min(w - 1) + 1) } else { (0, 0) };
        let (u0, u1) = if u0 < u1 { (u0, u1) } else { (0, 0) };
        // clear only what the last frame wrote and this one does not
        if old0 < old1 {
            row[old0..old1.min(u0).max(old0)].fill([0.0; 4]);
            row[u1.max(old0).min(old1)..old1].fill([0.0; 4]);
        }
        *span = (u0 as u32, u1 as u32);
        if u0 == u1 {
            return;
        }
        // every tap of this span lies in the valid rectangle or its cleared ring,
        // whose left/top edge is at least 1, so p, q > 0 here. Coordinates step in
        // 32.32 fixed point: exact integer parts, no float→int conversion per pixel,
        // drift below 1e-6 pixel over a row.
        let iw = inter.size[0];
        let (ih, rgba) = (inter.size[1], &inter.rgba);
        const ONE: f64 = 4_294_967_296.0;
        // p(u) = round(pb·2³²) + u·round(pa·2³²): a function of u alone, so the same
        // pixel gets the same coordinate whatever span (valid rectangle) it is in
        let (dp, dq) = ((pa * ONE).round() as i64, (qa * ONE).round() as i64);
        let (mut p, mut q) = ((pb * ONE).round() as i64 + u0 as i64 * dp, (qb * ONE).round() as i64 + u0 as i64 * dq);
        for px in row[u0..u1].iter_mut() {
            let (x0, y0) = (((p >> 32) as usize).min(iw - 2), ((q >> 32) as usize).min(ih - 2));
            let fx = (p & 0xFFFF_FFFF) as f32 * (1.0 / ONE as f32);
            let fy = (q & 0xFFFF_FFFF) as f32 * (1.0 / ONE as f32);
            let i = y0 * iw + x0;
            let (top, bot) = (&rgba[i..i + 2], &rgba[i + iw..i + iw + 2]);
            // all four channels at once in one SSE register (glam's Vec4)
            let t = Vec4::from_array(top[0]).lerp(Vec4::from_array(top[1]), fx);
            let b = Vec4::from_array(bot[0]).lerp(Vec4::from_array(bot[1]), fx);
            *px = t.lerp(b, fy).to_array();
            p += dp;
            q += dq;
        }
    });
}
