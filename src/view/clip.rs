//! Clipping planes: half-spaces of the volume that are kept, as per-pixel ray
//! limits ([`ClipPlanes`], a [`Limiter`]).
//!
//! A plane is given in world coordinates — millimetres from the volume centre
//! along the volume's x, y, z (index) axes, `w = S · (v − (n − 1)/2)` for voxel
//! index `v` and spacing `S` (the convention of [`crate::view::Factorization`])
//! — as a normal `n` and an offset `d`: the side **kept** is `n · w ≤ d`.
//!
//! For every intermediate pixel `(p, q)` of a frame plan the limiter takes the
//! pixel's ray as the plan samples it: the sample of slice `k` sits at in-slice
//! position `(i_k, j_k)` — the parallel plan's exact translation
//! `(p − pad) + trans[k]`, or the perspective plan's `σ_k · (a, b) + τ_k` —
//! and depth `k`. A sample is kept iff that voxel-space point satisfies every
//! plane. Each ray is a straight line whose points are affine in `k`, so each
//! plane keeps one interval of slices; it is solved from the signed distances
//! at the first and last slice and its end slices are then checked (and moved)
//! by evaluating the signed distance at each sample itself, so the limits agree
//! with the per-sample rule at slice granularity. The limits are the
//! intersection of every plane's interval.
//!
//! Every traversal (binary rays, RLE slices, both brute-force references)
//! reads these limits through [`FramePlan::ray_range`]; a pixel with no
//! slice left composites nothing and stays background.
//!
//! Convex clip regions ([`ClipRegion`]: a sphere or a box in voxel-index
//! coordinates, the samples *inside* kept) work the same way: a straight ray
//! meets a convex region in one interval, solved analytically and then
//! checked on the samples themselves. [`Limiters`] applies several limiters
//! in turn (each only narrows a ray's interval: the intersection).
//!
//! A region may keep its **outside** instead ([`Keep::Outside`],
//! [`ClipRegion::keeping`]): the same interval of slices, solved and checked
//! the same way, is then cut out of the ray as its *hole*
//! ([`RayLimits`]: the ray composites `[k0, h0 − 1]` then `[h1 + 1, k1]`;
//! [`crate::view::plan::cut_ray`]). A ray holds one hole, so a limiter set
//! may hold one outside region at most ([`Limiters::new`] refuses more);
//! planes and inside regions narrow the interval around it in any order.

use std::sync::Arc;

use glam::DVec3;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::view::plan::{FramePlan, Limiter, MapKind, RayLimits, cut_ray};

/// Most planes a [`ClipPlanes`] holds.
pub const MAX_PLANES: usize = 6;

/// One half-space `normal · w ≤ offset` in world millimetres from the volume
/// centre (see the [module docs](self)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClipPlane {
    pub normal: [f64; 3],
    pub offset: f64,
}

impl ClipPlane {
    /// The half-space `normal · w ≤ offset`. The normal need not be unit
    /// length (the offset is then in units of `|normal|` mm) but must be
    /// finite and non-zero; the offset must be finite.
    pub fn new(normal: [f64; 3], offset: f64) -> Result<Self> {
        if normal.iter().any(|x| !x.is_finite()) {
            return Err(Error::value("clip plane", format!("the normal must be finite, got {normal:?}")));
        }
        if normal.iter().all(|&x| x == 0.0) {
            return Err(Error::value("clip plane", "the normal is zero: it has no side to keep"));
        }
        if !offset.is_finite() {
            return Err(Error::value("clip plane", format!("the offset must be finite, got {offset}")));
        }
        Ok(ClipPlane { normal, offset })
    }

    /// The half-space `normal · v ≤ offset` given in **voxel index**
    /// coordinates `v = (x, y, z)` of a volume of `dims` voxels with voxel
    /// `spacing` (the CLI's `--clip-plane`), as the same half-space in world
    /// millimetres from the volume centre: `v = w / S + c` with
    /// `c = (dims − 1) / 2`, so `(normal / S) · w ≤ offset − normal · c`.
    pub fn in_voxel_coordinates(normal: [f64; 3], offset: f64, dims: [usize; 3], spacing: [f32; 3]) -> Result<Self> {
        Self::new(normal, offset)?;
        if spacing.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(Error::value("clip plane", format!("the voxel spacing must be finite and > 0, got {spacing:?}")));
        }
        let c = dims.map(|d| (d as f64 - 1.0) / 2.0);
        let m = [0, 1, 2].map(|a| normal[a] / spacing[a] as f64);
        let shifted = offset - (0..3).map(|a| normal[a] * c[a]).sum::<f64>();
        if m.iter().any(|x| !x.is_finite()) || !shifted.is_finite() {
            // (the numbers were finite as given: too large for the volume's frame)
            return Err(Error::value(
                "clip plane",
                format!(
                    "normal {normal:?} and offset {offset} are too large: moved to the volume's centre they overflow; scale them down (only their ratio matters)"
                ),
            ));
        }
        Self::new(m, shifted)
    }

    /// The half-space through `point` (mm) keeping the side opposite `normal`
    /// (`normal · (w − point) ≤ 0`).
    pub fn through(point: [f64; 3], normal: [f64; 3]) -> Result<Self> {
        if point.iter().any(|x| !x.is_finite()) {
            return Err(Error::value("clip plane", format!("the point must be finite, got {point:?}")));
        }
        Self::new(normal, normal[0] * point[0] + normal[1] * point[1] + normal[2] * point[2])
    }
}

/// Up to [`MAX_PLANES`] half-spaces of one volume; the region kept is their
/// intersection. A [`Limiter`]: give it to [`crate::render::Renderer::set_limiter`].
#[derive(Clone, Debug, PartialEq)]
pub struct ClipPlanes {
    planes: Vec<ClipPlane>,
    spacing: [f64; 3],
}

impl ClipPlanes {
    /// The planes of a volume with voxel `spacing` (the renderer's volume:
    /// the planes are in millimetres, the limits in voxels).
    pub fn new(planes: &[ClipPlane], spacing: [f32; 3]) -> Result<Self> {
        if planes.len() > MAX_PLANES {
            return Err(Error::value("clip planes", format!("at most {MAX_PLANES}, got {}", planes.len())));
        }
        if spacing.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(Error::value("clip planes", format!("the voxel spacing must be finite and > 0, got {spacing:?}")));
        }
        for p in planes {
            ClipPlane::new(p.normal, p.offset)?;
        }
        Ok(ClipPlanes { planes: planes.to_vec(), spacing: spacing.map(|s| s as f64) })
    }

    /// The planes.
    pub fn planes(&self) -> &[ClipPlane] {
        &self.planes
    }

    /// The planes in the plan's permuted voxel space `(i, j, k)`: `m · (i, j, k) ≤ e`.
    fn in_voxels(&self, plan: &FramePlan) -> Vec<([f64; 3], f64)> {
        let f = &plan.view;
        let mut dims = [0usize; 3];
        for c in 0..3 {
            dims[f.perm[c]] = f.n[c];
        }
        self.planes
            .iter()
            .map(|pl| {
                // n · S(v − c) ≤ d  ⇔  (n S) · v ≤ d + (n S) · c
                let nv: [f64; 3] = [0, 1, 2].map(|a| pl.normal[a] * self.spacing[a]);
                let e = pl.offset + (0..3).map(|a| nv[a] * (dims[a] as f64 - 1.0) / 2.0).sum::<f64>();
                ([nv[f.perm[0]], nv[f.perm[1]], nv[f.perm[2]]], e)
            })
            .collect()
    }
}

/// The in-slice sample position `(i, j)` of pixel `(p, q)` in slice `k`
/// (voxel units, before the floor every traversal takes).
#[inline]
fn sample_ij(plan: &FramePlan, k: usize, p: usize, q: usize) -> [f64; 2] {
    let pad = plan.grid.pad as f64;
    match plan.kind {
        MapKind::Translate => [p as f64 - pad + plan.shear.trans[0][k], q as f64 - pad + plan.shear.trans[1][k]],
        MapKind::ScaleTranslate => {
            let m = &plan.scaled[k];
            let [pa, pb] = plan.grid.pitch;
            [m.scale * ((p as f64 - pad) * pa) + m.trans[0], m.scale * ((q as f64 - pad) * pb) + m.trans[1]]
        }
    }
}

/// The signed distance (positive: removed) of pixel `(p, q)`'s sample in
/// slice `k` from plane `m · x ≤ e`, in the plane's voxel units.
#[inline]
fn signed(plan: &FramePlan, (m, e): ([f64; 3], f64), k: usize, p: usize, q: usize) -> f64 {
    let [i, j] = sample_ij(plan, k, p, q);
    m[0] * i + m[1] * j + m[2] * k as f64 - e
}

/// Whether pixel `(p, q)`'s sample in slice `k` lies on the kept side of every plane.
pub fn sample_kept(clip: &ClipPlanes, plan: &FramePlan, k: usize, p: usize, q: usize) -> bool {
    clip.in_voxels(plan).into_iter().all(|pl| signed(plan, pl, k, p, q) <= 0.0)
}

/// The slices `[k0, k1]` (signed; `k0 > k1` for none) of `0 .. nk` whose
/// samples of pixel `(p, q)` plane `pl` keeps.
fn kept_interval(plan: &FramePlan, pl: ([f64; 3], f64), nk: usize, p: usize, q: usize) -> [i64; 2] {
    let last = nk as i64 - 1;
    let g = |k: i64| signed(plan, pl, k as usize, p, q);
    let (g0, g1) = (g(0), g(last));
    if g0 <= 0.0 && g1 <= 0.0 {
        return [0, last];
    }
    if g0 > 0.0 && g1 > 0.0 {
        return [1, 0];
    }
    // one crossing: g is affine in k, zero at k* = g0 / (g0 − g1) · last
    let ks = (g0 / (g0 - g1) * last as f64).clamp(0.0, last as f64);
    if g0 <= 0.0 {
        // kept from the first slice up to the crossing
        let mut b = (ks.floor() as i64).clamp(0, last);
        while b >= 0 && g(b) > 0.0 {
            b -= 1;
        }
        while b < last && g(b + 1) <= 0.0 {
            b += 1;
        }
        [0, b]
    } else {
        let mut a = (ks.ceil() as i64).clamp(0, last);
        while a <= last && g(a) > 0.0 {
            a += 1;
        }
        while a > 0 && g(a - 1) <= 0.0 {
            a -= 1;
        }
        [a, last]
    }
}

impl Limiter for ClipPlanes {
    fn limit(&self, plan: &FramePlan, limits: &mut RayLimits) {
        let nk = plan.slices();
        if nk == 0 || self.planes.is_empty() {
            return;
        }
        let planes = self.in_voxels(plan);
        // rows in parallel (on the caller's pool; each pixel's interval depends
        // on that pixel alone, so the limits are the same for any thread count)
        limits.par_rows_mut().enumerate().for_each(|(q, row)| {
            for (p, l) in row.iter_mut().enumerate() {
                let (mut lo, mut hi) = (l[0] as i64, l[1] as i64);
                for &pl in &planes {
                    if lo > hi {
                        break;
                    }
                    let [a, b] = kept_interval(plan, pl, nk, p, q);
                    lo = lo.max(a);
                    hi = hi.min(b);
                }
                *l = if lo > hi { [1, 0] } else { [lo as u32, hi as u32] };
            }
        });
    }
}

/// A convex region of the volume, in voxel-index coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Region {
    /// A ball: centre in voxel indices, radius in units of the smallest voxel
    /// spacing (voxels on an isotropic grid), round in world space.
    Sphere { centre: [f64; 3], radius: f64 },
    /// The axis-aligned box `[lo, hi]` of voxel indices.
    Box { lo: [f64; 3], hi: [f64; 3] },
}

/// Which side of a clip region is kept.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Keep {
    /// The samples inside (boundary included).
    #[default]
    Inside,
    /// The samples outside: the region is cut out of the volume.
    Outside,
}

/// A convex clip region whose inside (or, [`ClipRegion::keeping`], outside)
/// is kept (see the [module docs](self)): a [`Limiter`].
#[derive(Clone, Debug, PartialEq)]
pub struct ClipRegion {
    region: Region,
    spacing: [f64; 3],
    keep: Keep,
}

impl ClipRegion {
    /// The region `region` of a volume with voxel `spacing`, checked (finite
    /// numbers, a radius > 0, `lo < hi` on every axis).
    pub fn new(region: Region, spacing: [f32; 3]) -> Result<Self> {
        if spacing.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(Error::value("clip region", format!("the voxel spacing must be finite and > 0, got {spacing:?}")));
        }
        match region {
            Region::Sphere { centre, radius } => {
                if !(centre.iter().all(|c| c.is_finite()) && radius.is_finite() && radius > 0.0) {
                    return Err(Error::value(
                        "clip sphere",
                        format!("centre {centre:?}, radius {radius} (needs finite numbers, radius > 0)"),
                    ));
                }
            }
            Region::Box { lo, hi } => {
                if !(lo.iter().chain(&hi).all(|c| c.is_finite()) && (0..3).all(|a| lo[a] < hi[a])) {
                    return Err(Error::value("clip box", format!("{lo:?} .. {hi:?} (needs finite corners, lo < hi on every axis)")));
                }
            }
        }
        Ok(ClipRegion { region, spacing: spacing.map(|s| s as f64), keep: Keep::Inside })
    }

    /// The same region keeping `keep` (default: inside).
    pub fn keeping(mut self, keep: Keep) -> Self {
        self.keep = keep;
        self
    }

    /// The region.
    pub fn region(&self) -> Region {
        self.region
    }

    /// The side kept.
    pub fn keep(&self) -> Keep {
        self.keep
    }

    /// Whether voxel-index point `v` is kept: inside the region, or outside
    /// it for [`Keep::Outside`].
    pub fn keeps(&self, v: DVec3) -> bool {
        self.contains(v) == (self.keep == Keep::Inside)
    }

    /// Whether voxel-index point `v` is inside (boundary included).
    pub fn contains(&self, v: DVec3) -> bool {
        match self.region {
            Region::Sphere { centre, radius } => {
                let unit = self.spacing.iter().fold(f64::INFINITY, |a, &b| a.min(b));
                let d = DVec3::from_array([0, 1, 2].map(|a| (v[a] - centre[a]) * self.spacing[a] / unit));
                d.length_squared() <= radius * radius
            }
            Region::Box { lo, hi } => (0..3).all(|a| lo[a] <= v[a] && v[a] <= hi[a]),
        }
    }

    /// The intermediate pixels `[p0, p1] × [q0, q1]` (inclusive) outside
    /// which no ray has a sample inside the region (`None`: no ray has one):
    /// in each slice the region's bounding box widened by a voxel, mapped
    /// to pixels through the slice's sample map (affine in the pixel) and
    /// widened by a pixel; the whole grid where a map is degenerate.
    /// (The negated comparisons read a NaN bound as no ray.)
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    fn grid_bounds(&self, plan: &FramePlan) -> Option<[usize; 4]> {
        let (nk, [gw, gh]) = (plan.slices(), plan.grid.size);
        if nk == 0 || gw == 0 || gh == 0 {
            return None;
        }
        let (lo, hi) = match self.region {
            Region::Sphere { centre, radius } => {
                let unit = self.spacing.iter().fold(f64::INFINITY, |a, &b| a.min(b));
                let e: [f64; 3] = std::array::from_fn(|a| radius * unit / self.spacing[a]);
                (std::array::from_fn(|a| centre[a] - e[a]), std::array::from_fn(|a| centre[a] + e[a]))
            }
            Region::Box { lo, hi } => (lo, hi),
        };
        let (lo, hi): ([f64; 3], [f64; 3]) = (lo.map(|x| x - 1.0), hi.map(|x| x + 1.0));
        let perm = plan.view.perm;
        let k0 = lo[perm[2]].ceil().max(0.0);
        let k1 = hi[perm[2]].floor().min((nk - 1) as f64);
        if !(k0 <= k1) {
            return None;
        }
        let mut r = [f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY];
        for k in k0 as usize..=k1 as usize {
            for axis in 0..2 {
                let a0 = plan.sample_at(k, axis, 0);
                let s = plan.sample_at(k, axis, 1) - a0;
                if !(s > 0.0 && s.is_finite() && a0.is_finite()) {
                    return Some([0, gw - 1, 0, gh - 1]);
                }
                let (x0, x1) = ((lo[perm[axis]] - a0) / s, (hi[perm[axis]] - a0) / s);
                r[2 * axis] = r[2 * axis].min(x0);
                r[2 * axis + 1] = r[2 * axis + 1].max(x1);
            }
        }
        let (p0, p1) = ((r[0].floor() - 1.0).max(0.0), (r[1].ceil() + 1.0).min((gw - 1) as f64));
        let (q0, q1) = ((r[2].floor() - 1.0).max(0.0), (r[3].ceil() + 1.0).min((gh - 1) as f64));
        if !(p0 <= p1 && q0 <= q1) {
            return None;
        }
        Some([p0 as usize, p1 as usize, q0 as usize, q1 as usize])
    }

    /// Whether the line `o + t·d` passes the ball of `radius` (in units of
    /// the smallest spacing) farther than 10⁻⁶ of a unit (plus the same
    /// fraction of the radius) away at its closest point `t`, the closest
    /// approach [`ClipRegion::line_interval`] returns for a line missing it.
    fn line_misses_ball(&self, o: DVec3, d: DVec3, t: f64, radius: f64) -> bool {
        let Region::Sphere { centre, .. } = self.region else { return false };
        let unit = self.spacing.iter().fold(f64::INFINITY, |a, &b| a.min(b));
        let x = o + t * d;
        let e = DVec3::from_array([0, 1, 2].map(|a| (x[a] - centre[a]) * self.spacing[a] / unit));
        t.is_finite() && e.length() > radius * (1.0 + 1e-6) + 1e-6
    }

    /// The real interval `[t0, t1]` of `t` with `o + t·d` inside (empty: `t0 > t1`).
    fn line_interval(&self, o: DVec3, d: DVec3) -> [f64; 2] {
        match self.region {
            Region::Sphere { centre, radius } => {
                let unit = self.spacing.iter().fold(f64::INFINITY, |a, &b| a.min(b));
                let w = |v: DVec3, c: bool| {
                    DVec3::from_array([0, 1, 2].map(|a| (v[a] - if c { centre[a] } else { 0.0 }) * self.spacing[a] / unit))
                };
                let (o, d) = (w(o, true), w(d, false));
                // |o + t d|² = r²
                let (a, b, c) = (d.length_squared(), o.dot(d), o.length_squared() - radius * radius);
                if a == 0.0 {
                    return if c <= 0.0 { [f64::NEG_INFINITY, f64::INFINITY] } else { [1.0, 0.0] };
                }
                let disc = b * b - a * c;
                if disc < 0.0 {
                    // (no crossing, or a tangent lost to rounding: the closest
                    // approach, which the samples then decide)
                    return [-b / a, -b / a];
                }
                let s = disc.sqrt();
                [(-b - s) / a, (-b + s) / a]
            }
            Region::Box { lo, hi } => {
                let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
                for a in 0..3 {
                    if d[a] == 0.0 {
                        if o[a] < lo[a] || o[a] > hi[a] {
                            return [1.0, 0.0];
                        }
                    } else {
                        let (x, y) = ((lo[a] - o[a]) / d[a], (hi[a] - o[a]) / d[a]);
                        t0 = t0.max(x.min(y));
                        t1 = t1.min(x.max(y));
                    }
                }
                [t0, t1]
            }
        }
    }
}

/// The voxel-index position of pixel `(p, q)`'s sample in slice `k`.
fn sample_voxel(plan: &FramePlan, k: usize, p: usize, q: usize) -> DVec3 {
    crate::view::unpermute(plan.view.perm, DVec3::new(plan.sample_at(k, 0, p), plan.sample_at(k, 1, q), k as f64))
}

impl ClipRegion {
    /// The slices `[a, b]` (`a > b`: none) of `0 ..= last` whose samples of
    /// pixel `(p, q)` lie inside the region.
    fn inside_interval(&self, plan: &FramePlan, last: i64, p: usize, q: usize) -> [i64; 2] {
        // the ray's samples are affine in k: o + k·d
        let o = sample_voxel(plan, 0, p, q);
        let d = if last > 0 { (sample_voxel(plan, last as usize, p, q) - o) / last as f64 } else { DVec3::ZERO };
        let inside = |k: i64| self.contains(sample_voxel(plan, k as usize, p, q));
        let [t0, t1] = self.line_interval(o, d);
        if let Region::Sphere { radius, .. } = self.region
            && t0 == t1
            && self.line_misses_ball(o, d, t0, radius)
        {
            // a line clearly outside the ball (a lens's focus: most rays of
            // the frame) has no sample inside it: the samples lie on the
            // line up to rounding, far below the margin, so the checks on
            // the samples below would find none
            return [1, 0];
        }
        // a one-sample margin for rounding (an interval empty by rounding
        // alone is checked around where it closed)
        let (t0, t1) = if t0 <= t1 { (t0, t1) } else { (t0.clamp(-1.0, last as f64 + 1.0), t0.clamp(-1.0, last as f64 + 1.0)) };
        ends_on_samples(t0, t1, last, inside)
    }
}

/// The slices `[a, b]` (`a > b`: none) of `0 ..= last` inside a convex region
/// whose ray interval was solved as `[t0, t1]` (fractional slices; NaN reads
/// as 0): the solved ends widened by a one-sample margin for rounding, then
/// moved onto the samples themselves by `inside(k)` (a ray meets a convex
/// region in one interval, so walking in from both ends finds it).
pub(crate) fn ends_on_samples(t0: f64, t1: f64, last: i64, inside: impl Fn(i64) -> bool) -> [i64; 2] {
    let edge = |t: f64| if t.is_nan() { 0.0 } else { t.clamp(-2.0, last as f64 + 2.0) };
    let mut a = (edge(t0).floor() as i64 - 1).clamp(0, last);
    let mut b = (edge(t1).ceil() as i64 + 1).clamp(0, last);
    while a <= b && !inside(a) {
        a += 1;
    }
    while b >= a && !inside(b) {
        b -= 1;
    }
    if a <= b {
        while a > 0 && inside(a - 1) {
            a -= 1;
        }
        while b < last && inside(b + 1) {
            b += 1;
        }
    }
    [a, b]
}

/// A convex region's limits: every open ray of `limits` keeps the slices of
/// `inside_interval(last, p, q)` (`Keep::Inside`: the intersection) or loses
/// them (`Keep::Outside`: the hole, [`cut_ray`]). Shared by [`ClipRegion`]
/// and the convex clip mesh.
pub(crate) fn limit_convex(
    keep: Keep,
    plan: &FramePlan,
    limits: &mut RayLimits,
    inside_interval: impl Fn(i64, usize, usize) -> [i64; 2] + Sync,
) {
    let nk = plan.slices();
    if nk == 0 {
        return;
    }
    let last = nk as i64 - 1;
    match keep {
        Keep::Inside => limits.par_rows_mut().enumerate().for_each(|(q, row)| {
            for (p, l) in row.iter_mut().enumerate() {
                if l[0] > l[1] {
                    continue;
                }
                let [a, b] = inside_interval(last, p, q);
                let (lo, hi) = ((l[0] as i64).max(a), (l[1] as i64).min(b));
                *l = if lo > hi { [1, 0] } else { [lo as u32, hi as u32] };
            }
        }),
        Keep::Outside => limits.holes_rows_mut().enumerate().for_each(|(q, (row, holes))| {
            for (p, (l, h)) in row.iter_mut().zip(holes.iter_mut()).enumerate() {
                if l[0] > l[1] {
                    continue;
                }
                (*l, *h) = cut_ray(*l, *h, inside_interval(last, p, q));
            }
        }),
    }
}

impl Limiter for ClipRegion {
    fn limit(&self, plan: &FramePlan, limits: &mut RayLimits) {
        // the rays outside the region's grid bounds have no sample inside it
        // (the checks would find none): a region small on a large grid (a
        // lens on a matched-sampling still frame) costs its own rays only
        let b = self.grid_bounds(plan);
        let near = |p: usize, q: usize| b.is_some_and(|[p0, p1, q0, q1]| p0 <= p && p <= p1 && q0 <= q && q <= q1);
        limit_convex(self.keep, plan, limits, |last, p, q| if near(p, q) { self.inside_interval(plan, last, p, q) } else { [1, 0] });
    }

    fn holes(&self) -> usize {
        (self.keep == Keep::Outside) as usize
    }
}

/// Several limiters applied in turn: each narrows the rays' intervals (or
/// cuts their hole), so the result keeps the samples every one keeps.
#[derive(Clone, Default)]
pub struct Limiters(pub Vec<Arc<dyn Limiter>>);

impl Limiters {
    /// The limiters, checked: a ray holds one hole, so at most one of them
    /// may keep the outside of a region ([`Limiter::holes`]).
    pub fn new(limiters: Vec<Arc<dyn Limiter>>) -> Result<Self> {
        let holes: usize = limiters.iter().map(|l| l.holes()).sum();
        if holes > 1 {
            return Err(Error::value(
                "clip regions",
                format!("{holes} regions keep their outside; a ray holds one hole, so at most one region may keep its outside"),
            ));
        }
        Ok(Limiters(limiters))
    }
}

impl Limiter for Limiters {
    fn limit(&self, plan: &FramePlan, limits: &mut RayLimits) {
        for l in &self.0 {
            l.limit(plan, limits);
        }
    }

    fn holes(&self) -> usize {
        self.0.iter().map(|l| l.holes()).sum()
    }

    fn parallel(&self, plan: &FramePlan) -> bool {
        self.0.iter().any(|l| l.parallel(plan))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::view::perspective::PerspectiveView;
    use crate::view::{Camera, Factorization};
    use glam::{DMat3, EulerRot};

    fn plans() -> Vec<FramePlan> {
        let (dims, sp) = ([14, 17, 11], [1.0f32, 0.8, 1.5]);
        let mut out = vec![];
        for (x, y, z) in [(0.0, 0.0, 0.0), (0.4, -0.9, 0.2), (-1.3, 2.1, 0.7), (std::f64::consts::FRAC_PI_4, 0.6155, 0.0)] {
            let cam = Camera { rotation: DMat3::from_euler(EulerRot::XYZ, x, y, z), zoom: Some(2.0), size: [64, 64] };
            let f = Factorization::new(&cam, dims, sp).unwrap();
            out.push(FramePlan::parallel(&f, sp));
            let pv = PerspectiveView::new(&cam, 60.0, dims, sp).unwrap();
            out.push(FramePlan::perspective(&pv, &f, sp, 0.5));
        }
        out
    }

    /// Asserts that `limiter`'s limits on `plan` keep exactly the samples
    /// `kept(k, p, q)` keeps: the interval less the hole, once normalized
    /// (every hole strictly inside its interval).
    fn assert_limits_are(plan: &FramePlan, limiter: &dyn Limiter, kept: impl Fn(usize, usize, usize) -> bool, what: &str) -> usize {
        let mut l = RayLimits::open(plan.grid.size, plan.slices());
        limiter.limit(plan, &mut l);
        l.normalize();
        let [w, h] = plan.grid.size;
        let mut n = 0;
        for q in 0..h {
            for p in 0..w {
                let [a, b] = l.get(p, q);
                let [h0, h1] = l.hole(p, q);
                assert!(h0 > h1 || (a < h0 && h1 < b), "{what} pixel ({p}, {q}): hole {:?} not strictly inside {:?}", [h0, h1], [a, b]);
                for k in 0..plan.slices() {
                    let inside = a <= b && (a as usize..=b as usize).contains(&k) && !(h0 as usize..=h1 as usize).contains(&k);
                    assert_eq!(inside, l.keeps(p, q, k));
                    assert_eq!(inside, kept(k, p, q), "{what} pixel ({p}, {q}) slice {k}: {:?} hole {:?}", [a, b], [h0, h1]);
                    n += inside as usize;
                }
            }
        }
        n
    }

    /// Spheres and boxes inside, across, around and off the test plans' volume.
    const REGIONS: [Region; 6] = [
        Region::Sphere { centre: [7.0, 8.0, 5.0], radius: 4.5 },
        Region::Sphere { centre: [0.0, 0.0, 0.0], radius: 6.0 },
        Region::Sphere { centre: [70.0, 8.0, 5.0], radius: 2.0 },
        Region::Box { lo: [2.5, 3.0, 1.2], hi: [9.0, 12.5, 8.0] },
        Region::Box { lo: [-5.0, -5.0, -5.0], hi: [50.0, 50.0, 50.0] },
        Region::Box { lo: [6.0, 0.0, 0.0], hi: [7.2, 17.0, 11.0] },
    ];

    #[test]
    fn clip_region_outside_limits_are_exactly_the_samples_outside() {
        let sp = [1.0f32, 0.8, 1.5];
        let regions = REGIONS;
        let mut holes = 0;
        for plan in plans() {
            for r in regions {
                let clip = ClipRegion::new(r, sp).unwrap().keeping(Keep::Outside);
                assert_eq!(clip.holes(), 1);
                let kept = assert_limits_are(&plan, &clip, |k, p, q| !clip.contains(sample_voxel(&plan, k, p, q)), &format!("{r:?}"));
                let all = plan.grid.size[0] * plan.grid.size[1] * plan.slices();
                assert_eq!(kept < all, !matches!(r, Region::Sphere { centre: [70.0, ..], .. }), "{r:?}");
                let mut l = RayLimits::open(plan.grid.size, plan.slices());
                clip.limit(&plan, &mut l);
                l.normalize();
                holes += l.has_holes() as usize;
            }
        }
        assert!(holes > 8, "only {holes} frames cut holes");
    }

    /// Planes and inside regions (intervals) chained with an outside region
    /// (a hole), in either order, keep the samples every one keeps.
    #[test]
    fn clip_chained_with_an_outside_region_keep_the_samples_every_one_keeps() {
        let sp = [1.0f32, 0.8, 1.5];
        let plane = ClipPlanes::new(&[ClipPlane::new([0.3, -0.5, 0.8], 1.3).unwrap()], sp).unwrap();
        let ball = ClipRegion::new(Region::Sphere { centre: [7.0, 8.0, 5.0], radius: 6.0 }, sp).unwrap();
        let hole = ClipRegion::new(Region::Box { lo: [4.5, 5.0, 2.2], hi: [9.0, 11.5, 7.0] }, sp).unwrap().keeping(Keep::Outside);
        let chains: [Vec<Arc<dyn Limiter>>; 3] = [
            vec![Arc::new(plane.clone()), Arc::new(ball.clone()), Arc::new(hole.clone())],
            vec![Arc::new(hole.clone()), Arc::new(plane.clone()), Arc::new(ball.clone())],
            vec![Arc::new(ball.clone()), Arc::new(hole.clone())],
        ];
        for plan in plans() {
            for (i, chain) in chains.iter().enumerate() {
                let both = Limiters::new(chain.clone()).unwrap();
                let want = |k, p, q| {
                    let v = sample_voxel(&plan, k, p, q);
                    (i == 2 || sample_kept(&plane, &plan, k, p, q)) && ball.contains(v) && hole.keeps(v)
                };
                assert_limits_are(&plan, &both, want, &format!("chain {i}"));
            }
        }
        // two outside regions: a ray holds one hole
        let e = Limiters::new(vec![Arc::new(hole.clone()), Arc::new(hole.clone())]).err().unwrap().to_string();
        assert!(e.contains("outside"), "{e}");
    }

    #[test]
    fn clip_cut_ray_unions_and_normalizes_holes() {
        use crate::view::plan::{NO_HOLE, cut_ray};
        assert_eq!(cut_ray([0, 9], NO_HOLE, [3, 5]), ([0, 9], [3, 5]));
        assert_eq!(cut_ray([0, 9], NO_HOLE, [-4, 2]), ([3, 9], NO_HOLE));
        assert_eq!(cut_ray([0, 9], NO_HOLE, [7, 20]), ([0, 6], NO_HOLE));
        assert_eq!(cut_ray([0, 9], NO_HOLE, [-1, 12]), (NO_HOLE, NO_HOLE));
        assert_eq!(cut_ray([0, 9], [3, 5], [6, 7]), ([0, 9], [3, 7]));
        assert_eq!(cut_ray([0, 9], [3, 5], [1, 4]), ([0, 9], [1, 5]));
        assert_eq!(cut_ray([0, 9], [3, 5], [5, 9]), ([0, 2], NO_HOLE));
        assert_eq!(cut_ray([0, 9], NO_HOLE, [12, 15]), ([0, 9], NO_HOLE));
        assert_eq!(cut_ray(NO_HOLE, NO_HOLE, [2, 3]), (NO_HOLE, NO_HOLE));
    }

    #[test]
    fn limits_are_exactly_the_samples_kept() {
        let sp = [1.0f32, 0.8, 1.5];
        let sets = [
            vec![ClipPlane::new([1.0, 0.0, 0.0], 0.0).unwrap()],
            vec![ClipPlane::new([0.3, -0.5, 0.8], 1.3).unwrap(), ClipPlane::new([-1.0, 0.2, 0.1], 2.0).unwrap()],
            vec![ClipPlane::new([0.0, 0.0, 1.0], 100.0).unwrap()],
            vec![ClipPlane::new([0.0, 1.0, 0.0], -100.0).unwrap()],
            vec![ClipPlane::through([1.0, 2.0, -1.5], [0.2, 0.7, -0.4]).unwrap(), ClipPlane::new([0.0, 0.0, 1.0], 3.0).unwrap()],
        ];
        for plan in plans() {
            for set in &sets {
                let clip = ClipPlanes::new(set, sp).unwrap();
                assert_limits_are(&plan, &clip, |k, p, q| sample_kept(&clip, &plan, k, p, q), "");
            }
        }
    }

    #[test]
    fn clip_region_limits_are_exactly_the_samples_inside() {
        let sp = [1.0f32, 0.8, 1.5];
        let regions = REGIONS;
        for plan in plans() {
            for r in regions {
                let clip = ClipRegion::new(r, sp).unwrap();
                let kept = assert_limits_are(&plan, &clip, |k, p, q| clip.contains(sample_voxel(&plan, k, p, q)), &format!("{r:?}"));
                assert_eq!(kept > 0, !matches!(r, Region::Sphere { centre: [70.0, ..], .. }), "{r:?}");
            }
        }
    }

    #[test]
    fn chained_limiters_keep_the_samples_every_one_keeps() {
        let sp = [1.0f32, 0.8, 1.5];
        let plane = ClipPlanes::new(&[ClipPlane::new([0.3, -0.5, 0.8], 1.3).unwrap()], sp).unwrap();
        let ball = ClipRegion::new(Region::Sphere { centre: [7.0, 8.0, 5.0], radius: 5.0 }, sp).unwrap();
        let both = Limiters(vec![Arc::new(plane.clone()), Arc::new(ball.clone())]);
        for plan in plans() {
            let want = |k, p, q| sample_kept(&plane, &plan, k, p, q) && ball.contains(sample_voxel(&plan, k, p, q));
            assert_limits_are(&plan, &both, want, "");
        }
    }

    #[test]
    fn bad_clip_regions_are_errors() {
        let sp = [1.0f32; 3];
        assert!(ClipRegion::new(Region::Sphere { centre: [0.0; 3], radius: 0.0 }, sp).is_err());
        assert!(ClipRegion::new(Region::Sphere { centre: [f64::NAN, 0.0, 0.0], radius: 1.0 }, sp).is_err());
        assert!(ClipRegion::new(Region::Box { lo: [0.0; 3], hi: [1.0, 0.0, 1.0] }, sp).is_err());
        assert!(ClipRegion::new(Region::Box { lo: [0.0; 3], hi: [1.0, f64::INFINITY, 1.0] }, sp).is_err());
        assert!(ClipRegion::new(Region::Box { lo: [0.0; 3], hi: [1.0; 3] }, [0.0, 1.0, 1.0]).is_err());
    }

    #[test]
    fn zero_nan_and_infinite_normals_are_errors() {
        for n in [[0.0; 3], [f64::NAN, 1.0, 0.0], [0.0, f64::INFINITY, 0.0], [-0.0, 0.0, -0.0]] {
            let e = ClipPlane::new(n, 0.0).unwrap_err();
            assert!(e.to_string().contains("normal"), "{e}");
        }
        assert!(ClipPlane::new([1.0, 0.0, 0.0], f64::NAN).is_err());
        assert!(ClipPlane::through([f64::NAN, 0.0, 0.0], [1.0, 0.0, 0.0]).is_err());
        // a struct built by hand is checked too
        let bad = ClipPlane { normal: [f64::NAN; 3], offset: 0.0 };
        assert!(ClipPlanes::new(&[bad], [1.0; 3]).is_err());
        let one = ClipPlane::new([1.0, 0.0, 0.0], 0.0).unwrap();
        assert!(ClipPlanes::new(&[one; 7], [1.0; 3]).is_err());
        assert!(ClipPlanes::new(&[one; 6], [1.0; 3]).is_ok());
        assert!(ClipPlanes::new(&[one], [0.0, 1.0, 1.0]).is_err());
    }
}
