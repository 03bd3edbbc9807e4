//! The frame plan: everything a traversal reads about the geometry of one frame.
//!
//! A projection (today the parallel one, [`FramePlan::set_parallel`]) is a
//! *producer* of plans; every traversal — the binary rays, the RLE slices and
//! both brute-force references — and the warp read the plan and nothing else
//! about the view. A plan holds:
//!
//! - **the view** ([`FramePlan::view`]): the factorization it was made from
//!   (principal axis, permutation, slice order, shading directions);
//! - **per-slice sample maps** ([`FramePlan::maps`]): for every slice `k`, the
//!   map from intermediate pixel `(p, q)` to the in-slice sample position. A
//!   parallel view only translates ([`MapKind::Translate`], the fast path: one
//!   integer offset and one in-cell weight per axis, [`SliceMap`]); the exact
//!   translations sit in [`FramePlan::shear`], which is also what the binary
//!   rotator shears its mask to, so the mask and the rays use the same numbers;
//! - **the intermediate grid** ([`Grid`]): size, padding and pixel pitch;
//! - **the warp** ([`Warp`]): a 3×3 homogeneous map from sheared coordinates to
//!   output pixels and its inverse (affine today);
//! - **the slice range** ([`FramePlan::k_range`]) composited front to back;
//! - **per-pixel ray limits** ([`RayLimits`], optional): each intermediate
//!   pixel composites only slices `k0 ..= k1` of its own (clip regions and
//!   geometry write them);
//! - **the opacity correction** ([`FramePlan::opacity_ratio`]): the ratio of the
//!   real sample spacing to the spacing opacities are defined at, uniform over
//!   the frame for a parallel view.

use glam::{DMat3, DVec3};

use crate::view::opacity::{OpacityTable, RayRow};
use crate::view::perspective::PerspectiveView;
use crate::view::shear::ShearState;
use crate::view::{Factorization, Warp};

/// How the slices' sample maps are built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MapKind {
    /// Every slice is the intermediate grid translated: `(i, j) = (p − pad, q − pad) + trans[k]`.
    Translate,
    /// Every slice is the intermediate grid scaled and translated (a
    /// perspective view, [`FramePlan::set_perspective`]):
    /// `(i, j) = σ_k · (a, b) + τ_k` for the sheared point `(a, b)` of pixel
    /// `(p, q)`, with `σ_k ≥ 1` ([`ScaledMap`], [`FramePlan::scaled`]).
    ScaleTranslate,
}

/// One slice's map under [`MapKind::ScaleTranslate`]: the ray of sheared point
/// `(a, b)` meets slice `k` at in-slice position `scale · (a, b) + trans`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ScaledMap {
    pub scale: f64,
    pub trans: [f64; 2],
}

/// What a perspective plan keeps to give each ray its own sample spacing.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PerspectiveRays {
    /// The eye's foot `(E_i, E_j)` on the slices (voxel units, in the plan's
    /// sheared coordinates), and `κ`: the ray of sheared point `(a, b)` moves
    /// by `κ · ((a, b) − E)` per slice.
    pub foot: [f64; 2],
    /// The plan's sheared point `(a, b)` is the view's base-plane point
    /// `(a, b) + shift` ([`PerspectiveView::sheared_to_voxel`]): see
    /// [`FramePlan::set_perspective`].
    pub shift: [f64; 2],
    pub kappa: f64,
    /// Voxel spacing along `(i, j, k)` over the spacing opacities are defined
    /// at (the smallest voxel spacing).
    pub rel_spacing: [f64; 3],
}

impl PerspectiveRays {
    /// The real sample spacing (one slice along the ray) of the ray through
    /// sheared point `(a, b)`, over the spacing opacities are defined at.
    pub fn ratio(&self, a: f64, b: f64) -> f64 {
        let [si, sj, sk] = self.rel_spacing;
        let (di, dj) = (self.kappa * (a - self.foot[0]) * si, self.kappa * (b - self.foot[1]) * sj);
        (di * di + dj * dj + sk * sk).sqrt()
    }
}

/// One slice's translation map, as a ray reads it in one 16-byte load: the
/// integer offset `floor(trans)` and the in-cell weight `trans − floor(trans)`
/// along `i` and `j`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SliceMap {
    pub floor: [i32; 2],
    pub weight: [f32; 2],
}

/// The intermediate image's grid. Pixel `(p, q)` is the sheared point
/// `(a, b) = ((p − pad) · pitch₀, (q − pad) · pitch₁)`: one pixel per voxel
/// (`pitch` `[1, 1]`) with `pad` pixels of margin on every side for the
/// shear, or resampled ([`FramePlan::set_pitch`]: the adaptive image size,
/// one pitch for both axes; matched sampling, a pitch per axis).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Grid {
    /// `[width, height]` in pixels.
    pub size: [usize; 2],
    /// Margin, in pixels, between the grid's edge and sheared `(0, 0)`.
    pub pad: usize,
    /// Voxels per intermediate pixel along each axis.
    pub pitch: [f64; 2],
}

impl Grid {
    /// The grid of a volume of `cells` cells per slice and `nk` slices under any
    /// parallel view: the shear moves a slice by at most `(nk − 1)/2` voxels from
    /// the centre (plus a rounding margin).
    pub fn parallel(cells: [usize; 2], nk: usize) -> Grid {
        let pad = nk.saturating_sub(1).div_ceil(2) + 2;
        Grid { size: [cells[0] + 2 * pad, cells[1] + 2 * pad], pad, pitch: [1.0; 2] }
    }

    /// Pixels.
    pub fn pixels(&self) -> usize {
        self.size[0] * self.size[1]
    }
}

/// Per-pixel ray limits over the intermediate grid: pixel `(p, q)` composites
/// only slices `k0 ..= k1` (slice indices, `k0 > k1` for none), whichever
/// order the view walks them in, less an optional *hole* `h0 ..= h1` per
/// pixel (a region whose outside is kept: [`crate::view::clip::ClipRegion`]
/// with [`crate::view::clip::Keep::Outside`]): the ray composites
/// `k0 ..= h0 − 1`, then `h1 + 1 ..= k1`.
///
/// Holes exist only once a limiter asks for them ([`RayLimits::holes_rows_mut`]);
/// a plan without them ([`RayLimits::has_holes`] false) costs the traversals
/// nothing. After the limiter, [`RayLimits::normalize`] (run by
/// [`FramePlan::apply_limiter`]) leaves every hole strictly inside its
/// interval (`k0 < h0 ≤ h1 < k1`) or none (`[1, 0]`): a hole touching an
/// end of the interval narrows the interval instead, and when no pixel has a
/// hole left the holes are dropped.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RayLimits {
    width: usize,
    limits: Vec<[u32; 2]>,
    /// Per pixel, the hole `[h0, h1]` (`h0 > h1`: none); empty: no pixel has one.
    holes: Vec<[u32; 2]>,
}

/// No hole (also: an empty interval).
pub const NO_HOLE: [u32; 2] = [1, 0];

/// Removes the slices `cut = [c0, c1]` (signed; `c0 > c1`: nothing) from a
/// ray's kept set `[k0, k1] \ hole`, as one interval and one hole: where the
/// cut meets an end of the interval the interval narrows, strictly inside it
/// becomes (or joins, when they overlap or touch) the hole. Two disjoint holes
/// cannot be held: the span between them is removed too (a limiter set with
/// more than one outside region is refused before it gets here:
/// [`Limiter::holes`]). Returns the new interval and hole.
pub fn cut_ray(l: [u32; 2], hole: [u32; 2], cut: [i64; 2]) -> ([u32; 2], [u32; 2]) {
    let (k0, k1) = (l[0] as i64, l[1] as i64);
    if k0 > k1 {
        return (NO_HOLE, NO_HOLE);
    }
    let (c0, c1) = (cut[0].max(k0), cut[1].min(k1));
    if c0 > c1 {
        return normalized(l, hole);
    }
    let (h0, h1) = (hole[0] as i64, hole[1] as i64);
    let (n0, n1) = if h0 > h1 { (c0, c1) } else { (c0.min(h0), c1.max(h1)) };
    normalized(l, [n0 as u32, n1 as u32])
}

/// `l` and `hole` with the hole clipped to the interval and moved into it
/// where it touches an end (see [`RayLimits`]).
#[inline]
pub fn normalized(l: [u32; 2], hole: [u32; 2]) -> ([u32; 2], [u32; 2]) {
    let (mut k0, mut k1) = (l[0] as i64, l[1] as i64);
    if k0 > k1 {
        return (NO_HOLE, NO_HOLE);
    }
    let (h0, h1) = ((hole[0] as i64).max(k0), (hole[1] as i64).min(k1));
    if h0 > h1 {
        return (l, NO_HOLE);
    }
    if h0 == k0 {
        k0 = h1 + 1;
    } else if h1 == k1 {
        k1 = h0 - 1;
    } else {
        return (l, [h0 as u32, h1 as u32]);
    }
    if k0 > k1 { (NO_HOLE, NO_HOLE) } else { ([k0 as u32, k1 as u32], NO_HOLE) }
}

impl RayLimits {
    /// Limits for a grid, every pixel open over `0 ..= nk − 1`.
    pub fn open(grid: [usize; 2], nk: usize) -> Self {
        RayLimits { width: grid[0], limits: vec![[0, nk.saturating_sub(1) as u32]; grid[0] * grid[1]], holes: vec![] }
    }

    /// Whether some pixel may have a hole (see [`RayLimits`]).
    #[inline(always)]
    pub fn has_holes(&self) -> bool {
        !self.holes.is_empty()
    }

    /// The hole `[h0, h1]` of pixel `(p, q)` ([`NO_HOLE`] for none).
    #[inline(always)]
    pub fn hole(&self, p: usize, q: usize) -> [u32; 2] {
        if self.holes.is_empty() { NO_HOLE } else { self.holes[q * self.width + p] }
    }

    /// The holes of row `q`, by pixel (empty when there are none).
    #[inline(always)]
    pub fn hole_row(&self, q: usize) -> &[[u32; 2]] {
        if self.holes.is_empty() { &[] } else { &self.holes[q * self.width..(q + 1) * self.width] }
    }

    /// Whether pixel `(p, q)` composites slice `k`: in its interval, not in its hole.
    #[inline(always)]
    pub fn keeps(&self, p: usize, q: usize, k: usize) -> bool {
        let [k0, k1] = self.get(p, q);
        let [h0, h1] = self.hole(p, q);
        (k0 as usize) <= k && k <= k1 as usize && !((h0 as usize) <= k && k <= h1 as usize)
    }

    /// The rows of intervals and holes, mutable, as a parallel iterator (item
    /// `q` is row `q`), for a [`Limiter`] that cuts holes (see [`cut_ray`]):
    /// makes the holes (none yet) on first use.
    pub fn holes_rows_mut(&mut self) -> impl rayon::iter::IndexedParallelIterator<Item = (&mut [[u32; 2]], &mut [[u32; 2]])> {
        use rayon::prelude::*;
        if self.holes.is_empty() {
            self.holes.resize(self.limits.len(), NO_HOLE);
        }
        let w = self.width.max(1);
        self.limits.par_chunks_mut(w).zip(self.holes.par_chunks_mut(w))
    }

    /// Leaves every hole strictly inside its interval or none (see
    /// [`RayLimits`]), and drops the holes when no pixel has one.
    pub fn normalize(&mut self) {
        if self.holes.is_empty() {
            return;
        }
        let mut any = false;
        for (l, h) in self.limits.iter_mut().zip(self.holes.iter_mut()) {
            (*l, *h) = normalized(*l, *h);
            any |= h[0] <= h[1];
        }
        if !any {
            self.holes.clear();
        }
    }

    /// The limits `[k0, k1]` of pixel `(p, q)`.
    #[inline(always)]
    pub fn get(&self, p: usize, q: usize) -> [u32; 2] {
        self.limits[q * self.width + p]
    }

    /// Sets the limits of pixel `(p, q)`.
    pub fn set(&mut self, p: usize, q: usize, k: [u32; 2]) {
        self.limits[q * self.width + p] = k;
    }

    /// The limits of row `q`, by pixel.
    #[inline(always)]
    pub fn row(&self, q: usize) -> &[[u32; 2]] {
        &self.limits[q * self.width..(q + 1) * self.width]
    }

    /// The limits of row `q`, by pixel, to change.
    #[inline(always)]
    pub fn row_mut(&mut self, q: usize) -> &mut [[u32; 2]] {
        &mut self.limits[q * self.width..(q + 1) * self.width]
    }

    /// The rows, mutable, as a parallel iterator (item `q` is row `q`), for a
    /// [`Limiter`] that writes rows on several threads.
    pub fn par_rows_mut(&mut self) -> rayon::slice::ChunksMut<'_, [u32; 2]> {
        use rayon::prelude::*;
        self.limits.par_chunks_mut(self.width.max(1))
    }

    /// The grid width.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Reopens every pixel of a grid over `0 ..= nk − 1` (no holes), reusing the allocation.
    pub fn reset(&mut self, grid: [usize; 2], nk: usize) {
        self.width = grid[0];
        self.holes.clear();
        self.limits.clear();
        self.limits.resize(grid[0] * grid[1], [0, nk.saturating_sub(1) as u32]);
    }
}

/// A producer of per-pixel ray limits — a clip region, geometry in the volume —
/// asked once per frame, after the projection has made the plan: it narrows
/// `limits` (every pixel open when it is called) for the plan's grid and slices.
pub trait Limiter: Send + Sync {
    fn limit(&self, plan: &FramePlan, limits: &mut RayLimits);
    /// How many holes this limiter may cut in one ray (an outside region:
    /// one); a ray holds one ([`RayLimits`]), so the renderer refuses a
    /// limiter set with more.
    fn holes(&self) -> usize {
        0
    }
    /// Whether this limiter's work on `plan` is worth the renderer's thread
    /// pool (the default); one that answers no is run on the calling thread
    /// (a needle's few thousand pixels cost less than waking the pool), and
    /// must then not use rayon itself.
    fn parallel(&self, _plan: &FramePlan) -> bool {
        true
    }
}

impl<F: Fn(&FramePlan, &mut RayLimits) + Send + Sync> Limiter for F {
    fn limit(&self, plan: &FramePlan, limits: &mut RayLimits) {
        self(plan, limits)
    }
}

/// The most samples per voxel along one axis Deluxe M takes
/// ([`FramePlan::matched_samples`]): past a 16× magnification the warp
/// magnifies the rest.
pub const MAX_MATCHED: usize = 16;

/// The widest box footprint, in voxels: a slice minified more than this is
/// filtered at this width ([`FramePlan::footprint`]).
pub const MAX_FOOTPRINT: f64 = 4.0;
/// Pixels further apart than this many voxels of a slice are box-filtered
/// ([`FramePlan::footprint`]); up to it, bilinearly sampled.
pub const BOX_FROM: f64 = 2.0;

/// `floor(s)` of a finite `s` well inside the i64 range: a truncation and a
/// correction, not a call to `floor` (the x86-64 baseline has no instruction
/// for it). The one floor of every scaled map ([`FramePlan::cell_of`],
/// [`FramePlan::pixels_of_cells`]).
#[inline(always)]
pub(crate) fn floor_i64(s: f64) -> i64 {
    let c = s as i64;
    if (c as f64) > s { c - 1 } else { c }
}

/// Fractional bits of an [`AxisMap`]'s fixed-point positions.
const AXIS_FRAC: u32 = 36;

/// One slice's scaled map along one in-slice axis, over the grid
/// ([`FramePlan::axis_map`]): pixel `x` samples at
/// `scale · ((x − pad) · pitch) + trans`.
///
/// Held in fixed point, `2^−36` voxel units: `base + step · x`, with `step`
/// and `base` that formula's slope and intercept truncated once. So a pixel's
/// cell and weight cost an integer multiply, a shift and a mask (no float
/// floor per sample), they are exact functions of `x` (the traversals and
/// their brute force read the same numbers), and the position is within
/// `2^−36 · (|x| + 1)` of the formula (below 1e-6 voxels on a grid up to
/// 65 536 pixels wide).
#[derive(Clone, Copy, Debug)]
pub struct AxisMap {
    /// The position of pixel 0 and the step from one pixel to the next, in
    /// `2^−AXIS_FRAC` voxel units.
    base: i64,
    step: i64,
}

impl AxisMap {
    /// The map `scale · ((x − pad) · pitch) + trans` (scale and pitch > 0;
    /// held as its fixed-point slope and intercept alone).
    #[inline]
    pub fn new(scale: f64, trans: f64, pad: f64, pitch: f64) -> Self {
        let unit = (1u64 << AXIS_FRAC) as f64;
        // (truncated: a float-to-integer conversion, no call to `round`)
        let (step, base) = ((scale * pitch * unit) as i64, ((trans - scale * pad * pitch) * unit) as i64);
        AxisMap { base, step }
    }

    /// The cell and in-cell weight of pixel `x` (which may lie off the grid).
    #[inline(always)]
    pub fn cell(&self, x: i64) -> (i64, f32) {
        let s = self.base.wrapping_add(self.step.wrapping_mul(x));
        // the weight from the fraction's top 24 bits: exact in f32, below 1
        let w = ((s as u64 & ((1u64 << AXIS_FRAC) - 1)) >> (AXIS_FRAC - 24)) as f32 * (1.0 / (1u32 << 24) as f32);
        (s >> AXIS_FRAC, w)
    }

    /// The pixels `[x0, x1]` whose cells ([`AxisMap::cell`]) are in
    /// `c0 ..= c1` (`x0 > x1`: none): the inverse map's estimate, then exact
    /// by the map itself (monotone: scale and pitch > 0).
    pub fn pixels_of_cells(&self, c0: i64, c1: i64) -> [i64; 2] {
        let cell = |x: i64| self.cell(x).0;
        let unit = (1u64 << AXIS_FRAC) as f64;
        let inv = |c: i64| floor_i64((c as f64 * unit - self.base as f64) / self.step as f64);
        let mut x0 = inv(c0);
        while cell(x0) >= c0 {
            x0 -= 1;
        }
        while cell(x0) < c0 {
            x0 += 1;
        }
        let mut x1 = inv(c1 + 1);
        while cell(x1) > c1 {
            x1 -= 1;
        }
        while cell(x1 + 1) <= c1 {
            x1 += 1;
        }
        [x0, x1]
    }
}

/// The map of Deluxe I's intermediate samples along one in-slice axis
/// ([`FramePlan::mid_map`]).
#[derive(Clone, Copy, Debug)]
pub enum MidMap {
    /// A translated plan: pixel `x` samples cell `x + off` at `weight` (one
    /// pixel per voxel; every pixel the same weight, as a slice's
    /// [`SliceMap`]).
    Shift { off: i64, weight: f32 },
    /// A scaled plan (or another pitch): the mean of the two slices' maps.
    Map(AxisMap),
}

impl MidMap {
    /// The cell and in-cell weight of pixel `x` (which may lie off the grid).
    #[inline(always)]
    pub fn cell(&self, x: i64) -> (i64, f32) {
        match *self {
            MidMap::Shift { off, weight } => (x + off, weight),
            MidMap::Map(m) => m.cell(x),
        }
    }

    /// The pixels `[x0, x1]` whose cells ([`MidMap::cell`]) are in `c0 ..= c1`.
    pub fn pixels_of_cells(&self, c0: i64, c1: i64) -> [i64; 2] {
        match *self {
            MidMap::Shift { off, .. } => [c0 - off, c1 - off],
            MidMap::Map(m) => m.pixels_of_cells(c0, c1),
        }
    }
}

/// The geometry of one frame, read by every traversal and the warp.
#[derive(Clone, Debug)]
pub struct FramePlan {
    /// The factorization this plan was made from.
    pub view: Factorization,
    /// How [`FramePlan::maps`] map pixels to slices.
    pub kind: MapKind,
    /// Per slice `k` (index order), its sample map.
    pub maps: Vec<SliceMap>,
    /// The exact per-slice translations and their integer parts.
    pub shear: ShearState,
    pub grid: Grid,
    pub warp: Warp,
    /// The slices composited, `[k0, k1]` in index order (front to back is
    /// `k0..=k1` when [`Factorization::ascending`], else reversed).
    pub k_range: [usize; 2],
    /// Optional per-pixel limits within `k_range`.
    pub limits: Option<RayLimits>,
    /// Optional per-pixel focus interval (focus+context): ray `(p, q)`'s
    /// sample in slice `k` is classified by the focus classification iff `k`
    /// lies in its interval `[f0, f1]` ([`FramePlan::in_focus`]), else by the
    /// frame's own. Written by [`FramePlan::apply_focus`].
    pub focus: Option<RayLimits>,
    /// Real sample spacing over the spacing opacities are defined at (the
    /// smallest voxel spacing): `α' = 1 − (1 − α)^ratio`. In a perspective
    /// plan each ray has its own spacing; this is the smallest of them (the
    /// classification tables are corrected to it) and
    /// [`FramePlan::opacity_exponent`] gives each pixel the rest.
    pub opacity_ratio: f32,
    /// Per slice, the scaled map ([`MapKind::ScaleTranslate`] only; empty for a
    /// parallel plan, whose [`FramePlan::maps`] are exact). In a perspective
    /// plan `maps[k]` is the split of `scaled[k].trans` alone.
    pub scaled: Vec<ScaledMap>,
    /// The perspective rays' geometry (None: a parallel plan).
    pub perspective: Option<PerspectiveRays>,
    /// Per intermediate pixel (row-major over the grid), the exponent that takes
    /// an opacity corrected to [`FramePlan::opacity_ratio`] to the pixel's own
    /// ray spacing: `α'' = 1 − (1 − α')^e`, `e ≥ 1`. Empty when every ray has the
    /// uniform ratio (parallel plans, and perspective plans in iso mode: see
    /// [`FramePlan::set_ray_opacity`]).
    exponents: Vec<f32>,
    /// Per intermediate pixel, its exponent's place in
    /// [`FramePlan::opacity_table`] (found once a frame, not per sample).
    ray_rows: Vec<RayRow>,
    /// What [`FramePlan::exponents`] were computed for (`None`: not computed),
    /// so asking again for the same grid and rays costs nothing.
    exponents_for: Option<(Grid, PerspectiveRays)>,
    /// Whether a perspective producer computes the exponents (the last
    /// [`FramePlan::set_ray_opacity`]: the renderer turns it off in iso mode).
    ray_opacity: bool,
    /// The correction [`FramePlan::correct_opacity`] applies with those
    /// exponents, covering the largest (kept across frames, grown as needed).
    opacity_table: OpacityTable,
    /// Whether a minified slice's pixels are box-filtered ([`FramePlan::footprint`]).
    box_footprint: bool,
    /// Shear-Warp Deluxe I: one intermediate sample between each pair of
    /// slices ([`FramePlan::set_intermediate`]).
    half_step: bool,
}

impl FramePlan {
    /// The plan of a parallel view `f` of a volume with voxel `spacing`.
    pub fn parallel(f: &Factorization, spacing: [f32; 3]) -> Self {
        let mut p = FramePlan {
            view: f.clone(),
            kind: MapKind::Translate,
            maps: vec![],
            shear: ShearState::identity(0),
            grid: Grid::default(),
            warp: Warp::default(),
            k_range: [0, 0],
            limits: None,
            focus: None,
            opacity_ratio: 1.0,
            scaled: vec![],
            perspective: None,
            exponents: vec![],
            ray_rows: vec![],
            exponents_for: None,
            ray_opacity: true,
            opacity_table: OpacityTable::default(),
            box_footprint: true,
            half_step: false,
        };
        p.set_parallel(f, spacing);
        p
    }

    /// The plan of perspective view `pv` (see [`FramePlan::set_perspective`]).
    pub fn perspective(pv: &PerspectiveView, f: &Factorization, spacing: [f32; 3], near: f64) -> Self {
        let mut p = FramePlan::parallel(f, spacing);
        p.set_perspective(pv, f, spacing, near);
        p
    }

    /// Overwrites this plan with that of parallel view `f`, reusing its arrays
    /// (no allocation per frame once they have grown). Clears any ray limits
    /// (see [`FramePlan::apply_limiter`]).
    pub fn set_parallel(&mut self, f: &Factorization, spacing: [f32; 3]) {
        self.view.clone_from(f);
        self.kind = MapKind::Translate;
        self.shear.set_view(f);
        let st = &self.shear;
        self.maps.clear();
        let weight = |a: usize, k: usize| (st.trans[a][k] - st.floor[a][k] as f64) as f32;
        self.maps
            .extend((0..st.slices()).map(|k| SliceMap { floor: [st.floor[0][k], st.floor[1][k]], weight: [weight(0, k), weight(1, k)] }));
        self.grid = Grid::parallel([f.n[0].saturating_sub(1), f.n[1].saturating_sub(1)], f.n[2]);
        let [[m00, m01], [m10, m11]] = f.warp_m;
        let (inv, it) = f.inverse_warp();
        self.warp = Warp {
            forward: DMat3::from_cols(DVec3::new(m00, m10, 0.0), DVec3::new(m01, m11, 0.0), DVec3::new(f.warp_t[0], f.warp_t[1], 1.0)),
            inverse: DMat3::from_cols(
                DVec3::new(inv[0][0], inv[1][0], 0.0),
                DVec3::new(inv[0][1], inv[1][1], 0.0),
                DVec3::new(it[0], it[1], 1.0),
            ),
        };
        self.k_range = [0, f.n[2].saturating_sub(1)];
        self.limits = None;
        self.focus = None;
        let min_sp = spacing.iter().fold(f32::MAX, |a, &b| a.min(b)) as f64;
        self.opacity_ratio = (f.sample_spacing / min_sp) as f32;
        self.scaled.clear();
        self.perspective = None;
        self.exponents.clear();
        self.ray_rows.clear();
        self.exponents_for = None;
    }

    /// Moves each slice's samples by its own in-slice offset `off(k)` (voxels
    /// along `(i, j)`): the exact translations, their integer parts and the
    /// maps together, so every traversal sees it. What a lattice whose slices
    /// are not stacked straight needs: the two sub-grids of a BCC grid, half a
    /// cell apart ([`crate::data::bcc::BccLattice::slice_offset`]). For a
    /// parallel plan (after [`FramePlan::set_parallel`], before
    /// [`FramePlan::set_pitch`], which keeps the offsets).
    pub fn offset_slices(&mut self, off: impl Fn(usize) -> [f64; 2]) {
        assert_eq!(self.kind, MapKind::Translate, "offset_slices needs a parallel plan");
        let st = &mut self.shear;
        for k in 0..st.slices() {
            for (a, o) in off(k).into_iter().enumerate() {
                let t = st.trans[a][k] + o;
                st.trans[a][k] = t;
                st.floor[a][k] = t.floor() as i32;
                self.maps[k].floor[a] = st.floor[a][k];
                self.maps[k].weight[a] = (t - st.floor[a][k] as f64) as f32;
            }
        }
        st.ends = [0, 1].map(|a| [st.trans[a].first().copied().unwrap_or(0.0), st.trans[a].last().copied().unwrap_or(0.0)]);
    }

    /// Makes this parallel plan (of a sub-volume, a *brick*, whose voxel
    /// `(0, 0, 0)` is voxel `origin` of a larger volume, along `(i, j, k)`)
    /// sample exactly where the larger volume's plan `global` (the same
    /// camera) samples: slice `k` of the brick takes the map of the larger
    /// volume's slice `k + origin[2]`, its integer part moved by the brick's
    /// in-slice origin and a whole number of pixels that keeps the brick's
    /// translations about its own centre (the range its sheared mask is
    /// padded for). So a brick's sample is the larger volume's sample at the
    /// same place, weight for weight. Returns that whole number: brick pixel
    /// `(p, q)` is the larger plan's pixel `(p, q) + offset`.
    pub fn place_in(&mut self, global: &Factorization, origin: [usize; 3]) -> [i64; 2] {
        assert_eq!(self.kind, MapKind::Translate, "place_in needs a parallel plan");
        let nk = self.slices();
        let kc = origin[2] + nk.saturating_sub(1) / 2;
        // the brick's translations: the larger volume's less whole voxels `m`
        // (its samples move by `origin` besides, through the pixel offset)
        let m: [i64; 2] = [0, 1].map(|a| global.trans(kc)[a].round() as i64);
        let st = &mut self.shear;
        for k in 0..nk {
            let t = global.trans(k + origin[2]);
            for a in 0..2 {
                let f = t[a].floor() as i32;
                let w = (t[a] - f as f64) as f32;
                st.floor[a][k] = f - m[a] as i32;
                st.trans[a][k] = t[a] - m[a] as f64;
                self.maps[k].floor[a] = st.floor[a][k];
                self.maps[k].weight[a] = w;
            }
        }
        st.ends = [0, 1].map(|a| [st.trans[a].first().copied().unwrap_or(0.0), st.trans[a].last().copied().unwrap_or(0.0)]);
        let gpad = Grid::parallel([global.n[0].saturating_sub(1), global.n[1].saturating_sub(1)], global.n[2]).pad as i64;
        // brick pixel p samples i_b = p − pad_b + t − m, the larger plan's pixel
        // p' samples i_b + origin = p' − pad_g + t
        [0, 1].map(|a| gpad - self.grid.pad as i64 - m[a] + origin[a] as i64)
    }

    /// Moves the plan's sheared coordinates by `d` voxels: the plan's
    /// sheared point `(a, b)` is its view's `(a − d_a, b − d_b)` (the warp and
    /// its inverse follow; the slices' maps are the caller's to shift, with
    /// [`FramePlan::offset_slices`]). The BCC grid's sheared grid meets
    /// sub-grid A's samples ([`crate::data::bcc::BccLattice::SHEARED_SHIFT`]).
    pub fn shift_sheared(&mut self, d: [f64; 2]) {
        let t = |x: f64, y: f64| DMat3::from_cols(DVec3::X, DVec3::Y, DVec3::new(x, y, 1.0));
        self.warp.forward *= t(-d[0], -d[1]);
        self.warp.inverse = t(d[0], d[1]) * self.warp.inverse;
    }

    /// Overwrites this plan with that of perspective view `pv`, reusing its
    /// arrays. `f` is the parallel factorization of the same camera (same
    /// principal axis and slice order): the plan's [`FramePlan::view`], read for
    /// the axis, the permutation and the shading directions (the headlight is
    /// the central view direction); its affine warp is not used.
    ///
    /// - **Maps.** Slice `k` is sampled at `σ_k · (a, b) + τ_k`
    ///   ([`MapKind::ScaleTranslate`], [`FramePlan::scaled`]).
    /// - **Slices.** `k_range` holds the slices at least `near` slices in front
    ///   of the eye (a slice on or behind the near plane is never composited).
    /// - **Grid.** One pixel per voxel at the base plane (the slice nearest the
    ///   eye, `σ = 1`), so compositing only minifies; its size and origin are the
    ///   exact bounding box of every composited slice's cells (plus the one-pixel
    ///   ring the warp's bilinear taps may read), so no slice is ever cut off.
    ///   One `pad` serves both axes: the axis with the smaller low margin keeps
    ///   some unused pixels (never composited: the occupied rectangle skips them).
    ///   A pyramid of the split ([`PerspectiveView::window`]) keeps only the
    ///   part of that box inside its window, and puts the window at the origin.
    /// - **Rays.** The intermediate pixels' rays are those of the parallel view's
    ///   pixels in the limit: pixel `(p, q)` is the base-plane point
    ///   `(p − pad, q − pad) + shift`, with `shift` chosen so the ray of sheared
    ///   `(0, 0)` meets the centre slice `kc` at a voxel column, as every parallel
    ///   ray does. As the eye recedes the samples become the parallel plan's,
    ///   exactly (not only the same rays resampled on another lattice).
    /// - **Warp.** The projective map of `pv` (after the shift) and its inverse.
    /// - **Opacity.** Each ray's sample spacing is constant along it
    ///   ([`PerspectiveRays::ratio`]); [`FramePlan::opacity_ratio`] is the smallest
    ///   possible one (the ray along k) and [`FramePlan::opacity_exponent`] the rest.
    ///
    /// Clears any ray limits.
    pub fn set_perspective(&mut self, pv: &PerspectiveView, f: &Factorization, spacing: [f32; 3], near: f64) {
        debug_assert_eq!((pv.axis, pv.n, pv.ascending), (f.axis, f.n, f.ascending));
        self.view.clone_from(f);
        self.view.ascending = pv.ascending;
        self.kind = MapKind::ScaleTranslate;
        // the binary rotator does not read perspective plans (the renderer refuses it)
        self.shear.set_view(f);
        let nk = pv.n[2];
        // the shift that puts sheared (0, 0)'s sample in the centre slice on a
        // voxel column; for a pyramid of the split, the one that puts its window
        // at the grid's origin
        let kc = (nk as f64 - 1.0) / 2.0;
        let (sc, tc) = (pv.scale(kc), pv.trans(kc));
        let shift = match pv.window {
            None => tc.map(|t| (t.round() - t) / sc),
            Some([lo, _]) => lo.map(f64::floor),
        };
        self.scaled.clear();
        self.scaled.extend((0..nk).map(|k| {
            let (s, t) = (pv.scale(k as f64), pv.trans(k as f64));
            ScaledMap { scale: s, trans: [s * shift[0] + t[0], s * shift[1] + t[1]] }
        }));
        self.maps.clear();
        self.maps.extend(self.scaled.iter().map(|m| {
            let fl = m.trans.map(|t| t.floor());
            SliceMap { floor: fl.map(|x| x as i32), weight: [(m.trans[0] - fl[0]) as f32, (m.trans[1] - fl[1]) as f32] }
        }));
        // the slices in front of the near plane
        let ek = pv.eye[2];
        let front = |k: usize| if pv.ascending { k as f64 - ek } else { ek - k as f64 };
        // (front(k) is monotone in k: the slices kept are one range; no allocation)
        let (first, last) = ((0..nk).find(|&k| front(k) >= near), (0..nk).rev().find(|&k| front(k) >= near));
        self.k_range = match (first, last) {
            (Some(a), Some(b)) => [a, b],
            _ => [1, 0],
        };
        let ks = if first.is_some() { self.k_range[0]..self.k_range[1] + 1 } else { 0..0 };
        let cells = [pv.n[0].saturating_sub(1), pv.n[1].saturating_sub(1)];
        let [mut lo, mut hi] = self.cells_box(ks.clone());
        // a pyramid of the split: only its window's rays
        if let Some([wlo, whi]) = pv.window {
            for a in 0..2 {
                lo[a] = lo[a].max(wlo[a] - shift[a]);
                hi[a] = hi[a].min(whi[a] - shift[a]);
            }
        }
        let (pad, size) = if ks.is_empty() || cells[0] == 0 || cells[1] == 0 || !(lo[0] <= hi[0] && lo[1] <= hi[1]) {
            (1, [2, 2])
        } else {
            // pixel p samples a = p − pad: the first pixel at or after lo is
            // ceil(lo) + pad = 2 − floor(−lo) + floor(max(−lo)) ≥ 2, the last before
            // hi is ceil(hi) − 1 + pad ≤ size − 3
            // (lo ≤ |shift| ≤ 1/2: the front slice starts at sheared 0 − shift)
            let pad = ((-lo[0]).max(-lo[1]).floor() as i64 + 2).max(0) as usize;
            (pad, [0, 1].map(|a| (pad as f64 + hi[a].ceil()) as usize + 2))
        };
        self.grid = Grid { size, pad, pitch: [1.0; 2] };
        let to_base = DMat3::from_cols(DVec3::X, DVec3::Y, DVec3::new(shift[0], shift[1], 1.0));
        let from_base = DMat3::from_cols(DVec3::X, DVec3::Y, DVec3::new(-shift[0], -shift[1], 1.0));
        self.warp = Warp { forward: pv.warp.forward * to_base, inverse: from_base * pv.warp.inverse };
        self.limits = None;
        self.focus = None;
        let min_sp = spacing.iter().fold(f32::MAX, |a, &b| a.min(b)) as f64;
        let p = pv.perm;
        let rays = PerspectiveRays {
            foot: [pv.eye[0] - shift[0], pv.eye[1] - shift[1]],
            shift,
            kappa: pv.kappa,
            rel_spacing: [0, 1, 2].map(|c| spacing[p[c]] as f64 / min_sp),
        };
        self.perspective = Some(rays);
        self.opacity_ratio = rays.rel_spacing[2] as f32;
        self.set_ray_opacity(self.ray_opacity);
    }

    /// The exact bounding box `[lo, hi]` of the cells of slices `ks` of a
    /// scaled plan, in sheared coordinates: cell `c` of slice `k` covers
    /// sample positions `[c, c + 1)`, sheared `a = (x − τ_k) / σ_k`
    /// (`lo > hi` on an axis: no slice).
    fn cells_box(&self, ks: impl Iterator<Item = usize>) -> [[f64; 2]; 2] {
        let cells = [self.view.n[0].saturating_sub(1), self.view.n[1].saturating_sub(1)];
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for k in ks {
            let m = self.scaled[k];
            for a in 0..2 {
                lo[a] = lo[a].min((0.0 - m.trans[a]) / m.scale);
                hi[a] = hi[a].max((cells[a] as f64 - m.trans[a]) / m.scale);
            }
        }
        [lo, hi]
    }

    /// Resamples this plan's intermediate grid at `pitch` voxels per
    /// intermediate pixel along each axis (the adaptive image size of
    /// Schulze et al., one pitch for both: quality `q = 1 / pitch`
    /// intermediate pixels per voxel; Deluxe M, a pitch per axis), keeping
    /// every ray's geometry: pixel `(p, q)` becomes the sheared point
    /// `((p − pad) · pitch₀, (q − pad) · pitch₁)`, and each slice samples it
    /// through its map as before. A parallel plan becomes
    /// [`MapKind::ScaleTranslate`] with `σ_k = 1` and `τ_k` its exact
    /// translation. The grid covers the sheared rectangle the old grid
    /// covered, narrowed to the bounding box of the composited slices' cells
    /// (a parallel plan's grid is padded for the shear of any view; a
    /// resampled one holds this view's slices), plus a two-pixel ring. The
    /// warp (sheared → output) is unchanged, the intermediate pixel of an
    /// output pixel divides by the pitch
    /// ([`FramePlan::output_to_intermediate`]); the per-ray opacity exponents
    /// are recomputed for the new pixels. Call it after the projection's
    /// producer and before a [`Limiter`]; pitch `[1, 1]` on a pitch-1 plan
    /// changes nothing. Each pitch must be finite and > 0 (the renderer keeps
    /// them in `[1/`[`MAX_MATCHED`]`, 4]`: `--quality` 0.25–2, Deluxe M down
    /// to 1/16, and checks the grid against its pixel limit).
    pub fn set_pitch(&mut self, pitch: [f64; 2]) {
        assert!(pitch.iter().all(|p| p.is_finite() && *p > 0.0), "pitch {pitch:?}");
        let old = self.grid.pitch;
        if pitch == old {
            return;
        }
        if self.kind == MapKind::Translate {
            let st = &self.shear;
            self.scaled.clear();
            self.scaled.extend((0..st.slices()).map(|k| ScaledMap { scale: 1.0, trans: [st.trans[0][k], st.trans[1][k]] }));
            self.kind = MapKind::ScaleTranslate;
        }
        // the sheared rectangle the old grid covered inside a one-pixel ring
        let [w, h] = self.grid.size;
        let pad = self.grid.pad as f64;
        let mut lo = [0, 1].map(|a| (1.0 - pad) * old[a]);
        let mut hi = [0, 1].map(|a| ([w, h][a] as f64 - 2.0 - pad) * old[a]);
        // narrowed to the composited slices' cells
        let [slo, shi] = self.cells_box(self.front_to_back());
        if (0..2).all(|a| slo[a] <= shi[a]) {
            for a in 0..2 {
                lo[a] = lo[a].max(slo[a]);
                hi[a] = hi[a].min(shi[a]).max(lo[a]);
            }
        }
        let new_pad = ((0..2).map(|a| -lo[a] / pitch[a]).fold(0.0f64, f64::max).ceil() as usize) + 2;
        let size = [0, 1].map(|a| new_pad + (hi[a] / pitch[a]).ceil().max(0.0) as usize + 3);
        self.grid = Grid { size, pad: new_pad, pitch };
        self.limits = None;
        self.focus = None;
        self.set_ray_opacity(self.ray_opacity);
    }

    /// Shear-Warp Deluxe M (matched sampling on zoom, Sweeney & Mueller §3.3):
    /// the samples per voxel `[ns_a, ns_b]` along the sheared axes that make
    /// the warped intermediate image's pixels at most one output pixel apart,
    /// `ns = ⌈|∂(u, v)/∂a|⌉` and `⌈|∂(u, v)/∂b|⌉`, the lengths of the warp's
    /// columns (the paper's eq. 3; its eq. 1 is written display → base plane,
    /// while these are the columns of the base → display map, [`Warp::forward`],
    /// in voxels of the base plane), each in `1..=`[`MAX_MATCHED`].
    /// An affine warp has one Jacobian; a projective one (perspective) is
    /// evaluated at the four corners of the grid, the base plane (where the
    /// plan samples at one pixel per voxel: the front slice, the most
    /// magnified) and the largest taken (a projective map's scale is monotone
    /// in `w`, which is affine, so it is largest at a corner). A length within
    /// 1e-9 above an integer counts as that integer (a zoom of exactly 7 is 7
    /// samples, not 8).
    pub fn matched_samples(&self) -> [usize; 2] {
        let f = &self.warp.forward;
        let pad = self.grid.pad as f64;
        let jac = |a: f64, b: f64| -> Option<[f64; 2]> {
            let x = f.x_axis.x * a + f.y_axis.x * b + f.z_axis.x;
            let y = f.x_axis.y * a + f.y_axis.y * b + f.z_axis.y;
            let w = f.x_axis.z * a + f.y_axis.z * b + f.z_axis.z;
            if w <= 0.0 || !w.is_finite() {
                return None;
            }
            let col = |c: glam::DVec3| {
                let du = (c.x * w - x * c.z) / (w * w);
                let dv = (c.y * w - y * c.z) / (w * w);
                (du * du + dv * dv).sqrt()
            };
            Some([col(f.x_axis), col(f.y_axis)])
        };
        let [w, h] = self.grid.size;
        let pitch = self.grid.pitch;
        let (a1, b1) = ((w as f64 - 1.0 - pad) * pitch[0], (h as f64 - 1.0 - pad) * pitch[1]);
        let (a0, b0) = (-pad * pitch[0], -pad * pitch[1]);
        let mut m = [0f64; 2];
        for (a, b) in [(a0, b0), (a1, b0), (a0, b1), (a1, b1)] {
            if let Some(l) = jac(a, b) {
                m = [m[0].max(l[0]), m[1].max(l[1])];
            }
        }
        m.map(|l| if l.is_finite() { ((l - 1e-9).ceil().max(1.0) as usize).min(MAX_MATCHED) } else { 1 })
    }

    /// Whether each ray's opacity is corrected to its own sample spacing
    /// (perspective plans; a no-op for parallel ones). The renderer turns it
    /// off in iso mode, whose opacities are 0 or 1 and never corrected.
    ///
    /// Computed once per grid and rays: asking again for the plan as it is
    /// (the renderer asks after every producer) costs nothing, and in iso
    /// mode the producer computes none after the first frame turned it off.
    pub fn set_ray_opacity(&mut self, on: bool) {
        self.ray_opacity = on;
        let Some(rays) = self.perspective.filter(|_| on) else {
            self.exponents.clear();
            self.ray_rows.clear();
            self.exponents_for = None;
            return;
        };
        if self.exponents_for == Some((self.grid, rays)) {
            return;
        }
        self.exponents.clear();
        self.exponents_for = Some((self.grid, rays));
        let [w, h] = self.grid.size;
        let base = self.opacity_ratio as f64;
        let mut e_max = 1f32;
        for q in 0..h {
            for p in 0..w {
                let [a, b] = self.intermediate_to_sheared(p as f64, q as f64);
                let e = (rays.ratio(a, b) / base).max(1.0) as f32;
                e_max = e_max.max(e);
                self.exponents.push(e);
            }
        }
        self.opacity_table.cover(e_max);
        let table = &self.opacity_table;
        self.ray_rows.clear();
        self.ray_rows.extend(self.exponents.iter().map(|&e| table.row(e)));
    }

    /// The exponent `e ≥ 1` that takes an opacity corrected to
    /// [`FramePlan::opacity_ratio`] to intermediate pixel `(p, q)`'s own ray:
    /// `α'' = 1 − (1 − α')^e` ([`FramePlan::correct_opacity`]; the raycast paths
    /// [`crate::composite::correct_alpha`]); 1 for every pixel of a parallel plan.
    #[inline(always)]
    pub fn opacity_exponent(&self, p: usize, q: usize) -> f32 {
        if self.exponents.is_empty() { 1.0 } else { self.exponents[q * self.grid.size[0] + p] }
    }

    /// Premultiplied sample `s` of intermediate pixel `(p, q)`, its opacity
    /// corrected to [`FramePlan::opacity_ratio`], corrected on to the pixel's
    /// own ray ([`FramePlan::opacity_exponent`], by the plan's
    /// [`OpacityTable`]): `s` itself, bit for bit, in a parallel plan. The
    /// pre-classified slices and their brute force correct every sample here.
    #[inline(always)]
    pub fn correct_opacity(&self, p: usize, q: usize, s: [f32; 4]) -> [f32; 4] {
        if self.ray_rows.is_empty() { s } else { self.opacity_table.correct_row(s, self.ray_rows[q * self.grid.size[0] + p]) }
    }

    /// Intermediate row `q`'s rays' places in the opacity table, by pixel
    /// over the grid (empty when the plan corrects no ray): with
    /// [`FramePlan::opacity_table`], [`FramePlan::correct_opacity`] of a
    /// whole row without its per-sample lookups.
    #[inline(always)]
    pub fn ray_rows_of(&self, q: usize) -> &[RayRow] {
        if self.ray_rows.is_empty() { &[] } else { &self.ray_rows[q * self.grid.size[0]..(q + 1) * self.grid.size[0]] }
    }

    /// The table [`FramePlan::correct_opacity`] corrects with.
    #[inline(always)]
    pub fn opacity_table(&self) -> &OpacityTable {
        &self.opacity_table
    }

    /// The real sample spacing of intermediate pixel `(p, q)`'s ray over the
    /// spacing opacities are defined at: uniform for a parallel plan.
    pub fn opacity_ratio_at(&self, p: f64, q: f64) -> f64 {
        match &self.perspective {
            None => self.opacity_ratio as f64,
            Some(r) => {
                let [a, b] = self.intermediate_to_sheared(p, q);
                r.ratio(a, b)
            }
        }
    }

    /// The cell (integer part) and in-cell weight along in-slice axis `axis`
    /// (0 = i, 1 = j) of intermediate pixel column/row `x` in slice `k`: where
    /// every traversal samples. Exactly the maps' numbers for a parallel plan.
    #[inline(always)]
    pub fn cell_of(&self, k: usize, axis: usize, x: usize) -> (i64, f32) {
        match self.kind {
            MapKind::Translate => {
                let m = &self.maps[k];
                (x as i64 - self.grid.pad as i64 + m.floor[axis] as i64, m.weight[axis])
            }
            MapKind::ScaleTranslate => self.axis_map(k, axis).cell(x as i64),
        }
    }

    /// Slice `k`'s scaled map along in-slice axis `axis` with the grid's
    /// numbers, for a traversal that samples many pixels of one slice
    /// ([`MapKind::ScaleTranslate`] only): [`AxisMap::cell`] is
    /// [`FramePlan::cell_of`], bit for bit.
    #[inline(always)]
    pub fn axis_map(&self, k: usize, axis: usize) -> AxisMap {
        let m = &self.scaled[k];
        AxisMap::new(m.scale, m.trans[axis], self.grid.pad as f64, self.grid.pitch[axis])
    }

    /// The exact in-slice sample position (voxel units, before the floor)
    /// along `axis` of intermediate pixel column/row `x` in slice `k`:
    /// [`FramePlan::cell_of`]'s cell plus weight, in f64.
    #[inline(always)]
    pub fn sample_at(&self, k: usize, axis: usize, x: usize) -> f64 {
        match self.kind {
            MapKind::Translate => x as f64 - self.grid.pad as f64 + self.shear.trans[axis][k],
            MapKind::ScaleTranslate => {
                let m = &self.scaled[k];
                m.scale * ((x as f64 - self.grid.pad as f64) * self.grid.pitch[axis]) + m.trans[axis]
            }
        }
    }

    /// The box footprint, in voxels of slice `k` along each in-slice axis, of
    /// one intermediate pixel where its pixels are more than [`BOX_FROM`]
    /// voxels apart along either axis (a slice minified that much: the far
    /// slices of a perspective eye near the volume, a grid of half a pixel
    /// per voxel or coarser), each capped at [`MAX_FOOTPRINT`]; `[1, 1]` where
    /// the slice is sampled bilinearly (parallel slices, magnified ones, and
    /// those minified up to 2×, where the bilinear tent, two voxels wide,
    /// already reaches every voxel between two pixels). In a box-filtered
    /// slice an axis whose pixels lie at most [`BOX_FROM`] voxels apart (a
    /// grid with a pitch per axis) takes a box one voxel wide: against voxels
    /// one voxel wide that is the linear tent.
    #[inline(always)]
    pub fn footprint(&self, k: usize) -> [f64; 2] {
        match self.kind {
            _ if !self.box_footprint => [1.0; 2],
            MapKind::Translate => [1.0; 2],
            MapKind::ScaleTranslate => {
                let s = self.grid.pitch.map(|p| self.scaled[k].scale * p);
                if s[0].max(s[1]) > BOX_FROM { s.map(|s| if s > BOX_FROM { s.min(MAX_FOOTPRINT) } else { 1.0 }) } else { [1.0; 2] }
            }
        }
    }

    /// Whether slice `k` is box-filtered ([`FramePlan::footprint`] wider than
    /// one voxel along either axis).
    #[inline(always)]
    pub fn boxed(&self, k: usize) -> bool {
        let s = self.footprint(k);
        s[0].max(s[1]) > 1.0
    }

    /// Shear-Warp Deluxe I (a producer of plans): the slices are sampled at
    /// half spacing, one intermediate sample at the midpoint of each ray
    /// between consecutive slices ([`FramePlan::mid_map`]), so every sample's
    /// opacity is corrected to [`FramePlan::sample_ratio`], half the slice
    /// spacing (`α_n = 1 − √(1 − α)` of the one-slice opacity; premultiplied
    /// colour scaled with it). The per-ray exponents of a perspective plan are
    /// ratios of spacings and stay as they are. Kept across `set_parallel` /
    /// `set_perspective`, like the footprint.
    pub fn set_intermediate(&mut self, on: bool) {
        self.half_step = on;
    }

    /// Whether the plan samples between slices ([`FramePlan::set_intermediate`]).
    #[inline(always)]
    pub fn intermediate(&self) -> bool {
        self.half_step
    }

    /// The spacing every sample's opacity is corrected to, over the spacing
    /// opacities are defined at: [`FramePlan::opacity_ratio`], halved when the
    /// plan samples between slices. The classification tables of the
    /// pre- and post-classified slices are corrected to it.
    pub fn sample_ratio(&self) -> f32 {
        if self.half_step { 0.5 * self.opacity_ratio } else { self.opacity_ratio }
    }

    /// The map of the intermediate samples between slices `k` and `k + 1`
    /// (index order) along in-slice axis `axis`: pixel `x` samples both slices
    /// at the ray's position at depth `k + ½`, the mean of its positions in
    /// the two slices ([`FramePlan::sample_at`]). A parallel plan translates
    /// every slice, a perspective one scales and translates it, each affinely
    /// in `k` along a straight ray, so the mean of the two maps (scale and
    /// translation) is the map at `k + ½` exactly. A translated plan's map is
    /// a whole shift of cells and one weight for every pixel
    /// ([`MidMap::Shift`], as a slice's [`SliceMap`]). The accelerated
    /// traversal and its brute force both sample through it.
    #[inline(always)]
    pub fn mid_map(&self, k: usize, axis: usize) -> MidMap {
        let (pad, pitch) = (self.grid.pad as f64, self.grid.pitch[axis]);
        match self.kind {
            MapKind::Translate => {
                let t = &self.shear.trans[axis];
                let m = 0.5 * (t[k] + t[k + 1]);
                let f = m.floor();
                MidMap::Shift { off: f as i64 - self.grid.pad as i64, weight: (m - f) as f32 }
            }
            MapKind::ScaleTranslate => {
                let (a, b) = (&self.scaled[k], &self.scaled[k + 1]);
                MidMap::Map(AxisMap::new(0.5 * (a.scale + b.scale), 0.5 * (a.trans[axis] + b.trans[axis]), pad, pitch))
            }
        }
    }

    /// Box-filters minified slices (the default) or samples them bilinearly
    /// at the pixel's centre ([`crate::render::Footprint`]).
    pub fn set_box_footprint(&mut self, on: bool) {
        self.box_footprint = on;
    }

    /// How many cells beyond its own a pixel's footprint in slice `k` may
    /// reach on each side along in-slice axis `axis` (0 for a bilinear sample).
    #[inline(always)]
    pub fn footprint_reach(&self, k: usize, axis: usize) -> i64 {
        let s = self.footprint(k);
        if s[0].max(s[1]) > 1.0 { (0.5 * s[axis]).ceil() as i64 + 1 } else { 0 }
    }

    /// The intermediate pixels `[x0, x1]` along in-slice axis `axis` whose
    /// samples in slice `k` fall in cells `c0 ..= c1` ([`FramePlan::cell_of`]),
    /// not clipped to the grid; `x0 > x1` when none do.
    pub fn pixels_of_cells(&self, k: usize, axis: usize, c0: i64, c1: i64) -> [i64; 2] {
        match self.kind {
            MapKind::Translate => {
                let off = self.grid.pad as i64 - self.maps[k].floor[axis] as i64;
                [c0 + off, c1 + off]
            }
            // the estimate from the inverse map, then exact by the map itself
            MapKind::ScaleTranslate => self.axis_map(k, axis).pixels_of_cells(c0, c1),
        }
    }

    /// Lets `limiter` narrow the rays of this plan, into `buf` (reused across
    /// frames; taken back with [`FramePlan::take_limits`]).
    pub fn apply_limiter(&mut self, limiter: &dyn Limiter, mut buf: RayLimits) {
        buf.reset(self.grid.size, self.slices());
        limiter.limit(self, &mut buf);
        buf.normalize();
        self.limits = Some(buf);
    }

    /// Removes and returns the ray limits (their buffer, for reuse).
    pub fn take_limits(&mut self) -> Option<RayLimits> {
        self.limits.take()
    }

    /// Sets each ray's focus interval (focus+context): the slices whose
    /// samples `region` keeps — any [`Limiter`] that narrows open limits to
    /// a region's samples, e.g. [`crate::view::clip::ClipRegion`] — into
    /// `buf` (reused across frames; taken back with [`FramePlan::take_focus`]).
    pub fn apply_focus(&mut self, region: &dyn Limiter, mut buf: RayLimits) {
        buf.reset(self.grid.size, self.slices());
        region.limit(self, &mut buf);
        self.focus = Some(buf);
    }

    /// Removes and returns the focus intervals (their buffer, for reuse).
    pub fn take_focus(&mut self) -> Option<RayLimits> {
        self.focus.take()
    }

    /// The focus interval `[f0, f1]` of ray `(p, q)` (empty, `f0 > f1`, without a focus region).
    #[inline(always)]
    pub fn focus_range(&self, p: usize, q: usize) -> [usize; 2] {
        match &self.focus {
            Some(f) => {
                let [a, b] = f.get(p, q);
                [a as usize, b as usize]
            }
            None => [1, 0],
        }
    }

    /// Whether ray `(p, q)`'s sample in slice `k` lies in the focus region.
    #[inline(always)]
    pub fn in_focus(&self, p: usize, q: usize, k: usize) -> bool {
        let [a, b] = self.focus_range(p, q);
        a <= k && k <= b
    }

    /// Whether ray `(p, q)`'s Deluxe I sample at the midpoint between slices
    /// `k` and `k + 1` lies in the focus region: iff both slices' samples do
    /// (the focus spans the same depths with or without Deluxe I).
    #[inline(always)]
    pub fn in_focus_mid(&self, p: usize, q: usize, k: usize) -> bool {
        let [a, b] = self.focus_range(p, q);
        a <= k && k < b
    }

    /// Number of slices.
    pub fn slices(&self) -> usize {
        self.maps.len()
    }

    /// True when some ray composites less than every slice: a `k_range` short of
    /// the volume, or per-pixel limits.
    pub fn limited(&self) -> bool {
        self.limits.is_some() || self.k_range != [0, self.slices().saturating_sub(1)]
    }

    /// The slices ray `(p, q)` composites, `[k0, k1]` in index order (`k0 > k1`: none).
    #[inline(always)]
    pub fn ray_range(&self, p: usize, q: usize) -> [usize; 2] {
        let [a, b] = self.k_range;
        match &self.limits {
            Some(l) => {
                let [c, d] = l.get(p, q);
                [a.max(c as usize), b.min(d as usize)]
            }
            None => [a, b],
        }
    }

    /// The hole `[h0, h1]` of ray `(p, q)` (index order, strictly inside its
    /// [`FramePlan::ray_range`]), if it has one.
    #[inline(always)]
    pub fn ray_hole(&self, p: usize, q: usize) -> Option<[usize; 2]> {
        match &self.limits {
            Some(l) if l.has_holes() => {
                let [h0, h1] = l.hole(p, q);
                (h0 <= h1).then_some([h0 as usize, h1 as usize])
            }
            _ => None,
        }
    }

    /// Whether ray `(p, q)` composites slice `k` (its range, less its hole).
    #[inline(always)]
    pub fn ray_keeps(&self, p: usize, q: usize, k: usize) -> bool {
        let [a, b] = self.k_range;
        a <= k && k <= b && self.limits.as_ref().is_none_or(|l| l.keeps(p, q, k))
    }

    /// Slice indices front to back over `k_range`.
    pub fn front_to_back(&self) -> impl Iterator<Item = usize> + use<> {
        let [a, b] = self.k_range;
        let asc = self.view.ascending;
        let n = if self.maps.is_empty() || a > b { 0 } else { b - a + 1 };
        (0..n).map(move |s| if asc { a + s } else { b - s })
    }

    /// The intermediate pixel `(p, q)` (fractional) of output pixel `(u, v)`, or
    /// `None` behind the eye.
    pub fn output_to_intermediate(&self, u: f64, v: f64) -> Option<[f64; 2]> {
        let [a, b] = self.warp.to_sheared(u, v)?;
        let pad = self.grid.pad as f64;
        Some([a / self.grid.pitch[0] + pad, b / self.grid.pitch[1] + pad])
    }

    /// The sheared point `(a, b)` of intermediate pixel `(p, q)`.
    pub fn intermediate_to_sheared(&self, p: f64, q: f64) -> [f64; 2] {
        let pad = self.grid.pad as f64;
        [(p - pad) * self.grid.pitch[0], (q - pad) * self.grid.pitch[1]]
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::view::{Camera, rotate_eye};

    fn plan(r: DMat3, dims: [usize; 3]) -> FramePlan {
        let f = Factorization::new(&Camera::new(r, [96, 64]), dims, [1.0, 0.8, 1.5]).unwrap();
        FramePlan::parallel(&f, [1.0, 0.8, 1.5])
    }

    #[test]
    #[allow(clippy::needless_range_loop)] // the index picks one axis of several arrays
    fn the_maps_are_the_exact_translations_split() {
        let p = plan(rotate_eye(DMat3::from_rotation_x(0.4), 1, 31.0), [20, 24, 18]);
        assert_eq!(p.maps.len(), p.view.n[2]);
        for (k, m) in p.maps.iter().enumerate() {
            let t = p.view.trans(k);
            for a in 0..2 {
                assert_eq!(m.floor[a], t[a].floor() as i32);
                assert!((m.floor[a] as f64 + m.weight[a] as f64 - t[a]).abs() < 1e-6);
                assert!((0.0..1.0).contains(&m.weight[a]));
            }
        }
        assert!(p.warp.is_affine());
        assert!(!p.limited());
    }

    #[test]
    fn the_warp_and_its_inverse_agree_and_match_the_factorization() {
        let p = plan(DMat3::from_euler(glam::EulerRot::XYZ, 0.3, -0.7, 1.1), [17, 23, 29]);
        for (a, b) in [(0.0, 0.0), (3.5, -2.25), (16.0, 22.0)] {
            let [u, v] = p.warp.to_output(a, b).unwrap();
            let f = &p.view;
            assert!((u - (f.warp_m[0][0] * a + f.warp_m[0][1] * b + f.warp_t[0])).abs() < 1e-9);
            assert!((v - (f.warp_m[1][0] * a + f.warp_m[1][1] * b + f.warp_t[1])).abs() < 1e-9);
            let [a2, b2] = p.warp.to_sheared(u, v).unwrap();
            assert!((a2 - a).abs() < 1e-9 && (b2 - b).abs() < 1e-9);
            let [pp, qq] = p.output_to_intermediate(u, v).unwrap();
            let [a3, b3] = p.intermediate_to_sheared(pp, qq);
            assert!((a3 - a).abs() < 1e-9 && (b3 - b).abs() < 1e-9);
        }
    }

    #[test]
    fn a_projective_warp_rejects_points_behind_the_eye() {
        let w = Warp { forward: DMat3::IDENTITY, inverse: DMat3::from_cols(DVec3::X, DVec3::Y, DVec3::new(0.0, 0.0, -1.0)) };
        assert!(!w.is_affine());
        assert_eq!(w.to_sheared(1.0, 2.0), None);
        let w = Warp { forward: DMat3::IDENTITY, inverse: DMat3::from_cols(DVec3::X, DVec3::Y, DVec3::new(0.0, 0.0, 2.0)) };
        assert_eq!(w.to_sheared(1.0, 2.0), Some([0.5, 1.0]));
    }

    /// Random perspective views of one pyramid, with their plans.
    fn perspective_plans(n: usize, near: f64) -> Vec<(PerspectiveView, FramePlan)> {
        let mut seed = 11u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let (dims, sp) = ([20, 26, 17], [1.0f32, 0.8, 1.5]);
        let mut out = vec![];
        while out.len() < n {
            let r = DMat3::from_euler(glam::EulerRot::XYZ, rnd() * 7.0, rnd() * 7.0, rnd() * 7.0);
            let cam = Camera { rotation: r, zoom: Some(2.0), size: [96, 80] };
            let Ok(pv) = PerspectiveView::new(&cam, 45.0 + rnd() * 300.0, dims, sp) else { continue };
            let f = Factorization::new(&cam, dims, sp).unwrap();
            let plan = FramePlan::perspective(&pv, &f, sp, near);
            out.push((pv, plan));
        }
        out
    }

    /// Virvo drops a slice that does not fit its fixed intermediate image. The
    /// perspective grid is the exact bounding box of every slice's cells: each
    /// slice's pixels lie inside it (with the one-pixel ring the warp reads),
    /// the box's extreme pixels are reached by some slice, and no slice
    /// composited is empty.
    #[test]
    fn perspective_grid_covers_every_slice_exactly() {
        for (pv, plan) in perspective_plans(200, 0.5) {
            assert_eq!(plan.kind, MapKind::ScaleTranslate);
            assert!(!plan.warp.is_affine());
            let [w, h] = plan.grid.size;
            let cells = [pv.n[0] as i64 - 1, pv.n[1] as i64 - 1];
            let (mut lo, mut hi) = ([i64::MAX; 2], [i64::MIN; 2]);
            for k in plan.front_to_back() {
                for a in 0..2 {
                    let [x0, x1] = plan.pixels_of_cells(k, a, 0, cells[a] - 1);
                    assert!(x0 <= x1, "slice {k} has no pixel");
                    assert!(x0 >= 1 && x1 <= [w, h][a] as i64 - 2, "slice {k} axis {a}: [{x0}, {x1}] in {:?}", plan.grid);
                    // exact: the end pixels sample the end cells, their outer neighbours miss
                    // (a minified slice's cell 0 itself may fall between two pixels)
                    assert!(plan.cell_of(k, a, x0 as usize).0 >= 0);
                    assert!(plan.cell_of(k, a, x0 as usize - 1).0 < 0);
                    assert!((0..cells[a]).contains(&plan.cell_of(k, a, x1 as usize).0));
                    assert!(plan.cell_of(k, a, x1 as usize + 1).0 > cells[a] - 1);
                    lo[a] = lo[a].min(x0);
                    hi[a] = hi[a].max(x1);
                }
            }
            // the grid is the box plus its margins: 2 pixels on the high side,
            // on the low side 2 for the axis with the larger low margin
            assert_eq!([w as i64 - 3, h as i64 - 3], hi, "{:?}", plan.grid);
            assert_eq!(lo[0].min(lo[1]), 2);
        }
    }

    /// A resampled grid (the adaptive image size) still holds every slice:
    /// at pitches 0.25–4, for parallel and perspective plans, each slice's
    /// pixels lie inside the grid with the one-pixel ring the warp reads, and
    /// every pixel keeps its ray (its sample in a slice is the same map at
    /// the new sheared point).
    #[test]
    fn resampled_grids_cover_every_slice() {
        let mut plans: Vec<FramePlan> = perspective_plans(40, 0.5).into_iter().map(|x| x.1).collect();
        for a in [0.0, 0.3, 0.8, 1.4] {
            let r = rotate_eye(rotate_eye(DMat3::IDENTITY, 1, a * 40.0), 0, a * 25.0);
            plans.push(plan(r, [20, 26, 17]));
        }
        for base in plans {
            for pitch in [[0.25; 2], [0.5; 2], [0.8; 2], [2.0; 2], [4.0; 2], [1.0, 0.2], [0.5, 1.0 / 6.0], [0.25, 1.0]] {
                let mut p = base.clone();
                p.set_pitch(pitch);
                assert_eq!(p.kind, MapKind::ScaleTranslate);
                assert_eq!(p.grid.pitch, pitch);
                let [w, h] = p.grid.size;
                let n = p.view.n;
                for k in p.front_to_back() {
                    for a in 0..2 {
                        let [x0, x1] = p.pixels_of_cells(k, a, 0, n[a] as i64 - 2);
                        if x0 > x1 {
                            // a slice minified between two pixels of a coarse grid
                            assert!(pitch[a] > 1.0);
                            continue;
                        }
                        assert!(x0 >= 1 && x1 <= [w, h][a] as i64 - 2, "pitch {pitch:?} slice {k} axis {a}: [{x0}, {x1}] in {:?}", p.grid);
                    }
                    // the same ray: the sample at sheared (a, b) is the base plan's map there
                    let [sa, sb] = p.intermediate_to_sheared(3.0, 5.0);
                    let (ci, wi) = p.cell_of(k, 0, 3);
                    let want = match base.kind {
                        MapKind::Translate => sa + base.shear.trans[0][k],
                        MapKind::ScaleTranslate => base.scaled[k].scale * sa + base.scaled[k].trans[0],
                    };
                    assert!((ci as f64 + wi as f64 - want).abs() < 1e-5, "pitch {pitch:?} slice {k}: {ci} + {wi} vs {want} ({sb})");
                }
                // not larger than needed: within the base grid's coverage and
                // the bounding box of the slices' cells (plus the rings)
                let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
                for k in p.front_to_back() {
                    for a in 0..2 {
                        let m = p.scaled[k];
                        lo[a] = lo[a].min(-m.trans[a] / m.scale);
                        hi[a] = hi[a].max((n[a] as f64 - 1.0 - m.trans[a]) / m.scale);
                    }
                }
                for a in 0..2 {
                    let (pad, base_pad) = (p.grid.pad as f64, base.grid.pad as f64);
                    assert!(pad <= (base_pad / pitch[0]).max(base_pad / pitch[1]).ceil() + 3.0);
                    assert!(p.grid.size[a] as f64 - pad <= ((base.grid.size[a] as f64 - base_pad) / pitch[a]).ceil() + 8.0);
                    let slack = (lo[0] / pitch[0]).min(lo[1] / pitch[1]).min(0.0).abs();
                    assert!(p.grid.size[a] as f64 <= hi[a].max(0.0) / pitch[a] + slack + 8.0, "pitch {pitch:?} axis {a}: {:?}", p.grid);
                }
            }
        }
    }

    /// The maps follow the perspective rays: pixel (p, q)'s sample in slice k
    /// is where the ray through its sheared point meets the slice.
    #[test]
    fn perspective_maps_follow_the_rays() {
        for (pv, plan) in perspective_plans(50, 0.5) {
            for k in [0, pv.n[2] / 2, pv.n[2] - 1] {
                for (p, q) in [(3usize, 4usize), (17, 9), (plan.grid.size[0] - 2, plan.grid.size[1] - 3)] {
                    let [a, b] = plan.intermediate_to_sheared(p as f64, q as f64);
                    let sh = plan.perspective.unwrap().shift;
                    let x = pv.sheared_to_voxel(a + sh[0], b + sh[1], k as f64);
                    // and the warp takes the pixel where the view takes that point
                    let want = pv.warp.to_output(a + sh[0], b + sh[1]).unwrap();
                    let got = plan.warp.to_output(a, b).unwrap();
                    assert!((want[0] - got[0]).abs() < 1e-9 && (want[1] - got[1]).abs() < 1e-9);
                    let (ci, wi) = plan.cell_of(k, 0, p);
                    let (cj, wj) = plan.cell_of(k, 1, q);
                    assert!((ci as f64 + wi as f64 - x[pv.perm[0]]).abs() < 1e-5);
                    assert!((cj as f64 + wj as f64 - x[pv.perm[1]]).abs() < 1e-5);
                }
            }
        }
    }

    /// Each ray's opacity ratio is the world length of its step from one slice
    /// to the next over the smallest spacing; the exponents are that over the
    /// plan's uniform ratio, at least 1.
    #[test]
    fn perspective_opacity_ratio_is_each_rays_own_spacing() {
        let sp = DVec3::new(1.0, 0.8, 1.5);
        for (pv, plan) in perspective_plans(50, 0.5) {
            for (p, q) in [(3usize, 4usize), (17, 9), (plan.grid.size[0] - 2, plan.grid.size[1] - 3)] {
                let [a, b] = plan.intermediate_to_sheared(p as f64, q as f64);
                let sh = plan.perspective.unwrap().shift;
                let x0 = DVec3::from_array(pv.sheared_to_voxel(a + sh[0], b + sh[1], 3.0));
                let x1 = DVec3::from_array(pv.sheared_to_voxel(a + sh[0], b + sh[1], 4.0));
                let want = ((x1 - x0) * sp).length() / 0.8;
                assert!((plan.opacity_ratio_at(p as f64, q as f64) - want).abs() < 1e-6 * want);
                let e = plan.opacity_exponent(p, q);
                assert!(e >= 1.0 && (e as f64 - want / plan.opacity_ratio as f64).abs() < 1e-5);
            }
        }
    }

    /// Slices on or behind the near plane are not composited.
    #[test]
    fn perspective_near_plane_excludes_slices() {
        for (pv, plan) in perspective_plans(20, 0.5) {
            let ahead = |k: usize| if pv.ascending { k as f64 - pv.eye[2] } else { pv.eye[2] - k as f64 };
            assert!(plan.front_to_back().all(|k| ahead(k) >= 0.5));
            let f = plan.view.clone();
            // a near plane through the middle of the volume
            let near = ahead(pv.n[2] / 2);
            let p2 = FramePlan::perspective(&pv, &f, [1.0, 0.8, 1.5], near);
            assert!(p2.front_to_back().all(|k| ahead(k) >= near));
            assert_eq!(p2.front_to_back().count(), (0..pv.n[2]).filter(|&k| ahead(k) >= near).count());
            assert!(p2.front_to_back().count() < pv.n[2] && p2.limited());
            // beyond the volume: nothing
            let p3 = FramePlan::perspective(&pv, &f, [1.0, 0.8, 1.5], 1e9);
            assert_eq!(p3.front_to_back().count(), 0);
        }
    }

    #[test]
    fn ray_ranges_intersect_the_slice_range_and_the_limits() {
        let mut p = plan(DMat3::IDENTITY, [8, 8, 10]);
        assert_eq!(p.ray_range(3, 4), [0, 9]);
        assert_eq!(p.front_to_back().collect::<Vec<_>>(), (0..10).rev().collect::<Vec<_>>());
        p.k_range = [2, 7];
        assert!(p.limited());
        let mut l = RayLimits::open(p.grid.size, 10);
        l.set(3, 4, [5, 9]);
        p.limits = Some(l);
        assert_eq!(p.ray_range(3, 4), [5, 7]);
        assert_eq!(p.ray_range(0, 0), [2, 7]);
        assert_eq!(p.front_to_back().collect::<Vec<_>>(), [7, 6, 5, 4, 3, 2]);
    }
}
