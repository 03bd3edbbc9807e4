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

use crate::encode::shear::ShearState;
use crate::view::Factorization;

/// How the slices' sample maps are built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MapKind {
    /// Every slice is the intermediate grid translated: `(i, j) = (p − pad, q − pad) + trans[k]`.
    Translate,
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
/// `(a, b) = (p − pad, q − pad) · pitch`: today one pixel per voxel (`pitch` 1)
/// with `pad` pixels of margin on every side for the shear.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Grid {
    /// `[width, height]` in pixels.
    pub size: [usize; 2],
    /// Margin, in pixels, between the grid's edge and sheared `(0, 0)`.
    pub pad: usize,
    /// Voxels per intermediate pixel.
    pub pitch: f64,
}

impl Grid {
    /// The grid of a volume of `cells` cells per slice and `nk` slices under any
    /// parallel view: the shear moves a slice by at most `(nk − 1)/2` voxels from
    /// the centre (plus a rounding margin).
    pub fn parallel(cells: [usize; 2], nk: usize) -> Grid {
        let pad = nk.saturating_sub(1).div_ceil(2) + 2;
        Grid { size: [cells[0] + 2 * pad, cells[1] + 2 * pad], pad, pitch: 1.0 }
    }

    /// Pixels.
    pub fn pixels(&self) -> usize {
        self.size[0] * self.size[1]
    }
}

/// The warp from sheared coordinates `(a, b)` to output pixels `(u, v)` as 3×3
/// homogeneous matrices (column vectors: `[u w, v w, w] = forward · [a, b, 1]`),
/// and the inverse, which the warp kernel and the depth lookups use.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Warp {
    pub forward: DMat3,
    pub inverse: DMat3,
}

impl Default for Warp {
    fn default() -> Self {
        Warp { forward: DMat3::IDENTITY, inverse: DMat3::IDENTITY }
    }
}

impl Warp {
    /// True when both maps are affine (bottom row `0, 0, 1`): the warp kernel's
    /// fast path, with coordinates stepping linearly along a row.
    pub fn is_affine(&self) -> bool {
        let f = self.forward.row(2);
        let i = self.inverse.row(2);
        f == DVec3::Z && i == DVec3::Z
    }

    /// The sheared point of output pixel `(u, v)`, or `None` where the
    /// back-projection has `w ≤ 0` (behind the eye).
    pub fn to_sheared(&self, u: f64, v: f64) -> Option<[f64; 2]> {
        let m = &self.inverse;
        // in the affine case this is the 2×2 map plus translation, term by term
        let a = m.x_axis.x * u + m.y_axis.x * v + m.z_axis.x;
        let b = m.x_axis.y * u + m.y_axis.y * v + m.z_axis.y;
        let w = m.x_axis.z * u + m.y_axis.z * v + m.z_axis.z;
        if w == 1.0 {
            Some([a, b])
        } else if w > 0.0 {
            Some([a / w, b / w])
        } else {
            None
        }
    }

    /// The output pixel of sheared point `(a, b)`, or `None` behind the eye.
    pub fn to_output(&self, a: f64, b: f64) -> Option<[f64; 2]> {
        let p = self.forward * DVec3::new(a, b, 1.0);
        if p.z == 1.0 {
            Some([p.x, p.y])
        } else if p.z > 0.0 {
            Some([p.x / p.z, p.y / p.z])
        } else {
            None
        }
    }
}

/// Per-pixel ray limits over the intermediate grid: pixel `(p, q)` composites
/// only slices `k0 ..= k1` (slice indices, `k0 > k1` for none), whichever
/// order the view walks them in.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RayLimits {
    width: usize,
    limits: Vec<[u32; 2]>,
}

impl RayLimits {
    /// Limits for a grid, every pixel open over `0 ..= nk − 1`.
    pub fn open(grid: [usize; 2], nk: usize) -> Self {
        RayLimits { width: grid[0], limits: vec![[0, nk.saturating_sub(1) as u32]; grid[0] * grid[1]] }
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

    /// The grid width.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Reopens every pixel of a grid over `0 ..= nk − 1`, reusing the allocation.
    pub fn reset(&mut self, grid: [usize; 2], nk: usize) {
        self.width = grid[0];
        self.limits.clear();
        self.limits.resize(grid[0] * grid[1], [0, nk.saturating_sub(1) as u32]);
    }
}

/// A producer of per-pixel ray limits — a clip region, geometry in the volume —
/// asked once per frame, after the projection has made the plan: it narrows
/// `limits` (every pixel open when it is called) for the plan's grid and slices.
pub trait Limiter: Send + Sync {
    fn limit(&self, plan: &FramePlan, limits: &mut RayLimits);
}

impl<F: Fn(&FramePlan, &mut RayLimits) + Send + Sync> Limiter for F {
    fn limit(&self, plan: &FramePlan, limits: &mut RayLimits) {
        self(plan, limits)
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
    /// Real sample spacing over the spacing opacities are defined at (the
    /// smallest voxel spacing): `α' = 1 − (1 − α)^ratio`.
    pub opacity_ratio: f32,
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
            opacity_ratio: 1.0,
        };
        p.set_parallel(f, spacing);
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
        let min_sp = spacing.iter().fold(f32::MAX, |a, &b| a.min(b)) as f64;
        self.opacity_ratio = (f.sample_spacing / min_sp) as f32;
    }

    /// Lets `limiter` narrow the rays of this plan, into `buf` (reused across
    /// frames; taken back with [`FramePlan::take_limits`]).
    pub fn apply_limiter(&mut self, limiter: &dyn Limiter, mut buf: RayLimits) {
        buf.reset(self.grid.size, self.slices());
        limiter.limit(self, &mut buf);
        self.limits = Some(buf);
    }

    /// Removes and returns the ray limits (their buffer, for reuse).
    pub fn take_limits(&mut self) -> Option<RayLimits> {
        self.limits.take()
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
        Some([a / self.grid.pitch + pad, b / self.grid.pitch + pad])
    }

    /// The sheared point `(a, b)` of intermediate pixel `(p, q)`.
    pub fn intermediate_to_sheared(&self, p: f64, q: f64) -> [f64; 2] {
        let pad = self.grid.pad as f64;
        [(p - pad) * self.grid.pitch, (q - pad) * self.grid.pitch]
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
