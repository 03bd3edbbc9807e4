//! The inverse warp: geometry's depth buffer (output resolution) as per-pixel
//! ray limits of the frame plan, and the final image of volume over geometry.
//!
//! Bruckner's hybrid reads the z-buffer after the view is factorized and maps
//! it into the intermediate image with a footprint and a min operator; a
//! sample at or beyond the stored depth closes the pixel. Here each
//! intermediate pixel gathers that minimum itself: the output pixels whose
//! centres fall inside the image of its footprint (its square, through the
//! frame's warp: scaled by the image ratio and, under a projective warp, by
//! depth). A gather leaves no holes whatever the angle of the surface or
//! the image ratio (tested on a plane at 45°, coarse and fine output), and
//! it runs on the plan's rows in parallel. The depth is then met
//! analytically on the pixel's ray (its samples are affine in the slice
//! index in both projections): the slices kept are those whose sample lies
//! strictly in front of the geometry.
//!
//! What it costs is Bruckner's scatter order: the rasterizer keeps each
//! row's covered span, so [`GeometryLimits::new`] copies only those pixels'
//! depths (row-packed) and marks the covered 4×4 output tiles, kept as runs
//! along tile rows; each frame maps every run back through the warp (widened
//! by the footprint's reach, measured at its corners) to mark the
//! intermediate pixels that can see it, and only those gather. The gather of
//! one pixel is a handful of operations: its footprint's corners from one
//! 3×3 map of intermediate pixels (in a parallel frame, the same box about
//! every centre, in fixed point: its pixel range is two shifts per axis,
//! exact whichever way the pixel is reached), the minimum over packed row
//! segments, and its samples' depth from two affine functions of the pixel
//! set up once per frame and per row. The limits are those of
//! the gather over every pixel, bit for bit (tested, isotropic and
//! chest-CT-like voxels, both projections). A needle costs what it covers.
//!
//! The iso crossing: the cut is per slice, and the raycaster's iso test
//! needs the sample after a crossing, so a surface less than a slice in
//! front of the geometry would be lost. [`GeometryLimits::with_iso_crossing`]
//! keeps that one slice more, and [`composite_iso_over_geometry`] compares
//! the volume's iso depth with the geometry's at each output pixel the
//! geometry covers (a hit at or behind it is hidden). The depth test at
//! composition was chosen over a fractional limit in the traversal: the
//! plan's limits and every traversal stay as they are, the intermediate
//! image already holds the refined hit depth, and the test costs only the
//! covered output pixels. Blend mode and the RLE path (pre-classified:
//! its iso samples are opaque steps, unrefined) keep the paper's per-slice
//! cut.

use glam::{DMat3, DVec3};
use rayon::prelude::*;

use super::raster::{GeometryImage, Projector};
use super::sampling::slice_depth;
use crate::view::plan::{FramePlan, Limiter, RayLimits};
use crate::warp::Image;

/// The side of the output tiles whose coverage decides which intermediate
/// pixels gather.
const TILE: usize = 4;

/// Depths kept row by row: each row's span `[x0, x1]`
/// (`x0 > x1`: none) and where its values start in `packed` (`+∞` where no
/// geometry is).
#[derive(Clone, Debug, Default)]
struct Rows {
    rows: Vec<([u32; 2], usize)>,
    packed: Vec<f64>,
}

impl Rows {
    /// The smallest value of line `y` over positions `x0 ..= x1`, folded into
    /// `d`.
    #[inline(always)]
    fn fold(&self, y: usize, x0: u32, x1: u32, d: f64) -> f64 {
        let ([a, b], off) = self.rows[y];
        let (s, e) = (x0.max(a), x1.min(b));
        if s > e {
            return d;
        }
        let seg = &self.packed[off + (s - a) as usize..off + (e - a) as usize + 1];
        let mut d = d;
        for &x in seg {
            d = min(d, x);
        }
        d
    }
}

/// Geometry's depth in one frame, as a producer of ray limits.
#[derive(Clone, Debug)]
pub struct GeometryLimits {
    projector: Projector,
    /// The depths of each output row's covered span (a needle copies what it
    /// covers, not the whole buffer).
    depths: Rows,
    size: [usize; 2],
    /// `size` as numbers (for the footprint's bounds, per pixel).
    size_f: [f64; 2],
    size_i: [i32; 2],
    /// The output pixels holding geometry: `[x0, y0, x1, y1]` (None: none).
    bounds: Option<[usize; 4]>,
    /// The covered output tiles ([`TILE`]² pixels), as runs of neighbouring
    /// tiles along a tile row: output rectangles `[x0, y0, x1, y1]`.
    runs: Vec<[usize; 4]>,
    /// How many tiles the runs hold.
    tiles: usize,
    /// Visit only the intermediate pixels that can reach `bounds` (false:
    /// every pixel, the reference the tests compare with).
    cull: bool,
    /// Keep the first slice at or beyond the geometry too (iso mode of the
    /// raycaster: the sample after an iso crossing in front of the geometry),
    /// for [`composite_iso_over_geometry`] to reject hits behind it.
    crossing: bool,
}

impl GeometryLimits {
    /// The limits of `geometry` (rasterized with `projector`, the frame's own
    /// camera). Reads only the rows' covered spans the rasterizer kept.
    pub fn new(projector: Projector, geometry: &GeometryImage) -> Self {
        let (w, h) = (geometry.width, geometry.height);
        let mut bounds: Option<[usize; 4]> = None;
        let tw = w.div_ceil(TILE);
        let mut covered = vec![false; tw];
        let mut runs = vec![];
        let mut tiles = 0;
        // (sized once: growing it by the rows would copy it again and again)
        let n: usize = (0..h).filter_map(|y| geometry.row_span(y)).map(|[x0, x1]| x1 + 1 - x0).sum();
        let mut depths = Rows { rows: vec![([1u32, 0u32], 0usize); h], packed: Vec::with_capacity(n) };
        // (the tile row's covered tiles lie in t_lo .. t_hi)
        let (mut t_lo, mut t_hi) = (0, 0);
        for ty in 0..h.div_ceil(TILE) {
            let ys = ty * TILE..((ty + 1) * TILE).min(h);
            let mut any = false;
            for y in ys.clone() {
                let Some([x0, x1]) = geometry.row_span(y) else { continue };
                let row = &geometry.depth[y * w + x0..=y * w + x1];
                depths.rows[y] = ([x0 as u32, x1 as u32], depths.packed.len());
                depths.packed.extend_from_slice(row);
                if !any {
                    covered.fill(false);
                    any = true;
                    (t_lo, t_hi) = (tw, 0);
                }
                // (the span's tiles: a gap inside a span is rare, and marking
                // it only costs its pixels a gather that finds nothing)
                covered[x0 / TILE..x1 / TILE + 1].fill(true);
                (t_lo, t_hi) = (t_lo.min(x0 / TILE), t_hi.max(x1 / TILE + 1));
                bounds = Some(match bounds {
                    None => [x0, y, x1, y],
                    Some([a, b, c, _]) => [a.min(x0), b, c.max(x1), y],
                });
            }
            if !any {
                continue;
            }
            let mut tx = t_lo;
            while tx < t_hi {
                if !covered[tx] {
                    tx += 1;
                    continue;
                }
                let t0 = tx;
                while tx < t_hi && covered[tx] {
                    tx += 1;
                }
                runs.push([t0 * TILE, ys.start, (tx * TILE).min(w) - 1, ys.end - 1]);
                tiles += tx - t0;
            }
        }
        let size_i = [w, h].map(|n| n.min(i32::MAX as usize / 2) as i32);
        GeometryLimits {
            projector,
            depths,
            size: [w, h],
            size_f: size_i.map(f64::from),
            size_i,
            bounds,
            runs,
            tiles,
            cull: true,
            crossing: false,
        }
    }

    /// [`GeometryLimits::new`] visiting every intermediate pixel (the
    /// reference the rectangle's skip is tested against).
    pub fn visiting_every_pixel(projector: Projector, geometry: &GeometryImage) -> Self {
        GeometryLimits { cull: false, ..GeometryLimits::new(projector, geometry) }
    }

    /// Keeps (`on`) one more slice per limited ray: the first whose sample
    /// lies at or beyond the geometry, so that an iso surface crossing less
    /// than a slice in front of the geometry is found (the raycaster refines
    /// a hit against the sample before it). Only for the binary rotator's and
    /// its brute force's iso mode, with [`composite_iso_over_geometry`],
    /// which hides the hits that land behind the geometry; blend mode and
    /// the RLE path (pre-classified, unrefined) cut at the last slice in front.
    pub fn with_iso_crossing(mut self, on: bool) -> Self {
        self.crossing = on;
        self
    }

    /// The geometry's projector (the frame's camera).
    pub fn projector(&self) -> &Projector {
        &self.projector
    }

    /// The intermediate pixels `[p0, q0, p1, q1]` (inclusive) whose footprint
    /// can reach the geometry's rectangle in `plan` (None: none can).
    fn reach(&self, plan: &FramePlan) -> Option<[usize; 4]> {
        let [w, h] = plan.grid.size;
        if !self.cull {
            return self.bounds.map(|_| [0, 0, w.saturating_sub(1), h.saturating_sub(1)]);
        }
        reach_of(plan, self.bounds?)
    }
}

/// The intermediate pixels `[p0, q0, p1, q1]` (inclusive) of `plan` whose
/// footprint can reach the output rectangle `[x0, y0, x1, y1]` (inclusive;
/// None: none can).
fn reach_of(plan: &FramePlan, rect: [usize; 4]) -> Option<[usize; 4]> {
    reach_with(plan, rect, None)
}

/// How far (output pixels, along x and y) the footprint of intermediate pixel
/// `(p, q)` reaches from its centre's image (None: behind the eye).
fn footprint_half(plan: &FramePlan, p: f64, q: f64) -> Option<[f64; 2]> {
    let at = |dp: f64, dq: f64| {
        let [a, b] = plan.intermediate_to_sheared(p + dp, q + dq);
        plan.warp.to_output(a, b)
    };
    let (o, a, b) = (at(0.0, 0.0)?, at(1.0, 0.0)?, at(0.0, 1.0)?);
    Some([((a[0] - o[0]).abs() + (b[0] - o[0]).abs()) / 2.0, ((a[1] - o[1]).abs() + (b[1] - o[1]).abs()) / 2.0])
}

/// The margin a rectangle is widened by before it is mapped back, for
/// footprints reaching `(hx, hy)`. An affine warp (a parallel frame) gives
/// every pixel the same box, of half extents (hx, hy) about its centre (the
/// gather's), and a box under a pixel takes the pixel nearest its centre:
/// the centres that can reach the rectangle lie within max(hx, ½) of it, and
/// the quad is exact up to rounding (a millionth of a pixel more). A
/// projective warp's footprint varies over the quad: a quarter more and a
/// pixel for safety.
fn margin_of([hx, hy]: [f64; 2], affine: bool) -> [f64; 2] {
    if affine { [hx.max(0.5) + 1e-6, hy.max(0.5) + 1e-6] } else { [1.25 * hx + 1.0, 1.25 * hy + 1.0] }
}

/// The margin [`reach_of`] widens a rectangle by in a parallel frame (an
/// affine warp: the same for every rectangle, so measured once per plan), or
/// None (a projective warp, or a degenerate one).
fn affine_margin(plan: &FramePlan) -> Option<[f64; 2]> {
    if plan.warp.forward.row(2) != DVec3::Z {
        return None;
    }
    let h = footprint_half(plan, 0.0, 0.0)?;
    h.iter().all(|x| x.is_finite()).then(|| margin_of(h, true))
}

/// [`reach_of`], with the affine margin given ([`affine_margin`]) or measured.
fn reach_with(plan: &FramePlan, [x0, y0, x1, y1]: [usize; 4], margin: Option<[f64; 2]>) -> Option<[usize; 4]> {
    let [w, h] = plan.grid.size;
    let all = Some([0, 0, w.saturating_sub(1), h.saturating_sub(1)]);
    if w == 0 || h == 0 {
        return all;
    }
    // the rectangle's corners back in the intermediate image, widened by
    // (ex, ey) output pixels first (None: a corner behind the eye, where
    // the projective map is not convex)
    let back = |ex: f64, ey: f64| -> Option<[[f64; 2]; 4]> {
        let (u0, v0, u1, v1) = (x0 as f64 - ex, y0 as f64 - ey, x1 as f64 + ex, y1 as f64 + ey);
        let c = [(u0, v0), (u1, v0), (u0, v1), (u1, v1)].map(|(u, v)| plan.output_to_intermediate(u, v));
        c.iter().all(|x| x.is_some_and(|x| x.iter().all(|c| c.is_finite()))).then(|| c.map(Option::unwrap))
    };
    let [ex, ey] = match margin {
        // (a parallel frame: the margin is known)
        Some(m) => m,
        None => {
            // an intermediate pixel's footprint (its square through the warp)
            // reaches (hx, hy) output pixels from its centre's image, and the
            // box takes the output pixel nearest it (half a pixel more): the
            // pixels that can reach the rectangle have their centres' images
            // in it widened by that much. Measured at the corners (the
            // largest footprint of a projective warp is at one of them).
            let Some(inner) = back(0.0, 0.0) else { return all };
            let (mut hx, mut hy) = (0.0f64, 0.0f64);
            for [p, q] in inner {
                let Some([a, b]) = footprint_half(plan, p, q) else { return all };
                (hx, hy) = (hx.max(a), hy.max(b));
            }
            if !(hx.is_finite() && hy.is_finite()) {
                return all;
            }
            let affine = plan.warp.forward.row(2) == DVec3::Z;
            margin_of([hx, hy], affine)
        }
    };
    let Some(outer) = back(ex, ey) else { return all };
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for [p, q] in outer {
        lo = [lo[0].min(p), lo[1].min(q)];
        hi = [hi[0].max(p), hi[1].max(q)];
    }
    // the pixels whose centres lie in the quad's bounding box (a projective
    // map takes the rectangle's edges to lines, so the box of its corners'
    // images is exact up to rounding; the margin above already holds the
    // footprint's variation over the quad)
    centres_in(lo, hi, [w, h])
}

/// The pixels `[p0, q0, p1, q1]` (inclusive) of a grid of `[w, h]` (both
/// above 0) whose centres lie in the box `lo ..= hi` (finite), widened by
/// 10⁻⁶ for rounding (None: the box lies off the grid).
#[inline]
fn centres_in(lo: [f64; 2], hi: [f64; 2], [w, h]: [usize; 2]) -> Option<[usize; 4]> {
    if !(hi[0] >= -1.0 && hi[1] >= -1.0 && lo[0] <= w as f64 && lo[1] <= h as f64) {
        return None;
    }
    // (clamped to the grid first: ⌈⌉ and ⌊⌋ commute with a clamp to whole numbers)
    let first = |x: f64, n: usize| ceil_in(max(x - 1e-6, 0.0)).min(n as i32 - 1) as usize;
    let last = |x: f64, n: usize| floor_in(min(x + 1e-6, n as f64 - 1.0)).max(0) as usize;
    Some([first(lo[0], w), first(lo[1], h), last(hi[0], w), last(hi[1], h)])
}

/// [`reach_with`] of an affine frame, set up once for all of a frame's
/// rectangles: the output → intermediate map's two rows (`p = m[0]·(u, v, 1)`,
/// `q = m[1]·(u, v, 1)`) and the margin. The image of a rectangle under an
/// affine map is a parallelogram whose bounding box is its centre's image ±
/// the absolute map times its half extents: two products a bound instead of
/// four corners through the homogeneous warp (the same box up to rounding,
/// far inside the 10⁻⁶ pixel slack the bounds keep).
struct AffineBack {
    /// The two rows, and their absolute values.
    m: [[f64; 3]; 2],
    abs: [[f64; 2]; 2],
    margin: [f64; 2],
    size: [usize; 2],
}

impl AffineBack {
    /// None unless the inverse warp is affine and finite.
    #[allow(clippy::neg_cmp_op_on_partial_ord)] // NaN fails the test too
    fn new(plan: &FramePlan, margin: [f64; 2]) -> Option<AffineBack> {
        let inv = &plan.warp.inverse;
        if inv.row(2) != DVec3::Z || !plan.grid.pitch.iter().all(|&p| p > 0.0) {
            return None;
        }
        let (pad, [pa, pb]) = (plan.grid.pad as f64, plan.grid.pitch);
        let m = [
            [inv.x_axis.x / pa, inv.y_axis.x / pa, inv.z_axis.x / pa + pad],
            [inv.x_axis.y / pb, inv.y_axis.y / pb, inv.z_axis.y / pb + pad],
        ];
        let abs = m.map(|r| [r[0].abs(), r[1].abs()]);
        let finite = m.iter().flatten().chain(&margin).all(|x| x.is_finite());
        finite.then_some(AffineBack { m, abs, margin, size: plan.grid.size })
    }

    /// The intermediate pixels `[p0, q0, p1, q1]` (inclusive) whose footprint
    /// can reach the output rectangle `[x0, y0, x1, y1]` (None: none can).
    #[inline]
    fn reach(&self, [x0, y0, x1, y1]: [usize; 4]) -> Option<[usize; 4]> {
        let [w, h] = self.size;
        if w == 0 || h == 0 {
            return Some([0, 0, w.saturating_sub(1), h.saturating_sub(1)]);
        }
        let [ex, ey] = self.margin;
        let (uc, vc) = ((x0 + x1) as f64 * 0.5, (y0 + y1) as f64 * 0.5);
        let (hu, hv) = ((x1 - x0) as f64 * 0.5 + ex, (y1 - y0) as f64 * 0.5 + ey);
        let [mp, mq] = &self.m;
        let [ap, aq] = &self.abs;
        let (pc, pe) = (mp[0] * uc + mp[1] * vc + mp[2], ap[0] * hu + ap[1] * hv);
        let (qc, qe) = (mq[0] * uc + mq[1] * vc + mq[2], aq[0] * hu + aq[1] * hv);
        centres_in([pc - pe, qc - qe], [pc + pe, qc + qe], self.size)
    }
}

/// `⌊x⌋` as an integer, for `x` well inside the `i32` range (a clamped
/// pixel position). Exact, and no library call (the default x86-64 target
/// has no rounding instruction).
#[inline(always)]
fn floor_in(x: f64) -> i32 {
    let t = x as i32;
    if t as f64 > x { t - 1 } else { t }
}

/// `⌈x⌉`, as [`floor_in`].
#[inline(always)]
fn ceil_in(x: f64) -> i32 {
    let t = x as i32;
    if (t as f64) < x { t + 1 } else { t }
}

/// The smaller of `a` and `b` (no NaN handling: the depths and positions
/// compared here are numbers or `+∞`).
#[inline(always)]
fn min(a: f64, b: f64) -> f64 {
    if b < a { b } else { a }
}

/// The larger of `a` and `b`, as [`min`].
#[inline(always)]
fn max(a: f64, b: f64) -> f64 {
    if b > a { b } else { a }
}

impl GeometryLimits {
    /// The output pixels whose centres lie in the box `[u0, u1] × [v0, v1]`
    /// (at least the pixel nearest its centre on each axis): `[x0, x1]`,
    /// `[y0, y1]`, inclusive (None: none in the image).
    #[inline(always)]
    fn footprint(&self, u0: f64, u1: f64, v0: f64, v1: f64) -> Option<([u32; 2], [u32; 2])> {
        let [w, h] = self.size_f;
        // no pixel can be taken (a NaN box takes none either); else the box
        // may be clamped to [-1, w] × [-1, h]: that changes no pixel taken
        if !(u1 >= -0.5 && v1 >= -0.5 && u0 <= w - 0.5 && v0 <= h - 0.5) {
            return None;
        }
        let (u0, u1) = (max(u0, -1.0), min(u1, w));
        let (v0, v1) = (max(v0, -1.0), min(v1, h));
        let (mut x0, mut x1) = (ceil_in(u0), floor_in(u1));
        let (mut y0, mut y1) = (ceil_in(v0), floor_in(v1));
        // a footprint smaller than a pixel takes the pixel nearest its centre
        if x0 > x1 {
            let m = floor_in((u0 + u1) / 2.0 + 0.5);
            (x0, x1) = (m, m);
        }
        if y0 > y1 {
            let m = floor_in((v0 + v1) / 2.0 + 0.5);
            (y0, y1) = (m, m);
        }
        let [wi, hi] = self.size_i;
        if x1 < 0 || y1 < 0 || x0 > wi - 1 || y0 > hi - 1 {
            return None;
        }
        Some(([x0.max(0) as u32, x1.min(wi - 1) as u32], [y0.max(0) as u32, y1.min(hi - 1) as u32]))
    }

    /// The nearest geometry depth over the output pixels whose centres lie in
    /// the box `[u0, u1] × [v0, v1]` (at least the nearest pixel's), `+∞` for none.
    /// (Also read by [`super::clip_mesh`].)
    #[inline(always)]
    pub(crate) fn min_depth(&self, u0: f64, u1: f64, v0: f64, v1: f64) -> f64 {
        let Some((xs, ys)) = self.footprint(u0, u1, v0, v1) else { return f64::INFINITY };
        self.min_over(xs, ys)
    }

    /// The nearest geometry depth over the output pixels `[x0, x1] × [y0, y1]`
    /// (inclusive, inside the image), `+∞` for none.
    #[inline(always)]
    fn min_over(&self, [x0, x1]: [u32; 2], [y0, y1]: [u32; 2]) -> f64 {
        let mut d = f64::INFINITY;
        for y in y0 as usize..y1 as usize + 1 {
            d = self.depths.fold(y, x0, x1, d);
        }
        d
    }

    /// [`GeometryLimits::min_over`] with `table` (the minima over `k`
    /// consecutive rows, [`GeometryLimits::row_minima`]) where the box holds
    /// `k ..= 2k` rows: two row folds, whatever its height (the rows' union,
    /// so the same value); else the rows themselves.
    #[inline(always)]
    fn min_over_with(&self, table: Option<&(Rows, u32)>, [x0, x1]: [u32; 2], [y0, y1]: [u32; 2]) -> f64 {
        match table {
            Some((t, k)) if y1 + 1 - y0 >= *k && y1 + 1 - y0 <= 2 * k => {
                let d = t.fold(y0 as usize, x0, x1, f64::INFINITY);
                // (a box of exactly k rows is one line)
                if y1 + 1 - y0 == *k { d } else { t.fold((y1 + 1 - k) as usize, x0, x1, d) }
            }
            _ => self.min_over([x0, x1], [y0, y1]),
        }
    }

    /// [`GeometryLimits::min_depth`] read through `table` (the same value).
    #[cfg(test)]
    fn min_depth_with(&self, table: &(Rows, u32), u0: f64, u1: f64, v0: f64, v1: f64) -> f64 {
        let Some((xs, ys)) = self.footprint(u0, u1, v0, v1) else { return f64::INFINITY };
        self.min_over_with(Some(table), xs, ys)
    }

    /// The minima over `k` consecutive output rows (`k` a power of two):
    /// line `y` holds, over the union of their spans, the smallest depth of
    /// rows `y .. y + k` (those in the image), so that a box of `k ..= 2k`
    /// rows is the minimum of two lines (a sparse table's one level, by
    /// doubling: log₂ k passes over the covered pixels, row-contiguous).
    fn row_minima(&self, k: u32) -> Rows {
        let h = self.size[1];
        let mut t = std::borrow::Cow::Borrowed(&self.depths);
        let mut s = 1;
        while s < k as usize {
            t = std::borrow::Cow::Owned(double_rows(&t, s, h));
            s *= 2;
        }
        t.into_owned()
    }
}

/// One doubling of [`GeometryLimits::row_minima`]: line `y` of the result is
/// the minimum of lines `y` and `y + s` of `prev` (of `h`; past it, none),
/// over the union of their spans (`+∞` in a gap between them).
fn double_rows(prev: &Rows, s: usize, h: usize) -> Rows {
    const NONE: ([u32; 2], usize) = ([1, 0], 0);
    let mut rows = Vec::with_capacity(h);
    let mut packed = Vec::with_capacity(prev.packed.len() + prev.packed.len() / 4);
    let seg = |([x0, x1], off): ([u32; 2], usize)| &prev.packed[off..off + (x1 - x0) as usize + 1];
    for y in 0..h {
        let a = prev.rows[y];
        let b = if y + s < h { prev.rows[y + s] } else { NONE };
        let off = packed.len();
        match (a.0[0] <= a.0[1], b.0[0] <= b.0[1]) {
            (false, false) => rows.push((NONE.0, off)),
            (true, false) => {
                rows.push((a.0, off));
                packed.extend_from_slice(seg(a));
            }
            (false, true) => {
                rows.push((b.0, off));
                packed.extend_from_slice(seg(b));
            }
            (true, true) => {
                let (lo, hi) = (a.0[0].min(b.0[0]), a.0[1].max(b.0[1]));
                rows.push(([lo, hi], off));
                packed.resize(off + (hi - lo) as usize + 1, f64::INFINITY);
                let out = &mut packed[off..];
                let (sa, sb) = (seg(a), seg(b));
                out[(a.0[0] - lo) as usize..][..sa.len()].copy_from_slice(sa);
                for (o, &v) in out[(b.0[0] - lo) as usize..].iter_mut().zip(sb) {
                    *o = min(*o, v);
                }
            }
        }
    }
    Rows { rows, packed }
}

/// What the gather of one frame reads, set once per plan: intermediate pixel
/// `(p, q, 1)` → homogeneous output point (`to_out`, and its half-pixel steps
/// along p and q), and the eye depth of the first and last slice's samples
/// as affine functions `c + c_p·p + c_q·q` of the pixel (a sample's voxel
/// position is affine in the pixel for a fixed slice in both projections,
/// and the depth affine in the position). Along a ray, the samples are
/// affine in the slice index, so slice `k`'s depth is `d₀ + k·(d_last − d₀)/last`.
struct Gather {
    to_out: DMat3,
    /// An affine warp (a parallel frame): the footprint box's half extents,
    /// the same about every pixel's centre.
    affine: Option<[f64; 2]>,
    /// An affine warp in fixed point (the usual case: every position of the
    /// frame well inside its range).
    fixed: Option<Fixed>,
    half_p: DVec3,
    half_q: DVec3,
    first: [f64; 3],
    last_depth: [f64; 3],
    last: usize,
    /// A parallel frame: the depth step from slice to slice, the same on
    /// every ray, and its inverse.
    step: Option<[f64; 2]>,
    /// A parallel frame whose footprint boxes are at least 5 rows tall: the
    /// minima over `k` consecutive rows ([`GeometryLimits::row_minima`]) and `k`.
    table: Option<(Rows, u32)>,
}

/// One in [`Fixed`]'s units: 2⁻³² output pixel.
const FIXED_ONE: i64 = 1 << 32;

/// An affine frame's footprint boxes in fixed point (2⁻³² output pixel):
/// the centre of pixel `(p, q)` is `x[0] + x[1]·p + x[2]·q` (and `y`), the
/// box's half extents `e`. Integer arithmetic is exact, so a pixel's box is
/// the same however it is reached (row by row, or pixel by pixel), and its
/// pixel range is two shifts, with no float-to-integer conversion (a fifth
/// of the gather's instructions in the float version).
struct Fixed {
    x: [i64; 3],
    y: [i64; 3],
    e: [i64; 2],
}

impl Fixed {
    /// None when a position of the `grid` could leave the range kept exact
    /// (|x| < 2⁶¹: a billion output pixels), or the warp is not finite.
    fn new(to_out: &DMat3, [ex, ey]: [f64; 2], grid: [usize; 2]) -> Option<Fixed> {
        let fix = |v: f64| {
            let s = (v * FIXED_ONE as f64).round();
            (s.abs() < 2f64.powi(60)).then_some(s as i64)
        };
        let x = [fix(to_out.z_axis.x)?, fix(to_out.x_axis.x)?, fix(to_out.y_axis.x)?];
        let y = [fix(to_out.z_axis.y)?, fix(to_out.x_axis.y)?, fix(to_out.y_axis.y)?];
        let e = [fix(ex)?, fix(ey)?];
        let reach = |c: [i64; 3], e: i64| {
            c[0].unsigned_abs() as f64
                + c[1].unsigned_abs() as f64 * grid[0] as f64
                + c[2].unsigned_abs() as f64 * grid[1] as f64
                + e as f64
        };
        (reach(x, e[0]) < 2f64.powi(61) && reach(y, e[1]) < 2f64.powi(61)).then_some(Fixed { x, y, e })
    }
}

/// The output pixels `[a, b]` (inclusive, of `0 .. n`) whose centres lie
/// within `e` of `c` (fixed point), or the pixel nearest `c` when the box
/// holds none (None: none in the image).
#[inline(always)]
fn fixed_span(c: i64, e: i64, n: i64) -> Option<[u32; 2]> {
    let (mut a, mut b) = ((c - e + (FIXED_ONE - 1)) >> 32, (c + e) >> 32);
    if a > b {
        a = (c + FIXED_ONE / 2) >> 32;
        b = a;
    }
    if b < 0 || a >= n {
        return None;
    }
    Some([a.max(0) as u32, b.min(n - 1) as u32])
}

/// What the gather of one row `q` of intermediate pixels shares.
struct RowAt {
    /// The output point of pixel `(0, q)` (a projective warp).
    c: DVec3,
    /// Its fixed-point position (an affine one).
    fixed: [i64; 2],
    /// The first and last slice's depths at pixel `(0, q)`.
    d: [f64; 2],
}

impl Gather {
    fn new(plan: &FramePlan, gl: &GeometryLimits) -> Self {
        let (pad, [pa, pb]) = (plan.grid.pad as f64, plan.grid.pitch);
        let to_sheared = DMat3::from_cols(DVec3::new(pa, 0.0, 0.0), DVec3::new(0.0, pb, 0.0), DVec3::new(-pad * pa, -pad * pb, 1.0));
        let to_out = plan.warp.forward * to_sheared;
        let last = plan.slices().saturating_sub(1);
        let depths = |k: usize| slice_depth(plan, &gl.projector, k);
        let (half_p, half_q) = (to_out.x_axis * 0.5, to_out.y_axis * 0.5);
        let affine = (to_out.row(2) == DVec3::Z).then(|| [half_p.x.abs() + half_q.x.abs(), half_p.y.abs() + half_q.y.abs()]);
        let fixed = affine.and_then(|e| Fixed::new(&to_out, e, plan.grid.size));
        let (first, last_depth) = (depths(0), depths(last));
        let dk = (last_depth[0] - first[0]) / last as f64;
        let step = (affine.is_some() && last > 0 && dk != 0.0 && dk.is_finite()).then_some([dk, 1.0 / dk]);
        // boxes of up to n rows (n ≥ 5: the table's log₂ k passes over the
        // covered pixels cost less than the rows a box no longer folds)
        let table = fixed.as_ref().and_then(|f| {
            let n = ((2 * f.e[1]) >> 32) + 1;
            let k = (n.clamp(1, 1 << 30) as u32).next_power_of_two() / 2;
            (k >= 4).then(|| (gl.row_minima(k), k))
        });
        Gather { to_out, affine, fixed, half_p, half_q, first, last_depth, last, step, table }
    }

    /// What row `q`'s pixels share.
    #[inline(always)]
    fn row(&self, q: usize) -> RowAt {
        let qf = q as f64;
        let qi = q as i64;
        let fixed = self.fixed.as_ref().map_or([0; 2], |f| [f.x[0] + f.x[2] * qi, f.y[0] + f.y[2] * qi]);
        RowAt {
            c: self.to_out.y_axis * qf + self.to_out.z_axis,
            fixed,
            d: [self.first[0] + self.first[2] * qf, self.last_depth[0] + self.last_depth[2] * qf],
        }
    }
}

impl GeometryLimits {
    /// Narrows the limits `l` of pixel `(p, q)` (`r`: row `q`) to the slices in
    /// front of the nearest geometry depth over its footprint (the gather of
    /// one pixel).
    #[inline(always)]
    #[allow(clippy::neg_cmp_op_on_partial_ord)] // NaN fails the test too
    fn limit_at(&self, g: &Gather, r: &RowAt, p: usize, l: &mut [u32; 2]) {
        if l[0] > l[1] {
            return;
        }
        // the footprint: the pixel's square through the warp (its corners'
        // bounding box in the output image)
        let pf = p as f64;
        let d = if let Some(f) = &g.fixed {
            // a parallel frame: the same box about every centre, in fixed point
            let pi = p as i64;
            let [w, h] = self.size_i;
            let Some(xs) = fixed_span(r.fixed[0] + f.x[1] * pi, f.e[0], w as i64) else { return };
            let Some(ys) = fixed_span(r.fixed[1] + f.y[1] * pi, f.e[1], h as i64) else { return };
            self.min_over_with(g.table.as_ref(), xs, ys)
        } else {
            let c = r.c + g.to_out.x_axis * pf;
            if let Some([ex, ey]) = g.affine {
                // (an affine frame too far out for the fixed point)
                self.min_depth(c.x - ex, c.x + ex, c.y - ey, c.y + ey)
            } else {
                let (mut u0, mut u1, mut v0, mut v1) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
                for h in [c - g.half_p - g.half_q, c + g.half_p - g.half_q, c + g.half_p + g.half_q, c - g.half_p + g.half_q] {
                    if !(h.z > 0.0) {
                        return;
                    }
                    let (u, v) = (h.x / h.z, h.y / h.z);
                    (u0, u1, v0, v1) = (min(u0, u), max(u1, u), min(v0, v), max(v1, v));
                }
                self.min_depth(u0, u1, v0, v1)
            }
        };
        if !d.is_finite() {
            return;
        }
        // the samples' depth is affine in k: keep those strictly in front of d
        let last = g.last;
        let d0 = r.d[0] + g.first[1] * pf;
        // the depth step from slice to slice (in a parallel frame the same on
        // every ray, and the crossing a product; else a quotient per ray)
        let [dk, inv] = match g.step {
            Some(s) => s,
            None if last > 0 => {
                let d1 = r.d[1] + g.last_depth[1] * pf;
                [(d1 - d0) / last as f64, f64::NAN]
            }
            None => [0.0, f64::NAN],
        };
        let (mut lo, mut hi) = (l[0] as i64, l[1] as i64);
        // (with the crossing slice: one more past the last kept, in walking order)
        let extra = self.crossing as i64;
        if dk == 0.0 {
            if d0 >= d && !self.crossing {
                (lo, hi) = (1, 0);
            }
        } else {
            let keep = |k: i64| d0 + dk * (k as f64) < d;
            let ks = if g.step.is_some() { (d - d0) * inv } else { (d - d0) / dk };
            let ks = max(0.0, min(ks, last as f64));
            // `keep` is monotone in k and `ks` lies within rounding (far less
            // than a slice) of where it changes: one step corrects it. (Straight
            // code: the searching loops this replaces were vectorized 16 slices
            // at a time, a quarter of the gather's time.)
            if dk > 0.0 {
                // depth grows with k: keep k up to the crossing
                let mut b = floor_in(ks) as i64;
                if !keep(b) {
                    b -= 1;
                } else if b < last as i64 && keep(b + 1) {
                    b += 1;
                }
                hi = hi.min((b + extra).min(last as i64));
            } else {
                let mut a = ceil_in(ks) as i64;
                if !keep(a) {
                    a += 1;
                } else if a > 0 && keep(a - 1) {
                    a -= 1;
                }
                lo = lo.max((a - extra).max(0));
            }
        }
        *l = if lo > hi { [1, 0] } else { [lo as u32, hi as u32] };
    }
}

/// The marked intermediate pixels: one bit each, row by row (`words` per
/// row), with each row's first and last word holding any (`w0 > w1`: none).
struct Marks {
    bits: Vec<u64>,
    words: usize,
    rows: Vec<[usize; 2]>,
}

impl Marks {
    /// How many pixels are marked.
    #[cfg(test)]
    fn count(&self) -> usize {
        self.bits.iter().map(|x| x.count_ones() as usize).sum()
    }

    /// Calls `f(p)` for every marked pixel `p` of row `q`, in order.
    #[inline(always)]
    fn each(&self, q: usize, mut f: impl FnMut(usize)) {
        let [w0, w1] = self.rows[q];
        for wi in w0..w1.saturating_add(1) {
            let mut m = self.bits[q * self.words + wi];
            while m != 0 {
                f(wi * 64 + m.trailing_zeros() as usize);
                m &= m - 1;
            }
        }
    }
}

impl GeometryLimits {
    /// The intermediate pixels whose footprint can reach a covered output
    /// tile (bits: a needle marks a few thousand of a million pixels).
    fn marks(&self, plan: &FramePlan) -> Marks {
        let [w, h] = plan.grid.size;
        let words = w.div_ceil(64);
        let mut m = Marks { bits: vec![0; words * h], words, rows: vec![[usize::MAX, 0]; h] };
        let margin = affine_margin(plan);
        let back = margin.and_then(|m| AffineBack::new(plan, m));
        for &run in &self.runs {
            let reach = match &back {
                Some(b) => b.reach(run),
                None => reach_with(plan, run, margin),
            };
            let Some([p0, q0, p1, q1]) = reach.filter(|[p0, q0, p1, q1]| p0 <= p1 && q0 <= q1) else { continue };
            let (a, b) = (p0 / 64, p1 / 64);
            // the run's bits in its first and last word (one word: both)
            let lo = u64::MAX << (p0 % 64);
            let hi = u64::MAX >> (63 - p1 % 64);
            for q in q0..=q1 {
                let row = &mut m.bits[q * words..(q + 1) * words];
                if a == b {
                    row[a] |= lo & hi;
                } else {
                    row[a] |= lo;
                    row[a + 1..b].fill(u64::MAX);
                    row[b] |= hi;
                }
                m.rows[q] = [m.rows[q][0].min(a), m.rows[q][1].max(b)];
            }
        }
        m
    }
}

/// Below about this many marked pixels the gather runs on the calling
/// thread (waking the pool costs more than it saves).
const SERIAL_BELOW: f64 = 2048.0;

impl Limiter for GeometryLimits {
    /// Parallel when the marked pixels may be many: each covered tile marks
    /// about its area in intermediate pixels, at least one, and the
    /// footprint's margin about as many again (an estimate before the
    /// marks, so that the renderer knows where to run it).
    fn parallel(&self, plan: &FramePlan) -> bool {
        let ratio = plan.grid.pixels() as f64 / (self.size[0] * self.size[1]).max(1) as f64;
        !self.cull || 2.0 * self.tiles as f64 * (ratio * (TILE * TILE) as f64).max(1.0) >= SERIAL_BELOW
    }

    fn limit(&self, plan: &FramePlan, limits: &mut RayLimits) {
        if plan.slices() == 0 || plan.grid.pixels() == 0 || self.bounds.is_none() {
            return;
        }
        if !self.cull {
            // the reference: every pixel gathers, over the rows themselves
            let g = Gather { table: None, ..Gather::new(plan, self) };
            let Some([p0, q0, p1, q1]) = self.reach(plan) else { return };
            limits.par_rows_mut().enumerate().skip(q0).take(q1 + 1 - q0).for_each(|(q, row)| {
                let r = g.row(q);
                for (p, l) in row.iter_mut().enumerate().skip(p0).take(p1 + 1 - p0) {
                    self.limit_at(&g, &r, p, l);
                }
            });
            return;
        }
        let par = self.parallel(plan);
        // (the gather's set-up, with any table of row minima, beside the marks)
        let (g, marks) =
            if par { rayon::join(|| Gather::new(plan, self), || self.marks(plan)) } else { (Gather::new(plan, self), self.marks(plan)) };
        // (a row without marks sets nothing up)
        let gather_row = |q: usize, row: &mut [[u32; 2]]| {
            if marks.rows[q][0] <= marks.rows[q][1] {
                let r = g.row(q);
                marks.each(q, |p| self.limit_at(&g, &r, p, &mut row[p]))
            }
        };
        // (the rows holding marks)
        let Some(qa) = marks.rows.iter().position(|r| r[0] <= r[1]) else { return };
        let qb = marks.rows.iter().rposition(|r| r[0] <= r[1]).unwrap_or(qa);
        if !par {
            for q in qa..=qb {
                gather_row(q, limits.row_mut(q));
            }
            return;
        }
        limits.par_rows_mut().enumerate().skip(qa).take(qb + 1 - qa).for_each(|(q, row)| gather_row(q, row));
    }
}

/// The final image: the volume (`image`, premultiplied colour over black with
/// its coverage) over the geometry's colour, `out = vol + (1 − α_vol)·geometry`.
pub fn composite_over_geometry(image: &mut Image, geometry: &GeometryImage) {
    assert_eq!((image.width, image.height), (geometry.width, geometry.height), "image sizes");
    // (only the rows' covered spans: the geometry's colour is 0 elsewhere,
    // and its untouched pages are never read)
    let w = image.width;
    for y in 0..image.height {
        let Some([x0, x1]) = geometry.row_span(y) else { continue };
        let (a, b) = (y * w + x0, y * w + x1);
        for (px, g) in image.data[a..=b].iter_mut().zip(&geometry.color[a..=b]) {
            let t = 1.0 - px[3].clamp(0.0, 1.0);
            for c in 0..4 {
                px[c] += t * g[c];
            }
        }
    }
}

/// The final image of an iso frame whose rays kept the crossing slice
/// ([`GeometryLimits::with_iso_crossing`]): at each output pixel the
/// geometry covers, the eye depth of the volume's iso hit under it (that of
/// [`super::volume_hit`]'s position: the warp's bilinear weights over the
/// intermediate hits, here from each plan's slice depths set up once, with
/// no sample position per pixel; equal up to rounding, tested) is compared
/// with the geometry's depth: a hit at or behind the geometry is hidden (the pixel
/// is the geometry's colour), one in front is composed over it as in
/// [`composite_over_geometry`]. Elsewhere the volume is over the geometry as
/// there. A perspective frame split into pyramids is tested the same way,
/// each pixel against the pyramid that owns it, when the renderer kept the
/// pyramids' depths ([`crate::render::Renderer::set_keep_depths`]; without,
/// its pixels are composed without the test).
pub fn composite_iso_over_geometry(
    image: &mut Image,
    geometry: &GeometryImage,
    renderer: &crate::render::Renderer,
    limits: &GeometryLimits,
) {
    assert_eq!((image.width, image.height), (geometry.width, geometry.height), "image sizes");
    let w = image.width;
    // the eye depth of the volume's hit, from each plan's slice depths (no
    // sample positions per pixel)
    let hits = super::hit::HitDepths::new(renderer, &limits.projector);
    // (only the rows' covered spans, as composite_over_geometry)
    image.data.par_chunks_mut(w.max(1)).enumerate().for_each(|(v, row)| {
        let Some([x0, x1]) = geometry.row_span(v) else { return };
        for (u, px) in row.iter_mut().enumerate().take(x1 + 1).skip(x0) {
            let i = v * w + u;
            let (gd, g) = (geometry.depth[i], geometry.color[i]);
            if !gd.is_finite() {
                continue;
            }
            let hidden = hits.at(u as f64, v as f64).is_some_and(|d| d >= gd);
            if hidden {
                *px = g;
            } else {
                let t = 1.0 - px[3].clamp(0.0, 1.0);
                for c in 0..4 {
                    px[c] += t * g[c];
                }
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accuracy::reference::{Rays, fast_path_depth};
    use crate::accuracy::truth::cylinder_hit;
    use crate::composite::Mode;
    use crate::data::phantom::{SPHERE_ISO, sphere, sphere_geometry};
    use crate::geometry::sampling::sample_voxel;
    use crate::geometry::{Cull, Material, Mesh, rasterize};
    use crate::render::{Method, Renderer, Settings};
    use crate::view::{Camera, NamedView, Projection, rotate_eye};
    use glam::DMat3;
    use std::sync::Arc;

    /// Visiting only the intermediate pixels that can reach the geometry's
    /// rectangle gives exactly the limits of visiting every pixel (a small
    /// needle, a plate across the image, nothing on screen, a mesh partly
    /// behind a perspective eye), and for a small mesh visits far fewer.
    /// The table of minima over k consecutive rows gives the rows' minimum
    /// over every box of k to 2k rows, and the rows themselves elsewhere,
    /// bit for bit (random boxes, sub-pixel to tall, inside and across the
    /// image's edges, over a needle and a plate with gaps between them; k = 2
    /// to 16, with chest-CT-like voxels).
    #[test]
    fn inverse_warp_row_minima_give_the_rows_minimum() {
        let dims = [40, 36, 30];
        let c = DVec3::new(19.5, 17.5, 14.5);
        let cam = Camera::new(DMat3::from_euler(glam::EulerRot::XYZ, 0.5, -0.8, 0.3), [120, 90]);
        let proj = Projector::new(&cam, &Projection::Parallel, dims, [0.6, 0.6, 5.0]).unwrap();
        let mut geo = GeometryImage::new(120, 90);
        for mesh in [
            Mesh::cylinder(c + DVec3::new(-6.0, -2.0, 1.0), c + DVec3::new(5.0, 3.0, -2.0), 1.5, 16).unwrap(),
            Mesh::cuboid(DVec3::new(25.0, -5.0, 10.0), DVec3::new(60.0, 8.0, 11.0)).unwrap(),
        ] {
            rasterize(&mesh, &Material::default(), Cull::None, &proj, &mut geo).unwrap();
        }
        let gl = GeometryLimits::new(proj, &geo);
        let tables: Vec<(Rows, u32)> = [2, 4, 8, 16].into_iter().map(|k| (gl.row_minima(k), k)).collect();
        let mut rnd = crate::geometry::test_rng(0x9e3779b97f4a7c15u64);
        let [x0, y0, x1, y1] = gl.bounds.unwrap().map(|x| x as f64);
        let (mut finite, mut n, mut used) = (0, 0, [0usize; 4]);
        for i in 0..20000 {
            // (half the boxes about the geometry's bounds, half anywhere)
            let (u, v) =
                if i % 2 == 0 { (rnd(x0 - 5.0, x1 + 5.0), rnd(y0 - 5.0, y1 + 5.0)) } else { (rnd(-10.0, 130.0), rnd(-10.0, 100.0)) };
            let (ex, ey) = (rnd(0.0, 4.0), rnd(0.0, 17.0));
            let rows = gl.min_depth(u - ex, u + ex, v - ey, v + ey);
            for (i, t) in tables.iter().enumerate() {
                let (k, fp) = (t.1, gl.footprint(u - ex, u + ex, v - ey, v + ey));
                used[i] += fp.is_some_and(|(_, [y0, y1])| (k..=2 * k).contains(&(y1 + 1 - y0))) as usize;
                assert_eq!(
                    rows.to_bits(),
                    gl.min_depth_with(t, u - ex, u + ex, v - ey, v + ey).to_bits(),
                    "k = {}: box at ({u}, {v}) ± ({ex}, {ey})",
                    t.1
                );
            }
            finite += rows.is_finite() as usize;
            n += 1;
        }
        assert!(finite * 10 > n, "only {finite} of {n} boxes met geometry");
        assert!(used.iter().all(|&u| u > 500), "boxes read through each table: {used:?}");
    }

    /// The fixed-point box of an affine frame takes the output pixels the
    /// float box takes ([`GeometryLimits::footprint`]): random centres and
    /// half extents, sub-pixel to wide, inside and across the image's edges
    /// (away from a pixel edge by more than the fixed point's 2⁻³²).
    #[test]
    fn inverse_warp_fixed_boxes_take_the_float_boxes_pixels() {
        let gl = GeometryLimits::new(
            Projector::new(&Camera::new(DMat3::IDENTITY, [97, 61]), &Projection::Parallel, [8, 8, 8], [1.0; 3]).unwrap(),
            &GeometryImage::new(97, 61),
        );
        let mut rnd = crate::geometry::test_rng(0x2545f4914f6cdd1du64);
        let near_edge = |x: f64| (x - x.round()).abs() < 1e-6;
        let fix = |x: f64| (x * FIXED_ONE as f64).round() as i64;
        let (mut n, mut some) = (0, 0);
        while n < 50_000 {
            let (u, v, ex, ey) = (rnd(-6.0, 104.0), rnd(-6.0, 68.0), rnd(0.0, 3.0), rnd(0.0, 5.0));
            if [u - ex, u + ex, u + 0.5, v - ey, v + ey, v + 0.5].into_iter().any(near_edge) {
                continue;
            }
            let float = gl.footprint(u - ex, u + ex, v - ey, v + ey);
            let fixed = fixed_span(fix(u), fix(ex), 97).zip(fixed_span(fix(v), fix(ey), 61));
            assert_eq!(fixed, float, "box at ({u}, {v}) ± ({ex}, {ey})");
            some += fixed.is_some() as usize;
            n += 1;
        }
        assert!(some * 10 > n * 7, "only {some} of {n} boxes in the image");
    }

    /// An affine frame's rectangles mapped back in one step ([`AffineBack`])
    /// reach the intermediate pixels the four corners through the warp
    /// reach ([`reach_with`]): random parallel views (isotropic and
    /// chest-CT-like voxels, coarse and fine output), random rectangles,
    /// thin and wide, inside, across and outside the image.
    #[test]
    fn inverse_warp_affine_reach_equals_the_corners_reach() {
        use crate::view::Factorization;
        let mut rnd = crate::geometry::test_rng(0x853c49e6748fea9bu64);
        let (mut n, mut some) = (0, 0);
        for (sp, size) in [([1.0f32; 3], [96usize, 80usize]), ([0.6, 0.6, 5.0], [300, 250]), ([1.0; 3], [512, 512])] {
            for _ in 0..20 {
                let rot = DMat3::from_euler(glam::EulerRot::XYZ, rnd(-3.2, 3.2), rnd(-3.2, 3.2), rnd(-3.2, 3.2));
                let plan = FramePlan::parallel(&Factorization::new(&Camera::new(rot, size), [40, 36, 30], sp).unwrap(), sp);
                let Some(margin) = affine_margin(&plan) else { continue };
                let back = AffineBack::new(&plan, margin).expect("a parallel frame's inverse warp is affine");
                for _ in 0..200 {
                    let (x0, y0) = (rnd(-50.0, size[0] as f64 + 50.0) as i64, rnd(-50.0, size[1] as f64 + 50.0) as i64);
                    let (x0, y0) = (x0.max(0) as usize, y0.max(0) as usize);
                    let (x1, y1) = (x0 + rnd(0.0, 40.0) as usize, y0 + rnd(0.0, 8.0) as usize);
                    let rect = [x0, y0, x1, y1];
                    let want = reach_with(&plan, rect, Some(margin));
                    assert_eq!(back.reach(rect), want, "{rect:?}, {sp:?}, {size:?}, {rot}");
                    some += want.is_some() as usize;
                    n += 1;
                }
            }
        }
        assert!(some * 2 > n, "only {some} of {n} rectangles reach the grid");
    }

    #[test]
    fn inverse_warp_rectangle_skip_changes_no_limit() {
        use crate::view::Factorization;
        use crate::view::perspective::PerspectiveView;
        let dims = [40, 36, 30];
        let c = DVec3::new(19.5, 17.5, 14.5);
        let meshes = [
            Mesh::cylinder(c + DVec3::new(-6.0, -2.0, 1.0), c + DVec3::new(5.0, 3.0, -2.0), 1.5, 16).unwrap(),
            Mesh::cuboid(DVec3::new(-30.0, -30.0, 14.0), DVec3::new(70.0, 70.0, 15.0)).unwrap(),
            Mesh::sphere(c + DVec3::new(500.0, 0.0, 0.0), 3.0, 16).unwrap(),
            Mesh::cylinder(c - DVec3::new(0.0, 0.0, 400.0), c + DVec3::new(0.0, 0.0, 400.0), 2.0, 16).unwrap(),
        ];
        // isotropic and chest-CT-like voxels, a coarse and a fine output image
        for (sp, size) in [([1.0f32; 3], [96, 80]), ([0.6, 0.6, 5.0], [96, 80]), ([1.0; 3], [300, 250]), ([0.6, 0.6, 5.0], [300, 250])] {
            for rot in [
                DMat3::IDENTITY,
                DMat3::from_euler(glam::EulerRot::XYZ, 0.5, -0.8, 0.3),
                rotate_eye(NamedView::Anterior.rotation(), 1, 40.0),
                rotate_eye(NamedView::Anterior.rotation(), 0, 70.0),
            ] {
                let cam = Camera::new(rot, size);
                for projection in [
                    Projection::Parallel,
                    Projection::perspective(50.0, 1.2).unwrap(),
                    Projection::perspective(80.0, 0.9).unwrap(),
                    Projection::perspective(25.0, 4.0).unwrap(),
                ] {
                    let plan = match projection.resolve(&cam, dims, sp).unwrap() {
                        None => FramePlan::parallel(&Factorization::new(&cam, dims, sp).unwrap(), sp),
                        Some((pc, d)) => {
                            let f = Factorization::new(&pc, dims, sp).unwrap();
                            let Ok(pv) = PerspectiveView::new(&pc, d, dims, sp) else { continue };
                            FramePlan::perspective(&pv, &f, sp, 0.5)
                        }
                    };
                    for (i, mesh) in meshes.iter().enumerate() {
                        let proj = Projector::new(&cam, &projection, dims, sp).unwrap();
                        let mut geo = GeometryImage::new(size[0], size[1]);
                        rasterize(mesh, &Material::default(), Cull::None, &proj, &mut geo).unwrap();
                        let (fast, full) = (GeometryLimits::new(proj, &geo), GeometryLimits::visiting_every_pixel(proj, &geo));
                        let mut a = RayLimits::open(plan.grid.size, plan.slices());
                        let mut b = a.clone();
                        fast.limit(&plan, &mut a);
                        full.limit(&plan, &mut b);
                        assert_eq!(a, b, "mesh {i}, {projection:?}, spacing {sp:?}, {size:?}, {rot}");
                        if i == 0 && sp[2] == 1.0 {
                            let visited = fast.marks(&plan).count();
                            assert!(visited * 4 < plan.grid.pixels(), "a needle visits {visited} of {} pixels", plan.grid.pixels());
                        }
                    }
                }
            }
        }
    }

    /// The marks change no limit in random views: random rotations, parallel
    /// and perspective (fields of view 20–100°, the eye 0.7–6 diagonals
    /// away), random needles and plates, isotropic and chest-CT-like voxels,
    /// output images coarser and finer than the grid; the limits equal the
    /// every-pixel gather's, bit for bit.
    #[test]
    fn inverse_warp_marks_change_no_limit_in_random_views() {
        use crate::view::Factorization;
        use crate::view::perspective::PerspectiveView;
        let mut rnd = crate::geometry::test_rng(0xda942042e4dd58b5u64);
        let dims = [40, 36, 30];
        let (mut cases, mut limited) = (0, 0);
        while cases < 150 {
            let sp = if rnd(0.0, 1.0) < 0.5 { [1.0f32; 3] } else { [0.6, 0.6, 3.0] };
            let side = rnd(48.0, 360.0) as usize;
            let size = [side, (side as f64 * rnd(0.6, 1.3)) as usize];
            let rot = DMat3::from_euler(glam::EulerRot::XYZ, rnd(-3.2, 3.2), rnd(-3.2, 3.2), rnd(-3.2, 3.2));
            let cam = Camera::new(rot, size);
            let projection =
                if rnd(0.0, 1.0) < 0.3 { Projection::Parallel } else { Projection::perspective(rnd(20.0, 100.0), rnd(0.7, 6.0)).unwrap() };
            let plan = match projection.resolve(&cam, dims, sp).unwrap() {
                None => FramePlan::parallel(&Factorization::new(&cam, dims, sp).unwrap(), sp),
                Some((pc, d)) => {
                    let f = Factorization::new(&pc, dims, sp).unwrap();
                    let Ok(pv) = PerspectiveView::new(&pc, d, dims, sp) else { continue };
                    FramePlan::perspective(&pv, &f, sp, rnd(0.3, 1.5))
                }
            };
            let (a, b) = (
                DVec3::new(rnd(-10.0, 50.0), rnd(-10.0, 46.0), rnd(-10.0, 40.0)),
                DVec3::new(rnd(-10.0, 50.0), rnd(-10.0, 46.0), rnd(-10.0, 40.0)),
            );
            let mesh = if rnd(0.0, 1.0) < 0.7 {
                Mesh::cylinder(a, b, rnd(0.3, 4.0), 12).unwrap()
            } else {
                Mesh::cuboid(a, a + DVec3::new(rnd(1.0, 30.0), rnd(1.0, 30.0), rnd(0.5, 3.0))).unwrap()
            };
            let proj = Projector::new(&cam, &projection, dims, sp).unwrap();
            let mut geo = GeometryImage::new(size[0], size[1]);
            rasterize(&mesh, &Material::default(), Cull::None, &proj, &mut geo).unwrap();
            let (fast, full) = (GeometryLimits::new(proj, &geo), GeometryLimits::visiting_every_pixel(proj, &geo));
            let mut a = RayLimits::open(plan.grid.size, plan.slices());
            let mut b = a.clone();
            fast.limit(&plan, &mut a);
            full.limit(&plan, &mut b);
            assert_eq!(a, b, "{projection:?}, spacing {sp:?}, {size:?}, {rot}, grid {:?}", plan.grid.size);
            limited += (a != RayLimits::open(plan.grid.size, plan.slices())) as usize;
            cases += 1;
        }
        assert!(limited * 3 > cases, "only {limited} of {cases} views limited any ray");
    }

    /// The plans of `cam` over a volume of `dims` (isotropic voxels), both
    /// projections (a perspective view that needs the pyramid split is left out).
    fn plans_of(cam: &Camera, dims: [usize; 3]) -> Vec<(Projection, FramePlan)> {
        use crate::view::Factorization;
        use crate::view::perspective::PerspectiveView;
        let mut out = vec![];
        for projection in [Projection::Parallel, Projection::perspective(40.0, 2.0).unwrap()] {
            let plan = match projection.resolve(cam, dims, [1.0; 3]).unwrap() {
                None => FramePlan::parallel(&Factorization::new(cam, dims, [1.0; 3]).unwrap(), [1.0; 3]),
                Some((pc, d)) => {
                    let f = Factorization::new(&pc, dims, [1.0; 3]).unwrap();
                    let Ok(pv) = PerspectiveView::new(&pc, d, dims, [1.0; 3]) else { continue };
                    FramePlan::perspective(&pv, &f, [1.0; 3], 0.5)
                }
            };
            out.push((projection, plan));
        }
        out
    }

    /// The inverse-warped depth of a flat plane at 45° to the view has no
    /// holes (parallel and perspective, an output image coarser and one finer
    /// than the intermediate image, several views): every intermediate pixel
    /// whose footprint lies on the plane (its centre's output pixel and the
    /// output pixels its footprint box reaches, one more around, all covered)
    /// is cut at the plane: the last sample kept, in walking order, lies in
    /// front of the farthest plane depth over that neighbourhood (no sample
    /// behind the plane everywhere around the pixel survives: no hole), and
    /// the next sample lies behind the nearest (nothing in front of the
    /// whole neighbourhood is cut).
    #[test]
    fn inverse_warp_of_a_plane_at_45_degrees_has_no_holes() {
        let dims = [48, 40, 44];
        let c = DVec3::new(23.5, 19.5, 21.5);
        for size in [[64, 56], [320, 280]] {
            for rot in [
                rotate_eye(NamedView::Anterior.rotation(), 1, 20.0),
                DMat3::from_euler(glam::EulerRot::XYZ, 0.5, -0.8, 0.3),
                rotate_eye(NamedView::Anterior.rotation(), 0, 50.0),
            ] {
                let cam = Camera::new(rot, size);
                // eye-space axes in voxel space; the plane's normal halfway between the view and screen x
                let (ex, ey, ez) = (rot.transpose() * DVec3::X, rot.transpose() * DVec3::Y, rot.transpose() * DVec3::Z);
                let (u, v) = ((ez - ex).normalize() * 80.0, ey * 80.0);
                let plane = Mesh::new(vec![c - u - v, c + u - v, c + u + v, c - u + v], vec![[0, 1, 2], [0, 2, 3]]).unwrap();
                for (projection, plan) in plans_of(&cam, dims) {
                    let proj = Projector::new(&cam, &projection, dims, [1.0; 3]).unwrap();
                    let mut geo = GeometryImage::new(size[0], size[1]);
                    rasterize(&plane, &Material::default(), Cull::None, &proj, &mut geo).unwrap();
                    let gl = GeometryLimits::new(proj, &geo);
                    let mut l = RayLimits::open(plan.grid.size, plan.slices());
                    gl.limit(&plan, &mut l);
                    let (w, h) = (size[0] as i64, size[1] as i64);
                    let depth_at = |x: i64, y: i64| {
                        if x < 0 || y < 0 || x >= w || y >= h { f64::INFINITY } else { geo.depth[(y * w + x) as usize] }
                    };
                    let depth_of = |k: usize, p: usize, q: usize| -proj.eye_space(sample_voxel(&plan, k, p, q)).z;
                    let last = plan.slices() - 1;
                    let mut checked = 0;
                    for q in 0..plan.grid.size[1] {
                        for p in 0..plan.grid.size[0] {
                            let out = |dp: f64, dq: f64| {
                                let [a, b] = plan.intermediate_to_sheared(p as f64 + dp, q as f64 + dq);
                                plan.warp.to_output(a, b)
                            };
                            let Some(o) = out(0.0, 0.0) else { continue };
                            let Some(cs) =
                                [out(-0.5, -0.5), out(0.5, -0.5), out(0.5, 0.5), out(-0.5, 0.5)].into_iter().collect::<Option<Vec<_>>>()
                            else {
                                continue;
                            };
                            // the footprint box, one output pixel more around
                            let x0 = cs.iter().map(|c| c[0]).fold(o[0], f64::min).floor() as i64 - 1;
                            let x1 = cs.iter().map(|c| c[0]).fold(o[0], f64::max).ceil() as i64 + 1;
                            let y0 = cs.iter().map(|c| c[1]).fold(o[1], f64::min).floor() as i64 - 1;
                            let y1 = cs.iter().map(|c| c[1]).fold(o[1], f64::max).ceil() as i64 + 1;
                            let box_depths: Vec<f64> =
                                (y0..=y1).flat_map(|y| (x0..=x1).map(move |x| (x, y))).map(|(x, y)| depth_at(x, y)).collect();
                            if box_depths.iter().any(|d| !d.is_finite()) {
                                continue;
                            }
                            let dmin = box_depths.iter().copied().fold(f64::INFINITY, f64::min);
                            let dmax = box_depths.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                            let (d0, d1) = (depth_of(0, p, q), depth_of(last, p, q));
                            let [lo, hi] = l.get(p, q);
                            // the last kept and the next sample in walking order (depth grows along it)
                            let (kept, next) = if d1 >= d0 {
                                (
                                    (lo <= hi).then_some(hi as usize),
                                    if lo > hi { Some(0) } else { (hi < last as u32).then(|| hi as usize + 1) },
                                )
                            } else {
                                ((lo <= hi).then_some(lo as usize), if lo > hi { Some(last) } else { (lo > 0).then(|| lo as usize - 1) })
                            };
                            let ctx = format!("{projection:?} {size:?} {rot}: pixel ({p}, {q}) limits [{lo}, {hi}], plane {dmin}..{dmax}");
                            if let Some(k) = kept {
                                assert!(depth_of(k, p, q) < dmax, "{ctx}: slice {k} kept at {}", depth_of(k, p, q));
                            }
                            if let Some(k) = next {
                                // (the footprint box above is one pixel wider than the gather's)
                                assert!(depth_of(k, p, q) >= dmin, "{ctx}: slice {k} cut at {}", depth_of(k, p, q));
                            }
                            checked += 1;
                        }
                    }
                    assert!(checked * 10 > plan.grid.pixels(), "{projection:?} {size:?}: {checked} pixels on the plane");
                }
            }
        }
    }

    /// A needle through the sphere phantom, in both projections, on the
    /// binary rotator's iso preview: the visible surface (the nearer of the
    /// volume's limited iso depth and the needle's) is the nearer of the
    /// analytic sphere and the analytic cylinder within half a voxel, at the
    /// pixels where the unlimited iso depth itself is that accurate, away from
    /// the needle's outline (where the intermediate image's coarser limits cut
    /// the volume within a footprint of the edge), also where the two
    /// surfaces are less than a slice apart: the rays keep the crossing
    /// slice ([`GeometryLimits::with_iso_crossing`]) and the visible surface
    /// is the depth test of [`composite_iso_over_geometry`] (where the needle
    /// pierces the sphere, within a quarter voxel of each other, ¾ voxel: the
    /// warp's depth there is the mean of the neighbouring hits that survive).
    /// The depth test's hit depths from each plan's slice depths equal the
    /// eye depth of the volume's hit position ([`super::super::volume_hit`])
    /// at every output pixel, up to rounding: parallel, perspective, and a
    /// perspective frame split into pyramids (the eye close to the volume).
    #[test]
    fn inverse_warp_hit_depths_are_the_hits_eye_depths() {
        let dims = [40, 40, 40];
        let vol = sphere(dims).unwrap();
        let size = 96;
        let cam = Camera::new(rotate_eye(rotate_eye(NamedView::Anterior.rotation(), 1, 35.0), 0, 20.0), [size, size]);
        let mut split_seen = false;
        for projection in [Projection::Parallel, Projection::perspective(40.0, 2.0).unwrap(), Projection::perspective(90.0, 0.7).unwrap()] {
            let settings = Settings { method: Method::Binary, mode: Mode::Iso, threads: 1, ..Settings::default() };
            let tf = crate::classify::TransferFunction::threshold(SPHERE_ISO, [1.0; 3]);
            let mut r = Renderer::new(vol.clone(), &tf, settings).unwrap();
            r.set_iso(SPHERE_ISO).unwrap();
            r.set_projection(projection).unwrap();
            r.set_keep_depths(true);
            let mut img = Image::new(size, size);
            r.render(&cam, &mut img).unwrap();
            split_seen |= r.last_plans().len() > 1;
            let proj = Projector::new(&cam, &projection, dims, [1.0; 3]).unwrap();
            let hits = crate::geometry::hit::HitDepths::new(&r, &proj);
            let mut some = 0;
            for y in 0..size {
                for x in 0..size {
                    let (u, v) = (x as f64, y as f64);
                    let want = crate::geometry::volume_hit(&r, u, v).map(|at| -proj.eye_space(at).z);
                    let got = hits.at(u, v);
                    match (want, got) {
                        (None, None) => {}
                        (Some(a), Some(b)) => {
                            assert!((a - b).abs() <= 1e-9 * (1.0 + a.abs()), "{projection:?} ({x}, {y}): {a} against {b}");
                            some += 1;
                        }
                        _ => panic!("{projection:?} ({x}, {y}): {want:?} against {got:?}"),
                    }
                }
            }
            assert!(some > 300, "{projection:?}: only {some} hits");
        }
        assert!(split_seen, "no frame was split into pyramids");
    }

    /// Where no geometry falls in a pixel's footprint the volume is
    /// untouched, bit for bit. The final image of the scene is the needle's
    /// colour where its depth test hides the volume.
    #[test]
    fn inverse_warp_needle_through_the_sphere_is_the_nearer_surface() {
        let dims = [48, 48, 48];
        let vol = sphere(dims).unwrap();
        let (c, radius) = sphere_geometry(dims);
        let c = DVec3::from_array(c);
        let (na, nb, nr) = (c + DVec3::new(-30.0, -6.0, -4.0), c + DVec3::new(30.0, 8.0, 5.0), 3.5);
        let needle = Mesh::cylinder(na, nb, nr, 64).unwrap();
        let size = 128;
        let cam = Camera::new(rotate_eye(rotate_eye(NamedView::Anterior.rotation(), 1, 25.0), 0, 15.0), [size, size]);
        for projection in [Projection::Parallel, Projection::perspective(40.0, 2.0).unwrap()] {
            let settings = Settings { method: Method::Binary, mode: Mode::Iso, threads: 1, ..Settings::default() };
            let tf = crate::classify::TransferFunction::threshold(SPHERE_ISO, [1.0; 3]);
            let mut r = Renderer::new(vol.clone(), &tf, settings).unwrap();
            r.set_iso(SPHERE_ISO).unwrap();
            r.set_projection(projection).unwrap();
            let proj = Projector::new(&cam, &projection, dims, [1.0; 3]).unwrap();
            let mut geo = GeometryImage::new(size, size);
            rasterize(&needle, &Material::default(), Cull::Back, &proj, &mut geo).unwrap();
            let mut img = Image::new(size, size);
            r.render(&cam, &mut img).unwrap();
            let plain = fast_path_depth(&r, &cam).unwrap();
            r.set_limiter(Some(Arc::new(GeometryLimits::new(proj, &geo).with_iso_crossing(true))));
            r.render(&cam, &mut img).unwrap();
            let vdepth = fast_path_depth(&r, &cam).unwrap();
            let rays = Rays::with_projection(&cam, &projection, dims, [1.0; 3]).unwrap();
            let mut fin = img.clone();
            let gl = GeometryLimits::new(proj, &geo).with_iso_crossing(true);
            composite_iso_over_geometry(&mut fin, &geo, &r, &gl);
            for (i, (&vd, &gd)) in vdepth.iter().zip(&geo.depth).enumerate() {
                if gd.is_finite() && vd >= gd {
                    assert_eq!(fin.data[i], geo.color[i], "{projection:?}: pixel {i}: the needle hides the volume behind it");
                }
            }
            let (mut checked, mut needle_px) = (0, 0);
            for y in 0..size {
                for x in 0..size {
                    let i = y * size + x;
                    // away from the needle's outline: all 5×5 neighbours agree on coverage
                    let covered = |x: i64, y: i64| {
                        geo.depth[(y.clamp(0, size as i64 - 1) as usize) * size + x.clamp(0, size as i64 - 1) as usize].is_finite()
                    };
                    let here = covered(x as i64, y as i64);
                    let near = (-2..=2).any(|dy| (-2..=2).any(|dx| covered(x as i64 + dx, y as i64 + dy)));
                    if !near {
                        // no geometry within the footprint: the volume is untouched
                        assert!(vdepth[i] == plain[i] || (vdepth[i].is_nan() && plain[i].is_nan()), "({x}, {y}) changed");
                    }
                    if (-2..=2).any(|dy| (-2..=2).any(|dx| covered(x as i64 + dx, y as i64 + dy) != here)) {
                        continue;
                    }
                    let (o, d) = rays.ray(x as f64, y as f64);
                    let oc = o - c;
                    let (a, b, cc) = (d.dot(d), oc.dot(d), oc.dot(oc) - radius * radius);
                    let ts = if b * b - a * cc >= 0.0 { Some((-b - (b * b - a * cc).sqrt()) / a) } else { None };
                    let tn = cylinder_hit(o, d, na, nb, nr, f64::NEG_INFINITY);
                    // the volume path's own error (its silhouettes) is not the geometry's: check the
                    // pixels where the unlimited iso depth meets the analytic sphere within half a voxel
                    let sphere_depth = ts.map(|t| rays.depth_of(o + t * d));
                    let own_ok = match (sphere_depth, plain[i].is_nan()) {
                        (Some(s), false) => (plain[i] - s).abs() <= 0.5,
                        (None, true) => true,
                        _ => false,
                    };
                    if !own_ok {
                        continue;
                    }
                    let truth = [ts, tn].into_iter().flatten().map(|t| rays.depth_of(o + t * d)).fold(f64::INFINITY, f64::min);
                    let seen = if vdepth[i].is_nan() { geo.depth[i] } else { vdepth[i].min(geo.depth[i]) };
                    if truth.is_infinite() {
                        assert!(seen.is_infinite(), "{projection:?} ({x}, {y}): {seen} where nothing is");
                        continue;
                    }
                    checked += 1;
                    needle_px += here as usize;
                    // where the needle pierces the sphere (surfaces within a quarter voxel) the
                    // output depth is the warp's mean over the neighbouring hits that survive the
                    // cut, which can lean toward the nearer ones: there within three quarters
                    let pierce = matches!((sphere_depth, tn.map(|t| rays.depth_of(o + t * d))), (Some(a), Some(b)) if (a - b).abs() < 0.25);
                    let tol = if pierce { 0.75 } else { 0.5 };
                    assert!(
                        (seen - truth).abs() <= tol,
                        "{projection:?} ({x}, {y}): seen {seen} (volume {}, needle {}), truth {truth} (sphere {:?}, needle {:?})",
                        vdepth[i],
                        geo.depth[i],
                        ts.map(|t| rays.depth_of(o + t * d)),
                        tn.map(|t| rays.depth_of(o + t * d))
                    );
                }
            }
            assert!(checked > 1000 && needle_px > 100, "{projection:?}: {checked} pixels checked, {needle_px} on the needle");
        }
    }

    /// The needle through the sphere phantom on the paths and modes without
    /// an iso depth (the RLE path in iso and blend mode, the binary rotator
    /// in blend mode; an opaque step at the iso value with early ray
    /// termination, so the visible surface is defined), both projections, by
    /// colour: away from the needle's outline and from the sphere's
    /// silhouette, where the needle is the nearer surface by more than 2.5
    /// voxels (or the ray misses the sphere) the final image is the needle's
    /// colour within 10⁻⁵ (the volume composites nothing in front of it); where the
    /// sphere is nearer by more than 2.5 voxels (or the ray misses the
    /// needle) the volume is the plain render's pixel, bit for bit. Within 2.5 voxels the per-slice cut decides (the paper's
    /// behaviour: samples are a slice apart along the ray, up to √3 voxels,
    /// the cut is at the footprint's nearest depth, and the warp mixes the
    /// neighbouring rays; measured: the first wrong pixels at 2.0–2.2).
    #[test]
    fn inverse_warp_needle_through_the_sphere_by_colour_rle_and_blend() {
        let dims = [48, 48, 48];
        let vol = sphere(dims).unwrap();
        let (c, radius) = sphere_geometry(dims);
        let c = DVec3::from_array(c);
        let (na, nb, nr) = (c + DVec3::new(-30.0, -6.0, -4.0), c + DVec3::new(30.0, 8.0, 5.0), 3.5);
        let needle = Mesh::cylinder(na, nb, nr, 64).unwrap();
        let size = 128;
        let cam = Camera::new(rotate_eye(rotate_eye(NamedView::Anterior.rotation(), 1, 25.0), 0, 15.0), [size, size]);
        let material = Material { color: [0.1, 0.9, 0.2], ..Material::default() };
        for projection in [Projection::Parallel, Projection::perspective(40.0, 2.0).unwrap()] {
            let proj = Projector::new(&cam, &projection, dims, [1.0; 3]).unwrap();
            let mut geo = GeometryImage::new(size, size);
            rasterize(&needle, &material, Cull::Back, &proj, &mut geo).unwrap();
            let rays = Rays::with_projection(&cam, &projection, dims, [1.0; 3]).unwrap();
            for (method, mode) in [(Method::Rle, Mode::Iso), (Method::Rle, Mode::Blend), (Method::Binary, Mode::Blend)] {
                let settings = Settings { method, mode, threads: 1, ..Settings::default() };
                let tf = crate::classify::TransferFunction::threshold(SPHERE_ISO, [1.0, 0.8, 0.6]);
                let mut r = Renderer::new(vol.clone(), &tf, settings).unwrap();
                r.set_iso(SPHERE_ISO).unwrap();
                r.set_projection(projection).unwrap();
                let mut plain = Image::new(size, size);
                r.render(&cam, &mut plain).unwrap();
                r.set_limiter(Some(Arc::new(GeometryLimits::new(proj, &geo))));
                let mut img = Image::new(size, size);
                r.render(&cam, &mut img).unwrap();
                let vol_img = img.clone();
                composite_over_geometry(&mut img, &geo);
                let ctx = format!("{projection:?} {method:?} {mode:?}");
                let near = |a: [f32; 4], b: [f32; 4]| a.iter().zip(&b).all(|(a, b)| (a - b).abs() <= 1e-5);
                let (mut needle_px, mut sphere_px) = (0, 0);
                for y in 0..size {
                    for x in 0..size {
                        let i = y * size + x;
                        let covered = |x: i64, y: i64| {
                            geo.depth[(y.clamp(0, size as i64 - 1) as usize) * size + x.clamp(0, size as i64 - 1) as usize].is_finite()
                        };
                        let here = covered(x as i64, y as i64);
                        if (-2..=2).any(|dy| (-2..=2).any(|dx| covered(x as i64 + dx, y as i64 + dy) != here)) {
                            continue;
                        }
                        let (o, d) = rays.ray(x as f64, y as f64);
                        // away from the sphere's silhouette: the ray passes a voxel inside or outside it
                        let oc = o - c;
                        let dn = d.normalize();
                        let miss = (oc - dn * oc.dot(dn)).length() - radius;
                        if miss.abs() < 1.5 {
                            continue;
                        }
                        let (a, b, cc) = (d.dot(d), oc.dot(d), oc.dot(oc) - radius * radius);
                        let ts = (miss < 0.0).then(|| (-b - (b * b - a * cc).sqrt()) / a);
                        let sphere_depth = ts.map(|t| rays.depth_of(o + t * d));
                        let needle_depth = cylinder_hit(o, d, na, nb, nr, f64::NEG_INFINITY).map(|t| rays.depth_of(o + t * d));
                        match (sphere_depth, needle_depth) {
                            (s, Some(n)) if s.is_none_or(|s| s > n + 2.5) => {
                                needle_px += 1;
                                assert!(
                                    near(img.data[i], geo.color[i]),
                                    "{ctx} ({x}, {y}): {:?}, the needle {:?}",
                                    img.data[i],
                                    geo.color[i]
                                );
                            }
                            (Some(s), n) if n.is_none_or(|n| n > s + 2.5) => {
                                sphere_px += 1;
                                assert!(
                                    vol_img.data[i] == plain.data[i],
                                    "{ctx} ({x}, {y}): {:?}, the plain render {:?}",
                                    vol_img.data[i],
                                    plain.data[i]
                                );
                            }
                            _ => {}
                        }
                    }
                }
                assert!(needle_px > 30 && sphere_px > 500, "{ctx}: {needle_px} needle and {sphere_px} sphere pixels checked");
            }
        }
    }

    /// The inverse warp's cost, one thread, in-process (no pool wake-ups):
    /// `cargo test --release --lib inverse_warp_cost -- --ignored --nocapture`.
    /// The gather over the rectangle the geometry's bounds reach (the design
    /// before the tiles) against the tiled one, on the CLI's needles (/tmp/iw
    /// in the branch's report) at 512²: the head phantom's 128×128×113 and
    /// the chest CT's 512×512×48 at 0.57×0.57×5 mm, parallel and perspective.
    #[test]
    #[ignore]
    fn inverse_warp_cost_of_the_gather_and_the_tiles() {
        use crate::view::Factorization;
        use crate::view::perspective::PerspectiveView;
        let cases = [
            ("head", [128usize, 128, 113], [1.0f32; 3], DVec3::new(10.0, 30.0, 20.0), DVec3::new(118.0, 100.0, 95.0), 2.0),
            ("chest", [512, 512, 48], [0.57, 0.57, 5.0], DVec3::new(40.0, 100.0, 5.0), DVec3::new(470.0, 400.0, 42.0), 6.0),
        ];
        for (name, dims, sp, a, b, radius) in cases {
            let needle = Mesh::cylinder(a, b, radius, 32).unwrap();
            let cam = Camera::new(NamedView::Anterior.rotation(), [512, 512]);
            for projection in [Projection::Parallel, Projection::perspective(40.0, 2.0).unwrap()] {
                // (IW_ONLY=text: only the cases whose "name projection" holds it)
                if std::env::var("IW_ONLY").is_ok_and(|o| !format!("{name} {projection:?}").contains(&o)) {
                    continue;
                }
                let plan = match projection.resolve(&cam, dims, sp).unwrap() {
                    None => FramePlan::parallel(&Factorization::new(&cam, dims, sp).unwrap(), sp),
                    Some((pc, d)) => {
                        let f = Factorization::new(&pc, dims, sp).unwrap();
                        let Ok(pv) = PerspectiveView::new(&pc, d, dims, sp) else { continue };
                        FramePlan::perspective(&pv, &f, sp, 0.5)
                    }
                };
                let proj = Projector::new(&cam, &projection, dims, sp).unwrap();
                let mut geo = GeometryImage::new(512, 512);
                rasterize(&needle, &Material::default(), Cull::None, &proj, &mut geo).unwrap();
                // (IW_REPS=N IW_ONLY_TILES=1: more rounds of the tiled limiter alone, for a profiler)
                let n = std::env::var("IW_REPS").ok().and_then(|s| s.parse().ok()).unwrap_or(20);
                let only_tiles = std::env::var_os("IW_ONLY_TILES").is_some();
                let (mut t_new, mut t_gather, mut t_make, mut t_marks) = (vec![], vec![], vec![], vec![]);
                let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
                let mut l = RayLimits::open(plan.grid.size, plan.slices());
                for _ in 0..n {
                    let t = std::time::Instant::now();
                    let gl = GeometryLimits::new(proj, &geo);
                    t_make.push(t.elapsed().as_secs_f64() * 1e3);
                    // the tiles: marks, then the marked pixels (the limiter itself, one thread)
                    l.reset(plan.grid.size, plan.slices());
                    let t = std::time::Instant::now();
                    one.install(|| gl.limit(&plan, &mut l));
                    t_new.push(t.elapsed().as_secs_f64() * 1e3);
                    let t = std::time::Instant::now();
                    let _ = std::hint::black_box(gl.marks(&plan));
                    t_marks.push(t.elapsed().as_secs_f64() * 1e3);
                    // the gather over the bounds' rectangle
                    if only_tiles {
                        continue;
                    }
                    l.reset(plan.grid.size, plan.slices());
                    let t = std::time::Instant::now();
                    let [p0, q0, p1, q1] = gl.reach(&plan).unwrap();
                    let g = Gather::new(&plan, &gl);
                    for q in q0..=q1 {
                        let r = g.row(q);
                        for p in p0..=p1 {
                            let mut x = l.get(p, q);
                            gl.limit_at(&g, &r, p, &mut x);
                            l.set(p, q, x);
                        }
                    }
                    t_gather.push(t.elapsed().as_secs_f64() * 1e3);
                }
                let med = |v: &mut Vec<f64>| {
                    v.sort_by(f64::total_cmp);
                    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
                };
                let (tn, tg, tm, tk) = (med(&mut t_new), med(&mut t_gather), med(&mut t_make), med(&mut t_marks));
                let marked = gl_marked(&GeometryLimits::new(proj, &geo), &plan);
                let open = RayLimits::open(plan.grid.size, plan.slices());
                let mut cut = RayLimits::open(plan.grid.size, plan.slices());
                GeometryLimits::new(proj, &geo).limit(&plan, &mut cut);
                let changed = (0..plan.grid.size[1])
                    .flat_map(|q| (0..plan.grid.size[0]).map(move |p| (p, q)))
                    .filter(|&(p, q)| cut.get(p, q) != open.get(p, q))
                    .count();
                println!("{name} {projection:?}: {changed} of {marked} marked pixels limited");
                println!(
                    "{name} {projection:?}: grid {:?}, covered {:.1} %, marked {marked}; GeometryLimits::new {tm:.3} ms; rectangle gather {tg:.3} ms ({:.2} ns/output px); the limiter (one thread) {tn:.3} ms ({:.2} ns/output px, {:.0} ns/marked px), of which marks {tk:.3} ms",
                    plan.grid.size,
                    geo.coverage() * 100.0,
                    tg * 1e6 / (512.0 * 512.0),
                    tn * 1e6 / (512.0 * 512.0),
                    (tn - tk) * 1e6 / marked as f64
                );
            }
        }
    }

    fn gl_marked(gl: &GeometryLimits, plan: &FramePlan) -> usize {
        gl.marks(plan).count()
    }
}
