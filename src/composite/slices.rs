//! The slice traversal: compositing a run-length-encoded volume slice by slice,
//! front to back, into the intermediate image ([`render_rle`]), and its
//! brute-force reference ([`render_brute_preclassified`]).
//!
//! Both read the frame plan (slice maps, slice range, per-pixel ray limits) and
//! share the bilinear blend of four premultiplied voxels, the early ray
//! termination policy ([`crate::composite::terminated`]) and "over"
//! ([`crate::composite::composite_premultiplied`]) with every other path. See
//! [`crate::encode::rle`] for the encoding and the skips.

// Negated float comparisons (`!(a > b)`) are deliberate here: NaN takes the
// "no" branch.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use rayon::prelude::*;

use crate::composite::Rect;
use crate::composite::{Intermediate, OpacityTable, RayRow, composite_premultiplied, terminated};
use crate::encode::rle::runs::{Cursor, INF};
use crate::encode::rle::{PostTables, Preclass, RleCache, RleScratch, RleVolume, RleVoxel, ViewTables, VoxelSource};
use crate::kernels::CpuLevel;
use crate::view::plan::{FramePlan, MapKind, MidMap, RayLimits, floor_i64};

/// What a sample is made of (a sampler of the one slice traversal): each
/// voxel read becomes a 4-vector ([`Sampler::voxel`], [`Sampler::MISSING`]
/// for one the encoding left out), four (a cell) are blended bilinearly with
/// the one bilinear `blend`, and [`Sampler::finish`] turns the blend into the
/// premultiplied sample that is composited.
///
/// - Pre-classified ([`ViewTables`]): the voxel's shaded, opacity-corrected,
///   premultiplied colour; `finish` is the identity.
/// - Post-classified ([`PostTables`], Shear-Warp Deluxe P): the voxel's
///   density (as its classifier node, a float) and its unit normal; `finish`
///   classifies the interpolated density and shades the normalized
///   interpolated normal. A voxel left out is NaN, so a cell with one
///   finishes to zero: the encoding stores every voxel of each cell that may
///   be visible, so such a cell is invisible (its brute force classifies to
///   zero opacity).
pub trait Sampler: Sync {
    /// Whether minified slices are box-filtered (pre-classified only: a box
    /// average of densities would classify a density no voxel has, so the
    /// post-classified sampler samples every slice bilinearly).
    const BOX: bool;
    /// The 4-vector of a voxel the encoding left out.
    const MISSING: [f32; 4];
    /// The 4-vector of a stored voxel.
    fn voxel(&self, v: RleVoxel) -> [f32; 4];
    /// A blend of 4-vectors → the premultiplied sample.
    fn finish(&self, s: [f32; 4]) -> [f32; 4];
    /// The brute force's 4-vector of voxel `(i, j, k)` of `stack`.
    fn brute_voxel<V: VoxelSource + ?Sized>(&self, pre: &Preclass, stack: &V, i: usize, j: usize, k: usize) -> [f32; 4];
    /// A cell column's two voxels (bottom, top) as [`Sampler::blend_columns`]
    /// takes them (a row of cells reads each column once).
    #[inline(always)]
    fn column(&self, b: [f32; 4], t: [f32; 4]) -> [[f32; 4]; 2] {
        [b, t]
    }
    /// The bilinear blend of a cell from its left and right columns (each
    /// through [`Sampler::column`]) at weights `w`.
    #[inline(always)]
    fn blend_columns(&self, l: [[f32; 4]; 2], r: [[f32; 4]; 2], w: &Weights) -> [f32; 4] {
        blend(l[0], r[0], l[1], r[1], w)
    }
    /// The bilinear blend of a cell's four voxels (`c00`, `c10`, `c01`,
    /// `c11`) at weights `w` (every path's slice sample): its columns'
    /// blend, bit for bit.
    #[inline(always)]
    fn blend(&self, c00: [f32; 4], c10: [f32; 4], c01: [f32; 4], c11: [f32; 4], w: &Weights) -> [f32; 4] {
        self.blend_columns(self.column(c00, c01), self.column(c10, c11), w)
    }
    /// What a midpoint's cell keeps of one of its two columns (Deluxe I):
    /// what [`Sampler::mid_column`] makes of the column's four voxels.
    type MidColumn: Copy;
    /// A midpoint cell's column from its four voxels: slice `k`'s bottom
    /// and top (`bk`, `tk`), slice `k + 1`'s (`bk1`, `tk1`); a row of
    /// midpoints reads each column once, as a slice's row does.
    fn mid_column(&self, bk: [f32; 4], tk: [f32; 4], bk1: [f32; 4], tk1: [f32; 4]) -> Self::MidColumn;
    /// The midpoint of a cell from its left and right columns at weights `w`.
    fn mid_blend(&self, l: Self::MidColumn, r: Self::MidColumn, w: &Weights) -> [f32; 4];
    /// The midpoint of a cell's eight voxels (`v`: slice `k`'s four in
    /// [`Sampler::blend`]'s order, then slice `k + 1`'s) at weights `w`
    /// (every path's Deluxe I sample): trilinear interpolation at depth
    /// `k + ½`, the bilinear blend of the two slices' means; its columns'
    /// [`Sampler::mid_blend`], bit for bit.
    #[inline(always)]
    fn mid(&self, v: &[[f32; 4]; 8], w: &Weights) -> [f32; 4] {
        self.mid_blend(self.mid_column(v[0], v[2], v[4], v[6]), self.mid_column(v[1], v[3], v[5], v[7]), w)
    }
    /// [`Sampler::voxel`], [`Sampler::MISSING`] for `None`.
    #[inline(always)]
    fn get_or_missing(&self, v: Option<RleVoxel>) -> [f32; 4] {
        match v {
            Some(v) => self.voxel(v),
            None => Self::MISSING,
        }
    }
}

impl Sampler for ViewTables {
    const BOX: bool = true;
    const MISSING: [f32; 4] = [0.0; 4];
    #[inline(always)]
    fn voxel(&self, v: RleVoxel) -> [f32; 4] {
        ViewTables::voxel(self, v)
    }
    #[inline(always)]
    fn finish(&self, s: [f32; 4]) -> [f32; 4] {
        s
    }
    #[inline(always)]
    fn brute_voxel<V: VoxelSource + ?Sized>(&self, pre: &Preclass, stack: &V, i: usize, j: usize, k: usize) -> [f32; 4] {
        self.get(pre.classify_voxel(stack, i, j, k))
    }
    /// The column's two slices' means, bottom and top.
    type MidColumn = [[f32; 4]; 2];
    #[inline(always)]
    fn mid_column(&self, bk: [f32; 4], tk: [f32; 4], bk1: [f32; 4], tk1: [f32; 4]) -> [[f32; 4]; 2] {
        [mean(bk, bk1), mean(tk, tk1)]
    }
    #[inline(always)]
    fn mid_blend(&self, l: [[f32; 4]; 2], r: [[f32; 4]; 2], w: &Weights) -> [f32; 4] {
        blend(l[0], r[0], l[1], r[1], w)
    }
}

impl Sampler for PostTables {
    const BOX: bool = false;
    const MISSING: [f32; 4] = [f32::NAN; 4];
    #[inline(always)]
    fn voxel(&self, v: RleVoxel) -> [f32; 4] {
        PostTables::voxel(self, v)
    }
    #[inline(always)]
    fn finish(&self, s: [f32; 4]) -> [f32; 4] {
        PostTables::finish(self, s)
    }
    #[inline(always)]
    fn brute_voxel<V: VoxelSource + ?Sized>(&self, pre: &Preclass, stack: &V, i: usize, j: usize, k: usize) -> [f32; 4] {
        PostTables::voxel(self, pre.post_voxel(stack, i, j, k))
    }
    /// The column with its top normal turned to the bottom one's side
    /// (`turn`: negated where their dot product's sign bit is set).
    #[inline(always)]
    fn column(&self, b: [f32; 4], t: [f32; 4]) -> [[f32; 4]; 2] {
        [b, turn(t, normal_dot(&t, &b))]
    }
    /// The blend with the right column's normals turned to the left
    /// column's side (the sign of the dot product of the columns' normal
    /// sums, so a zero normal in either column does not decide it).
    #[inline(always)]
    fn blend_columns(&self, l: [[f32; 4]; 2], r: [[f32; 4]; 2], w: &Weights) -> [f32; 4] {
        let sum = |c: &[[f32; 4]; 2]| [0.0, c[0][1] + c[1][1], c[0][2] + c[1][2], c[0][3] + c[1][3]];
        let d = normal_dot(&sum(&l), &sum(&r));
        blend(l[0], turn(r[0], d), l[1], turn(r[1], d), w)
    }
    /// The column's four voxels as they are: the cell's eight are turned
    /// to one side together (`align_normals`).
    type MidColumn = [[f32; 4]; 4];
    #[inline(always)]
    fn mid_column(&self, bk: [f32; 4], tk: [f32; 4], bk1: [f32; 4], tk1: [f32; 4]) -> [[f32; 4]; 4] {
        [bk, tk, bk1, tk1]
    }
    #[inline(always)]
    fn mid_blend(&self, l: [[f32; 4]; 4], r: [[f32; 4]; 4], w: &Weights) -> [f32; 4] {
        let v = align_normals([l[0], r[0], l[1], r[1], l[2], r[2], l[3], r[3]]);
        blend(mean(v[0], v[4]), mean(v[1], v[5]), mean(v[2], v[6]), mean(v[3], v[7]), w)
    }
}

/// Post-classified voxels `[node, n]` (a midpoint's eight) with each normal
/// `n` turned to the side of the first one's (negated where their dot
/// product's sign bit is set; the reference is the first voxel's normal if it
/// is not zero, else the last's). A normal code holds a direction up to sign
/// (shading is two-sided, `|n·l|`), so two neighbours' codes may point
/// opposite ways: where a surface's normal crosses the codes' hemisphere
/// boundary, and across a thin shell, whose two sides' gradients point apart.
/// Blended as they are, they partly cancel (dark seams between voxels);
/// turned to one side first, they blend to the surface's direction. A slice's
/// cell turns its normals column by column instead ([`Sampler::column`],
/// [`Sampler::blend_columns`]), so a row of cells turns each column once; a
/// midpoint's eight are turned whole: turned column by column (each column's
/// four to one side, then the columns by the slice's rule) the cube phantom's
/// I,P error rose by up to 13 % at 0° and 45° (IMP 28 %).
#[inline(always)]
fn align_normals<const N: usize>(mut v: [[f32; 4]; N]) -> [[f32; 4]; N] {
    let r = if normal_dot(&v[0], &v[0]) > 0.0 { v[0] } else { v[N - 1] };
    // (the first one is the reference or zero: it stays)
    for x in v.iter_mut().skip(1) {
        *x = turn(*x, normal_dot(x, &r));
    }
    v
}

/// The dot product of two post-classified voxels' normals (`[node, n]`).
#[inline(always)]
fn normal_dot(a: &[f32; 4], b: &[f32; 4]) -> f32 {
    a[1] * b[1] + a[2] * b[2] + a[3] * b[3]
}

/// Voxel `x` (`[node, n]`) with its normal negated where `d`'s sign bit is
/// set: branch-free (a NaN normal, a voxel the encoding left out, stays NaN).
#[inline(always)]
fn turn(mut x: [f32; 4], d: f32) -> [f32; 4] {
    let sign = d.to_bits() & 0x8000_0000;
    for c in &mut x[1..] {
        *c = f32::from_bits(c.to_bits() ^ sign);
    }
    x
}

/// The mean of two 4-vectors (a midpoint's pair across two slices).
#[inline(always)]
fn mean(a: [f32; 4], b: [f32; 4]) -> [f32; 4] {
    let mut s = [0f32; 4];
    for c in 0..4 {
        s[c] = 0.5 * (a[c] + b[c]);
    }
    s
}

/// Intermediate rows per parallel band.
const BAND: usize = 16;

/// Weights of the cell's voxels `(ci, cj)`, `(ci + 1, cj)`, `(ci, cj + 1)`,
/// `(ci + 1, cj + 1)`, each repeated over the four channels (so [`blend`] is
/// four plain vector multiply-adds).
type Weights = [[f32; 4]; 4];

#[inline(always)]
fn cell_weights(wi: f32, wj: f32) -> Weights {
    [(1.0 - wi) * (1.0 - wj), wi * (1.0 - wj), (1.0 - wi) * wj, wi * wj].map(|x| [x; 4])
}

/// The bilinear blend of four premultiplied voxels (both paths use exactly this).
#[inline(always)]
fn blend(c00: [f32; 4], c10: [f32; 4], c01: [f32; 4], c11: [f32; 4], w: &Weights) -> [f32; 4] {
    let mut s = [0f32; 4];
    for c in 0..4 {
        s[c] = c00[c] * w[0][c] + c10[c] * w[1][c] + c01[c] * w[2][c] + c11[c] * w[3][c];
    }
    s
}

/// First pixel at or after `x` that is not opaque, compressing the path.
///
/// `links[x] == 0` means pixel `x` is not opaque; otherwise `x + links[x]` is a
/// pixel further on to continue from. The row's last entry is a sentinel that
/// never becomes opaque, so the walk always ends.
/// Most voxels a box footprint ([`box_weights`]) spans along one axis.
const MAXW: usize = 6;

/// The box footprint of width `s` (1 < s ≤ [`crate::view::plan::MAX_FOOTPRINT`])
/// centred on sample position `pos` along an axis of `n` voxels: the first
/// voxel under it and how many, each weighted by the overlap of its cell
/// `[i − ½, i + ½]` with `[pos − s/2, pos + s/2]`, over `s` (an area average
/// of the voxels' opacity-weighted colours; at `s = 1` it would be the linear
/// weights). Voxels outside the volume are left out (they are transparent).
/// One function for the accelerated path and its brute force: the same
/// weights, bit for bit.
#[inline(always)]
fn box_weights(pos: f64, s: f64, n: usize, w: &mut [f32; MAXW]) -> (usize, usize) {
    let (a, b) = (pos - 0.5 * s, pos + 0.5 * s);
    // (floor and ceil without a libm call: the baseline x86-64 has no instruction for them)
    let first = floor_i64(a + 0.5).max(0);
    let last = (-floor_i64(-(b + 0.5)) - 1).min(n as i64 - 1).min(first + MAXW as i64 - 1);
    if last < first {
        return (0, 0);
    }
    let inv = 1.0 / s;
    for (t, i) in (first..=last).enumerate() {
        let c = i as f64;
        w[t] = (((c + 0.5).min(b) - (c - 0.5).max(a)).max(0.0) * inv) as f32;
    }
    (first as usize, (last - first + 1) as usize)
}

/// One column of a box footprint: `Σ_t wj[t] · voxel(t)` over its rows `t`
/// in order (a row of the intermediate image has one `wj` for every pixel,
/// so the accelerated path computes each column once and reuses it).
#[inline(always)]
fn box_column(wj: &[f32], mut voxel: impl FnMut(usize) -> [f32; 4]) -> [f32; 4] {
    let mut col = [0f32; 4];
    for (t, &wt) in wj.iter().enumerate() {
        let v = voxel(t);
        for c in 0..4 {
            col[c] += wt * v[c];
        }
    }
    col
}

/// The box-filtered sample `Σ_u wi[u] · column(u)` over the footprint's
/// columns in order ([`box_column`]): the accelerated path and its brute force
/// add the same numbers in the same order.
#[inline(always)]
fn box_sample(wi: &[f32], mut column: impl FnMut(usize) -> [f32; 4]) -> [f32; 4] {
    let mut smp = [0f32; 4];
    for (u, &wu) in wi.iter().enumerate() {
        let v = column(u);
        for c in 0..4 {
            smp[c] += wu * v[c];
        }
    }
    smp
}

/// Focus+context: calls `run(x0, x1, in_focus)` for the maximal runs of
/// pixels `x0 ..= x1` of `[lo, hi]` (pixel indices of `frow`, a row of the
/// plan's focus intervals) whose sample between slices `k0` and `k1` (`[k,
/// k]`: slice `k`'s; `[k, k + 1]`: Deluxe I's midpoint, in the focus iff both
/// slices are, as [`FramePlan::in_focus_mid`]) is all inside or all outside
/// the focus, in order. The one place the slice traversal reads the focus:
/// each run is composited with the focus's or the context's sampler.
#[inline]
fn focus_runs(frow: &[[u32; 2]], [k0, k1]: [u32; 2], lo: i64, hi: i64, mut run: impl FnMut(i64, i64, bool)) {
    let inside = |x: i64| {
        let [a, b] = frow[x as usize];
        a <= k0 && k1 <= b
    };
    let mut x = lo;
    while x <= hi {
        let f = inside(x);
        let mut e = x;
        while e < hi && inside(e + 1) == f {
            e += 1;
        }
        run(x, e, f);
        x = e + 1;
    }
}

#[inline(always)]
fn find(links: &mut [u32], x: usize) -> usize {
    if links[x] == 0 {
        return x;
    }
    let mut y = x;
    while links[y] != 0 {
        y += links[y] as usize;
    }
    // every pixel on the way now points straight at y
    let mut z = x;
    while z != y {
        let next = z + links[z] as usize;
        links[z] = (y - z) as u32;
        z = next;
    }
    y
}

/// Composites slice `k`'s cells between scanlines `bot` (row `cj`) and `top`
/// (row `cj + 1`) into one intermediate row: pixel `x = ci + off` for cell
/// columns `ci` in `[ci_lo, ci_hi]`.
///
/// Alternates two skips: opaque pixels through the links, transparent voxels
/// through the runs. Between them, [`span`] composites the pixels that touch
/// some non-transparent voxel.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn composite_row<'v, S: Sampler, const LIM: bool>(
    mut bot: Cursor<'v>,
    mut top: Cursor<'v>,
    [ci_lo, ci_hi]: [u32; 2],
    t: &S,
    row: &SliceRow,
    px: &mut [[f32; 4]],
    links: &mut [u32],
    cache: &mut ScanCache<'_>,
) {
    let off = row.off;
    let mut ci = ci_lo;
    loop {
        // skip opaque pixels through the links
        let x = find(links, (ci as isize + off) as usize);
        ci = (x as isize - off) as u32;
        if ci > ci_hi {
            return;
        }
        // skip transparent voxels: pixel ci reads columns ci and ci + 1 of both scanlines
        bot.seek(ci);
        top.seek(ci);
        let nx = bot.first_from(ci).min(top.first_from(ci));
        if nx > ci + 1 {
            if nx == INF || nx - 1 > ci_hi {
                return;
            }
            ci = nx - 1;
            continue;
        }
        let on = SpanOn { bot: &mut bot, top: &mut top, px: &mut *px, links: &mut *links, cache: &mut *cache };
        ci = span::<S, LIM>(on, [ci, ci_hi], t, row);
        if ci > ci_hi {
            return;
        }
    }
}

/// What a span walks and writes: the two scanlines' cursors (moved along),
/// the row's pixels and their links, and the band's scanline cache.
struct SpanOn<'a, 'v, 'c> {
    bot: &'a mut Cursor<'v>,
    top: &'a mut Cursor<'v>,
    px: &'a mut [[f32; 4]],
    links: &'a mut [u32],
    cache: &'a mut ScanCache<'c>,
}

/// Composites the span of pixels from `ci` (not opaque, touching a
/// non-transparent voxel) up to the first pixel that is opaque or touches only
/// transparent voxels, or past `ci_hi`; returns where it stopped.
///
/// The span is walked in segments: columns over which both scanlines stay in the
/// same kind of run, so each is a plain loop over one or two voxel slices
/// ([`segment`]). The right column of one pixel is the left column of the next,
/// so each voxel is shaded once per row.
///
/// Runs [`span_avx2`] when the row says so (`row.avx2`), else the plain
/// build of [`span_body`]: the same code and float operations, so the same
/// pixels bit for bit.
#[inline(never)] // one small function per span keeps the loops' state in registers
fn span<S: Sampler, const LIM: bool>(on: SpanOn, ci: [u32; 2], t: &S, row: &SliceRow) -> u32 {
    #[cfg(target_arch = "x86_64")]
    if row.avx2 {
        // SAFETY: `row.avx2` is set only from a CPU level capped to what
        // this CPU has (`RleFrame::avx2`), and that level has AVX2.
        return unsafe { span_avx2::<S, LIM>(on, ci, t, row) };
    }
    span_body::<S, LIM>(on, ci, t, row)
}

/// [`span_body`] compiled for AVX2: the same vector operations in VEX
/// encoding (three operands, loads folded into them, broadcasts from
/// memory; no fused multiply-add, so every sum and product rounds as in
/// [`span`]). Callers must run on a CPU with AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,avx2")]
#[inline(never)]
unsafe fn span_avx2<S: Sampler, const LIM: bool>(on: SpanOn, ci: [u32; 2], t: &S, row: &SliceRow) -> u32 {
    span_body::<S, LIM>(on, ci, t, row)
}

/// The body of [`span`] and [`span_avx2`].
#[inline(always)]
fn span_body<S: Sampler, const LIM: bool>(
    SpanOn { bot, top, px, links, cache }: SpanOn,
    [mut ci, ci_hi]: [u32; 2],
    t: &S,
    row: &SliceRow,
) -> u32 {
    // the row's weights as a local copy: the loops below keep them in registers
    let (off, w, lim) = (row.off, row.w, row.lim);
    let smp = &SliceSamples { w: &w, ert: row.ert };
    let (vb, vt) = (bot.at(ci), top.at(ci));
    let [b, tp] = t.column(t.get_or_missing(vb), t.get_or_missing(vt));
    let mut left = Left { b, t: tp, any: vb.is_some() || vt.is_some() };
    loop {
        let c1 = ci + 1;
        bot.step(c1);
        top.step(c1);
        let (bin, tin) = (c1 >= bot.s, c1 >= top.s);
        // the segment's right columns: [c1, end)
        let end = (if bin { bot.e } else { bot.s }).min(if tin { top.e } else { top.s }).min(ci_hi + 2);
        let n = (end - c1) as usize;
        let x0 = (ci as isize + off) as usize;
        let (p, l) = (&mut px[x0..x0 + n], &mut links[x0..x0 + n]);
        let lm = Limits {
            row: if LIM { &lim.row[x0..x0 + n] } else { &[][..] },
            holes: if LIM && !lim.holes.is_empty() { &lim.holes[x0..x0 + n] } else { &[][..] },
            k: lim.k,
        };
        let bv = if bin { &bot.vox[bot.base.wrapping_add(c1) as usize..][..n] } else { &[][..] };
        let tv = if tin { &top.vox[top.base.wrapping_add(c1) as usize..][..n] } else { &[][..] };
        let (want, done) = match (bin, tin) {
            (true, true) => (n, segment::<S, true, true, LIM>(p, l, [bv, tv], &mut left, t, smp, lm, cache.at(c1 as usize, n))),
            (true, false) => (n, segment::<S, true, false, LIM>(p, l, [bv, &[]], &mut left, t, smp, lm, cache.at(c1 as usize, n))),
            (false, true) => (n, segment::<S, false, true, LIM>(p, l, [&[], tv], &mut left, t, smp, lm, cache.at(c1 as usize, n))),
            (false, false) => {
                if !left.any {
                    return ci; // all four voxels transparent: back to run skipping
                }
                let lm1 = Limits {
                    row: if LIM { &lm.row[..1] } else { &[][..] },
                    holes: if LIM && !lm.holes.is_empty() { &lm.holes[..1] } else { &[][..] },
                    k: lm.k,
                };
                (1, segment::<S, false, false, LIM>(&mut p[..1], &mut l[..1], [&[], &[]], &mut left, t, smp, lm1, cache.at(0, 0)))
            }
        };
        ci += done as u32;
        if done < want || ci > ci_hi {
            return ci; // an opaque pixel (back to the links), or the end
        }
    }
}

/// One row of a box-filtered slice ([`RleFrame::box_slice`]): slice `k`,
/// intermediate row `q`, footprint `s` (per in-slice axis), the `nb` rows of
/// the box (their cursors and weights) whose non-transparent columns end at
/// `hi`.
struct BoxRow<'w, 'c> {
    k: usize,
    q: usize,
    s: [f64; 2],
    nb: usize,
    hi: i64,
    curs: [Cursor<'c>; MAXW],
    wj: &'w [f32; MAXW],
}

/// How a translated slice's samples are weighted and composited: the
/// slice's cell weights (one for all its pixels) and the early ray
/// termination threshold.
struct SliceSamples<'a> {
    w: &'a Weights,
    ert: f32,
}

/// One intermediate row of a translated slice ([`composite_row`]): cell
/// column `ci` lands on the row's pixel `ci + off`; the slice's cell
/// weights `w`, the termination threshold `ert`, the pixels' ray limits.
/// (The sampler travels beside it, as its own argument: the traversal's
/// inner loops then read its tables' addresses once.)
struct SliceRow<'a> {
    off: isize,
    w: Weights,
    ert: f32,
    lim: Limits<'a>,
    /// Whether its spans run compiled for AVX2 ([`span`]).
    avx2: bool,
}

/// The left column of the next pixel: its two voxels' colours (through
/// [`Sampler::column`]), and whether either is non-transparent.
struct Left {
    b: [f32; 4],
    t: [f32; 4],
    any: bool,
}

/// A band's voxels shaded by [`Sampler::voxel`], by voxel column: the top
/// scanline's of the row last composited (`stamp[c]` names the row that
/// wrote `shaded[c]`). The next row's bottom scanline is that row's top
/// one, so it reads a voxel there instead of shading it again (the same
/// value, bit for bit); rows are counted from 2 up, so a zero stamp never
/// names the row before (a band call counts two a slice and one a row of
/// it, far below `u32::MAX`). [`ScanCache::at`] gives a segment's columns as
/// a cache of their own.
struct ScanCache<'a> {
    shaded: &'a mut [[f32; 4]],
    stamp: &'a mut [u32],
    row: u32,
}

impl<'a> ScanCache<'a> {
    /// A cache over the voxel columns of `shaded` and `stamp` (the same
    /// length; the stamps are cleared).
    fn new(shaded: &'a mut [[f32; 4]], stamp: &'a mut [u32]) -> Self {
        stamp.fill(0);
        ScanCache { shaded, stamp, row: 2 }
    }

    /// The next row of the same slice and sampler: it reads what this one wrote.
    #[inline(always)]
    fn next_row(&mut self) {
        self.row += 1;
    }

    /// A row that must read nothing written so far (another slice, another
    /// sampler).
    #[inline(always)]
    fn forget(&mut self) {
        self.row += 2;
    }

    /// Its columns `c .. c + n`, at the current row.
    #[inline(always)]
    fn at(&mut self, c: usize, n: usize) -> ScanCache<'_> {
        ScanCache { shaded: &mut self.shaded[c..c + n], stamp: &mut self.stamp[c..c + n], row: self.row }
    }
}

/// The ray limits of a row's pixels and the slice being composited: with
/// `LIM`, pixel `x` composites slice `k` only when `row[x] = [k0, k1]` holds it
/// and, when the plan has holes (`holes` not empty), `holes[x]` does not.
#[derive(Clone, Copy)]
struct Limits<'a> {
    row: &'a [[u32; 2]],
    holes: &'a [[u32; 2]],
    k: u32,
}

impl<'a> Limits<'a> {
    const NONE: Limits<'static> = Limits { row: &[], holes: &[], k: 0 };

    /// Slice `k`'s limits of intermediate row `q` over the rect's columns
    /// `r.p0 ..= r.p1` (with the holes, when the limits have any).
    #[inline(always)]
    fn of(l: &'a RayLimits, q: usize, r: &Rect, k: usize) -> Self {
        let holes = l.hole_row(q);
        let holes = if holes.is_empty() { holes } else { &holes[r.p0..=r.p1] };
        Limits { row: &l.row(q)[r.p0..=r.p1], holes, k: k as u32 }
    }

    /// Whether pixel `s` of the row composites the slice.
    #[inline(always)]
    fn keeps(&self, s: usize) -> bool {
        self.keeps_pair(s, [self.k; 2])
    }

    /// Whether pixel `s` of the row composites a sample between slices
    /// `ka` and `kb` (the same slice for a slice's sample): both in its
    /// interval, and its hole (if any) not between or on them.
    #[inline(always)]
    fn keeps_pair(&self, s: usize, [ka, kb]: [u32; 2]) -> bool {
        let [k0, k1] = self.row[s];
        k0 <= ka
            && kb <= k1
            && (self.holes.is_empty() || {
                let [h0, h1] = self.holes[s];
                h0 > h1 || h1 < ka || kb < h0
            })
    }
}

/// What compositing a sample of one intermediate row of a scaled plan takes
/// from the plan, sliced to the rect's columns once a row
/// ([`RleFrame::row_composite`]): the ray limits and holes, each ray's place
/// in the opacity table, the termination threshold.
#[derive(Clone, Copy)]
struct RowComposite<'a> {
    /// The row's limits (`None`: every ray keeps every slice; their own
    /// slice unused: [`Limits::keeps_pair`] names the slices).
    limits: Option<Limits<'a>>,
    /// The rays' places in `table` (empty: no ray is corrected).
    rays: &'a [RayRow],
    table: &'a OpacityTable,
    ert: f32,
}

impl RowComposite<'_> {
    /// The row from its pixel `xs` on (rect-relative).
    #[inline(always)]
    fn skip(&self, xs: usize) -> Self {
        RowComposite {
            limits: self.limits.map(|l| Limits {
                row: &l.row[xs..],
                holes: if l.holes.is_empty() { l.holes } else { &l.holes[xs..] },
                k: l.k,
            }),
            rays: if self.rays.is_empty() { self.rays } else { &self.rays[xs..] },
            ..*self
        }
    }

    /// Composites `smp` (a blend, `t`'s [`Sampler::finish`]ed here) into
    /// pixel `xr` of the row (rect-relative), the sample between slices
    /// `ks[0]` and `ks[1]` (the same slice for a slice's sample), if its ray
    /// limits keep both, with the ray's own opacity correction
    /// ([`FramePlan::correct_opacity`]); marks the pixel in the links when it
    /// terminates.
    #[inline(always)]
    fn add<S: Sampler>(&self, t: &S, ks: [usize; 2], xr: usize, smp: [f32; 4], prow: &mut [[f32; 4]], lrow: &mut [u32]) {
        if self.limits.is_some_and(|l| !l.keeps_pair(xr, [ks[0] as u32, ks[1] as u32])) {
            return;
        }
        let smp = t.finish(smp);
        let smp = if self.rays.is_empty() { smp } else { self.table.correct_row(smp, self.rays[xr]) };
        let acc = &mut prow[xr];
        composite_premultiplied(acc, smp);
        if terminated(acc[3], self.ert) {
            lrow[xr] = 1;
        }
    }
}

/// Composites consecutive pixels `px` (their `links`) whose right columns are
/// `bv` / `tv` (bottom / top scanline; `B` / `T` false: transparent, the slice
/// is unused), skipping (`LIM`) pixels whose ray limits exclude the slice.
/// Stops before the first opaque pixel; returns how many it did.
///
/// A bottom voxel the row before shaded as its top one comes from `scan`
/// (the band's [`ScanCache`] over these columns); each top voxel shaded
/// goes into it for the next row.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn segment<S: Sampler, const B: bool, const T: bool, const LIM: bool>(
    px: &mut [[f32; 4]],
    links: &mut [u32],
    [bv, tv]: [&[RleVoxel]; 2],
    left: &mut Left,
    t: &S,
    smp: &SliceSamples,
    lim: Limits,
    scan: ScanCache,
) -> usize {
    let (w, ert) = (smp.w, smp.ert);
    // exact lengths, so the loop below needs no bounds checks
    let n = px.len();
    let links = &mut links[..n];
    let bv = &bv[..if B { n } else { 0 }];
    let tv = &tv[..if T { n } else { 0 }];
    let (shaded, stamp, this) = (&mut scan.shaded[..if B || T { n } else { 0 }], &mut scan.stamp[..if B || T { n } else { 0 }], scan.row);
    let (mut lb, mut lt) = (left.b, left.t);
    let mut done = n;
    for s in 0..n {
        if links[s] != 0 {
            done = s;
            break;
        }
        let rb = if !B {
            S::MISSING
        } else if stamp[s] == this - 1 {
            shaded[s]
        } else {
            t.voxel(bv[s])
        };
        let rt = if T {
            let v = t.voxel(tv[s]);
            (shaded[s], stamp[s]) = (v, this);
            v
        } else {
            S::MISSING
        };
        let [rb, rt] = t.column(rb, rt);
        let inside = !LIM || lim.keeps(s);
        if inside {
            let acc = &mut px[s];
            composite_premultiplied(acc, t.finish(t.blend_columns([lb, lt], [rb, rt], w)));
            if terminated(acc[3], ert) {
                links[s] = 1;
            }
        }
        (lb, lt) = (rb, rt);
    }
    if done > 0 {
        *left = Left { b: lb, t: lt, any: B || T };
    }
    done
}

/// A run of midpoints for [`mid_run`]: between slices `k` and `k + 1`,
/// pixels from `x` (the row's cell weight `wj`, the pixels' cells by
/// `imap`), their cells from `c`, their right columns `vox` (four
/// scanlines' voxels from column `c + 1`, in [`RleFrame::mid_row`]'s order,
/// all of one length).
struct MidRun<'v> {
    k: usize,
    x: i64,
    c: u32,
    vox: [&'v [RleVoxel]; 4],
    wj: f32,
    imap: MidMap,
}

/// Composites the midpoints of a [`MidRun`] into `px` / `links` (the
/// run's pixels; `rc` from its first), the first cell's left column
/// `left`, at weights `w` (`SHIFT`: a translated plan's row, every pixel
/// the next cell at one weight; else each pixel's cell and weight from
/// the run's `imap`, stopping at one whose cell does not follow on). Stops
/// before an opaque pixel. Returns how many it did and the last one's
/// columns.
#[inline(always)]
fn mid_run<S: Sampler, const SHIFT: bool>(
    t: &S,
    rc: &RowComposite,
    run: &MidRun,
    left: S::MidColumn,
    w: &Weights,
    px: &mut [[f32; 4]],
    links: &mut [u32],
) -> (usize, [S::MidColumn; 2]) {
    // exact lengths, so the loop below needs no bounds checks
    let n = px.len();
    let links = &mut links[..n];
    let (vox, imap) = (run.vox.map(|v| &v[..n]), run.imap);
    #[inline(always)]
    fn column<S: Sampler>(t: &S, vox: &[&[RleVoxel]; 4], s: usize) -> S::MidColumn {
        t.mid_column(t.voxel(vox[0][s]), t.voxel(vox[1][s]), t.voxel(vox[2][s]), t.voxel(vox[3][s]))
    }
    // the last cell's left and right columns
    let (mut pl, mut l, mut wl) = (left, left, (f32::NAN, *w));
    let mut done = n;
    for s in 0..n {
        if links[s] != 0 {
            done = s;
            break;
        }
        let w = if SHIFT {
            w
        } else {
            let (cn, wn) = imap.cell(run.x + s as i64);
            if cn != run.c as i64 + s as i64 {
                done = s;
                break;
            }
            if wn.to_bits() != wl.0.to_bits() {
                wl = (wn, cell_weights(wn, run.wj));
            }
            &wl.1
        };
        let r = column(t, &vox, s);
        rc.add(t, [run.k, run.k + 1], s, t.mid_blend(l, r, w), px, links);
        (pl, l) = (l, r);
    }
    (done, [pl, l])
}

/// Clears `rect`'s part of the intermediate rows in `px` / `depth` (row stride `gw`).
fn clear_rows(px: &mut [[f32; 4]], depth: &mut [f32], gw: usize, r: &Rect) {
    for (row, drow) in px.chunks_mut(gw).zip(depth.chunks_mut(gw)) {
        row[r.p0..=r.p1].fill([0.0; 4]);
        drow[r.p0..=r.p1].fill(f32::NAN);
    }
}

/// Composites `rle` into `frame.rect` of the intermediate image (every pixel
/// of the rectangle written, transparent where nothing composited; depth
/// NaN) and seals it, with `tables` (and `focus`'s sampler inside the plan's
/// focus intervals).
/// `scratch` is sized for the whole grid on first use and reused across
/// frames.
pub fn render_rle<S: Sampler>(
    rle: &RleVolume,
    tables: &S,
    focus: Option<&S>,
    frame: SliceFrame,
    scratch: &mut RleScratch,
    out: &mut Intermediate,
) {
    let SliceFrame { plan, ert, rect, cpu } = frame;
    out.seal(rect);
    let Some(r) = rect else { return };
    let gw = out.size[0];
    let width = r.p1 - r.p0 + 1;
    let lw = width + 1; // links per row, with the sentinel
    let rows = r.q1 - r.q0 + 1;
    // sized for the whole grid once, so no later rectangle grows it (a
    // translated slice's voxel columns fit in the grid's width)
    let RleScratch { links, shaded, stamps } = scratch;
    let most = out.size[1] * (out.size[0] + 1);
    if links.len() < most {
        links.resize(most, 0);
    }
    let cols = rle.n[0].max(gw);
    let most = out.size[1].div_ceil(BAND) * cols;
    if shaded.len() < most {
        shaded.resize(most, [0.0; 4]);
        stamps.resize(most, 0);
    }
    // focus+context: the focus's sampler where the plan has focus intervals
    let focus = focus.filter(|_| plan.focus.is_some());
    let avx2 = cpu.capped().has_avx2();
    let fr = RleFrame { rle, tables, focus, plan, pad: plan.grid.pad as isize, ert, avx2, r, gw, lw };
    let px = &mut out.rgba[r.q0 * gw..(r.q1 + 1) * gw];
    let depth = &mut out.depth[r.q0 * gw..(r.q1 + 1) * gw];
    let caches = shaded.par_chunks_mut(cols).zip(stamps.par_chunks_mut(cols));
    let bands = px.par_chunks_mut(gw * BAND).zip(depth.par_chunks_mut(gw * BAND)).zip(links[..rows * lw].par_chunks_mut(lw * BAND));
    bands.zip(caches).enumerate().for_each(|(b, (((px, depth), links), (shaded, stamps)))| {
        fr.band(r.q0 + b * BAND, px, depth, links, ScanCache::new(shaded, stamps))
    });
}

/// What a frame of the slice traversal composites: the plan's view, the
/// early ray termination threshold (a pixel whose opacity reaches `ert`
/// takes no more samples), the rectangle of the intermediate image
/// written (`None`: nothing is visible) and the CPU level.
#[derive(Clone, Copy, Debug)]
pub struct SliceFrame<'a> {
    pub plan: &'a FramePlan,
    pub ert: f32,
    pub rect: Option<Rect>,
    /// The CPU level the traversal's kernels run at (capped to what the CPU
    /// has; every level composites the same image bit for bit).
    pub cpu: CpuLevel,
}

/// One intermediate row of a scaled slice ([`RleFrame::scaled_row`]):
/// slice `k`, row `q`, its cells' scanlines `s` and `s + 1` at row weight
/// `wj`, no cell past `hi` holding a non-transparent voxel.
struct ScaledRow {
    k: usize,
    q: usize,
    s: usize,
    hi: i64,
    wj: f32,
}

/// One intermediate row of midpoints between slices `k` and `k + 1`
/// ([`RleFrame::mid_row`]): row `q`, columns by `imap`, the four scanlines
/// `scan` under it at row weight `wj`, no cell past `hi` holding a
/// non-transparent voxel.
struct MidRow {
    k: usize,
    q: usize,
    imap: MidMap,
    scan: [usize; 4],
    hi: i64,
    wj: f32,
}

/// The per-frame constants of [`render_rle`].
struct RleFrame<'a, S> {
    rle: &'a RleVolume,
    tables: &'a S,
    /// Focus+context: the sampler of the samples inside the plan's focus intervals.
    focus: Option<&'a S>,
    plan: &'a FramePlan,
    pad: isize,
    ert: f32,
    /// Whether the spans run compiled for AVX2 ([`span`]).
    avx2: bool,
    /// The rectangle written.
    r: Rect,
    /// Row stride of the intermediate image and of the links.
    gw: usize,
    lw: usize,
}

impl<S: Sampler> Clone for RleFrame<'_, S> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<S: Sampler> Copy for RleFrame<'_, S> {}

impl<S: Sampler> RleFrame<'_, S> {
    /// This frame with the focus's sampler in place of the context's (focus+context).
    fn focused(&self) -> Self {
        RleFrame { tables: self.focus.unwrap_or(self.tables), ..*self }
    }

    /// Renders the band of intermediate rows from `q_first` (`px`, `depth` and
    /// `links` hold its rows): clears it, then composites every slice front to back.
    #[inline(never)]
    fn band(&self, q_first: usize, px: &mut [[f32; 4]], depth: &mut [f32], links: &mut [u32], mut cache: ScanCache) {
        let (r, gw, lw, rle) = (&self.r, self.gw, self.lw, self.rle);
        let [ni, nj, _] = rle.n;
        clear_rows(px, depth, gw, r);
        links.fill(0);
        // nothing composites when even an empty pixel counts as terminated
        if terminated(0.0, self.ert) {
            return;
        }
        let nrows = px.len() / gw;
        let mut prev: Option<usize> = None;
        for k in self.plan.front_to_back() {
            // a slice's first row reads nothing shaded for another slice
            cache.forget();
            // Deluxe I: the intermediate samples between the last slice and this one
            if let Some(kp) = prev.filter(|_| self.plan.intermediate()) {
                self.mid_slice(kp.min(k), q_first, px, links);
            }
            prev = Some(k);
            let bb = rle.bbox[k];
            if bb[0] > bb[1] {
                continue;
            }
            if self.plan.kind == MapKind::ScaleTranslate {
                if S::BOX && self.plan.boxed(k) {
                    self.box_slice(k, q_first, px, links);
                } else {
                    self.scaled_slice(k, q_first, px, links);
                }
                continue;
            }
            let sp = self.plan.maps[k];
            let w = cell_weights(sp.weight[0], sp.weight[1]);
            // cell column ci lands on pixel ci + op (row-relative: ci + off)
            let op = self.pad - sp.floor[0] as isize;
            let off = op - r.p0 as isize;
            // cells of the rect that touch the slice's non-transparent box
            let ci_lo = (r.p0 as isize - op).max(bb[0] as isize - 1).max(0);
            let ci_hi = (r.p1 as isize - op).min(bb[1] as isize).min(ni as isize - 2);
            if ci_lo > ci_hi {
                continue;
            }
            let fj = sp.floor[1] as isize;
            for row in 0..nrows {
                // this row's bottom scanline is the last row's top one
                cache.next_row();
                let cj = (q_first + row) as isize - self.pad + fj;
                if cj < 0 || cj > nj as isize - 2 || cj + 1 < bb[2] as isize || cj > bb[3] as isize {
                    continue;
                }
                let s = cj as usize + nj * k;
                // the pixels that touch the pair's non-transparent columns: from one
                // left of the first to the last (an empty pair gives lo > hi)
                let (eb, et) = (rle.extent[s], rle.extent[s + 1]);
                let lo = (eb[0].min(et[0]) as isize - 1).max(ci_lo);
                let hi = (eb[1].max(et[1]) as isize).min(ci_hi);
                if lo > hi {
                    continue;
                }
                // all of them opaque already: nothing to do
                let lrow = &mut links[row * lw..(row + 1) * lw];
                let first = find(lrow, (lo + off) as usize) as isize - off;
                if first > hi {
                    continue;
                }
                // the next row brings in scanline s + 2: ask for its voxels at the
                // edges this row starts and ends at (silhouettes move slowly)
                rle.prefetch_scanline(s + 2, first as usize, hi as usize);
                let prow = &mut px[row * gw + r.p0..row * gw + r.p1 + 1];
                let (cb, ct) = (rle.cursor(s), rle.cursor(s + 1));
                match (&self.plan.limits, self.focus, &self.plan.focus) {
                    // focus+context: the cells of each run of pixels in / out of
                    // the focus with its sampler (the cursors afresh for each run)
                    (limits, Some(ft), Some(fl)) => {
                        let op = op as i64;
                        focus_runs(fl.row(q_first + row), [k as u32; 2], first as i64 + op, hi as i64 + op, |x0, x1, f| {
                            let (cb, ct) = (rle.cursor(s), rle.cursor(s + 1));
                            let (lo, hi, t) = ((x0 - op) as u32, (x1 - op) as u32, if f { ft } else { self.tables });
                            let (ert, avx2) = (self.ert, self.avx2);
                            let lim = limits.as_ref().map_or(Limits::NONE, |l| Limits::of(l, q_first + row, r, k));
                            let sr = SliceRow { off, w, ert, lim, avx2 };
                            // the runs' samplers differ: no row reads another's shaded voxels
                            cache.forget();
                            if limits.is_some() {
                                composite_row::<S, true>(cb, ct, [lo, hi], t, &sr, prow, lrow, &mut cache)
                            } else {
                                composite_row::<S, false>(cb, ct, [lo, hi], t, &sr, prow, lrow, &mut cache)
                            }
                            cache.forget();
                        })
                    }
                    (None, _, _) => {
                        let sr = SliceRow { off, w, ert: self.ert, lim: Limits::NONE, avx2: self.avx2 };
                        composite_row::<S, false>(cb, ct, [first as u32, hi as u32], self.tables, &sr, prow, lrow, &mut cache)
                    }
                    (Some(l), _, _) => {
                        let sr = SliceRow { off, w, ert: self.ert, lim: Limits::of(l, q_first + row, r, k), avx2: self.avx2 };
                        composite_row::<S, true>(cb, ct, [first as u32, hi as u32], self.tables, &sr, prow, lrow, &mut cache)
                    }
                }
            }
        }
    }
}

impl<S: Sampler> RleFrame<'_, S> {
    /// Composites slice `k` of a scaled plan ([`MapKind::ScaleTranslate`]: a
    /// perspective view) into the band from `q_first`. The same skips as the
    /// translated slices (opaque pixels through the links, transparent voxels
    /// through the runs), the same blend, "over" and termination policy; what
    /// differs is only the map: pixel `x` samples cell `ci(x)` with its own
    /// weight ([`FramePlan::cell_of`]), and since `σ_k ≥ 1` the cells of
    /// consecutive pixels are at least one apart (the slice is minified, never
    /// magnified), so the run cursors still only move forward. Each sample is
    /// the bilinear blend of its cell's four voxels, its opacity corrected to
    /// its ray's own spacing ([`FramePlan::correct_opacity`]).
    ///
    /// The pixels whose two columns lie inside both scanlines' current runs
    /// (most of them) read their voxels straight from the runs; the others
    /// move the cursors and skip transparent columns.
    ///
    /// A slice whose pixels are wider than a voxel (a minified one,
    /// [`FramePlan::footprint`] > 1) is box-filtered instead
    /// ([`RleFrame::box_slice`]); this bilinear one serves the rest (the base
    /// slice, magnified grids).
    #[inline(never)]
    fn scaled_slice(&self, k: usize, q_first: usize, px: &mut [[f32; 4]], links: &mut [u32]) {
        let (r, gw, lw, rle, plan) = (&self.r, self.gw, self.lw, self.rle, self.plan);
        let [ni, nj, _] = rle.n;
        let bb = rle.bbox[k];
        let (ci_lo, ci_hi) = ((bb[0] as i64 - 1).max(0), (bb[1] as i64).min(ni as i64 - 2));
        if ci_lo > ci_hi {
            return;
        }
        let nrows = px.len() / gw;
        let p0 = r.p0 as i64;
        for row in 0..nrows {
            let q = q_first + row;
            let (cj, wj) = plan.cell_of(k, 1, q);
            if cj < 0 || cj > nj as i64 - 2 || cj + 1 < bb[2] as i64 || cj > bb[3] as i64 {
                continue;
            }
            let s = cj as usize + nj * k;
            let (eb, et) = (rle.extent[s], rle.extent[s + 1]);
            let lo = (eb[0].min(et[0]) as i64 - 1).max(ci_lo);
            let hi = (eb[1].max(et[1]) as i64).min(ci_hi);
            if lo > hi {
                continue;
            }
            // the pixels of the rect whose cells are in [lo, hi]
            let [x0, x1] = plan.pixels_of_cells(k, 0, lo, hi);
            let (x0, x1) = (x0.max(p0), x1.min(r.p1 as i64));
            if x0 > x1 {
                continue;
            }
            let lrow = &mut links[row * lw..(row + 1) * lw];
            let prow = &mut px[row * gw + r.p0..row * gw + r.p1 + 1];
            match (self.focus, &plan.focus) {
                // focus+context: each run of pixels in / out of the focus with its sampler
                (Some(_), Some(fl)) => focus_runs(fl.row(q), [k as u32; 2], x0, x1, |a, b, f| {
                    let fr = if f { self.focused() } else { *self };
                    fr.scaled_row(&ScaledRow { k, q, s, hi, wj }, [a, b], prow, lrow);
                }),
                _ => self.scaled_row(&ScaledRow { k, q, s, hi, wj }, [x0, x1], prow, lrow),
            }
        }
    }

    /// The pixels `x0 ..= x1` of a row of [`RleFrame::scaled_slice`]
    /// ([`ScaledRow`]: its scanlines, its weight, where its non-transparent
    /// cells end).
    ///
    /// Two loops: the outer one skips opaque pixels (the links) and
    /// transparent columns (the cursors), and reads a cell's voxels through
    /// the cursors; the inner one composites consecutive pixels while they
    /// are not opaque and their cells' columns lie inside both scanlines'
    /// current runs, reading those voxels straight from the runs (a cell's
    /// right column is the next cell's left one when they are adjacent; a
    /// magnified slice's pixels may share a cell). Each sample is the
    /// bilinear blend of its cell, composited by the row's [`RowComposite`].
    #[inline(always)]
    fn scaled_row(&self, row: &ScaledRow, [x0, x1]: [i64; 2], prow: &mut [[f32; 4]], lrow: &mut [u32]) {
        let &ScaledRow { k, q, s, hi, wj } = row;
        let (r, rle, plan, t) = (&self.r, self.rle, self.plan, self.tables);
        let p0 = r.p0 as i64;
        let map = plan.axis_map(k, 0);
        let rc = self.row_composite(q);
        let mut cb = rle.cursor(s);
        let mut ct = rle.cursor(s + 1);
        // the first column the cursors may still be asked for
        let mut next = 0u32;
        // the last cell sampled and its four voxels (c00, c10, c01, c11)
        let (mut c, mut v) = (INF, [[0f32; 4]; 4]);
        let mut x = x0;
        'pixels: loop {
            // skip opaque pixels through the links
            if x > x1 {
                break;
            }
            x = find(lrow, (x - p0) as usize) as i64 + p0;
            if x > x1 {
                break;
            }
            let (ci, mut wi) = map.cell(x);
            if ci as u32 == c {
                // a magnified slice (pitch < 1): this pixel samples the last one's cell
                // (the inner loop's runs no longer apply: through the cursors after it)
                rc.add(t, [k, k], (x - p0) as usize, t.blend(v[0], v[1], v[2], v[3], &cell_weights(wi, wj)), prow, lrow);
                x += 1;
                continue;
            }
            c = ci as u32;
            if c < next {
                // (rounding made two pixels share a cell: start the walk again)
                (cb, ct) = (rle.cursor(s), rle.cursor(s + 1));
            }
            cb.seek(c);
            ct.seek(c);
            // skip transparent voxels: the pixel reads columns c and c + 1
            let nx = cb.first_from(c).min(ct.first_from(c));
            if nx > c + 1 {
                if nx == INF || nx as i64 - 1 > hi {
                    break;
                }
                next = c;
                let [xn, _] = map.pixels_of_cells(nx as i64 - 1, nx as i64 - 1);
                x = xn.max(x + 1);
                continue;
            }
            let (c00, c01) = (t.get_or_missing(cb.at(c)), t.get_or_missing(ct.at(c)));
            cb.step(c + 1);
            ct.step(c + 1);
            v = [c00, t.get_or_missing(cb.at(c + 1)), c01, t.get_or_missing(ct.at(c + 1))];
            next = c + 1;
            // the columns [lo_run, hi_run) both cursors' current runs hold
            let (lo_run, hi_run) = (cb.s.max(ct.s), cb.e.min(ct.e));
            let (vb, vt) = (cb.vox, ct.vox);
            let (bb, bt) = (cb.base, ct.base);
            loop {
                let xr = (x - p0) as usize;
                rc.add(t, [k, k], xr, t.blend(v[0], v[1], v[2], v[3], &cell_weights(wi, wj)), prow, lrow);
                x += 1;
                if x > x1 || lrow[xr + 1] != 0 {
                    continue 'pixels;
                }
                let (cn, wn) = map.cell(x);
                let cn = cn as u32;
                wi = wn;
                if cn == c {
                    continue; // a magnified slice (pitch < 1): the same cell
                }
                if cn < lo_run || cn + 1 >= hi_run {
                    // a column outside a run: through the cursors
                    continue 'pixels;
                }
                let (rb, rt) = (t.voxel(vb[bb.wrapping_add(cn + 1) as usize]), t.voxel(vt[bt.wrapping_add(cn + 1) as usize]));
                v = if cn == c + 1 {
                    [v[1], rb, v[3], rt]
                } else {
                    [t.voxel(vb[bb.wrapping_add(cn) as usize]), rb, t.voxel(vt[bt.wrapping_add(cn) as usize]), rt]
                };
                c = cn;
                next = c + 1;
            }
        }
    }

    /// Composites slice `k` of a scaled plan whose pixels are wider than a
    /// voxel ([`FramePlan::boxed`]: the far slices of a perspective
    /// view, any slice of a grid coarser than one pixel per voxel) with the
    /// paper's box footprint: each pixel's sample is the area average of the
    /// opacity-weighted colours of the voxels under an `s₀ × s₁` box centred on
    /// its sample position ([`box_weights`]), so no voxel falls between two
    /// pixels. Pixels whose centre cell lies outside the slice composite
    /// nothing (as with the bilinear sample). The same skips: opaque pixels
    /// through the links, a pixel whose box holds only transparent voxels
    /// (and the pixels after it up to the next non-transparent column in the
    /// box's rows), rows of the box outside the slice's occupied box.
    #[inline(never)]
    fn box_slice(&self, k: usize, q_first: usize, px: &mut [[f32; 4]], links: &mut [u32]) {
        let (r, gw, lw, rle, plan) = (&self.r, self.gw, self.lw, self.rle, self.plan);
        let [ni, nj, _] = rle.n;
        let bb = rle.bbox[k];
        let s = plan.footprint(k);
        let reach = plan.footprint_reach(k, 0);
        let nrows = px.len() / gw;
        let p0 = r.p0 as i64;
        let mut wj = [0f32; MAXW];
        for row in 0..nrows {
            let q = q_first + row;
            let (cj, _) = plan.cell_of(k, 1, q);
            if cj < 0 || cj > nj as i64 - 2 {
                continue;
            }
            let (j0, nb) = box_weights(plan.sample_at(k, 1, q), s[1], nj, &mut wj);
            if nb == 0 || ((j0 + nb - 1) as u32) < bb[2] || j0 as u32 > bb[3] {
                continue;
            }
            // the box's rows: their cursors and the columns they hold
            let base = j0 + nj * k;
            let mut curs = [rle.cursor(base); MAXW];
            let (mut lo, mut hi) = (i64::MAX, i64::MIN);
            for (t, c) in curs.iter_mut().enumerate().take(nb) {
                *c = rle.cursor(base + t);
                let e = rle.extent[base + t];
                if e[0] <= e[1] {
                    lo = lo.min(e[0] as i64);
                    hi = hi.max(e[1] as i64);
                }
            }
            if lo > hi {
                continue;
            }
            // the pixels whose centre cell is in the slice and whose box may reach [lo, hi]
            let [x0, x1] = plan.pixels_of_cells(k, 0, (lo - reach).max(0), (hi + reach).min(ni as i64 - 2));
            let (x0, x1) = (x0.max(p0), x1.min(r.p1 as i64));
            if x0 > x1 {
                continue;
            }
            let lrow = &mut links[row * lw..(row + 1) * lw];
            let prow = &mut px[row * gw + r.p0..row * gw + r.p1 + 1];
            let bx = BoxRow { k, q, s, nb, hi, curs, wj: &wj };
            match (self.focus, &plan.focus) {
                // focus+context: each run of pixels in / out of the focus with its sampler
                (Some(_), Some(fl)) => focus_runs(fl.row(q), [k as u32; 2], x0, x1, |a, b, f| {
                    let fr = if f { self.focused() } else { *self };
                    fr.box_row(&bx, [a, b], prow, lrow);
                }),
                _ => self.box_row(&bx, [x0, x1], prow, lrow),
            }
        }
    }

    /// The pixels `x0 ..= x1` of one row of [`RleFrame::box_slice`].
    #[inline(always)]
    fn box_row(&self, bx: &BoxRow, [x0, x1]: [i64; 2], prow: &mut [[f32; 4]], lrow: &mut [u32]) {
        let (r, rle, plan) = (&self.r, self.rle, self.plan);
        let ni = rle.n[0];
        let &BoxRow { k, q, s, nb, hi, curs, wj } = bx;
        let mut curs = curs;
        let p0 = r.p0 as i64;
        let rc = self.row_composite(q);
        let mut wi = [0f32; MAXW];
        {
            // the box's columns ([`box_column`]: this row's weights over its
            // rows) in a ring at ring[c % RING]; columns come in increasing
            // order, each decoded and summed once per row of the intermediate
            // image (by cursors of their own, apart from the skip test's, since
            // both only move forward)
            const RING: usize = 8;
            let mut ring = [[0f32; 4]; RING];
            let mut dec = curs;
            let mut decoded = 0usize;
            let mut x = x0;
            loop {
                x = find(lrow, (x - p0) as usize) as i64 + p0;
                if x > x1 {
                    break;
                }
                let (i0, na) = box_weights(plan.sample_at(k, 0, x as usize), s[0], ni, &mut wi);
                // the first non-transparent column at or after the box's first, over its rows
                let mut next = INF;
                for c in curs.iter_mut().take(nb) {
                    c.seek(i0 as u32);
                    next = next.min(c.first_from(i0 as u32));
                }
                if na == 0 || next as usize >= i0 + na {
                    if next == INF || next as i64 > hi {
                        break;
                    }
                    // on to the first pixel whose box may reach column `next`
                    let c = (next as f64 - 0.5 * s[0] - 1.5).floor() as i64;
                    let [xn, _] = plan.pixels_of_cells(k, 0, c, c);
                    x = xn.max(x + 1);
                    continue;
                }
                for col in decoded.max(i0)..i0 + na {
                    let c = col as u32;
                    ring[col % RING] = box_column(&wj[..nb], |t| {
                        let d = &mut dec[t];
                        d.seek(c);
                        self.tables.get_or_missing(d.at(c))
                    });
                }
                decoded = decoded.max(i0 + na);
                let smp = box_sample(&wi[..na], |u| ring[(i0 + u) % RING]);
                rc.add(self.tables, [k, k], (x - p0) as usize, smp, prow, lrow);
                x += 1;
            }
        }
    }

    /// Composites the intermediate samples between slices `k` and `k + 1`
    /// (index order; Shear-Warp Deluxe I) into the band from `q_first`: pixel
    /// `(x, q)` samples both slices at the ray's point at depth `k + ½`
    /// ([`FramePlan::mid_map`]), the mean ([`mid`]) of the two bilinear blends
    /// there (trilinear interpolation), composited if its ray limits keep
    /// both slices. One walk for translated and scaled plans: the four
    /// scanlines under a row (two per slice) are walked together with one set
    /// of row weights; opaque pixels are skipped through the links, and a
    /// pixel whose eight voxels are all outside the runs (so its sample is
    /// zero under either sampler) with the runs, to the first pixel whose
    /// cell reaches the next stored column. A cell's right column is the next
    /// pixel's left one when their cells are adjacent, so each voxel is read
    /// once per row. Minified slices are sampled bilinearly here too (the box
    /// footprint is the slice samples').
    #[inline(never)]
    fn mid_slice(&self, k: usize, q_first: usize, px: &mut [[f32; 4]], links: &mut [u32]) {
        let (r, gw, lw, rle, plan) = (&self.r, self.gw, self.lw, self.rle, self.plan);
        let [ni, nj, _] = rle.n;
        let (ba, bb) = (rle.bbox[k], rle.bbox[k + 1]);
        // the union of the two slices' boxes (an empty box is [MAX, 0, MAX, 0])
        let bx = [ba[0].min(bb[0]), ba[1].max(bb[1]), ba[2].min(bb[2]), ba[3].max(bb[3])];
        if bx[0] > bx[1] {
            return;
        }
        let (ci_lo, ci_hi) = ((bx[0] as i64 - 1).max(0), (bx[1] as i64).min(ni as i64 - 2));
        if ci_lo > ci_hi {
            return;
        }
        let (imap, jmap) = (plan.mid_map(k, 0), plan.mid_map(k, 1));
        let nrows = px.len() / gw;
        let p0 = r.p0 as i64;
        for row in 0..nrows {
            let q = q_first + row;
            let (cj, wj) = jmap.cell(q as i64);
            if cj < 0 || cj > nj as i64 - 2 || cj + 1 < bx[2] as i64 || cj > bx[3] as i64 {
                continue;
            }
            let s0 = cj as usize + nj * k;
            let scan = [s0, s0 + 1, s0 + nj, s0 + nj + 1];
            let (mut lo, mut hi) = (i64::MAX, i64::MIN);
            for &s in &scan {
                let e = rle.extent[s];
                if e[0] <= e[1] {
                    lo = lo.min(e[0] as i64);
                    hi = hi.max(e[1] as i64);
                }
            }
            let (lo, hi) = ((lo - 1).max(ci_lo), hi.min(ci_hi));
            if lo > hi {
                continue;
            }
            let [x0, x1] = imap.pixels_of_cells(lo, hi);
            let (x0, x1) = (x0.max(p0), x1.min(r.p1 as i64));
            if x0 > x1 {
                continue;
            }
            let lrow = &mut links[row * lw..(row + 1) * lw];
            let prow = &mut px[row * gw + r.p0..row * gw + r.p1 + 1];
            match (self.focus, &plan.focus) {
                // focus+context: each run of pixels whose midpoint is in / out of the focus with its sampler
                (Some(_), Some(fl)) => focus_runs(fl.row(q), [k as u32, k as u32 + 1], x0, x1, |a, b, f| {
                    let fr = if f { self.focused() } else { *self };
                    fr.mid_row(&MidRow { k, q, imap, scan, hi, wj }, [a, b], prow, lrow);
                }),
                _ => self.mid_row(&MidRow { k, q, imap, scan, hi, wj }, [x0, x1], prow, lrow),
            }
        }
    }

    /// The pixels `x0 ..= x1` of a row of [`RleFrame::mid_slice`]
    /// ([`MidRow`]: columns by `imap`, the slices' [`FramePlan::mid_map`];
    /// scanlines `scan`: slice `k`'s two under the row, then slice `k + 1`'s;
    /// no cell past `hi` holds a non-transparent voxel).
    ///
    /// A midpoint's cell is two columns of four voxels each; a column is
    /// read once ([`Sampler::mid_column`]) and is the left column of the next
    /// pixel's cell when that one is adjacent. Where the next pixels' cells
    /// follow each other and their right columns lie inside all four
    /// scanlines' current runs (most of a row), [`mid_run`] composites
    /// them in a plain loop over the runs' voxels.
    #[inline(always)]
    fn mid_row(&self, row: &MidRow, [x0, x1]: [i64; 2], prow: &mut [[f32; 4]], lrow: &mut [u32]) {
        let &MidRow { k, q, imap, scan, hi, wj } = row;
        let (rle, t) = (self.rle, self.tables);
        let p0 = self.r.p0 as i64;
        let rc = self.row_composite(q);
        let mut cur = scan.map(|s| rle.cursor(s));
        // the first column the cursors may still be asked for
        let mut next = 0u32;
        // the last cell read and its left and right columns
        let z = t.mid_column(S::MISSING, S::MISSING, S::MISSING, S::MISSING);
        let mut cell = (INF, [z, z]);
        // the last weights (a translated plan's row has one)
        let mut wc: (f32, Weights) = (f32::NAN, [[0.0; 4]; 4]);
        let mut weights = |wi: f32| {
            if wi.to_bits() != wc.0.to_bits() {
                wc = (wi, cell_weights(wi, wj));
            }
            wc.1
        };
        let column = |cur: &[Cursor; 4], c: u32| {
            let at = |cu: &Cursor| t.get_or_missing(cu.at(c));
            t.mid_column(at(&cur[0]), at(&cur[1]), at(&cur[2]), at(&cur[3]))
        };
        let mut x = x0;
        loop {
            if x > x1 {
                break;
            }
            x = find(lrow, (x - p0) as usize) as i64 + p0;
            if x > x1 {
                break;
            }
            let (ci, wi) = imap.cell(x);
            let c = ci as u32;
            if c != cell.0 {
                if c < next {
                    // (rounding made two pixels share a cell: start the walk again)
                    cur = scan.map(|s| rle.cursor(s));
                }
                let mut nx = INF;
                for cu in cur.iter_mut() {
                    cu.seek(c);
                    nx = nx.min(cu.first_from(c));
                }
                if nx > c + 1 {
                    // columns c and c + 1 empty in all four scanlines
                    if nx == INF || nx as i64 - 1 > hi {
                        break;
                    }
                    next = c;
                    let [xn, _] = imap.pixels_of_cells(nx as i64 - 1, nx as i64 - 1);
                    x = xn.max(x + 1);
                    continue;
                }
                let left = if cell.0 != INF && cell.0 + 1 == c { cell.1[1] } else { column(&cur, c) };
                for cu in cur.iter_mut() {
                    cu.step(c + 1);
                }
                cell = (c, [left, column(&cur, c + 1)]);
                next = c + 1;
            }
            let w = weights(wi);
            rc.add(t, [k, k + 1], (x - p0) as usize, t.mid_blend(cell.1[0], cell.1[1], &w), prow, lrow);
            // the pixels after x whose cells follow on and whose right
            // columns lie inside all four scanlines' current runs
            let (s_max, e_min) = cur.iter().fold((0u32, INF), |(s, e), cu| (s.max(cu.s), e.min(cu.e)));
            let c1 = cell.0.wrapping_add(2);
            let follows = match imap {
                MidMap::Shift { .. } => true,
                MidMap::Map(m) => m.cell(x + 1).0 == cell.0 as i64 + 1,
            };
            if x < x1 && c1 >= s_max && c1 < e_min && follows {
                let n = ((x1 - x) as u64).min((e_min - c1) as u64) as usize;
                let vox = cur.map(|cu| &cu.vox[cu.base.wrapping_add(c1) as usize..][..n]);
                let xs = (x + 1 - p0) as usize;
                let run = MidRun { k, x: x + 1, c: cell.0 + 1, vox, wj, imap };
                let rc = rc.skip(xs);
                let (p, l) = (&mut prow[xs..xs + n], &mut lrow[xs..xs + n]);
                let (done, last) = match imap {
                    MidMap::Shift { .. } => mid_run::<S, true>(t, &rc, &run, cell.1[1], &weights(wi), p, l),
                    MidMap::Map(_) => mid_run::<S, false>(t, &rc, &run, cell.1[1], &weights(wi), p, l),
                };
                if done > 0 {
                    cell = (cell.0 + done as u32, last);
                    next = c1 + done as u32 - 1;
                    x += done as i64;
                }
            }
            x += 1;
        }
    }

    /// Row `q`'s [`RowComposite`].
    #[inline(always)]
    fn row_composite(&self, q: usize) -> RowComposite<'_> {
        let (plan, r) = (self.plan, &self.r);
        let rays = plan.ray_rows_of(q);
        RowComposite {
            limits: plan.limits.as_ref().map(|l| Limits::of(l, q, r, 0)),
            rays: if rays.is_empty() { rays } else { &rays[r.p0..=r.p1] },
            table: plan.opacity_table(),
            ert: self.ert,
        }
    }
}

/// The reference for [`render_rle`]: slice by slice, front to back, every voxel
/// of the slice is classified from the densities into `slice_buf` (reused; two
/// slices), then every pixel of `rect` whose opacity is below `ert` composites
/// its cell's sample; with the plan's intermediate samples (Deluxe I), the
/// sample between the last slice and this one first. No runs, no links; same
/// positions, weights, sampler and arithmetic. With `focus` (focus+context,
/// `(its classification, its sampler)`) and the plan's focus intervals, a
/// pixel whose slice-`k` sample is in its interval reads the voxels
/// classified by the focus's (a second buffer of two slices), and so does
/// a Deluxe I midpoint whose two slices both are ([`FramePlan::in_focus_mid`]).
pub fn render_brute_preclassified<S: Sampler, V: VoxelSource + ?Sized>(
    stack: &V,
    pre: &Preclass,
    tables: &S,
    focus: Option<(&Preclass, &S)>,
    frame: SliceFrame,
    slice_buf: &mut Vec<[f32; 4]>,
    out: &mut Intermediate,
) {
    let SliceFrame { plan, ert, rect, .. } = frame;
    out.seal(rect);
    let Some(r) = rect else { return };
    let [ni, nj, _] = stack.slices().n;
    let gw = out.size[0];
    let px = &mut out.rgba[r.q0 * gw..(r.q1 + 1) * gw];
    let depth = &mut out.depth[r.q0 * gw..(r.q1 + 1) * gw];
    px.par_chunks_mut(gw).zip(depth.par_chunks_mut(gw)).for_each(|(p, d)| clear_rows(p, d, gw, &r));
    let n = ni * nj;
    slice_buf.resize(2 * n, [0.0; 4]);
    let focus = focus.filter(|_| plan.focus.is_some());
    // the focus's voxels of the slice and the last (a reference: allocated per frame)
    let mut focus_buf = vec![[0f32; 4]; if focus.is_some() { 2 * n } else { 0 }];
    let mut prev: Option<usize> = None;
    for k in plan.front_to_back() {
        // slice k's voxels in half k % 2 of the buffer (the last slice's in the other)
        slice_buf[(k % 2) * n..][..n].par_chunks_mut(ni).enumerate().for_each(|(j, row)| {
            for (i, c) in row.iter_mut().enumerate() {
                *c = tables.brute_voxel(pre, stack, i, j, k);
            }
        });
        if let Some((fpre, ft)) = focus {
            focus_buf[(k % 2) * n..][..n].par_chunks_mut(ni).enumerate().for_each(|(j, row)| {
                for (i, c) in row.iter_mut().enumerate() {
                    *c = ft.brute_voxel(fpre, stack, i, j, k);
                }
            });
        }
        let fbuf = &focus_buf[..];
        let buf = &slice_buf[..];
        if let Some(kp) = prev.filter(|_| plan.intermediate()) {
            // the intermediate samples between slices kl and kl + 1
            let kl = kp.min(k);
            fn halves(b: &[[f32; 4]], kl: usize, n: usize) -> (&[[f32; 4]], &[[f32; 4]]) {
                (&b[(kl % 2) * n..][..n], &b[((kl + 1) % 2) * n..][..n])
            }
            let (lo, hi) = halves(buf, kl, n);
            let flohi = if focus.is_some() { Some(halves(fbuf, kl, n)) } else { None };
            let (imap, jmap) = (plan.mid_map(kl, 0), plan.mid_map(kl, 1));
            px.par_chunks_mut(gw).enumerate().for_each(|(row, prow)| {
                let q = r.q0 + row;
                let (cj, wj) = jmap.cell(q as i64);
                if cj < 0 || cj > nj as i64 - 2 {
                    return;
                }
                for (p, acc) in prow.iter_mut().enumerate().take(r.p1 + 1).skip(r.p0) {
                    let (ci, wi) = imap.cell(p as i64);
                    if ci < 0 || ci > ni as i64 - 2 || terminated(acc[3], ert) {
                        continue;
                    }
                    if plan.limits.as_ref().is_some_and(|l| !l.keeps(p, q, kl) || !l.keeps(p, q, kl + 1)) {
                        continue;
                    }
                    // focus+context: a midpoint whose two slices are in the focus from the focus's voxels and sampler
                    let ((lo, hi), tables) = match (focus, flohi) {
                        (Some((_, ft)), Some(f)) if plan.in_focus_mid(p, q, kl) => (f, ft),
                        _ => ((lo, hi), tables),
                    };
                    let b = ci as usize + ni * cj as usize;
                    let w = cell_weights(wi, wj);
                    let smp = tables.mid(&[lo[b], lo[b + 1], lo[b + ni], lo[b + ni + 1], hi[b], hi[b + 1], hi[b + ni], hi[b + ni + 1]], &w);
                    composite_premultiplied(acc, plan.correct_opacity(p, q, tables.finish(smp)));
                }
            });
        }
        prev = Some(k);
        let buf = &buf[(k % 2) * n..][..n];
        let fbuf = if focus.is_some() { &fbuf[(k % 2) * n..][..n] } else { fbuf };
        let (boxed, fp) = if S::BOX { (plan.boxed(k), plan.footprint(k)) } else { (false, [1.0; 2]) };
        px.par_chunks_mut(gw).enumerate().for_each(|(row, prow)| {
            let q = r.q0 + row;
            let (cj, wj) = plan.cell_of(k, 1, q);
            if cj < 0 || cj > nj as i64 - 2 {
                return;
            }
            let mut wjs = [0f32; MAXW];
            let (j0, nb) = if boxed { box_weights(plan.sample_at(k, 1, q), fp[1], nj, &mut wjs) } else { (0, 0) };
            for (p, acc) in prow.iter_mut().enumerate().take(r.p1 + 1).skip(r.p0) {
                let (ci, wi) = plan.cell_of(k, 0, p);
                if ci < 0 || ci > ni as i64 - 2 {
                    continue;
                }
                if terminated(acc[3], ert) {
                    continue;
                }
                if plan.limits.as_ref().is_some_and(|l| !l.keeps(p, q, k)) {
                    continue;
                }
                // focus+context: the sample inside the focus from the focus's voxels and sampler
                let (buf, tables) = match focus {
                    Some((_, ft)) if plan.in_focus(p, q, k) => (fbuf, ft),
                    _ => (buf, tables),
                };
                let smp = if boxed {
                    // the box footprint of a minified slice (as RleFrame::box_slice)
                    let mut wis = [0f32; MAXW];
                    let (i0, na) = box_weights(plan.sample_at(k, 0, p), fp[0], ni, &mut wis);
                    box_sample(&wis[..na], |u| box_column(&wjs[..nb], |t| buf[i0 + u + ni * (j0 + t)]))
                } else {
                    let b = ci as usize + ni * cj as usize;
                    tables.blend(buf[b], buf[b + 1], buf[b + ni], buf[b + ni + 1], &cell_weights(wi, wj))
                };
                composite_premultiplied(acc, plan.correct_opacity(p, q, tables.finish(smp)));
            }
        });
    }
}

/// The RLE compositor of a renderer's pre-classified state: its encodings
/// and tables through [`render_rle`] and [`render_brute_preclassified`].
impl RleCache {
    /// Composites view `f` from the encoding of its axis (see [`render_rle`]);
    /// an axis that is not encoded (under the plan's permutation) renders transparent.
    /// `cpu`: the level its kernels run at (see [`SliceFrame::cpu`]).
    pub fn render(&mut self, plan: &FramePlan, ert: f32, rect: Option<Rect>, cpu: CpuLevel, out: &mut Intermediate) {
        let focused = self.focus.is_some();
        match (self.axes[plan.view.axis].as_ref().filter(|e| e.perm == plan.view.perm), &self.post_tables) {
            (Some(rle), Some(pt)) if self.post.is_some() => {
                let ft = self.focus_post_tables.as_deref().filter(|_| focused);
                render_rle(rle, pt.as_ref(), ft, SliceFrame { plan, ert, rect, cpu }, &mut self.scratch, out)
            }
            (Some(rle), _) => {
                let ft = Some(&self.focus_tables).filter(|_| focused);
                render_rle(rle, &self.tables, ft, SliceFrame { plan, ert, rect, cpu }, &mut self.scratch, out)
            }
            (None, _) => out.seal(None),
        }
    }

    /// The brute-force pre-classified reference of view `f` over `rect` (see
    /// [`render_brute_preclassified`]).
    pub fn render_brute<V: VoxelSource + ?Sized>(
        &mut self,
        stack: &V,
        plan: &FramePlan,
        ert: f32,
        rect: Option<Rect>,
        out: &mut Intermediate,
    ) {
        match (&self.pre, &self.post_tables) {
            (Some(pre), Some(pt)) if self.post.is_some() => {
                let focus = self.focus.as_ref().zip(self.focus_post_tables.as_deref());
                render_brute_preclassified(
                    stack,
                    pre,
                    pt.as_ref(),
                    focus,
                    SliceFrame { plan, ert, rect, cpu: CpuLevel::Scalar },
                    &mut self.slice_buf,
                    out,
                )
            }
            (Some(pre), _) => {
                let focus = self.focus.as_ref().map(|f| (f, &self.focus_tables));
                render_brute_preclassified(
                    stack,
                    pre,
                    &self.tables,
                    focus,
                    SliceFrame { plan, ert, rect, cpu: CpuLevel::Scalar },
                    &mut self.slice_buf,
                    out,
                )
            }
            (None, _) => out.seal(None),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::normals::{ZERO_NORMAL, encode_normal};

    #[test]
    fn links_compress_paths() {
        let mut links = vec![0u32; 11];
        for x in [2, 3, 4, 5, 7, 8] {
            links[x] = 1;
        }
        assert_eq!(find(&mut links, 0), 0);
        assert_eq!(find(&mut links, 2), 6);
        assert_eq!(links[2], 4);
        assert_eq!(links[3], 3);
        assert_eq!(find(&mut links, 7), 9);
        // 6 becomes opaque: 2 → 6 → 7 → 9
        links[6] = 1;
        assert_eq!(find(&mut links, 2), 9);
        assert_eq!(links[2], 7);
        links[9] = 1;
        assert_eq!(find(&mut links, 0), 0);
        assert_eq!(find(&mut links, 3), 10);
    }

    /// The post-classified sampler (Deluxe P) blends normals turned to one
    /// side: two neighbours on a surface whose normal crosses the codes'
    /// hemisphere boundary (their codes decode to nearly opposite vectors)
    /// blend to the surface's direction, not to a near-zero vector (the dark
    /// seams P showed at 0° on the head phantom); the pre-classified sampler's
    /// blend is the plain one.
    #[test]
    fn post_blend_turns_normals_to_one_side_before_blending() {
        let t = PostTables::default();
        let voxel = |n: [f32; 3]| t.voxel(RleVoxel { class: 7, normal: encode_normal(n) });
        let (a, b) = (voxel([1.0, 0.2, 0.05]), voxel([1.0, 0.2, -0.05]));
        // the codes alone: opposite sides
        assert!(a[1] * b[1] + a[2] * b[2] + a[3] * b[3] < -0.9, "{a:?} {b:?}");
        let unit = |s: [f32; 4]| {
            let l = (s[1] * s[1] + s[2] * s[2] + s[3] * s[3]).sqrt();
            [s[1] / l, s[2] / l, s[3] / l, l]
        };
        let truth = {
            let l = (1.0f32 + 0.04).sqrt();
            [1.0 / l, 0.2 / l]
        };
        for (wi, wj) in [(0.5, 0.5), (0.3, 0.8), (0.9, 0.1)] {
            let w = cell_weights(wi, wj);
            for cell in [[a, b, a, b], [b, a, a, b], [a, a, b, b], [b, b, b, a]] {
                let s = Sampler::blend(&t, cell[0], cell[1], cell[2], cell[3], &w);
                assert_eq!(s[0], 7.0, "the node blends as before");
                let n = unit(s);
                // the blend of unit vectors within a degree or so of each other: about unit length
                assert!(n[3] > 0.99, "{cell:?} at {wi}, {wj}: |n| = {}", n[3]);
                assert!((n[0].abs() - truth[0]).abs() < 0.02 && (n[1].abs() - truth[1]).abs() < 0.02, "{n:?}");
                // the midpoint of eight such voxels, too
                let m = Sampler::mid(&t, &[cell[0], cell[1], cell[2], cell[3], cell[3], cell[2], cell[1], cell[0]], &w);
                assert!(unit(m)[3] > 0.99, "{m:?}");
            }
        }
        // a zero first normal: the right column still turns to the left column's side
        let z = t.voxel(RleVoxel { class: 7, normal: ZERO_NORMAL });
        let s = Sampler::blend(&t, z, b, a, b, &cell_weights(0.5, 0.5));
        assert!(unit(s)[3] > 0.74, "{s:?}");
        // the pre-classified sampler: the plain blend, bit for bit
        let v = ViewTables::default();
        let c = [[0.1, 0.2, 0.3, 0.4], [0.5, 0.1, 0.0, 0.6], [0.2, 0.2, 0.2, 0.2], [0.0, 0.9, 0.1, 1.0]];
        let w = cell_weights(0.3, 0.6);
        assert_eq!(Sampler::blend(&v, c[0], c[1], c[2], c[3], &w), blend(c[0], c[1], c[2], c[3], &w));
    }
}
