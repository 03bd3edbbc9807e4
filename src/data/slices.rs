//! The volume seen along one principal axis.
//!
//! Owns [`SliceStack`]: the densities re-laid out as f32 in permuted `(i, j, k)`
//! order (i fastest) so that every slice a shear-warp path walks is contiguous,
//! plus the per-sample primitives every path shares: the bilinear density sample
//! inside one slice, its cell corners' range, and the central-difference gradient.
//! A stack for an axis is built only when a view first needs it.

use rayon::prelude::*;

use crate::data::volume::{Volume, VoxelData};
use crate::view::permutation;

/// Densities permuted for principal axis `axis`.
#[derive(Clone, Debug)]
pub struct SliceStack {
    /// Principal axis (0 = x, 1 = y, 2 = z).
    pub axis: usize,
    /// Sizes along `(i, j, k)`.
    pub n: [usize; 3],
    /// Object axes of `(i, j, k)`: [`permutation`]`(axis)`, or another
    /// permutation with `perm[2] == axis` ([`SliceStack::try_permuted`]).
    perm: [usize; 3],
    data: Vec<f32>,
}

/// One bilinear sample inside a slice: the interpolated density and the
/// location it came from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Interpolated density, clamped to the cell's corner range.
    pub density: f32,
    /// Cell index `(ci, cj)` and slice `k`.
    pub cell: [usize; 3],
    /// In-cell weights `(wi, wj)` in [0, 1).
    pub w: [f32; 2],
}

/// What a stage that needs a stack's densities one row at a time (the cell
/// codes) reads: a resident [`SliceStack`] or the packed cells of a
/// [`crate::data::normals::NormalStack`], which hold the same values exactly.
pub trait Densities: Sync {
    /// Sizes along `(i, j, k)`.
    fn dims(&self) -> [usize; 3];
    /// Writes row `j` of slice `k` (`dims()[0]` densities) into `out`.
    fn row(&self, j: usize, k: usize, out: &mut [f32]);
}

impl Densities for SliceStack {
    fn dims(&self) -> [usize; 3] {
        self.n
    }
    #[inline]
    fn row(&self, j: usize, k: usize, out: &mut [f32]) {
        let b = self.index(0, j, k);
        out.copy_from_slice(&self.data[b..b + self.n[0]]);
    }
}

/// Writes `f(src[i·s0 + j·s1 + k·s2])` to `data[i + n0·(j + n1·k)]` for every
/// `(i, j, k) < n`, in parallel over slices: the permutation behind every stack
/// ([`SliceStack`], the packed cells of [`crate::data::packing`] and back to
/// the volume's order).
pub(crate) fn gather<T: Copy + Sync, U: Send>(src: &[T], data: &mut [U], n: [usize; 3], s: [usize; 3], f: impl Fn(T) -> U + Sync) {
    let [si, sj, sk] = s;
    let n01 = n[0] * n[1];
    if sk == 1 && n01 > 0 {
        // the slices' own axis is the source's contiguous one: read each run
        // along k once for a block of slices, instead of one cache line per
        // voxel per slice
        const BLOCK: usize = 16;
        data.par_chunks_mut(BLOCK * n01).enumerate().for_each(|(b, block)| {
            let (k0, kb) = (b * BLOCK, block.len() / n01);
            for j in 0..n[1] {
                for i in 0..n[0] {
                    let base = k0 + j * sj + i * si;
                    for (dk, &v) in src[base..base + kb].iter().enumerate() {
                        block[dk * n01 + j * n[0] + i] = f(v);
                    }
                }
            }
        });
        return;
    }
    data.par_chunks_mut(n[0] * n[1].max(1)).enumerate().for_each(|(k, slice)| {
        for j in 0..n[1] {
            let row = &mut slice[j * n[0]..(j + 1) * n[0]];
            let base = k * sk + j * sj;
            if si == 1 {
                for (out, &v) in row.iter_mut().zip(&src[base..base + n[0]]) {
                    *out = f(v);
                }
            } else {
                for (i, out) in row.iter_mut().enumerate() {
                    *out = f(src[base + i * si]);
                }
            }
        }
    });
}

impl SliceStack {
    /// Permutes `vol` for principal axis `axis`.
    ///
    /// # Panics
    /// When the system refuses the allocation (as `vec!` would);
    /// [`SliceStack::try_new`] returns the error instead.
    pub fn new(vol: &Volume, axis: usize) -> Self {
        Self::try_new(vol, axis).unwrap_or_else(|e| panic!("{e}"))
    }

    /// [`SliceStack::new`], or [`crate::Error::Memory`] when the system refuses
    /// the allocation.
    pub fn try_new(vol: &Volume, axis: usize) -> crate::error::Result<Self> {
        let nk = vol.dims()[permutation(axis)[2]];
        Self::try_window(vol, axis, 0..nk)
    }

    /// The slices `ks` (along the principal axis) of [`SliceStack::new`]`(vol,
    /// axis)`: its slice `k` is the full stack's slice `ks.start + k`. What
    /// builds an axis's normal codes a few slices at a time, without the
    /// whole f32 stack in memory.
    pub fn try_window(vol: &Volume, axis: usize, ks: std::ops::Range<usize>) -> crate::error::Result<Self> {
        Self::try_window_permuted(vol, permutation(axis), ks)
    }

    /// [`SliceStack::try_new`] with object axes `perm` for `(i, j, k)` (any
    /// permutation of 0, 1, 2; the principal axis is `perm[2]`): what the
    /// RLE paths' mirrored permutation reads ([`crate::view::reuse_permutation`]).
    pub fn try_permuted(vol: &Volume, perm: [usize; 3]) -> crate::error::Result<Self> {
        assert!(crate::view::is_permutation(perm), "{perm:?} is not a permutation of the axes");
        Self::try_window_permuted(vol, perm, 0..vol.dims()[perm[2]])
    }

    fn try_window_permuted(vol: &Volume, perm: [usize; 3], ks: std::ops::Range<usize>) -> crate::error::Result<Self> {
        let axis = perm[2];
        let d = vol.dims();
        let ks = ks.start.min(d[perm[2]])..ks.end.min(d[perm[2]]);
        let n = [d[perm[0]], d[perm[1]], ks.len()];
        let mut data: Vec<f32> = crate::memory::zeroed(n[0] * n[1] * n[2], "the slice stack")?;
        let stride = [1usize, d[0], d[0] * d[1]];
        let st = [stride[perm[0]], stride[perm[1]], stride[perm[2]]];
        let from = ks.start * st[2];
        // one loop per voxel type (no type dispatch per voxel)
        match vol.data() {
            VoxelData::U8(v) => gather(&v[from..], &mut data, n, st, |x| x as f32),
            VoxelData::U16(v) => gather(&v[from..], &mut data, n, st, |x| x as f32),
            VoxelData::I16(v) => gather(&v[from..], &mut data, n, st, |x| x as f32),
            VoxelData::F32(v) => gather(&v[from..], &mut data, n, st, |x| x),
        }
        Ok(SliceStack { axis, n, perm, data })
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.data.len() * 4
    }

    /// A stack of `n` densities `data` (in `(i, j, k)` order) along `axis`.
    pub(crate) fn from_parts(axis: usize, n: [usize; 3], data: Vec<f32>) -> Self {
        assert_eq!(data.len(), n[0] * n[1] * n[2], "densities of another size");
        SliceStack { axis, n, perm: permutation(axis), data }
    }

    /// The densities, given back.
    pub(crate) fn into_data(self) -> Vec<f32> {
        self.data
    }

    /// The geometry of the stack of `vol` along `axis` without its densities:
    /// what a path that reads its samples from elsewhere (the binary path from
    /// packed cells, `NormalStack::try_cells`)
    /// needs. Reading a density from it panics; [`SliceStack::is_resident`] says which it is.
    pub fn shell(vol: &Volume, axis: usize) -> Self {
        let (perm, d) = (permutation(axis), vol.dims());
        SliceStack { axis, n: [d[perm[0]], d[perm[1]], d[perm[2]]], perm, data: Vec::new() }
    }

    /// Object axes of `(i, j, k)`.
    pub fn perm(&self) -> [usize; 3] {
        self.perm
    }

    /// False for a [`SliceStack::shell`].
    pub fn is_resident(&self) -> bool {
        self.data.len() == self.n[0] * self.n[1] * self.n[2]
    }

    /// Density at voxel `(i, j, k)`.
    #[inline(always)]
    pub fn at(&self, i: usize, j: usize, k: usize) -> f32 {
        self.data[self.index(i, j, k)]
    }

    /// The raw permuted densities.
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// Number of cells along i and j (`n − 1`, 0 for a flat axis).
    pub fn cells(&self) -> [usize; 2] {
        [self.n[0].saturating_sub(1), self.n[1].saturating_sub(1)]
    }

    /// Smallest and largest corner density of cell `(ci, cj)` in slice `k`.
    #[inline(always)]
    pub fn cell_range(&self, ci: usize, cj: usize, k: usize) -> (f32, f32) {
        let [a, c, d, e] = self.corners(ci, cj, k);
        (fmin(fmin(a, c), fmin(d, e)), fmax(fmax(a, c), fmax(d, e)))
    }

    /// Bilinear density in cell `(ci, cj)` of slice `k` at in-cell weights `(wi, wj)`.
    ///
    /// The result is clamped to the range of the four corners, so a cell whose
    /// corners are all transparent can never produce a visible sample through
    /// floating-point rounding: this is what makes the masks exactly conservative.
    #[inline(always)]
    pub fn bilinear(&self, ci: usize, cj: usize, k: usize, wi: f32, wj: f32) -> f32 {
        bilinear(self.corners(ci, cj, k), wi, wj)
    }

    /// The four corner densities of the cell whose first voxel has index `b`
    /// (order of [`SliceStack::bilinear`]).
    #[inline(always)]
    pub fn cell_at(&self, b: usize) -> [f32; 4] {
        cell_corners(&self.data, b, self.n[0])
    }

    /// The four corner densities of cell `(ci, cj)` in slice `k`, in the order
    /// `(i, j)`, `(i+1, j)`, `(i, j+1)`, `(i+1, j+1)`: one bounds check for all four.
    #[inline(always)]
    fn corners(&self, ci: usize, cj: usize, k: usize) -> [f32; 4] {
        cell_corners(&self.data, self.index(ci, cj, k), self.n[0])
    }

    /// Index of voxel `(i, j, k)` in [`SliceStack::data`].
    #[inline(always)]
    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.n[0] * (j + self.n[1] * k)
    }

    /// Hints the cache to fetch every voxel row an iso hit in cell `(ci, cj)` of
    /// slice `k` reads: the 4×4 in-slice neighbourhood of slice `k` and of the
    /// slice before it in walking order (the refinement's sample and gradient),
    /// and the two rows each of the slices one beyond on either side. No effect
    /// on results; rows outside the stack are skipped.
    #[inline(always)]
    pub fn prefetch_hit(&self, ci: usize, cj: usize, k: usize, ascending: bool) {
        let (n0, n01) = (self.n[0] as isize, (self.n[0] * self.n[1]) as isize);
        let b = self.index(ci, cj, k);
        let dk = if ascending { -n01 } else { n01 };
        let at = |o: isize| b.wrapping_add_signed(o);
        for s in [0, dk] {
            for r in -1..=2 {
                prefetch(&self.data, at(s + r * n0 - 1));
            }
        }
        for s in [-dk, 2 * dk] {
            prefetch(&self.data, at(s));
            prefetch(&self.data, at(s + n0));
        }
    }

    /// Hints the cache to fetch the two voxel rows of the cell whose first voxel
    /// has index `b` (what a bilinear sample reads). No effect on results.
    #[inline(always)]
    pub fn prefetch_cell(&self, b: usize) {
        prefetch_cell(&self.data, b, self.n[0]);
    }

    /// Hints the cache to fetch the line of voxel `b` (no effect on results).
    #[inline(always)]
    pub fn prefetch_voxel(&self, b: usize) {
        prefetch(&self.data, b);
    }

    /// Central-difference gradient at voxel `(i, j, k)` in voxel units of
    /// `(i, j, k)` (one-sided at the borders, zero along a flat axis).
    #[inline(always)]
    pub fn gradient_at(&self, i: usize, j: usize, k: usize) -> [f32; 3] {
        let n = self.n;
        let d = |lo: f32, hi: f32, span: f32| if span > 0.0 { (hi - lo) / span } else { 0.0 };
        let (i0, i1) = (i.saturating_sub(1), (i + 1).min(n[0] - 1));
        let (j0, j1) = (j.saturating_sub(1), (j + 1).min(n[1] - 1));
        let (k0, k1) = (k.saturating_sub(1), (k + 1).min(n[2] - 1));
        [
            d(self.at(i0, j, k), self.at(i1, j, k), (i1 - i0) as f32),
            d(self.at(i, j0, k), self.at(i, j1, k), (j1 - j0) as f32),
            d(self.at(i, j, k0), self.at(i, j, k1), (k1 - k0) as f32),
        ]
    }

    /// Gradient at an in-slice sample: the bilinear blend of the corners' gradients.
    #[inline]
    pub fn gradient(&self, ci: usize, cj: usize, k: usize, wi: f32, wj: f32) -> [f32; 3] {
        let n = self.n;
        if ci >= 1 && cj >= 1 && k >= 1 && ci + 2 < n[0] && cj + 2 < n[1] && k + 1 < n[2] {
            self.gradient_interior(ci, cj, k, wi, wj)
        } else {
            self.gradient_general(ci, cj, k, wi, wj)
        }
    }

    /// The in-slice components `[g_i, g_j]` of [`SliceStack::gradient`],
    /// the same numbers, without reading the neighbouring slices.
    #[inline]
    pub fn gradient_in_slice(&self, ci: usize, cj: usize, k: usize, wi: f32, wj: f32) -> [f32; 2] {
        let n = self.n;
        if ci >= 1 && cj >= 1 && k >= 1 && ci + 2 < n[0] && cj + 2 < n[1] && k + 1 < n[2] {
            let (n0, b) = (self.n[0], self.index(ci, cj, k));
            let r4 = |o: usize| -> [f32; 4] { self.data[o - 1..o + 3].try_into().expect("4 voxels") };
            let (rm, r0, r1, r2) = (r4(b - n0), r4(b), r4(b + n0), r4(b + 2 * n0));
            let lerp = |a: f32, c: f32, w: f32| a + (c - a) * w;
            let li = |r: [f32; 4]| lerp(r[1], r[2], wi);
            let di = |r: [f32; 4]| lerp(r[2] - r[0], r[3] - r[1], wi) * 0.5;
            [lerp(di(r0), di(r1), wj), lerp((li(r1) - li(rm)) * 0.5, (li(r2) - li(r0)) * 0.5, wj)]
        } else {
            let g = self.gradient_general(ci, cj, k, wi, wj);
            [g[0], g[1]]
        }
    }

    /// [`SliceStack::gradient`] for a cell whose 4×4 in-slice neighbourhood and
    /// both neighbouring slices exist. The blend of the corners' central
    /// differences is linear in the voxels, so it is evaluated as differences of
    /// rows already interpolated along i: 12 short row loads (one bounds check
    /// each), 8 lerps along i, then the j blends — about half the instructions of
    /// four separate corner gradients. Equal to [`SliceStack::gradient_general`]
    /// up to float rounding (a test bounds the difference).
    #[inline(always)]
    fn gradient_interior(&self, ci: usize, cj: usize, k: usize, wi: f32, wj: f32) -> [f32; 3] {
        let (n0, n01) = (self.n[0], self.n[0] * self.n[1]);
        let b = self.index(ci, cj, k);
        let data = &self.data;
        // row y (−1..=2) of slice k at x = −1..=2, and rows y = 0, 1 of slices k ± 1 at x = 0, 1
        let r4 = |o: usize| -> [f32; 4] { data[o - 1..o + 3].try_into().expect("4 voxels") };
        let r2 = |o: usize| -> [f32; 2] { data[o..o + 2].try_into().expect("2 voxels") };
        let (rm, r0, r1, r2_) = (r4(b - n0), r4(b), r4(b + n0), r4(b + 2 * n0));
        let (p0, p1, m0, m1) = (r2(b + n01), r2(b + n01 + n0), r2(b - n01), r2(b - n01 + n0));
        let lerp = |a: f32, c: f32, w: f32| a + (c - a) * w;
        // the row interpolated at x = wi, and its central difference along i
        let li = |r: [f32; 4]| lerp(r[1], r[2], wi);
        let di = |r: [f32; 4]| lerp(r[2] - r[0], r[3] - r[1], wi) * 0.5;
        let l2 = |r: [f32; 2]| lerp(r[0], r[1], wi);
        let (lm, l0, l1, l2r) = (li(rm), li(r0), li(r1), li(r2_));
        [lerp(di(r0), di(r1), wj), lerp((l1 - lm) * 0.5, (l2r - l0) * 0.5, wj), (lerp(l2(p0), l2(p1), wj) - lerp(l2(m0), l2(m1), wj)) * 0.5]
    }

    fn gradient_general(&self, ci: usize, cj: usize, k: usize, wi: f32, wj: f32) -> [f32; 3] {
        let g00 = self.gradient_at(ci, cj, k);
        let g10 = self.gradient_at(ci + 1, cj, k);
        let g01 = self.gradient_at(ci, cj + 1, k);
        let g11 = self.gradient_at(ci + 1, cj + 1, k);
        let mut g = [0f32; 3];
        for c in 0..3 {
            let top = g00[c] + (g10[c] - g00[c]) * wi;
            let bot = g01[c] + (g11[c] - g01[c]) * wi;
            g[c] = top + (bot - top) * wj;
        }
        g
    }
}

/// The smaller of two densities: one `minss` (`f32::min` adds NaN handling;
/// stacks hold finite values only, where both agree).
#[inline(always)]
pub(crate) fn fmin(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// The larger of two densities (see [`fmin`]).
#[inline(always)]
pub(crate) fn fmax(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}

/// The bilinear interpolation of a cell's corner densities `[v00, v10, v01, v11]`
/// at in-cell weights `(wi, wj)`, clamped to their range (see [`SliceStack::bilinear`]).
#[inline(always)]
pub fn bilinear([v00, v10, v01, v11]: [f32; 4], wi: f32, wj: f32) -> f32 {
    let top = v00 + (v10 - v00) * wi;
    let bot = v01 + (v11 - v01) * wi;
    let d = top + (bot - top) * wj;
    let lo = fmin(fmin(v00, v10), fmin(v01, v11));
    let hi = fmax(fmax(v00, v10), fmax(v01, v11));
    fmin(fmax(d, lo), hi)
}

/// [`bilinear`] of the four corner densities in one SSE vector, lanes
/// `[v00, v01, v10, v11]`: lane for lane the same float operations in the
/// same order (both in-row interpolations in one vector, then the one across
/// rows; the range's `min`/`max` have [`fmin`]/[`fmax`]'s operand order, so the
/// same value, zeros' signs included), hence the same result bit for bit
/// (tested against [`bilinear`] over corner and weight edge cases).
///
/// # Safety
/// The CPU must have SSE3, and the caller must be compiled with it (the
/// `target_feature` of the function this inlines into).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) unsafe fn bilinear_sse(x: std::arch::x86_64::__m128, wi: f32, wj: f32) -> f32 {
    use std::arch::x86_64::*;
    // SAFETY: the caller's SSE3 covers `bilinear_lerps` and
    // `_mm_movehdup_ps`; the rest is SSE, the x86-64 baseline.
    unsafe {
        let (d, h) = bilinear_lerps(x, wi, wj);
        // lo = fmin(fmin(v00, v10), fmin(v01, v11)), hi likewise
        let m = _mm_min_ps(x, h);
        let lo = _mm_min_ss(m, _mm_movehdup_ps(m));
        let d = _mm_max_ss(d, lo);
        let n = _mm_max_ps(x, h);
        let hi = _mm_max_ss(n, _mm_movehdup_ps(n));
        _mm_cvtss_f32(_mm_min_ss(d, hi))
    }
}

/// [`bilinear_sse`] of corners that are bytes (whole numbers in `[0, 255]`),
/// without the clamp to the corners' range, which cannot bind there: the
/// same value bit for bit (tested against [`bilinear`] over every byte
/// pattern class and weight edge case).
///
/// Why neither clamp changes the value for corners that are non-negative
/// whole numbers below 2²⁴ and weights in `[0, 1]` (round to nearest, ties to
/// even; `lo` and `hi` the corners' least and largest, whole numbers):
/// - each in-row lerp `a + (b − a)·w` has `b − a` exact and `|fl((b − a)·w)| ≤
///   |b − a|` (rounding is monotone), so `top` and `bot` lie between their
///   row's corners, hence in `[lo, hi]`;
/// - `hi`, if `bot < top`: `fl(bot − top)·wj` rounds to a value in
///   `[fl(bot − top), 0]`, so the sum is at most `top ≤ hi`;
/// - `hi`, if `bot ≥ top ≥ 0`: `fl(bot − top)` is `bot − top` plus at most
///   half an ulp of `bot` (the difference is at most `bot`), so `top +
///   fl(bot − top)` is `bot` plus at most half an ulp of `bot`, which rounds
///   to `bot`, or, on an exact tie, to the even one of `bot` and its
///   successor; the sum with `fl(fl(bot − top)·wj) ≤ fl(bot − top)` rounds no
///   higher (monotone). If `bot < hi`, its successor is at most `hi` (a
///   float); if `bot = hi`, a whole number below 2²⁴, its last mantissa bit
///   is 0, so the tie keeps `hi`;
/// - `lo`, if `bot ≥ top`: the sum adds a non-negative value to `top ≥ lo`;
/// - `lo`, if `bot < top`: `lo − top` is exact (`lo` is a whole number no
///   larger than `top`, so both are multiples of the ulp of `top`, and the
///   difference is no larger than `top`), and `bot − top ≥ lo − top`, so
///   `fl(bot − top) ≥ lo − top` and, as `wj ≤ 1` and `lo − top ≤ 0`,
///   `fl(fl(bot − top)·wj) ≥ lo − top` (monotone, `lo − top` a float); the
///   sum is then at least `top + (lo − top) = lo`, a float, so it rounds to
///   no less than `lo`. It is `+0` where it is zero (`x + (−x)` is `+0`), as
///   `lo` is, so even the sign of a zero is the clamped one's.
///
/// # Safety
/// As [`bilinear_sse`].
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(crate) unsafe fn bilinear_sse_bytes(x: std::arch::x86_64::__m128, wi: f32, wj: f32) -> f32 {
    // SAFETY: the caller's contract is `bilinear_lerps`'; SSE is the x86-64
    // baseline.
    unsafe { std::arch::x86_64::_mm_cvtss_f32(bilinear_lerps(x, wi, wj).0) }
}

/// The lerps of [`bilinear_sse`] before any clamp: both in-row lerps in one
/// vector, then the one across rows, in lane 0 of the first vector; the
/// second is `[v10, v11, v10, v11]` (for the corners' range).
///
/// # Safety
/// As [`bilinear_sse`].
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn bilinear_lerps(x: std::arch::x86_64::__m128, wi: f32, wj: f32) -> (std::arch::x86_64::__m128, std::arch::x86_64::__m128) {
    use std::arch::x86_64::*;
    // SAFETY: SSE and SSE2 are the x86-64 baseline; `_mm_movehdup_ps` needs
    // SSE3, which the caller guarantees.
    unsafe {
        // [v10, v11, v10, v11]
        let h = _mm_movehl_ps(x, x);
        // [top, bot] = [v00 + (v10 − v00)·wi, v01 + (v11 − v01)·wi]
        let t = _mm_add_ps(x, _mm_mul_ps(_mm_sub_ps(h, x), _mm_set1_ps(wi)));
        let bot = _mm_movehdup_ps(t);
        (_mm_add_ss(t, _mm_mul_ss(_mm_sub_ss(bot, t), _mm_set_ss(wj))), h)
    }
}

/// The four voxels of the cell whose first voxel is `v[b]` in a slice layout
/// with rows of `n0`: `b`, `b + 1`, `b + n0`, `b + n0 + 1`, one bounds check
/// for all four. Shared by the densities and the normal codes.
#[inline(always)]
pub(crate) fn cell_corners<T: Copy>(v: &[T], b: usize, n0: usize) -> [T; 4] {
    let s = &v[b..b + n0 + 2];
    [s[0], s[1], s[n0], s[n0 + 1]]
}

/// Asks the cache for both voxel rows of the cell whose first voxel is `v[b]`
/// (rows of `n0`): what [`cell_corners`] reads. No effect on results.
#[inline(always)]
pub(crate) fn prefetch_cell<T>(v: &[T], b: usize, n0: usize) {
    prefetch(v, b);
    prefetch(v, b.wrapping_add(n0));
}

/// Asks the cache for `v[i]` (a hint: no effect on results). No bounds test:
/// an index past the end asks for an address no read follows, which costs at
/// most a wasted fetch.
#[inline(always)]
pub(crate) fn prefetch<T>(v: &[T], i: usize) {
    // (`wrapping_add` forms the address without dereferencing it)
    prefetch_ptr(v.as_ptr().wrapping_add(i));
}

/// Asks the cache for the line at `at`, any address (a hint: no effect on
/// results).
#[inline(always)]
pub(crate) fn prefetch_ptr<T>(at: *const T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        // SAFETY: a prefetch only hints the cache hierarchy: it never faults and
        // never reads or writes memory architecturally, so it is sound for any
        // address, in range or not. Exercised by every RLE render
        // (tests/rle.rs) and every binary render (tests/invariants.rs,
        // tests/lean_frame.rs).
        unsafe { _mm_prefetch::<_MM_HINT_T0>(at.cast::<i8>()) }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = at;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn permutation_matches_volume() {
        // 37 along x: more than one block of the gather along x (16 slices)
        for dims in [[3, 4, 5], [37, 6, 5], [5, 37, 19]] {
            let v = Volume::from_fn(dims, [1.0; 3], |x, y, z| (x + 100 * y + 10000 * z) as f32).unwrap();
            for axis in 0..3 {
                let p = permutation(axis);
                let nk = dims[p[2]];
                // the whole stack, and windows of it
                for ks in [0..nk, 1..nk.min(18), nk / 2..nk] {
                    let s = SliceStack::try_window(&v, axis, ks.clone()).unwrap();
                    assert_eq!(s.n[2], ks.len());
                    for k in 0..s.n[2] {
                        for j in 0..s.n[1] {
                            for i in 0..s.n[0] {
                                let mut xyz = [0; 3];
                                xyz[p[0]] = i;
                                xyz[p[1]] = j;
                                xyz[p[2]] = ks.start + k;
                                assert_eq!(s.at(i, j, k), v.get(xyz[0], xyz[1], xyz[2]), "{dims:?} axis {axis} {ks:?}");
                            }
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn bilinear_stays_in_the_corner_range_and_gradient_is_exact_for_linear() {
        let v = Volume::from_fn([5, 5, 5], [1.0; 3], |x, y, z| 0.1 * x as f32 + 3.0 * y as f32 - 2.0 * z as f32).unwrap();
        let s = SliceStack::new(&v, 2);
        let d = s.bilinear(1, 2, 3, 0.25, 0.5);
        assert!((d - (0.125 + 7.5 - 6.0)).abs() < 1e-5);
        let g = s.gradient(1, 1, 2, 0.3, 0.7);
        assert!((g[0] - 0.1).abs() < 1e-5 && (g[1] - 3.0).abs() < 1e-5 && (g[2] + 2.0).abs() < 1e-5);
        let (lo, hi) = s.cell_range(1, 2, 3);
        assert!(lo <= d && d <= hi);
    }

    /// A xorshift64 stream from `seed` (the bilinear tests' random corners
    /// and weights).
    #[cfg(target_arch = "x86_64")]
    fn xorshift(mut rng: u64) -> impl FnMut() -> u64 {
        move || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            rng
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_sse_bilinear_is_the_scalar_one_bit_for_bit() {
        use std::arch::x86_64::_mm_setr_ps;
        if !std::arch::is_x86_feature_detected!("sse3") {
            return;
        }
        // corners: bytes, 16-bit values with offsets, negative and mixed
        // magnitudes, zeros of both signs; weights: 0, 1, their neighbours
        let values = [0.0f32, -0.0, 1.0, 3.0, 52.0, 255.0, -1024.0, -1023.0, 3071.0, 65535.0, 0.1, 1e-30, 7.25];
        let weights = [0.0f32, 1.0, 0.5, 0.25, 1.0 - f32::EPSILON / 2.0, f32::MIN_POSITIVE, 0.3, 0.999, 1e-7];
        let mut next = xorshift(0x9e37_79b9_7f4a_7c15u64);
        for n in 0..400_000u32 {
            let pick = |r: u64| if n.is_multiple_of(2) { values[(r % values.len() as u64) as usize] } else { (r % 65536) as f32 - 1024.0 };
            let c = [pick(next()), pick(next()), pick(next()), pick(next())];
            let w = |r: u64| {
                if r.is_multiple_of(3) { weights[(r / 3 % weights.len() as u64) as usize] } else { (r >> 40) as f32 / (1u64 << 24) as f32 }
            };
            let (wi, wj) = (w(next()), w(next()));
            // SAFETY: SSE3 detected above; the test is compiled for the
            // baseline, so the intrinsics run as calls, which is sound.
            let v = unsafe { bilinear_sse(_mm_setr_ps(c[0], c[2], c[1], c[3]), wi, wj) };
            let want = bilinear(c, wi, wj);
            assert_eq!(v.to_bits(), want.to_bits(), "{c:?} at ({wi}, {wj})");
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_byte_bilinear_needs_no_clamp() {
        use std::arch::x86_64::_mm_setr_ps;
        if !std::arch::is_x86_feature_detected!("sse3") {
            return;
        }
        // weights at and next to 0, ½ and 1, tiny ones (ties against small
        // tops, a bottom row just above its whole lower corner under a high
        // top row), and random ones; corners from classes that reach the
        // bounds: equal pairs, one high corner, 0 and 255, neighbours
        let weights = [
            0.0f32,
            1.0,
            0.5,
            1.0 - f32::EPSILON / 2.0,
            0.5 + f32::EPSILON,
            0.5 - f32::EPSILON / 2.0,
            f32::MIN_POSITIVE,
            1e-7,
            1e-30,
            f32::EPSILON,
        ];
        let mut next = xorshift(0x2545_f491_4f6c_dd1du64);
        let check = |c: [f32; 4], wi: f32, wj: f32| {
            // SAFETY: SSE3 detected above; the test is compiled for the
            // baseline, so the intrinsics run as calls, which is sound.
            let v = unsafe { bilinear_sse_bytes(_mm_setr_ps(c[0], c[2], c[1], c[3]), wi, wj) };
            assert_eq!(v.to_bits(), bilinear(c, wi, wj).to_bits(), "{c:?} at ({wi}, {wj})");
        };
        for n in 0..2_000_000u32 {
            let r = next();
            let byte = |s: u32| ((r >> s) & 255) as f32;
            let c = match n % 4 {
                0 => [byte(0), byte(8), byte(16), byte(24)],
                1 => [byte(0), byte(0), byte(8), byte(16)],
                2 => [byte(0), byte(8), byte(8), byte(8) + ((r >> 32) & 1) as f32].map(|v| v.min(255.0)),
                _ => [0.0, 255.0, byte(0), byte(8)],
            };
            let w = |r: u64| {
                if r.is_multiple_of(3) { weights[(r / 3 % weights.len() as u64) as usize] } else { (r >> 40) as f32 / (1u64 << 24) as f32 }
            };
            check(c, w(next()), w(next()));
        }
        for a in (0..256).step_by(17) {
            for b in [0, 1, 128, 254, 255] {
                for &wi in &weights {
                    for &wj in &weights {
                        check([a as f32, b as f32, b as f32, a as f32], wi, wj);
                        check([b as f32, a as f32, 255.0, b as f32], wi, wj);
                        // a high top row over a low bottom row of neighbours
                        check([a as f32, a as f32, b as f32, (b + 1).min(255) as f32], wi, wj);
                    }
                }
            }
        }
    }

    #[test]
    fn prefetch_at_the_stack_edges_is_harmless_and_min_max_agree_with_std() {
        let v = Volume::from_fn([5, 4, 3], [1.0; 3], |x, y, z| (x + y + z) as f32).unwrap();
        let s = SliceStack::new(&v, 2);
        // rows before the first and past the last voxel are skipped, not touched
        for (ci, cj, k) in [(0, 0, 0), (3, 2, 2), (0, 2, 1), (3, 0, 0)] {
            for asc in [false, true] {
                s.prefetch_hit(ci, cj, k, asc);
            }
        }
        prefetch(s.data(), usize::MAX);
        let xs = [-3.5f32, -0.0, 0.0, 1.0, 2.5, f32::MAX, f32::MIN];
        for a in xs {
            for b in xs {
                assert_eq!(fmin(a, b), a.min(b), "min {a} {b}");
                assert_eq!(fmax(a, b), a.max(b), "max {a} {b}");
            }
        }
    }

    #[test]
    fn interior_gradient_equals_the_general_path_to_rounding() {
        let v =
            Volume::from_fn([9, 8, 7], [1.0; 3], |x, y, z| ((x * 7 + y * 13 + z * 29) % 17) as f32 * 1.37 - (x * y) as f32 * 0.11).unwrap();
        for axis in 0..3 {
            let s = SliceStack::new(&v, axis);
            for k in 1..s.n[2] - 1 {
                for cj in 1..s.n[1] - 2 {
                    for ci in 1..s.n[0] - 2 {
                        for (wi, wj) in [(0.0, 0.0), (0.3, 0.7), (0.999, 0.5)] {
                            let a = s.gradient_interior(ci, cj, k, wi, wj);
                            let b = s.gradient_general(ci, cj, k, wi, wj);
                            for c in 0..3 {
                                assert!((a[c] - b[c]).abs() <= 1e-5 * (1.0 + b[c].abs()), "{a:?} vs {b:?}");
                            }
                        }
                    }
                }
            }
        }
    }
}
