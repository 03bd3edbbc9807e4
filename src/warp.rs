//! The warp: intermediate image to final image.
//!
//! Owns the final images — [`Image`] (premultiplied RGBA f32, row 0 at the
//! top: the exact result every test and metric compares) and [`Image8`] (the
//! same pixels rounded to 8 bits: what a window, a GIF or a PNG receives) —
//! and the bilinear affine warp shared by every shear-warp path: each output
//! pixel is mapped back through the inverse of the factorization's 2-D warp
//! into the intermediate image and resampled bilinearly. Only the output span
//! of each row whose preimage meets the intermediate image's valid rectangle is
//! resampled; the rest is cleared. One [`Canvas`] type and one warp, generic over
//! the pixel ([`Texel`]), serve both formats, and
//! [`crate::render::Renderer::render`] draws into either.

use glam::Vec4;
use rayon::prelude::*;

use crate::composite::Intermediate;
use crate::error::Result;
use crate::view::perspective::RayDirections;
use crate::view::plan::FramePlan;

/// A rendered image of pixels `T` ([`Texel`]), row 0 at the top: [`Image`]
/// (f32) or [`Image8`] (8-bit). Two images are equal when their sizes and
/// pixels are.
#[derive(Clone, Debug)]
pub struct Canvas<T> {
    pub width: usize,
    pub height: usize,
    pub data: Vec<T>,
    /// Per row, the span `[u0, u1)` the last warp wrote; everything else in the row
    /// is transparent. Lets the next warp clear only what it no longer covers.
    spans: Vec<(u32, u32)>,
    /// Which renderer frame last wrote this image (0: none); lets a renderer skip
    /// a frame whose inputs did not change.
    pub(crate) stamp: u64,
}

/// A rendered image: premultiplied RGBA in [0, 1] (over black when displayed),
/// exactly as the warp computed it: what tests and metrics compare.
pub type Image = Canvas<[f32; 4]>;

/// A rendered image rounded to 8 bits: premultiplied RGBA (over black when
/// displayed), each channel rounded by [`to8`] as the warp writes it (the same
/// bytes as rounding an [`Image`]). What a window, a GIF or a PNG receives,
/// without a conversion pass over an f32 image.
pub type Image8 = Canvas<[u8; 4]>;

impl<T: Texel> Canvas<T> {
    /// A transparent image.
    pub fn new(width: usize, height: usize) -> Self {
        Canvas { width, height, data: vec![T::CLEAR; width * height], spans: vec![(0, 0); height], stamp: 0 }
    }

    /// Resizes (and clears) when the size differs.
    pub fn prepare(&mut self, width: usize, height: usize) {
        if self.width != width || self.height != height {
            *self = Canvas::new(width, height);
        }
    }

    /// Pixel at `(x, y)`.
    pub fn at(&self, x: usize, y: usize) -> T {
        self.data[y * self.width + x]
    }

    /// 8-bit RGB over a black background (the same for an [`Image`] and its [`Image8`]).
    pub fn to_rgb8(&self) -> image::RgbImage {
        let mut out = image::RgbImage::new(self.width as u32, self.height as u32);
        for (px, c) in out.pixels_mut().zip(&self.data) {
            *px = image::Rgb(c.rgb8());
        }
        out
    }

    /// Writes a PNG, atomically ([`crate::output`]).
    pub fn save_png(&self, path: &std::path::Path) -> Result<()> {
        crate::output::write_png(path, &self.to_rgb8())
    }

    /// Counts pixels `x0..x1` of row `y` as written (with the span the last
    /// warp wrote there), for a pass that draws outside the warp's spans
    /// (geometry under the volume): the next warp into this image clears
    /// them where it does not write.
    pub fn mark_written(&mut self, y: usize, x0: usize, x1: usize) {
        let x1 = x1.min(self.width);
        if x0 >= x1 {
            return;
        }
        let s = &mut self.spans[y];
        *s = if s.0 >= s.1 { (x0 as u32, x1 as u32) } else { (s.0.min(x0 as u32), s.1.max(x1 as u32)) };
    }

    /// Fraction of pixels with any coverage.
    pub fn coverage(&self) -> f64 {
        self.data.iter().filter(|c| c.covered()).count() as f64 / self.data.len().max(1) as f64
    }

    /// `0RGB` words over black, as a window's framebuffer takes them: a byte
    /// shuffle for an [`Image8`], a rounding pass for an [`Image`].
    pub fn to_0rgb(&self, out: &mut Vec<u32>) {
        out.clear();
        out.extend(self.data.iter().map(|c| {
            let [r, g, b] = c.rgb8();
            (r as u32) << 16 | (g as u32) << 8 | b as u32
        }));
    }
}

impl Image {
    /// An image made from pixel data (`data.len()` must be `width · height`).
    pub fn from_data(width: usize, height: usize, data: Vec<[f32; 4]>) -> Self {
        assert_eq!(data.len(), width * height, "pixel count");
        Canvas { width, height, data, spans: vec![(0, width as u32); height], stamp: 0 }
    }

    /// This image's pixels as `T` into `out` (resized if needed): into an
    /// [`Image8`] each channel rounded by [`to8`], the bytes the warp writes
    /// ([`Texel::from_rgba`]). Every pixel of `out` counts as written (the
    /// next warp into it clears whatever it does not cover), and no renderer
    /// frame as its last (none is skipped into it).
    pub fn convert_into<T: Texel>(&self, out: &mut Canvas<T>) {
        out.prepare(self.width, self.height);
        for (o, p) in out.data.iter_mut().zip(&self.data) {
            *o = T::from_rgba(Vec4::from_array(*p));
        }
        out.spans.fill((0, self.width as u32));
        out.stamp = 0;
    }

    /// Every pixel rounded to 8 bits by [`to8`] (what the warp writes into an [`Image8`]).
    pub fn to_rgba8(&self) -> Vec<[u8; 4]> {
        self.data.iter().map(|c| c.map(to8)).collect()
    }
}

impl<T: PartialEq> PartialEq for Canvas<T> {
    fn eq(&self, o: &Self) -> bool {
        self.width == o.width && self.height == o.height && self.data == o.data
    }
}

/// One channel in [0, 1] rounded to 8 bits (clamped; NaN gives 0).
#[inline(always)]
pub fn to8(c: f32) -> u8 {
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

/// A pixel format the warp writes, made from the bilinear result (premultiplied
/// RGBA in f32).
pub trait Texel: Copy + Send + Sync {
    /// Transparent black.
    const CLEAR: Self;
    /// The pixel of a premultiplied RGBA value.
    fn from_rgba(v: Vec4) -> Self;
    /// 8-bit RGB over black.
    fn rgb8(self) -> [u8; 3];
    /// Whether the pixel has any coverage.
    fn covered(self) -> bool;
}

impl Texel for [f32; 4] {
    const CLEAR: Self = [0.0; 4];
    #[inline(always)]
    fn from_rgba(v: Vec4) -> Self {
        v.to_array()
    }
    fn rgb8(self) -> [u8; 3] {
        [to8(self[0]), to8(self[1]), to8(self[2])]
    }
    fn covered(self) -> bool {
        self[3] > 0.0
    }
}

impl Texel for [u8; 4] {
    const CLEAR: Self = [0; 4];
    /// [`to8`] of every channel, bit for bit (tested at NaN, ±∞ and every
    /// rounding boundary): one clamp, multiply-add, truncation and two packs
    /// for all four channels.
    #[inline(always)]
    fn from_rgba(v: Vec4) -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::*;
            let x: __m128 = v.into();
            // SAFETY: SSE and SSE2 belong to the x86-64 baseline, enabled in every
            // build for this architecture, which is all these register-only
            // intrinsics need (no memory is read or written). Exercised by
            // `texel_u8_is_to8` and every 8-bit warp.
            unsafe {
                // maxps returns its second operand (0) when the first is NaN, as
                // `NaN as u8` is 0; the product and sum are to8's, in its order
                let c = _mm_min_ps(_mm_max_ps(x, _mm_setzero_ps()), _mm_set1_ps(1.0));
                let i = _mm_cvttps_epi32(_mm_add_ps(_mm_mul_ps(c, _mm_set1_ps(255.0)), _mm_set1_ps(0.5)));
                // every lane in 0..=255: the saturating packs are exact
                let b = _mm_packus_epi16(_mm_packs_epi32(i, i), _mm_setzero_si128());
                (_mm_cvtsi128_si32(b) as u32).to_le_bytes()
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        v.to_array().map(to8)
    }
    fn rgb8(self) -> [u8; 3] {
        [self[0], self[1], self[2]]
    }
    fn covered(self) -> bool {
        self[3] > 0
    }
}

/// Warps `inter` into `out` (already sized) by `plan`'s warp: output pixel
/// `(u, v)` takes the bilinear sample of `inter` at the intermediate pixel of
/// the sheared point the plan's inverse warp gives, stored as `T` (into an
/// [`Image8`]: each channel rounded by [`to8`], the same bytes as
/// [`Image::to_rgba8`] of the f32 warp). The affine warp of a parallel view
/// steps along each row in fixed point.
///
/// A projective warp (a perspective plan) back-projects every output pixel
/// through the inverse homography: where the back-projected `w ≤ 0` (behind the
/// eye) the pixel is background, never a mirrored image; elsewhere it is the
/// bilinear sample at `(a/w, b/w)` ([`warp_projective`]).
pub fn warp<T: Texel>(inter: &Intermediate, plan: &FramePlan, out: &mut Canvas<T>) {
    if !plan.warp.is_affine() {
        return warp_projective(inter, plan, out);
    }
    // intermediate pixel = sheared point / pitch + pad (pitch 1: exactly the matrix)
    let m = &plan.warp.inverse;
    let g = plan.grid.pitch.map(|p| 1.0 / p);
    let (inv, it) =
        ([[m.x_axis.x * g[0], m.y_axis.x * g[0]], [m.x_axis.y * g[1], m.y_axis.y * g[1]]], [m.z_axis.x * g[0], m.z_axis.y * g[1]]);
    let origin = [plan.grid.pad as f64; 2];
    let w = out.width;
    let valid = inter.valid;
    // (an intermediate image with a valid rectangle holds at least 2 × 2 pixels)
    let taps = valid.map(|_| Taps::new(inter));
    let avx = crate::kernels::level().has_avx2();
    out.data.par_chunks_mut(w).zip(out.spans.par_iter_mut()).enumerate().for_each(|(v, (row, span))| {
        let (old0, old1) = (span.0 as usize, span.1 as usize);
        let (Some(r), Some(taps)) = (valid, &taps) else {
            row[old0..old1].fill(T::CLEAR);
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
            row[old0..old1.min(u0).max(old0)].fill(T::CLEAR);
            row[u1.max(old0).min(old1)..old1].fill(T::CLEAR);
        }
        *span = (u0 as u32, u1 as u32);
        if u0 == u1 {
            return;
        }
        // every tap of this span lies in the valid rectangle or its cleared ring,
        // whose left/top edge is at least 1, so p, q > 0 here. Coordinates step in
        // 32.32 fixed point: exact integer parts, no float→int conversion per pixel,
        // drift below 1e-6 pixel over a row.
        // p(u) = round(pb·2³²) + u·round(pa·2³²): a function of u alone, so the same
        // pixel gets the same coordinate whatever span (valid rectangle) it is in
        let (dp, dq) = ((pa * FIX_ONE).round() as i64, (qa * FIX_ONE).round() as i64);
        let (p, q) = ((pb * FIX_ONE).round() as i64 + u0 as i64 * dp, (qb * FIX_ONE).round() as i64 + u0 as i64 * dq);
        affine_row(&mut row[u0..u1], taps, [p, q], [dp, dq], avx);
    });
}

/// The intermediate image as the warps read it: its pixels, its width and its
/// height, at least 2 × 2 (so every tap's cell has a right and a lower
/// neighbour).
struct Taps<'a> {
    rgba: &'a [[f32; 4]],
    iw: usize,
    ih: usize,
}

impl<'a> Taps<'a> {
    /// The taps of `inter`, which holds at least 2 × 2 pixels (any image
    /// with a valid rectangle does).
    fn new(inter: &'a Intermediate) -> Self {
        let [iw, ih] = inter.size;
        assert!(iw >= 2 && ih >= 2 && inter.rgba.len() >= iw * ih, "intermediate image of {iw} × {ih} pixels");
        Taps { rgba: &inter.rgba, iw, ih }
    }

    /// The bilinear sample at 32.32 fixed-point `(p, q)`, its cell clamped
    /// into the image: `(p >> 32, q >> 32)` capped at `(iw − 2, ih − 2)` (a
    /// negative coordinate's cell, read as unsigned, caps there too).
    #[inline(always)]
    fn clamped<T: Texel>(&self, p: i64, q: i64) -> T {
        let (x0, y0) = (((p >> 32) as usize).min(self.iw - 2), ((q >> 32) as usize).min(self.ih - 2));
        bilinear(self.rgba, self.iw, [x0, y0], [frac32(p), frac32(q)])
    }
}

/// The pixels `row` of an affine warp's row span: pixel `t` takes the
/// bilinear sample at 32.32 fixed-point `start + t · step` (its cell clamped
/// into the image, [`Taps::clamped`]). The run of pixels whose cells lie in
/// the image as they are, found once for the row ([`linear_run`]), is
/// resampled without clamps or bounds tests ([`interior`], four pixels at
/// a time with AVX when `avx`: [`interior_avx`]); the pixels on either side
/// of it (if any) through the clamp. The same numbers every way.
#[inline(never)]
fn affine_row<T: Texel>(row: &mut [T], taps: &Taps, [p, q]: [i64; 2], [dp, dq]: [i64; 2], avx: bool) {
    let n = row.len() as i64;
    // cells x0 = p >> 32 in 0 ..= iw − 2 and y0 likewise: 0 ≤ p < (iw − 1)·2³²
    let [a0, b0] = linear_run(p, dp, [0, (taps.iw as i64 - 1) << 32], n);
    let [a1, b1] = linear_run(q, dq, [0, (taps.ih as i64 - 1) << 32], n);
    let (a, b) = (a0.max(a1), b0.min(b1).max(a0.max(a1)));
    let at = |t: i64| (p + t * dp, q + t * dq);
    for (t, px) in row.iter_mut().enumerate().take(a as usize) {
        let (p, q) = at(t as i64);
        *px = taps.clamped(p, q);
    }
    let run = &mut row[a as usize..b as usize];
    #[cfg(target_arch = "x86_64")]
    if avx {
        // SAFETY: `avx` is set only where the CPU runs AVX2 (so AVX), and every
        // pixel of `run` has its cell inside the image ([`linear_run`])
        unsafe { interior_avx(run, taps, at(a), [dp, dq]) };
    } else {
        interior(run, taps, at(a), [dp, dq]);
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = avx;
        interior(run, taps, at(a), [dp, dq]);
    }
    for (t, px) in row.iter_mut().enumerate().skip(b as usize) {
        let (p, q) = at(t as i64);
        *px = taps.clamped(p, q);
    }
}

/// The pixels `t` of `0..n` whose coordinate `p + t · dp` lies in `[lo, hi)`:
/// one run `[a, b)` (`a = b` when none), the coordinate being linear in `t`.
fn linear_run(p: i64, dp: i64, [lo, hi]: [i64; 2], n: i64) -> [i64; 2] {
    // floor and ceiling of a / b for b ≠ 0
    let floor = |a: i64, b: i64| {
        let d = a / b;
        if a % b != 0 && (a < 0) != (b < 0) { d - 1 } else { d }
    };
    let ceil = |a: i64, b: i64| -floor(-a, b);
    let [a, b] = match dp.signum() {
        0 if lo <= p && p < hi => [0, n],
        0 => [0, 0],
        // t·dp ≥ lo − p ⇔ t ≥ ⌈(lo − p)/dp⌉; t·dp < hi − p ⇔ t < ⌈(hi − p)/dp⌉
        1 => [ceil(lo - p, dp), ceil(hi - p, dp)],
        // dp < 0: t·dp < hi − p ⇔ t > (hi − p)/dp; t·dp ≥ lo − p ⇔ t ≤ (lo − p)/dp
        _ => [floor(hi - p, dp) + 1, floor(lo - p, dp) + 1],
    };
    let a = a.clamp(0, n);
    [a, b.clamp(a, n)]
}

/// The bilinear samples of `row` at 32.32 fixed-point `start + t · step`,
/// every one's cell inside the image (`p >> 32 ≤ iw − 2`, `q >> 32 ≤ ih − 2`,
/// both coordinates non-negative: what [`linear_run`] found): what
/// [`Taps::clamped`] gives there, bit for bit, without its clamps and bounds
/// tests.
#[inline(always)]
fn interior<T: Texel>(row: &mut [T], taps: &Taps, (mut p, mut q): (i64, i64), [dp, dq]: [i64; 2]) {
    let (iw, base) = (taps.iw, taps.rgba.as_ptr());
    for px in row.iter_mut() {
        debug_assert!(p >= 0 && q >= 0 && (p >> 32) as usize <= iw - 2 && (q >> 32) as usize <= taps.ih - 2);
        let i = (q >> 32) as usize * iw + (p >> 32) as usize;
        // SAFETY: the caller's run keeps 0 ≤ p >> 32 ≤ iw − 2 and
        // 0 ≤ q >> 32 ≤ ih − 2, so the last tap, i + iw + 1, is at most
        // (ih − 2)·iw + iw − 2 + iw + 1 = ih·iw − 1, inside `rgba`
        // (`Taps::new` checked rgba.len() ≥ iw·ih). Exercised by every
        // affine warp and by `affine_rows_equal_the_clamped_taps`.
        *px = unsafe { bilinear_raw(base.add(i), iw, [frac32(p), frac32(q)]) };
        p += dp;
        q += dq;
    }
}

/// [`interior`] with AVX, four pixels a step: the four pixels' in-cell
/// weights at once (the fractions' low 32 bits step in 32-bit lanes and
/// convert exactly as [`frac32`] does), each pixel's top and bottom pairs of
/// taps read as one 8-float vector each and weighted `[1 − fx, fx]` in one
/// multiply. Every sum and product is [`lerp2`]'s, in its order: the same
/// bits.
///
/// # Safety
/// The CPU runs AVX, and every pixel's cell lies inside the image (as for
/// [`interior`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn interior_avx<T: Texel>(row: &mut [T], taps: &Taps, (mut p, mut q): (i64, i64), [dp, dq]: [i64; 2]) {
    use std::arch::x86_64::*;
    let (iw, base) = (taps.iw, taps.rgba.as_ptr());
    let quads = row.len() / 4;
    // the low 32 bits of p + t·dp, t = 0..4, stepping by 4·dp (wrapping: the
    // low bits of a sum are the sum of the low bits)
    let lanes = |x: i64, d: i64| _mm_setr_epi32(x as i32, (x + d) as i32, (x + 2 * d) as i32, (x + 3 * d) as i32);
    let (mut plo, mut qlo) = (lanes(p, dp), lanes(q, dq));
    let (pstep, qstep) = (_mm_set1_epi32((4 * dp) as i32), _mm_set1_epi32((4 * dq) as i32));
    let (one, scale) = (_mm_set1_ps(1.0), _mm_set1_ps(1.0 / FIX_ONE as f32));
    // an unsigned 32-bit lane as f32, rounded once as `u32 as f32` is: its
    // high and low halves convert exactly, their sum rounds
    let to_f32 = |v: __m128i| {
        let hi = _mm_mul_ps(_mm_cvtepi32_ps(_mm_srli_epi32::<16>(v)), _mm_set1_ps(65536.0));
        _mm_add_ps(hi, _mm_cvtepi32_ps(_mm_and_si128(v, _mm_set1_epi32(0xFFFF))))
    };
    // pixel k's x weights: lanes 0–3 its 1 − fx, lanes 4–7 its fx
    let (sel_even, sel_odd) = (_mm256_setr_epi32(0, 0, 0, 0, 1, 1, 1, 1), _mm256_setr_epi32(2, 2, 2, 2, 3, 3, 3, 3));
    for quad in row.chunks_exact_mut(4).take(quads) {
        let fx = _mm_mul_ps(to_f32(plo), scale);
        let fy = _mm_mul_ps(to_f32(qlo), scale);
        let (gx, gy) = (_mm_sub_ps(one, fx), _mm_sub_ps(one, fy));
        // [1 − fx₀, fx₀, 1 − fx₁, fx₁] and the same for pixels 2 and 3, in both halves
        let (lo, hi) = (_mm_unpacklo_ps(gx, fx), _mm_unpackhi_ps(gx, fx));
        let (lo, hi) = (_mm256_set_m128(lo, lo), _mm256_set_m128(hi, hi));
        let wx = [
            _mm256_permutevar_ps(lo, sel_even),
            _mm256_permutevar_ps(lo, sel_odd),
            _mm256_permutevar_ps(hi, sel_even),
            _mm256_permutevar_ps(hi, sel_odd),
        ];
        macro_rules! pixel {
            ($k:literal, $sel:literal) => {{
                // SAFETY: (the caller's contract) the cell's pixels i, i + 1,
                // i + iw and i + iw + 1 lie inside the image: the two pairs
                // are 8 consecutive floats each, read unaligned
                let (top, bot) = unsafe {
                    let cell = base.add((q >> 32) as usize * iw + (p >> 32) as usize) as *const f32;
                    (_mm256_loadu_ps(cell), _mm256_loadu_ps(cell.add(4 * iw)))
                };
                let (tw, bw) = (_mm256_mul_ps(top, wx[$k]), _mm256_mul_ps(bot, wx[$k]));
                let t = _mm_add_ps(_mm256_castps256_ps128(tw), _mm256_extractf128_ps::<1>(tw));
                let b = _mm_add_ps(_mm256_castps256_ps128(bw), _mm256_extractf128_ps::<1>(bw));
                let s = _mm_add_ps(_mm_mul_ps(t, _mm_shuffle_ps::<$sel>(gy, gy)), _mm_mul_ps(b, _mm_shuffle_ps::<$sel>(fy, fy)));
                quad[$k] = T::from_rgba(Vec4::from(s));
                p += dp;
                q += dq;
            }};
        }
        pixel!(0, 0x00);
        pixel!(1, 0x55);
        pixel!(2, 0xAA);
        pixel!(3, 0xFF);
        plo = _mm_add_epi32(plo, pstep);
        qlo = _mm_add_epi32(qlo, qstep);
    }
    // SAFETY: the caller's contract, for the last pixels
    interior(&mut row[quads * 4..], taps, (p, q), [dp, dq]);
}

/// The span of `u` in `(lo, hi)` where a row's back-projection lies in front of
/// the eye and inside the box `p ∈ (p_lo, p_hi)`, `q ∈ (q_lo, q_hi)`: with
/// `X(u) = x[0]·u + x[1]`, `Y`, `W` likewise and `(p, q) = (X, Y)/W`, each
/// condition is linear in `u` (`W > 0`, `X − p_lo·W > 0`, `p_hi·W − X > 0`, …).
fn clip_to_box(lo: f64, hi: f64, x: [f64; 2], y: [f64; 2], w: [f64; 2], [p_lo, p_hi]: [f64; 2], [q_lo, q_hi]: [f64; 2]) -> (f64, f64) {
    let (mut lo, mut hi) = clip_positive(lo, hi, w[0], w[1]);
    for (a, [b_lo, b_hi]) in [(x, [p_lo, p_hi]), (y, [q_lo, q_hi])] {
        (lo, hi) = clip_positive(lo, hi, a[0] - b_lo * w[0], a[1] - b_lo * w[1]);
        (lo, hi) = clip_positive(lo, hi, b_hi * w[0] - a[0], b_hi * w[1] - a[1]);
    }
    (lo, hi)
}

/// The span `(lo, hi)` of `u` where `a·u + b > 0`, intersected with `(lo, hi)`.
fn clip_positive(lo: f64, hi: f64, a: f64, b: f64) -> (f64, f64) {
    if a == 0.0 {
        return if b > 0.0 { (lo, hi) } else { (1.0, 0.0) };
    }
    let x = -b / a;
    if a > 0.0 { (lo.max(x), hi) } else { (lo, hi.min(x)) }
}

/// The warp of a projective plan. Along output row
/// `v` the homogeneous back-projection `(X, Y, W) = inverse · (u, v, 1)` is
/// linear in `u`, and so is each condition for a pixel to read the
/// intermediate image: `W > 0` (in front of the eye; elsewhere background)
/// and `p0 − 1 < X/W + pad < p1 + 1`, the same for `q` (valid rectangle and its
/// cleared ring). Their intersection is one span of the row, solved exactly
/// (the ring widened by twice [`WARP_STRAY`]); only it is resampled, and only
/// what the last frame wrote outside it is cleared. The span is resampled in
/// linear pieces of the row (up to 64 pixels, exact at their ends, within
/// [`WARP_STRAY`] of `(X/W, Y/W)` between): each pixel takes the bilinear
/// sample at its piece's coordinates where those lie inside the ring, and is
/// background elsewhere, so a pixel's value is a function of the pixel and
/// the intermediate image alone (not of the span it was warped in).
pub fn warp_projective<T: Texel>(inter: &Intermediate, plan: &FramePlan, out: &mut Canvas<T>) {
    projective(inter, plan, out, None)
}

/// The output pixels of one pyramid of a split perspective frame
/// ([`crate::view::PerspectiveView::pyramids`]): those whose ray's owner
/// ([`crate::view::perspective::ray_owner`]) is `pyramid` (axis, toward +axis).
#[derive(Clone, Copy, Debug)]
pub struct Owned {
    pub rays: RayDirections,
    pub pyramid: (usize, bool),
}

/// Clears `out` (sized `width × height`) before the pyramids of a split
/// frame are warped into it with [`warp_owned`] (which write only their
/// own pixels).
pub fn clear_for_pyramids<T: Texel>(out: &mut Canvas<T>, width: usize, height: usize) {
    out.prepare(width, height);
    out.data.fill(T::CLEAR);
    // every row may be written: the next warp clears what it does not cover
    out.spans.fill((0, width as u32));
}

/// The projective warp of one pyramid of a split frame: as
/// [`warp_projective`], but only the output pixels `owned` holds are written
/// (the others, another pyramid's, are left alone), and nothing is cleared:
/// start the frame with [`clear_for_pyramids`]. Each pixel's owner is a
/// function of the pixel alone, so the pyramids' pixels tile the image, with
/// no seam and no pixel written twice.
pub fn warp_owned<T: Texel>(inter: &Intermediate, plan: &FramePlan, out: &mut Canvas<T>, owned: &Owned) {
    projective(inter, plan, out, Some(owned))
}

fn projective<T: Texel>(inter: &Intermediate, plan: &FramePlan, out: &mut Canvas<T>, owned: Option<&Owned>) {
    let m = plan.warp.inverse;
    let w = out.width;
    let (pad, [pa, pb]) = (plan.grid.pad as f64, plan.grid.pitch);
    let (iw, rgba) = (inter.size[0], &inter.rgba);
    out.data.par_chunks_mut(w).zip(out.spans.par_iter_mut()).enumerate().for_each(|(v, (row, span))| {
        let (old0, old1) = (span.0 as usize, span.1 as usize);
        let Some(r) = inter.valid else {
            if owned.is_none() {
                row[old0..old1].fill(T::CLEAR);
                *span = (0, 0);
            }
            return;
        };
        let vf = v as f64;
        // X(u) = xa·u + xb, Y, W likewise; p = X/(W·pitch₀) + pad, q with pitch₁
        let (xa, xb) = (m.x_axis.x / pa, (m.y_axis.x * vf + m.z_axis.x) / pa);
        let (ya, yb) = (m.x_axis.y / pb, (m.y_axis.y * vf + m.z_axis.y) / pb);
        let (wa, wb) = (m.x_axis.z, m.y_axis.z * vf + m.z_axis.z);
        // (the ring widened by the linear pieces' stray: which of these pixels
        // read the image is decided below, by the coordinates they sample at)
        let slack = 2.0 * WARP_STRAY;
        let (xr, yr, wr) = ([xa, xb], [ya, yb], [wa, wb]);
        let ring = |a: usize, b: usize| [a as f64 - 1.0 - slack - pad, b as f64 + 1.0 + slack - pad];
        let (mut lo, mut hi) = clip_to_box(0.0, (w - 1) as f64, xr, yr, wr, ring(r.p0, r.p1), ring(r.q0, r.q1));
        if let Some(o) = owned {
            // the pyramid's pixels of the row: s·d_axis ± d_c ≥ 0 for the other
            // two axes c, each linear in u; a pixel of slack (the exact owner
            // test below decides)
            let (m, (axis, up)) = (o.rays.dirs, o.pyramid);
            let s = if up { 1.0 } else { -1.0 };
            let (da, db) = (s * m.x_axis[axis], s * (m.y_axis[axis] * vf + m.z_axis[axis]));
            for c in (0..3).filter(|&c| c != axis) {
                let (ca, cb) = (m.x_axis[c], m.y_axis[c] * vf + m.z_axis[c]);
                for t in [1.0, -1.0] {
                    let (ga, gb) = (da + t * ca, db + t * cb);
                    (lo, hi) = clip_positive(lo, hi, ga, gb + ga.abs() + 1e-9 * (gb.abs() + ga.abs() * w as f64));
                }
            }
        }
        let (u0, u1) = if lo <= hi && hi >= 0.0 { (lo.ceil().max(0.0) as usize, (hi.floor() as usize).min(w - 1) + 1) } else { (0, 0) };
        let (u0, u1) = if u0 < u1 { (u0, u1) } else { (0, 0) };
        if owned.is_none() {
            if old0 < old1 {
                row[old0..old1.min(u0).max(old0)].fill(T::CLEAR);
                row[u1.max(old0).min(old1)..old1].fill(T::CLEAR);
            }
            *span = (u0 as u32, u1 as u32);
        }
        // inside the span every tap is in the valid rectangle or its ring
        // (clamped into the grid too: x0 and x0 + 1 are always pixels)
        let ih = inter.size[1];
        let (pmin, pmax) = ((r.p0 as f64 - 1.0).max(0.0), (r.p1 + 1).min(iw - 1) as f64 - 1e-9);
        let (qmin, qmax) = ((r.q0 as f64 - 1.0).max(0.0), (r.q1 + 1).min(ih - 1) as f64 - 1e-9);
        // a pyramid's pixels of the row are one run: its cone of rays is an
        // intersection of half-spaces and the row's rays are affine in u, so
        // the owner test (which decides ties) finds the run's two ends inside
        // the span's pixel of slack, and the pixels between need none
        let (mut u, mut u_end) = (u0, u1);
        if let Some(o) = owned {
            while u < u_end && o.rays.owner(u as f64, vf) != o.pyramid {
                u += 1;
            }
            while u_end > u && o.rays.owner((u_end - 1) as f64, vf) != o.pyramid {
                u_end -= 1;
            }
        }
        if u >= u_end {
            return;
        }
        // Pieces of `len` pixels whose ends are back-projected exactly (one
        // division each) and whose pixels between step linearly in 32.32 fixed
        // point, as the affine warp's do. The pieces are the row's own: laid
        // from the first pixel of the row's part that lands on the grid (in
        // front of the eye, within a pixel of the grid), `len` chosen for that
        // part, so a pixel's coordinates are a function of the pixel alone,
        // whatever valid rectangle or pyramid's run it is warped in (an
        // accelerated frame and its brute force get the same image). Along the
        // row `p(u) = X/W` has `p' = (xa·wb − xb·wa)/W²` and
        // `p'' = −2·(wa/W)·p'`, so a piece strays at most `len²/8 · max|p''|`
        // from the exact coordinates, largest where `W` is smallest (an end of
        // the part, `W` being linear): `len` is the largest power of two up to
        // 64 keeping that within `WARP_STRAY` pixels on both axes (1 where the
        // row passes too close to the eye).
        let [gw, gh] = plan.grid.size;
        let (glo, ghi) = clip_to_box(0.0, (w - 1) as f64, xr, yr, wr, [-1.0 - pad, gw as f64 - pad], [-1.0 - pad, gh as f64 - pad]);
        let e0 = (glo.ceil().max(0.0) as usize).min(u);
        let e1 = ((ghi.floor().max(0.0) as usize).min(w - 1)).max(u_end - 1);
        let w_min = (wa * e0 as f64 + wb).min(wa * e1 as f64 + wb);
        let curve = |a: f64, b: f64| 0.25 * (wa / w_min).abs() * ((a * wb - b * wa) / (w_min * w_min)).abs();
        let bend = curve(xa, xb).max(curve(ya, yb));
        let mut len = 64usize;
        // (a NaN bound, at W = 0, gives pieces of one pixel)
        while len > 1 && ((len * len) as f64 * bend > WARP_STRAY || bend.is_nan()) {
            len >>= 1;
        }
        // within 2^20 pixels (no fixed-point overflow; the ring's clamp below
        // decides where such a pixel samples)
        let fixed = |x: f64| (x.clamp(-1_048_576.0, 1_048_576.0) * FIX_ONE) as i64;
        let (pmin, pmax, qmin, qmax) = (fixed(pmin), fixed(pmax), fixed(qmin), fixed(qmax));
        // a pixel reads the image where the coordinates it samples at lie
        // inside the valid rectangle's ring (open), and is background
        // elsewhere: decided by those coordinates, not the exact ones, so a
        // pixel one frame draws and another (with a smaller valid rectangle
        // over the same image) does not reads only the cleared ring there
        let (ring_p, ring_q) = ([fixed(r.p0 as f64 - 1.0), fixed(r.p1 as f64 + 1.0)], [fixed(r.q0 as f64 - 1.0), fixed(r.q1 as f64 + 1.0)]);
        // pixel u's exact coordinates in fixed point
        let exact = |u: usize| {
            let (uf, inv_w) = (u as f64, 1.0 / (wa * u as f64 + wb));
            (fixed((xa * uf + xb) * inv_w + pad), fixed((ya * uf + yb) * inv_w + pad))
        };
        // the piece holding u: [start, end], its end the part's last pixel at
        // most; the next piece starts where this one ends
        let mut start = e0 + (u - e0) / len * len;
        let mut a = exact(start);
        while u < u_end {
            let end = (start + len).min(e1);
            let b = exact(end);
            let n = (end - start).max(1) as i64;
            let (dp, dq) = ((b.0 - a.0) / n, (b.1 - a.1) / n);
            let i = (u - start) as i64;
            let (mut p, mut q) = (a.0 + i * dp, a.1 + i * dq);
            // the piece's pixels before its end, or the part's last pixel itself
            let stop = if end == e1 { end + 1 } else { end }.min(u_end);
            for px in row[u..stop].iter_mut() {
                *px = if p > ring_p[0] && p < ring_p[1] && q > ring_q[0] && q < ring_q[1] {
                    let (p, q) = (p.clamp(pmin, pmax), q.clamp(qmin, qmax));
                    bilinear(rgba, iw, [(p >> 32) as usize, (q >> 32) as usize], [frac32(p), frac32(q)])
                } else {
                    T::CLEAR
                };
                p += dp;
                q += dq;
            }
            (u, start, a) = (stop, end, b);
        }
    });
}

/// How far (intermediate pixels) the projective warp's linear pieces may
/// stray from the exact back-projection: 1/256 of a pixel, which moves a
/// bilinear sample by at most 1/256 of the largest step between neighbouring
/// intermediate pixels (under one 8-bit level).
pub const WARP_STRAY: f64 = 1.0 / 256.0;

/// One in 32.32 fixed point: the warps' coordinates step in it.
const FIX_ONE: f64 = 4_294_967_296.0;

/// The fraction of a non-negative 32.32 fixed-point coordinate.
#[inline(always)]
fn frac32(p: i64) -> f32 {
    (p & 0xFFFF_FFFF) as f32 * (1.0 / FIX_ONE as f32)
}

/// The bilinear sample of `rgba` (row stride `iw`) between pixel `[x0, y0]`
/// and its right and lower neighbours (all inside the image) at in-cell
/// weights `[fx, fy]`: all four channels at once in one SSE register (glam's
/// `Vec4`). Both warps take their taps from it.
#[inline(always)]
fn bilinear<T: Texel>(rgba: &[[f32; 4]], iw: usize, [x0, y0]: [usize; 2], [fx, fy]: [f32; 2]) -> T {
    let i = y0 * iw + x0;
    let (top, bot) = (&rgba[i..i + 2], &rgba[i + iw..i + iw + 2]);
    lerp2(top[0], top[1], bot[0], bot[1], [fx, fy])
}

/// [`bilinear`] at `cell` (the cell's top-left pixel, row stride `iw`)
/// without bounds tests.
///
/// # Safety
/// `cell`, `cell + 1`, `cell + iw` and `cell + iw + 1` are pixels of one
/// image.
#[inline(always)]
unsafe fn bilinear_raw<T: Texel>(cell: *const [f32; 4], iw: usize, f: [f32; 2]) -> T {
    // SAFETY: the caller's contract
    unsafe { lerp2(*cell, *cell.add(1), *cell.add(iw), *cell.add(iw + 1), f) }
}

/// The bilinear blend of a cell's top pair `(t0, t1)` and bottom pair
/// `(b0, b1)` at in-cell weights `[fx, fy]`: along x in both rows, then
/// along y (each `a·(1 − s) + b·s`).
#[inline(always)]
fn lerp2<T: Texel>(t0: [f32; 4], t1: [f32; 4], b0: [f32; 4], b1: [f32; 4], [fx, fy]: [f32; 2]) -> T {
    let t = Vec4::from_array(t0).lerp(Vec4::from_array(t1), fx);
    let b = Vec4::from_array(b0).lerp(Vec4::from_array(b1), fx);
    T::from_rgba(t.lerp(b, fy))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Virvo's warp never checks the back-projected w: pixels whose ray meets
    /// the base plane behind the eye showed a mirrored image. Here they are
    /// background, and the pixels in front are the bilinear sample.
    #[test]
    fn perspective_warp_behind_the_eye_is_background() {
        use crate::view::Warp;
        use crate::view::plan::Grid;
        use glam::{DMat3, DVec3};
        let f = crate::view::Factorization::new(&crate::view::Camera::new(DMat3::IDENTITY, [8, 8]), [4, 4, 4], [1.0; 3]).unwrap();
        let mut plan = FramePlan::parallel(&f, [1.0; 3]);
        plan.grid = Grid { size: [8, 8], pad: 0, pitch: [1.0; 2] };
        // w = 1 − u/4: positive for u < 4, zero at 4, negative beyond; (a, b) = (u, v)/w
        let inverse = DMat3::from_cols(DVec3::new(1.0, 0.0, -0.25), DVec3::new(0.0, 1.0, 0.0), DVec3::new(0.0, 0.0, 1.0));
        plan.warp = Warp { forward: inverse.inverse(), inverse };
        let mut inter = Intermediate::default();
        inter.prepare([8, 8]);
        inter.rgba.fill([0.5, 0.25, 0.125, 0.5]);
        inter.valid = Some(crate::composite::Rect { p0: 0, p1: 7, q0: 0, q1: 7 });
        let mut out = Image::new(8, 8);
        warp(&inter, &plan, &mut out);
        for v in 0..8 {
            for u in 0..8 {
                let w = 1.0 - u as f64 / 4.0;
                let got = out.at(u, v);
                if w <= 0.0 {
                    assert_eq!(got, [0.0; 4], "({u}, {v}) is behind the eye");
                } else if (u as f64 / w) < 6.5 && (v as f64 / w) < 6.5 {
                    assert_eq!(got, [0.5, 0.25, 0.125, 0.5], "({u}, {v})");
                }
            }
        }
        // w = 4 − u, (a, b) = (u − 8, 4 − u)/w: in front of the eye a < 0 (off
        // the grid); behind it a = 3, 1, 0.33 and b = 1, inside the grid, so a
        // warp that ignored the sign of w would draw a mirrored image there
        let inverse = DMat3::from_cols(DVec3::new(1.0, -1.0, -1.0), DVec3::ZERO, DVec3::new(-8.0, 4.0, 4.0));
        plan.warp = Warp { forward: DMat3::IDENTITY, inverse };
        warp(&inter, &plan, &mut out);
        assert!(out.data.iter().all(|&c| c == [0.0; 4]), "nothing is in front of the eye");
    }

    /// The projective warp's linear pieces stay within [`WARP_STRAY`] of the
    /// exact back-projection: an intermediate image holding its own
    /// coordinates (`r = p/256`, `g = q/256`, which the bilinear sample
    /// reproduces exactly) warped through homographies from mild to steep,
    /// each output pixel's colour read back as the coordinate it sampled.
    #[test]
    fn projective_warp_pieces_stay_within_the_stray_bound() {
        use crate::view::Warp;
        use crate::view::plan::Grid;
        use glam::{DMat3, DVec3};
        let f = crate::view::Factorization::new(&crate::view::Camera::new(DMat3::IDENTITY, [8, 8]), [4, 4, 4], [1.0; 3]).unwrap();
        let mut plan = FramePlan::parallel(&f, [1.0; 3]);
        let n = 200usize;
        let mut inter = Intermediate::default();
        inter.prepare([n, n]);
        for q in 0..n {
            for p in 0..n {
                inter.rgba[q * n + p] = [p as f32 / 256.0, q as f32 / 256.0, 0.5, 1.0];
            }
        }
        inter.valid = Some(crate::composite::Rect { p0: 1, p1: n - 2, q0: 1, q1: n - 2 });
        let mut worst = 0f64;
        for (i, (wu, wv, pitch)) in [
            (0.0002, 0.0001, [1.0; 2]),
            (0.002, 0.001, [1.0; 2]),
            (0.004, -0.002, [0.5; 2]),
            (-0.003, 0.004, [2.0; 2]),
            (0.02, 0.0, [1.0; 2]),
            (0.003, 0.001, [1.0, 0.25]),
        ]
        .into_iter()
        .enumerate()
        {
            plan.grid = Grid { size: [n, n], pad: 0, pitch };
            // (X, Y, W) = inverse · (u, v, 1)
            let inverse = DMat3::from_cols(DVec3::new(0.6, 0.05, wu), DVec3::new(0.1, 0.7, wv), DVec3::new(10.0, 5.0, 0.9));
            plan.warp = Warp { forward: inverse.inverse(), inverse };
            let mut out = Image::new(256, 256);
            warp(&inter, &plan, &mut out);
            let mut seen = 0;
            for v in 0..256 {
                for u in 0..256 {
                    let h = inverse * DVec3::new(u as f64, v as f64, 1.0);
                    if h.z <= 0.0 {
                        continue;
                    }
                    let (p, q) = (h.x / h.z / pitch[0], h.y / h.z / pitch[1]);
                    // inside the valid rectangle, away from its clamped ring
                    if !(2.0..n as f64 - 3.0).contains(&p) || !(2.0..n as f64 - 3.0).contains(&q) {
                        continue;
                    }
                    let c = out.at(u, v);
                    let err = (c[0] as f64 * 256.0 - p).abs().max((c[1] as f64 * 256.0 - q).abs());
                    assert!(
                        err <= WARP_STRAY + 1e-4,
                        "homography {i}: pixel ({u}, {v}) sampled ({}, {}) for ({p}, {q})",
                        c[0] * 256.0,
                        c[1] * 256.0
                    );
                    worst = worst.max(err);
                    seen += 1;
                }
            }
            assert!(seen > 1000, "homography {i}: {seen} pixels checked");
        }
        assert!(worst > 0.0);
    }

    /// [`affine_row`] (the run without clamps and the clamped pixels on its
    /// sides) gives every pixel exactly what [`Taps::clamped`] gives it:
    /// rows that start, end, enter or leave the image on either side along
    /// either axis, steps of both signs and zero, coordinates on cell edges.
    #[test]
    fn affine_rows_equal_the_clamped_taps() {
        let (iw, ih) = (7usize, 5usize);
        let mut inter = Intermediate::default();
        inter.prepare([iw, ih]);
        for (i, c) in inter.rgba.iter_mut().enumerate() {
            *c = [i as f32 * 0.37, (i * i % 11) as f32, 1.0 / (1.0 + i as f32), (i % 3) as f32 * 0.5];
        }
        let taps = Taps::new(&inter);
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut next = |m: i64| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed % (2 * m as u64 + 1)) as i64 - m
        };
        let one = 1i64 << 32;
        for case in 0..4000 {
            let n = 1 + (next(20) + 20) as usize;
            let start = [next(9 * one), next(7 * one)];
            // steps of up to a pixel, some exactly zero or whole
            let step = [0, 1].map(|a| match case % 5 {
                0 if a == 0 => 0,
                1 => next(2) * one / 2,
                _ => next(one),
            });
            // the scalar run and (where the CPU has it) the AVX one
            for avx in [false, crate::kernels::detected().has_avx2()] {
                let mut got = vec![[f32::NAN; 4]; n];
                affine_row(&mut got, &taps, start, step, avx);
                for (t, g) in got.iter().enumerate() {
                    let want: [f32; 4] = taps.clamped(start[0] + t as i64 * step[0], start[1] + t as i64 * step[1]);
                    assert_eq!(g.map(f32::to_bits), want.map(f32::to_bits), "case {case} (avx {avx}): pixel {t} of {start:?} + t·{step:?}");
                }
                let mut got8 = vec![[0u8; 4]; n];
                affine_row(&mut got8, &taps, start, step, avx);
                for (t, g) in got8.iter().enumerate() {
                    let want: [u8; 4] = taps.clamped(start[0] + t as i64 * step[0], start[1] + t as i64 * step[1]);
                    assert_eq!(*g, want, "case {case} (avx {avx}): 8-bit pixel {t}");
                }
            }
        }
        // the run itself, against a scan
        for _ in 0..4000 {
            let (p, dp, n) = (next(5 * one), next(2 * one), next(30) + 31);
            let [a, b] = linear_run(p, dp, [0, 3 * one], n);
            let inside: Vec<i64> = (0..n).filter(|t| (0..3 * one).contains(&(p + t * dp))).collect();
            let want = if inside.is_empty() { 0 } else { inside.len() as i64 };
            assert_eq!(b - a, want, "{p} + t·{dp}");
            if want > 0 {
                assert_eq!([a, b], [inside[0], inside[0] + want]);
            }
        }
    }

    /// Every value the 8-bit texel can meet: NaN, ±∞, out of range, and both
    /// sides of every rounding boundary `(k + 0.5)/255` and of every `k/255`.
    #[test]
    fn texel_u8_is_to8() {
        let mut xs = vec![f32::NAN, -f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -0.0, 0.0, 1.0, 2.0, -1.0, f32::MAX, f32::MIN, 1e-30];
        for k in 0..=256 {
            for c in [(k as f32 + 0.5) / 255.0, k as f32 / 255.0] {
                xs.extend([c, f32::from_bits(c.to_bits() + 1), f32::from_bits(c.to_bits().saturating_sub(1))]);
            }
        }
        for (i, &x) in xs.iter().enumerate() {
            // each value in every lane, beside others
            let y = xs[(i * 7 + 3) % xs.len()];
            for v in [[x, y, x, y], [y, x, y, x], [x; 4]] {
                assert_eq!(<[u8; 4]>::from_rgba(Vec4::from_array(v)), v.map(to8), "{v:?}");
            }
        }
    }

    /// [`Image::convert_into`] gives an [`Image8`] the bytes of
    /// [`Image::to_rgba8`], and a later warp into it clears every pixel it
    /// does not write (the converted pixels count as written, as do pixels
    /// [`Canvas::mark_written`] marks).
    #[test]
    fn converted_and_marked_pixels_are_cleared_by_the_next_warp() {
        use crate::view::plan::Grid;
        use glam::DMat3;
        let data: Vec<[f32; 4]> = (0..8 * 6).map(|i| [i as f32 / 47.0, 0.5, 1.7, (i % 5) as f32 / 4.0]).collect();
        let src = Image::from_data(8, 6, data);
        let mut out = Image8::new(3, 3);
        src.convert_into(&mut out);
        assert_eq!((out.width, out.height), (8, 6));
        assert_eq!(out.data, src.to_rgba8());
        // a warp of an empty frame: nothing is left
        let f = crate::view::Factorization::new(&crate::view::Camera::new(DMat3::IDENTITY, [8, 6]), [4, 4, 4], [1.0; 3]).unwrap();
        let mut plan = FramePlan::parallel(&f, [1.0; 3]);
        plan.grid = Grid { size: [8, 8], pad: 0, pitch: [1.0; 2] };
        let inter = Intermediate::default();
        warp(&inter, &plan, &mut out);
        assert!(out.data.iter().all(|&c| c == [0; 4]));
        // pixels drawn past the last warp's spans and marked: cleared by the next
        out.data[2 * 8 + 5] = [9; 4];
        out.data[4 * 8 + 1] = [9; 4];
        out.mark_written(2, 5, 6);
        out.mark_written(4, 1, 2);
        warp(&inter, &plan, &mut out);
        assert!(out.data.iter().all(|&c| c == [0; 4]));
    }
}
