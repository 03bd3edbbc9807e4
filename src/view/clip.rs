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

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::view::plan::{FramePlan, Limiter, MapKind, RayLimits};

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
        Self::new(m, offset - (0..3).map(|a| normal[a] * c[a]).sum::<f64>())
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
            let pitch = plan.grid.pitch;
            [m.scale * ((p as f64 - pad) * pitch) + m.trans[0], m.scale * ((q as f64 - pad) * pitch) + m.trans[1]]
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
                let mut l = RayLimits::open(plan.grid.size, plan.slices());
                clip.limit(&plan, &mut l);
                let [w, h] = plan.grid.size;
                for q in 0..h {
                    for p in 0..w {
                        let [a, b] = l.get(p, q);
                        for k in 0..plan.slices() {
                            let inside = a <= b && (a as usize..=b as usize).contains(&k);
                            assert_eq!(inside, sample_kept(&clip, &plan, k, p, q), "pixel ({p}, {q}) slice {k}: {:?}", [a, b]);
                        }
                    }
                }
            }
        }
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
