//! The view factorization (parallel projection).
//!
//! Owns the camera ([`Camera`]: rotation, zoom, output size) and Lacroute's
//! factorization of the viewing transform into a *shear* of the volume slices and
//! a 2-D affine *warp* of the intermediate image ([`Factorization`]). Every render
//! path (binary, RLE, brute force, and later perspective/hybrid) takes its
//! principal axis, slice order, per-slice translations and warp from here.
//!
//! Conventions:
//! - World coordinates are millimetres with the volume centre at the origin:
//!   `w = S · (v − (n − 1)/2)` for voxel index `v` and spacing `S`.
//! - Eye coordinates are `e = R · w`: x right, y up, the viewer at +z looking
//!   toward −z (so larger `e.z` is nearer).
//! - Image pixel centres are at integer coordinates, row 0 at the top:
//!   `u = (W − 1)/2 + zoom · e.x`, `v = (H − 1)/2 − zoom · e.y`.
//! - The principal axis is chosen in *voxel index space* (spacing folded in), so
//!   the per-slice shear is at most one voxel per slice even for anisotropic
//!   volumes. Ties (exactly 45°) go to z, then y, then x, within a relative
//!   tolerance of [`TIE_TOLERANCE`].
//! - Permuted axes `(i, j, k)`: principal x → (y, z, x); y → (z, x, y); z → (x, y, z)
//!   ([`permutation`], cyclic). A factorization may be given other
//!   permutations ([`Factorization::with_permutations`]): the RLE paths' reuse
//!   of one encoding for two axes reads z through the mirrored (y, x, z)
//!   ([`reuse_permutation`]), whose scanlines run along y like x's. Nothing
//!   here assumes a cyclic (determinant +1) permutation: the warp, shear,
//!   shading directions and [`Factorization::sheared_to_voxel`] all follow
//!   `perm`, so the samples are the same 3-D points and the intermediate
//!   image is the cyclic one transposed.
//! - The ray through intermediate pixel `(a, b)` (sheared coordinates, relative
//!   to the volume's cell origin) meets slice `k` at in-slice position
//!   `(a + trans_i[k], b + trans_j[k])`, where `trans[k] = s · (k − kc)`,
//!   `kc = (nk − 1)/2`, and `s = d_i/d_k, d_j/d_k` is the shear.

use glam::{DMat3, DVec2, DVec3};

use crate::error::{Error, Result};
use crate::view::camera::Camera;

/// Relative tolerance under which two view-direction components count as equal.
pub const TIE_TOLERANCE: f64 = 1e-9;

/// The factorized view: everything a shear-warp path needs for one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Factorization {
    /// Principal (slicing) axis of the object: 0 = x, 1 = y, 2 = z.
    pub axis: usize,
    /// Object axes of `(i, j, k)`.
    pub perm: [usize; 3],
    /// Volume size along `(i, j, k)`.
    pub n: [usize; 3],
    /// Shear `(s_i, s_j)`: in-slice movement of a ray per slice, in voxels.
    pub shear: [f64; 2],
    /// Centre slice `kc = (nk − 1)/2`, the pivot of the shear.
    pub kc: f64,
    /// True when slices are visited front to back in ascending `k`.
    pub ascending: bool,
    /// Affine map from sheared coordinates `(a, b)` (at any slice) to image pixels:
    /// `[u, v] = warp_m · [a, b] + warp_t`.
    pub warp_m: [[f64; 2]; 2],
    /// Translation part of the warp.
    pub warp_t: [f64; 2],
    /// World distance between consecutive samples along a ray.
    pub sample_spacing: f64,
    /// Linear map from the voxel-space gradient `(g_i, g_j, g_k)` to its eye-space
    /// z component (the headlight's direction) — row of `R · S⁻¹ · P⁻¹`.
    pub grad_to_eye_z: [f64; 3],
    /// Map from the voxel-space gradient `(g_i, g_j, g_k)` to world space
    /// components `g_world[perm[c]] = g[c] / spacing[perm[c]]` (scale per c).
    pub grad_scale: [f64; 3],
    /// Output image size.
    pub size: [usize; 2],
    /// Zoom actually used (pixels per world unit).
    pub zoom: f64,
}

/// Principal axis for a voxel-space viewing direction, with deterministic ties.
pub fn principal_axis(d: DVec3) -> usize {
    let a = d.abs().to_array();
    let m = a[0].max(a[1]).max(a[2]);
    // prefer z, then y, then x among components within the tolerance of the max
    for c in [2usize, 1, 0] {
        if a[c] >= m * (1.0 - TIE_TOLERANCE) {
            return c;
        }
    }
    2
}

/// Object axes `(i, j, k)` for principal axis `c`.
pub fn permutation(c: usize) -> [usize; 3] {
    match c {
        0 => [1, 2, 0],
        1 => [2, 0, 1],
        _ => [0, 1, 2],
    }
}

/// The permutations the RLE paths use when one encoding serves two axes
/// (Sweeney & Mueller's re-use of RLE runs, §3.1): x and z keep their cyclic
/// ones, z takes the mirrored (y, x, z), so a z view's scanline `(j, k)` (along
/// y, at x = j, z = k) is scanline `(k, j)` of the x encoding (y, z, x).
/// Of the three pairs that could share (x-runs: y mirrored to (x, z, y) with
/// z; y-runs: this; z-runs: x mirrored to (z, y, x) with y) this one composited
/// fewest instructions on the CT heads (callgrind over a turn crossing all
/// three axes, 512², blend and iso: −2 to −6 % against separate encodings,
/// where the x-runs pair cost +1 to +9 %).
pub fn reuse_permutation(c: usize) -> [usize; 3] {
    match c {
        2 => [1, 0, 2],
        c => permutation(c),
    }
}

/// True when `p` is a permutation of the axes 0, 1, 2.
pub fn is_permutation(p: [usize; 3]) -> bool {
    p.iter().all(|&a| a < 3) && p[0] != p[1] && p[1] != p[2] && p[0] != p[2]
}

/// The zoom of `camera` for a volume of `nd` voxels per axis with spacing `sp`:
/// its own, or (None) the one that fits the volume's bounding diagonal to the
/// smaller image side.
pub(crate) fn camera_zoom(camera: &Camera, nd: DVec3, sp: DVec3) -> Result<f64> {
    let [w, h] = camera.size;
    match camera.zoom {
        Some(z) if z.is_finite() && z > 0.0 => Ok(z),
        Some(z) => Err(Error::value("zoom", format!("{z} (must be finite and > 0)"))),
        None => Ok((w.min(h) as f64) / ((nd - 1.0).max(DVec3::ONE) * sp).length()),
    }
}

/// The voxel-space vector of permuted coordinates `(i, j, k)` under `perm`.
pub(crate) fn unpermute(perm: [usize; 3], ijk: DVec3) -> DVec3 {
    let mut v = DVec3::ZERO;
    v[perm[0]] = ijk.x;
    v[perm[1]] = ijk.y;
    v[perm[2]] = ijk.z;
    v
}

impl Factorization {
    /// Factorizes `camera` for a volume of `dims` voxels with `spacing`.
    pub fn new(camera: &Camera, dims: [usize; 3], spacing: [f32; 3]) -> Result<Self> {
        Self::build(camera, dims, spacing, None, [permutation(0), permutation(1), permutation(2)])
    }

    /// [`Factorization::new`] with the object axes `(i, j, k)` of principal
    /// axis `c` given by `perms[c]` (each a permutation with `perms[c][2] ==
    /// c`; e.g. [`reuse_permutation`]) instead of the cyclic [`permutation`].
    pub fn with_permutations(camera: &Camera, dims: [usize; 3], spacing: [f32; 3], perms: [[usize; 3]; 3]) -> Result<Self> {
        if (0..3).any(|c| !is_permutation(perms[c]) || perms[c][2] != c) {
            return Err(Error::value("axis permutations", format!("{perms:?} (each must permute 0, 1, 2 with its own axis last)")));
        }
        Self::build(camera, dims, spacing, None, perms)
    }

    /// The factorization of `camera` along principal axis `axis`, whatever the
    /// view direction: what a pyramid of a split perspective frame takes its
    /// permutation and shading directions from. Its shear (the view
    /// direction's, which may pass 45° or be infinite along this axis) is
    /// clamped to `[−1, 1]`.
    pub fn with_axis(camera: &Camera, dims: [usize; 3], spacing: [f32; 3], axis: usize) -> Result<Self> {
        Self::build(camera, dims, spacing, Some(axis.min(2)), [permutation(0), permutation(1), permutation(2)])
    }

    fn build(camera: &Camera, dims: [usize; 3], spacing: [f32; 3], force_axis: Option<usize>, perms: [[usize; 3]; 3]) -> Result<Self> {
        let r = camera.rotation;
        let [w, h] = camera.size;
        if w == 0 || h == 0 || w > 1 << 15 || h > 1 << 15 {
            return Err(Error::value("image size", format!("{w}×{h} (each side must be 1..=32768)")));
        }
        if !r.is_finite() || (r.determinant() - 1.0).abs() > 1e-6 || !(r * r.transpose()).abs_diff_eq(DMat3::IDENTITY, 1e-6) {
            return Err(Error::value("rotation", "must be a finite proper rotation matrix"));
        }
        let sp = DVec3::new(spacing[0] as f64, spacing[1] as f64, spacing[2] as f64);
        let nd = DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64);
        let zoom = camera_zoom(camera, nd, sp)?;
        // viewing direction (into the scene) in world, then voxel space
        let dir_world = r.transpose() * DVec3::new(0.0, 0.0, -1.0);
        let dir_vox = dir_world / sp;
        let axis = force_axis.unwrap_or_else(|| principal_axis(dir_vox));
        let perm = perms[axis];
        let d = DVec3::new(dir_vox[perm[0]], dir_vox[perm[1]], dir_vox[perm[2]]);
        // at most one voxel a slice: a forced axis may lie off the principal
        // one, and a tie broken towards z within `TIE_TOLERANCE` leaves |d.x|
        // or |d.y| a hair above |d.z|, where the clamped shear is exactly one
        // voxel a slice, so every slice's translation is a whole multiple and
        // the rays' cells move by at most one a slice (a principal axis has
        // d.z ≠ 0)
        let shear = [d.x, d.y].map(|x| if d.z == 0.0 { 0.0 } else { (x / d.z).clamp(-1.0, 1.0) });
        let n = [dims[perm[0]], dims[perm[1]], dims[perm[2]]];
        let kc = (n[2] as f64 - 1.0) / 2.0;
        // voxel → image: u = cu + zoom·(R·S·(v − c)).x ; v = cv − zoom·(…).y
        let centre = (nd - 1.0) / 2.0;
        let img = |v: DVec3| -> DVec2 {
            let e = r * ((v - centre) * sp);
            DVec2::new((w as f64 - 1.0) / 2.0 + zoom * e.x, (h as f64 - 1.0) / 2.0 - zoom * e.y)
        };
        let unperm = |ijk: DVec3| unpermute(perm, ijk);
        // sheared (a, b) at slice kc is the voxel (a, b, kc)
        let o = img(unperm(DVec3::new(0.0, 0.0, kc)));
        let ua = img(unperm(DVec3::new(1.0, 0.0, kc))) - o;
        let ub = img(unperm(DVec3::new(0.0, 1.0, kc))) - o;
        let step = unperm(DVec3::new(shear[0], shear[1], 1.0)) * sp;
        let rz = r.row(2);
        let mut grad_to_eye_z = [0.0; 3];
        let mut grad_scale = [0.0; 3];
        for c in 0..3 {
            grad_scale[c] = 1.0 / sp[perm[c]];
            grad_to_eye_z[c] = rz[perm[c]] * grad_scale[c];
        }
        Ok(Factorization {
            axis,
            perm,
            n,
            shear,
            kc,
            ascending: d.z > 0.0,
            warp_m: [[ua.x, ub.x], [ua.y, ub.y]],
            warp_t: [o.x, o.y],
            sample_spacing: step.length(),
            grad_to_eye_z,
            grad_scale,
            size: [w, h],
            zoom,
        })
    }

    /// Exact translation of slice `k`: `(trans_i, trans_j) = s · (k − kc)`.
    pub fn trans(&self, k: usize) -> [f64; 2] {
        let t = k as f64 - self.kc;
        [self.shear[0] * t, self.shear[1] * t]
    }

    /// The voxel position `[x, y, z]` of sheared point `(a, b)` at (fractional)
    /// slice `k`: in-slice `(a + s_i·(k − kc), b + s_j·(k − kc))` along `(i, j)`.
    /// With `(a, b)` from [`Factorization::inverse_warp`] of an image pixel, this
    /// is where that pixel's ray meets slice `k` (used to turn the intermediate
    /// image's fractional iso depth into a point in space).
    pub fn sheared_to_voxel(&self, a: f64, b: f64, k: f64) -> [f64; 3] {
        let t = k - self.kc;
        let mut v = [0.0; 3];
        v[self.perm[0]] = a + self.shear[0] * t;
        v[self.perm[1]] = b + self.shear[1] * t;
        v[self.perm[2]] = k;
        v
    }

    /// The inverse warp: image pixel `(u, v)` to sheared coordinates `(a, b)`.
    pub fn inverse_warp(&self) -> ([[f64; 2]; 2], [f64; 2]) {
        let [[m00, m01], [m10, m11]] = self.warp_m;
        let det = m00 * m11 - m01 * m10;
        let inv = [[m11 / det, -m01 / det], [-m10 / det, m00 / det]];
        let t = self.warp_t;
        let it = [-(inv[0][0] * t[0] + inv[0][1] * t[1]), -(inv[1][0] * t[0] + inv[1][1] * t[1])];
        (inv, it)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::view::rotate_eye;

    fn fact(r: DMat3, dims: [usize; 3], sp: [f32; 3]) -> Factorization {
        Factorization::new(&Camera::new(r, [200, 100]), dims, sp).unwrap()
    }

    /// A forced axis equal to the principal one is the plain factorization;
    /// another axis keeps the camera's shading directions and warp, with the
    /// shear clamped to 45° (finite even when the view is along the slices).
    #[test]
    fn with_axis_forces_the_slicing_axis() {
        let cam = Camera::new(DMat3::from_euler(glam::EulerRot::XYZ, 0.3, -0.5, 0.2), [64, 48]);
        let (dims, sp) = ([20, 30, 40], [1.0f32, 0.5, 3.0]);
        let f = Factorization::new(&cam, dims, sp).unwrap();
        assert_eq!(Factorization::with_axis(&cam, dims, sp, f.axis).unwrap(), f);
        for axis in 0..3 {
            let g = Factorization::with_axis(&cam, dims, sp, axis).unwrap();
            assert_eq!((g.axis, g.perm), (axis, permutation(axis)));
            assert!(g.shear.iter().all(|s| s.is_finite() && s.abs() <= 1.0));
            // the same headlight in object space
            let light = |f: &Factorization| {
                let mut l = [0.0; 3];
                for c in 0..3 {
                    l[f.perm[c]] = f.grad_to_eye_z[c] / f.grad_scale[c];
                }
                l
            };
            let (a, b) = (light(&f), light(&g));
            assert!((0..3).all(|c| (a[c] - b[c]).abs() < 1e-12), "{a:?} vs {b:?}");
        }
        // looking along x: the z factorization's shear would be infinite
        let side = Camera::new(rotate_eye(DMat3::IDENTITY, 1, 90.0), [32, 32]);
        let g = Factorization::with_axis(&side, dims, sp, 2).unwrap();
        assert!(g.shear.iter().all(|s| s.is_finite()));
    }

    #[test]
    fn identity_view_looks_down_z() {
        let f = fact(DMat3::IDENTITY, [10, 20, 30], [1.0; 3]);
        assert_eq!(f.axis, 2);
        assert_eq!(f.perm, [0, 1, 2]);
        assert_eq!(f.shear, [0.0, 0.0]);
        // viewer at +z looking toward −z: front is high k
        assert!(!f.ascending);
    }

    #[test]
    fn principal_axis_ties_are_deterministic() {
        let r = rotate_eye(DMat3::IDENTITY, 1, 45.0);
        let f = fact(r, [16, 16, 16], [1.0; 3]);
        assert_eq!(f.axis, 2);
        assert!(f.shear[0].abs() <= 1.0 + 1e-9);
        for eps in [1e-12, -1e-12] {
            let f = fact(rotate_eye(DMat3::IDENTITY, 1, 45.0 + eps), [16, 16, 16], [1.0; 3]);
            assert_eq!(f.axis, 2);
        }
        assert_eq!(fact(rotate_eye(DMat3::IDENTITY, 1, 45.1), [16, 16, 16], [1.0; 3]).axis, 0);
        // the main diagonal: all three equal → z
        assert_eq!(principal_axis(DVec3::new(1.0, 1.0, 1.0)), 2);
        assert_eq!(principal_axis(DVec3::new(1.0, -1.0, 0.5)), 1);
    }

    #[test]
    fn shear_is_at_most_one_for_any_view() {
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..1000 {
            let r = DMat3::from_euler(glam::EulerRot::XYZ, rnd() * 7.0, rnd() * 7.0, rnd() * 7.0);
            let f = fact(r, [20, 30, 40], [1.0, 0.5, 3.0]);
            assert!(f.shear[0].abs() <= 1.0 + 1e-9 && f.shear[1].abs() <= 1.0 + 1e-9);
        }
    }

    #[test]
    fn warp_maps_every_point_of_a_ray_to_one_pixel() {
        let r = DMat3::from_euler(glam::EulerRot::XYZ, 0.3, -0.5, 0.2);
        let dims = [20, 30, 40];
        let sp = [1.0f32, 0.5, 3.0];
        let f = fact(r, dims, sp);
        // point (a, b) on the sheared ray, at slices k: voxel (a + t_i, b + t_j, k)
        let (a, b) = (3.25, 7.5);
        let sp3 = DVec3::new(1.0, 0.5, 3.0);
        let centre = (DVec3::new(20.0, 30.0, 40.0) - 1.0) / 2.0;
        let mut pix = vec![];
        for k in [0usize, 5, f.n[2] - 1] {
            let [ti, tj] = f.trans(k);
            let mut v = DVec3::ZERO;
            v[f.perm[0]] = a + ti;
            v[f.perm[1]] = b + tj;
            v[f.perm[2]] = k as f64;
            let e = r * ((v - centre) * sp3);
            pix.push(((200.0 - 1.0) / 2.0 + f.zoom * e.x, (100.0 - 1.0) / 2.0 - f.zoom * e.y));
        }
        let u = f.warp_m[0][0] * a + f.warp_m[0][1] * b + f.warp_t[0];
        let v = f.warp_m[1][0] * a + f.warp_m[1][1] * b + f.warp_t[1];
        for p in pix {
            assert!((p.0 - u).abs() < 1e-9 && (p.1 - v).abs() < 1e-9, "{p:?} vs {u},{v}");
        }
        let (inv, it) = f.inverse_warp();
        let a2 = inv[0][0] * u + inv[0][1] * v + it[0];
        let b2 = inv[1][0] * u + inv[1][1] * v + it[1];
        assert!((a2 - a).abs() < 1e-9 && (b2 - b).abs() < 1e-9);
    }

    #[test]
    fn rejects_bad_cameras() {
        let mut c = Camera::new(DMat3::IDENTITY, [0, 10]);
        assert!(Factorization::new(&c, [4, 4, 4], [1.0; 3]).is_err());
        c.size = [10, 10];
        c.zoom = Some(f64::NAN);
        assert!(Factorization::new(&c, [4, 4, 4], [1.0; 3]).is_err());
        c.zoom = None;
        c.rotation = DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0));
        assert!(Factorization::new(&c, [4, 4, 4], [1.0; 3]).is_err());
    }
}
