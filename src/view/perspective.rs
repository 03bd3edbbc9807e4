//! The perspective factorization (Schulze et al.; Lacroute's disabled
//! perspective code in VolPack): the first building block of perspective frames.
//!
//! The eye sits at eye-space `(0, 0, D)`, `D` world units in front of the
//! volume centre; a point at eye coordinates `e` lands on the output pixel
//! `u = cu + f·e.x / (D − e.z)`, `v = cv − f·e.y / (D − e.z)` with `f = zoom·D`,
//! so `zoom` keeps its parallel meaning in the plane through the centre and
//! `D → ∞` is the parallel projection.
//!
//! In voxel-index space (where central projection survives the spacing) the eye
//! is at `E`; the principal axis is the largest component of the direction from
//! the eye to the volume centre. Slice `k_f`, the one nearest the eye, is the
//! base plane at one intermediate pixel per voxel. The ray through sheared
//! point `(a, b)` of the base plane meets slice `k` at
//! `x_ij(k) = σ_k·(a, b) + τ_k` with `σ_k = 1 + κ·(k − k_f)`, `κ = 1/(k_f − E_k)`
//! and `τ_k = −κ·E_ij·(k − k_f)`: every slice is the base plane scaled by
//! `σ_k ≥ 1` (compositing only minifies) and translated. The warp from the base
//! plane to the output is the 3×3 projective map [`PerspectiveView::warp`].
//!
//! One pyramid: the rays into the volume may leave the principal axis by
//! up to `atan(MAX_RAY_SLOPE)` (63.4°) per in-slice axis, not only 45°, so
//! the 45° views and the main diagonal render from an eye 1.5 volume diagonals
//! away or farther (their far-side rays pass 45°: at slope 2 a ray samples a
//! slice every 3 voxels at worst, its opacity corrected for it).
//!
//! Views past that — the eye inside or very near the volume, a wide field of
//! view — get Lacroute's pyramid split ([`PerspectiveView::pyramids`],
//! chosen by [`PerspectiveView::frame`]): the eye is the apex of six
//! pyramids, one per signed axis of voxel space; each output pixel belongs to
//! the pyramid of its ray's largest direction component ([`ray_owner`]), so
//! every ray leaves its pyramid's axis by at most 45°. Each pyramid is a view
//! of its own (its axis, its slices walked away from the eye, the farthest
//! slice as base plane) with a window: the base-plane box of its pixels' rays.
//! [`crate::view::plan::FramePlan::set_perspective`] makes each plan, and the
//! renderer warps each pyramid into its own pixels only.

use glam::{DMat3, DVec3};

use crate::error::{Error, Result};
use crate::view::factor::{Warp, camera_zoom, unpermute};
use crate::view::{Camera, permutation, principal_axis};

/// The projection of a frame: parallel (orthographic), or perspective from an
/// eye on the view axis.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Projection {
    /// Orthographic: the camera's zoom (or the fit of the bounding diagonal).
    #[default]
    Parallel,
    /// Perspective: a vertical field of view of `fov_deg` degrees (in (0, 180))
    /// over the image height, the eye `eye_distance` volume diagonals from the
    /// volume's centre on the camera's +z axis (so 0.1 puts it inside). The
    /// field of view sets the image scale: the camera's zoom is not used.
    Perspective { fov_deg: f64, eye_distance: f64 },
}

impl Projection {
    /// A checked perspective projection.
    pub fn perspective(fov_deg: f64, eye_distance: f64) -> Result<Self> {
        let p = Projection::Perspective { fov_deg, eye_distance };
        p.check()?;
        Ok(p)
    }

    /// Checks the numbers: a field of view in (0°, 180°) and a finite eye
    /// distance > 0.
    pub fn check(&self) -> Result<()> {
        if let Projection::Perspective { fov_deg, eye_distance } = *self {
            if !(fov_deg > 0.0 && fov_deg < 180.0) {
                return Err(Error::value("field of view", format!("{fov_deg} degrees (must be in (0, 180))")));
            }
            if !(eye_distance.is_finite() && eye_distance > 0.0) {
                return Err(Error::value("eye distance", format!("{eye_distance} volume diagonals (must be finite and > 0)")));
            }
        }
        Ok(())
    }

    /// For a perspective projection: `camera` with the zoom its field of view
    /// gives in the plane through the volume centre, and the eye's distance
    /// from the centre in world units (volume diagonals, as the parallel fit
    /// measures them, times `eye_distance`). `None` for a parallel projection.
    pub fn resolve(&self, camera: &Camera, dims: [usize; 3], spacing: [f32; 3]) -> Result<Option<(Camera, f64)>> {
        self.check()?;
        let Projection::Perspective { fov_deg, eye_distance } = *self else { return Ok(None) };
        let sp = DVec3::new(spacing[0] as f64, spacing[1] as f64, spacing[2] as f64);
        let nd = DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64);
        let distance = eye_distance * ((nd - 1.0).max(DVec3::ONE) * sp).length();
        // f pixels per unit of e.x/(D − e.z): half the image height at half the field of view
        let f = camera.size[1] as f64 / 2.0 / (fov_deg.to_radians() / 2.0).tan();
        let zoom = f / distance;
        if !(zoom.is_finite() && zoom > 0.0) {
            return Err(Error::value("perspective view", format!("no finite image scale for {fov_deg}° at {eye_distance} diagonals")));
        }
        Ok(Some((Camera { zoom: Some(zoom), ..*camera }, distance)))
    }

    /// True for a perspective projection.
    pub fn is_perspective(&self) -> bool {
        matches!(self, Projection::Perspective { .. })
    }
}

/// The largest in-slice slope (per axis, in voxels per slice) of a ray into
/// the volume that one pyramid composites: `tan 63.4°`.
pub const MAX_RAY_SLOPE: f64 = 2.0;

/// A perspective view of one principal axis, factorized into scaled slices and
/// a projective warp.
#[derive(Clone, Debug, PartialEq)]
pub struct PerspectiveView {
    /// Principal axis (0 = x) and the object axes of `(i, j, k)`.
    pub axis: usize,
    pub perm: [usize; 3],
    /// Volume size along `(i, j, k)`.
    pub n: [usize; 3],
    /// The eye in permuted voxel-index coordinates `(i, j, k)`.
    pub eye: [f64; 3],
    /// The base plane (`σ = 1`): the slice nearest the eye for one pyramid
    /// (compositing only minifies), the slice farthest from it for a pyramid
    /// of the split (compositing only magnifies).
    pub k_front: usize,
    /// `κ = 1/(k_front − eye_k)`.
    pub kappa: f64,
    /// True when slices are walked front to back in ascending `k`.
    pub ascending: bool,
    /// Base-plane sheared coordinates → output pixels.
    pub warp: Warp,
    /// A pyramid of the split ([`PerspectiveView::pyramids`]): the box
    /// `[lo, hi]` of base-plane points `(a, b)` whose rays the view must
    /// composite (those of its output pixels, plus a margin). `None`: one
    /// pyramid, every ray into the volume.
    pub window: Option<[[f64; 2]; 2]>,
}

/// The pyramid (principal axis, and `true` for rays going toward `+axis`)
/// of a ray with voxel-space direction `d` (not zero): its largest component
/// by magnitude, exact ties going to z, then y, then x (as
/// [`crate::view::principal_axis`] prefers them). Every output pixel belongs
/// to exactly one pyramid.
#[inline(always)]
pub fn ray_owner(d: DVec3) -> (usize, bool) {
    let a = d.abs();
    let axis = if a.z >= a.x && a.z >= a.y {
        2
    } else if a.y >= a.x {
        1
    } else {
        0
    };
    (axis, d[axis] > 0.0)
}

/// The voxel-space ray directions of a perspective camera's output pixels:
/// pixel `(u, v)`'s ray from the eye runs along `dirs · (u, v, 1)`, linear in
/// the pixel (the warp of a pyramid of the split tests each pixel's owner
/// with it, [`ray_owner`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayDirections {
    pub dirs: DMat3,
}

impl RayDirections {
    /// The direction of pixel `(u, v)`'s ray (voxel space, not normalized).
    #[inline(always)]
    pub fn at(&self, u: f64, v: f64) -> DVec3 {
        self.dirs * DVec3::new(u, v, 1.0)
    }

    /// The pyramid of output pixel `(u, v)` ([`ray_owner`]).
    #[inline(always)]
    pub fn owner(&self, u: f64, v: f64) -> (usize, bool) {
        ray_owner(self.at(u, v))
    }
}

/// What every view of one perspective frame shares: the camera, the eye in
/// voxel space and the output pixels' rays.
struct EyeGeometry {
    r: DMat3,
    size: [usize; 2],
    sp: DVec3,
    centre: DVec3,
    dims: [usize; 3],
    /// The eye in eye coordinates (world units from the volume centre, the
    /// camera's axes; `(0, 0, D)` for an eye `D` in front of the centre) and
    /// the image scale `f` (pixels per unit of `(e.x − E.x)/(E.z − e.z)`).
    eye_e: DVec3,
    f: f64,
    /// The eye in voxel-index coordinates.
    eye_v: DVec3,
    rays: RayDirections,
}

impl EyeGeometry {
    fn new(camera: &Camera, distance: f64, dims: [usize; 3], spacing: [f32; 3]) -> Result<Self> {
        if !(distance.is_finite() && distance > 0.0) {
            return Err(Error::value("eye distance", format!("{distance} (must be finite and > 0)")));
        }
        let sp = DVec3::new(spacing[0] as f64, spacing[1] as f64, spacing[2] as f64);
        let nd = DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64);
        let zoom = camera_zoom(camera, nd, sp)?;
        Self::at(camera, zoom * distance, DVec3::new(0.0, 0.0, distance), dims, spacing)
    }

    /// The eye at `eye_e` (eye coordinates), image scale `f`.
    fn at(camera: &Camera, f: f64, eye_e: DVec3, dims: [usize; 3], spacing: [f32; 3]) -> Result<Self> {
        if !(f.is_finite() && f > 0.0 && eye_e.is_finite()) {
            return Err(Error::value("perspective view", format!("image scale {f}, eye {eye_e} (must be finite, the scale > 0)")));
        }
        let sp = DVec3::new(spacing[0] as f64, spacing[1] as f64, spacing[2] as f64);
        let nd = DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64);
        let centre = (nd - 1.0) / 2.0;
        let r = camera.rotation;
        let eye_v = (r.transpose() * eye_e) / sp + centre;
        // the eye-space direction through (u, v) is ((u − cu)/f, (cv − v)/f, −1)
        let [w, h] = camera.size;
        let (cu, cv) = ((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
        let rt = r.transpose();
        let to_vox = |e: DVec3| (rt * e) / sp;
        let dirs = DMat3::from_cols(
            to_vox(DVec3::new(1.0 / f, 0.0, 0.0)),
            to_vox(DVec3::new(0.0, -1.0 / f, 0.0)),
            to_vox(DVec3::new(-cu / f, cv / f, -1.0)),
        );
        Ok(EyeGeometry { r, size: camera.size, sp, centre, dims, eye_e, f, eye_v, rays: RayDirections { dirs } })
    }

    /// The one-pyramid view, or (inner `Err`) why the frame needs the split.
    fn one_pyramid(&self) -> Result<std::result::Result<PerspectiveView, &'static str>> {
        let axis = principal_axis(self.centre - self.eye_v);
        let perm = permutation(axis);
        let e = [self.eye_v[perm[0]], self.eye_v[perm[1]], self.eye_v[perm[2]]];
        let n = [self.dims[perm[0]], self.dims[perm[1]], self.dims[perm[2]]];
        let last = n[2].saturating_sub(1) as f64;
        let (k_front, ascending) = if e[2] < 0.0 {
            (0, true)
        } else if e[2] > last {
            (n[2] - 1, false)
        } else {
            return Ok(Err(
                "the eye is inside the volume's slab (between its first and last slice along the principal axis): that needs the pyramid split",
            ));
        };
        // one pyramid only if every ray into the box has an in-slice slope of at
        // most MAX_RAY_SLOPE: the conditions are linear over the box, so its
        // corners decide
        let mut corners = 0..8;
        if corners.any(|c| {
            let x = [0, 1, 2].map(|a| if c >> a & 1 == 1 { n[a].saturating_sub(1) as f64 } else { 0.0 });
            let dk = (x[2] - e[2]).abs();
            let lim = dk * MAX_RAY_SLOPE * (1.0 + 1e-12);
            (x[0] - e[0]).abs() > lim || (x[1] - e[1]).abs() > lim
        }) {
            return Ok(Err(
                "rays deviate more than 63.4° from the principal axis (the eye too near the volume): that needs the pyramid split",
            ));
        }
        self.view(axis, ascending, k_front).map(Ok)
    }

    /// The view of principal axis `axis`, slices walked in ascending `k` or
    /// not, with slice `k_base` as the base plane (`σ = 1`).
    fn view(&self, axis: usize, ascending: bool, k_base: usize) -> Result<PerspectiveView> {
        let perm = permutation(axis);
        let e = [self.eye_v[perm[0]], self.eye_v[perm[1]], self.eye_v[perm[2]]];
        let n = [self.dims[perm[0]], self.dims[perm[1]], self.dims[perm[2]]];
        let kappa = 1.0 / (k_base as f64 - e[2]);
        if !kappa.is_finite() {
            return Err(Error::value("perspective view", "the eye lies on the base plane"));
        }
        let (r, sp, centre, eye, f) = (self.r, self.sp, self.centre, self.eye_e, self.f);
        // the warp: sheared (a, b) on the base plane is voxel (a, b, k_base)
        let unperm = |ijk: DVec3| unpermute(perm, ijk);
        let to_eye = |v: DVec3| r * (v * sp);
        let e0 = r * ((unperm(DVec3::new(0.0, 0.0, k_base as f64)) - centre) * sp);
        let (ea, eb) = (to_eye(unperm(DVec3::X)), to_eye(unperm(DVec3::Y)));
        let [w, h] = self.size;
        let (cu, cv) = ((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
        // rows (u·w, v·w, w) over columns (a, b, 1)
        let rw = DVec3::new(-ea.z, -eb.z, eye.z - e0.z);
        let ru = cu * rw + f * DVec3::new(ea.x, eb.x, e0.x - eye.x);
        let rv = cv * rw - f * DVec3::new(ea.y, eb.y, e0.y - eye.y);
        let forward = DMat3::from_cols(ru, rv, rw).transpose();
        let det = forward.determinant();
        if !(det.is_finite() && det != 0.0) {
            return Err(Error::value("perspective view", "the base plane is seen edge-on"));
        }
        // F⁻¹ itself: (a, b, 1)/h with h > 0 in front of the eye (a negative
        // multiple, such as adj(F) when det F < 0, would flip that test)
        let inverse = forward.inverse();
        Ok(PerspectiveView { axis, perm, n, eye: e, k_front: k_base, kappa, ascending, warp: Warp { forward, inverse }, window: None })
    }

    /// The pyramids of the split (see [`PerspectiveView::pyramids`]),
    /// appended to `out`.
    fn pyramids_into(&self, near: f64, out: &mut Vec<PerspectiveView>) -> Result<()> {
        let [w, h] = self.size;
        // the output rectangle and a one-pixel ring, as a polygon
        let (u1, v1) = (w as f64, h as f64);
        let screen = Polygon::new(&[[-1.0, -1.0], [u1, -1.0], [u1, v1], [-1.0, v1]]);
        let first = out.len();
        for axis in 0..3 {
            for ascending in [false, true] {
                let perm = permutation(axis);
                let nk = self.dims[axis];
                let ek = self.eye_v[axis];
                let s = if ascending { 1.0 } else { -1.0 };
                // the base plane: the slice farthest from the eye, at least `near` in front of it
                let k_base = if ascending { nk - 1 } else { 0 };
                if s * (k_base as f64 - ek) < near {
                    continue;
                }
                // the pixels of this pyramid: s·d_k ≥ |d_i|, |d_j| (each linear in (u, v))
                let dirs = self.rays.dirs;
                let row = |c: usize| DVec3::new(dirs.x_axis[c], dirs.y_axis[c], dirs.z_axis[c]);
                let dk = row(axis) * s;
                let mut poly = screen;
                for c in [perm[0], perm[1]] {
                    for t in [1.0, -1.0] {
                        poly = poly.clip(dk + row(c) * t);
                    }
                }
                if poly.n < 3 {
                    continue;
                }
                let mut v = self.view(axis, ascending, k_base)?;
                let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
                for p in poly.vertices() {
                    // in the pyramid, so in front of its base plane: w > 0
                    let Some(ab) = v.warp.to_sheared(p[0], p[1]) else { continue };
                    for a in 0..2 {
                        lo[a] = lo[a].min(ab[a]);
                        hi[a] = hi[a].max(ab[a]);
                    }
                }
                if !(lo[0] <= hi[0] && lo[1] <= hi[1]) {
                    continue;
                }
                // the warp's bilinear taps reach one intermediate pixel past the
                // preimage of the pixels; two for safety
                v.window = Some([lo.map(|x| x - WINDOW_MARGIN), hi.map(|x| x + WINDOW_MARGIN)]);
                out.push(v);
            }
        }
        // the pyramid of the image centre first
        let c = self.rays.owner((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
        if let Some(i) = out[first..].iter().position(|v| (v.axis, v.ascending) == c) {
            out[first..=first + i].rotate_right(1);
        }
        Ok(())
    }
}

/// A convex polygon of at most 12 vertices (the screen rectangle clipped by
/// four half-planes has at most 8), on the stack.
#[derive(Clone, Copy)]
struct Polygon {
    v: [[f64; 2]; 12],
    n: usize,
}

impl Polygon {
    fn new(vs: &[[f64; 2]]) -> Self {
        let mut p = Polygon { v: [[0.0; 2]; 12], n: vs.len() };
        p.v[..vs.len()].copy_from_slice(vs);
        p
    }

    fn vertices(&self) -> &[[f64; 2]] {
        &self.v[..self.n]
    }

    /// Sutherland–Hodgman: the part where `c · (u, v, 1) ≥ 0`.
    fn clip(&self, c: DVec3) -> Self {
        let val = |p: &[f64; 2]| c.x * p[0] + c.y * p[1] + c.z;
        let mut out = Polygon { v: [[0.0; 2]; 12], n: 0 };
        let mut push = |p: [f64; 2]| {
            if out.n < out.v.len() {
                out.v[out.n] = p;
                out.n += 1;
            }
        };
        for i in 0..self.n {
            let (p, q) = (&self.v[i], &self.v[(i + 1) % self.n]);
            let (fp, fq) = (val(p), val(q));
            if fp >= 0.0 {
                push(*p);
            }
            if (fp >= 0.0) != (fq >= 0.0) {
                let t = fp / (fp - fq);
                push([p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])]);
            }
        }
        out
    }
}

/// Base-plane pixels a pyramid's window reaches past the preimage of its
/// output pixels (the warp's bilinear taps need one).
const WINDOW_MARGIN: f64 = 2.0;

impl PerspectiveView {
    /// The voxel-space ray directions of the output pixels of `camera` seen
    /// from `distance` world units in front of the volume centre.
    pub fn ray_directions(camera: &Camera, distance: f64, dims: [usize; 3], spacing: [f32; 3]) -> Result<RayDirections> {
        Ok(EyeGeometry::new(camera, distance, dims, spacing)?.rays)
    }

    /// Factorizes `camera` seen from `distance` world units in front of the
    /// volume centre, for a volume of `dims` voxels with `spacing`: one
    /// pyramid, or an error when the view needs the pyramid split
    /// ([`PerspectiveView::frame`] makes the split instead).
    pub fn new(camera: &Camera, distance: f64, dims: [usize; 3], spacing: [f32; 3]) -> Result<Self> {
        let g = EyeGeometry::new(camera, distance, dims, spacing)?;
        match g.one_pyramid()? {
            Ok(v) => Ok(v),
            Err(why) => Err(Error::value("perspective view", why)),
        }
    }

    /// The views of one perspective frame: the one pyramid of
    /// [`PerspectiveView::new`] when every ray into the volume stays within
    /// `atan(MAX_RAY_SLOPE)` of the principal axis; otherwise Lacroute's
    /// pyramid split ([`PerspectiveView::pyramids`]). Empty when nothing of
    /// the volume is in front of the near plane and on screen.
    pub fn frame(camera: &Camera, distance: f64, dims: [usize; 3], spacing: [f32; 3], near: f64) -> Result<Vec<Self>> {
        let mut out = vec![];
        Self::frame_into(camera, distance, dims, spacing, near, &mut out)?;
        Ok(out)
    }

    /// [`PerspectiveView::frame`] into `out` (cleared first; its allocation
    /// reused, so a renderer's frames allocate nothing here).
    pub fn frame_into(camera: &Camera, distance: f64, dims: [usize; 3], spacing: [f32; 3], near: f64, out: &mut Vec<Self>) -> Result<()> {
        out.clear();
        let g = EyeGeometry::new(camera, distance, dims, spacing)?;
        match g.one_pyramid()? {
            Ok(v) => out.push(v),
            Err(_) => g.pyramids_into(near, out)?,
        }
        Ok(())
    }

    /// The views of a perspective frame from an eye anywhere: at `eye`
    /// (eye coordinates: world units from the volume centre along the
    /// camera's axes, looking toward −z), `f` pixels per unit of
    /// `(e.x − eye.x)/(eye.z − e.z)`. As [`PerspectiveView::frame`] when the
    /// volume centre is in front of the eye; otherwise always the split.
    /// Empty when no part of the volume is in front of the near plane on
    /// screen: a volume entirely behind the eye gives an empty image.
    pub fn frame_at(camera: &Camera, f: f64, eye: [f64; 3], dims: [usize; 3], spacing: [f32; 3], near: f64) -> Result<Vec<Self>> {
        let g = EyeGeometry::at(camera, f, DVec3::from_array(eye), dims, spacing)?;
        if eye[2] > 0.0
            && let Ok(v) = g.one_pyramid()?
        {
            return Ok(vec![v]);
        }
        let mut out = vec![];
        g.pyramids_into(near, &mut out)?;
        Ok(out)
    }

    /// Lacroute's pyramid split of a perspective frame: the eye at the apex,
    /// one pyramid per signed axis `±x, ±y, ±z` of voxel space (the rays whose
    /// direction's largest component is along that axis, with that sign:
    /// [`ray_owner`]), each factorized along its own axis with the slice
    /// farthest from the eye as the base plane (`σ_k ≤ 1`: the slices nearer
    /// the eye are magnified, bilinearly) and slices walked away from the eye.
    /// Only the pyramids with a slice at least `near` in front of the eye and
    /// some output pixel are kept; each one's [`PerspectiveView::window`] is
    /// the base-plane box of the rays of its output pixels (plus a margin for
    /// the warp's bilinear taps). The pyramid owning the image centre comes
    /// first; the others follow in the order `−x, +x, −y, +y, −z, +z`.
    pub fn pyramids(camera: &Camera, distance: f64, dims: [usize; 3], spacing: [f32; 3], near: f64) -> Result<Vec<Self>> {
        let mut out = vec![];
        EyeGeometry::new(camera, distance, dims, spacing)?.pyramids_into(near, &mut out)?;
        Ok(out)
    }

    /// The scale `σ_k` of slice `k` (1 at the base plane, growing away from the eye).
    pub fn scale(&self, k: f64) -> f64 {
        1.0 + self.kappa * (k - self.k_front as f64)
    }

    /// The translation `τ_k` of slice `k` along `(i, j)`.
    pub fn trans(&self, k: f64) -> [f64; 2] {
        let d = k - self.k_front as f64;
        [-self.kappa * self.eye[0] * d, -self.kappa * self.eye[1] * d]
    }

    /// The voxel position `[x, y, z]` where the ray through base-plane point
    /// `(a, b)` meets (fractional) slice `k`.
    pub fn sheared_to_voxel(&self, a: f64, b: f64, k: f64) -> [f64; 3] {
        let (s, t) = (self.scale(k), self.trans(k));
        let mut v = [0.0; 3];
        v[self.perm[0]] = s * a + t[0];
        v[self.perm[1]] = s * b + t[1];
        v[self.perm[2]] = k;
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The camera's true perspective projection of a voxel point.
    fn project(cam: &Camera, distance: f64, zoom: f64, dims: [usize; 3], sp: [f32; 3], v: [f64; 3]) -> Option<[f64; 2]> {
        let c = DVec3::new(dims[0] as f64 - 1.0, dims[1] as f64 - 1.0, dims[2] as f64 - 1.0) / 2.0;
        let s = DVec3::new(sp[0] as f64, sp[1] as f64, sp[2] as f64);
        let e = cam.rotation * ((DVec3::from_array(v) - c) * s);
        let hz = distance - e.z;
        (hz > 0.0).then(|| {
            let f = zoom * distance;
            [(cam.size[0] as f64 - 1.0) / 2.0 + f * e.x / hz, (cam.size[1] as f64 - 1.0) / 2.0 - f * e.y / hz]
        })
    }

    #[test]
    fn perspective_worked_example() {
        // 3³ voxels, spacing 1, eye 15 units away, zoom 1, 3×3 output
        let r = DMat3::from_cols_array(&[0.8, 0.0, -0.6, 0.0, 1.0, 0.0, 0.6, 0.0, 0.8]);
        let cam = Camera { rotation: r, zoom: Some(1.0), size: [3, 3] };
        let p = PerspectiveView::new(&cam, 15.0, [3, 3, 3], [1.0; 3]).unwrap();
        assert_eq!((p.axis, p.k_front, p.ascending), (2, 2, false));
        assert!((DVec3::from_array(p.eye) - DVec3::new(-8.0, 1.0, 13.0)).length() < 1e-12);
        assert!((p.kappa + 1.0 / 11.0).abs() < 1e-15);
        assert!((p.scale(0.0) - 13.0 / 11.0).abs() < 1e-15);
        let want = DMat3::from_cols_array(&[12.6, 0.6, 0.6, 0.0, -15.0, 0.0, 10.6, 28.6, 13.6]);
        assert!(p.warp.forward.abs_diff_eq(want, 1e-12), "{:?}", p.warp.forward);
        for ((a, b), (u, v)) in [((0.0, 1.0), (0.779412, 1.0)), ((2.0, 0.0), (2.418919, 2.013514)), ((-1.2, 1.8), (-0.350932, 0.068323))] {
            let [u2, v2] = p.warp.to_output(a, b).unwrap();
            assert!((u2 - u).abs() < 1e-6 && (v2 - v).abs() < 1e-6, "({a}, {b}) → ({u2}, {v2})");
        }
    }

    /// Schulze's §2.4 as a numeric test: projecting a sample of the scaled,
    /// translated slices with the true camera gives the pixel the warp gives
    /// its base-plane point, for every slice.
    #[test]
    fn perspective_projection_and_warp_commute() {
        let mut seed = 7u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let (dims, sp) = ([20, 26, 17], [1.0f32, 0.8, 1.5]);
        let mut tested = 0;
        for _ in 0..400 {
            let r = DMat3::from_euler(glam::EulerRot::XYZ, rnd() * 7.0, rnd() * 7.0, rnd() * 7.0);
            let distance = 60.0 + rnd() * 400.0;
            let cam = Camera { rotation: r, zoom: Some(2.0), size: [96, 80] };
            let Ok(p) = PerspectiveView::new(&cam, distance, dims, sp) else { continue };
            tested += 1;
            for _ in 0..6 {
                let (a, b, k) = (rnd() * 20.0 - 2.0, rnd() * 26.0 - 2.0, rnd() * (p.n[2] - 1) as f64);
                let x = p.sheared_to_voxel(a, b, k);
                let want = project(&cam, distance, 2.0, dims, sp, x).unwrap();
                let got = p.warp.to_output(a, b).unwrap();
                assert!((got[0] - want[0]).abs() < 1e-8 && (got[1] - want[1]).abs() < 1e-8, "{got:?} vs {want:?}");
                // and the inverse takes the pixel back to the base-plane point
                let back = p.warp.to_sheared(got[0], got[1]).unwrap();
                assert!((back[0] - a).abs() < 1e-8 && (back[1] - b).abs() < 1e-8);
            }
            assert!(p.scale(p.k_front as f64) == 1.0);
            let far = if p.ascending { (p.n[2] - 1) as f64 } else { 0.0 };
            assert!(p.scale(far) >= 1.0, "slices away from the eye are scaled up");
        }
        assert!(tested > 200, "only {tested} views had one pyramid");
    }

    /// As the eye recedes, slices stop scaling and their translations become
    /// the parallel view's shear, so the perspective image converges to the
    /// parallel one.
    #[test]
    fn perspective_converges_to_parallel_as_the_eye_recedes() {
        let r = DMat3::from_euler(glam::EulerRot::XYZ, 0.3, -0.5, 0.2);
        let (dims, sp) = ([20, 30, 40], [1.0f32, 0.5, 3.0]);
        let cam = Camera::new(r, [200, 100]);
        let par = crate::view::Factorization::new(&cam, dims, sp).unwrap();
        let mut last = f64::INFINITY;
        for distance in [1e3, 1e4, 1e5, 1e6] {
            let p = PerspectiveView::new(&cam, distance, dims, sp).unwrap();
            assert_eq!(p.axis, par.axis);
            let d = (p.n[2] - 1) as f64 - p.k_front as f64;
            let err = (p.scale(p.k_front as f64 + d) - 1.0).abs()
                + (0..2).map(|a| (p.trans(p.k_front as f64 + 1.0)[a] - par.shear[a]).abs()).sum::<f64>();
            assert!(err < last * 0.2, "error {err} at {distance} did not shrink (was {last})");
            last = err;
        }
        assert!(last < 1e-4);
    }

    /// The pyramids of the split, from eyes anywhere (inside the volume, near
    /// it, beyond it): each pyramid's slices and warp follow the true camera
    /// (projecting a point of any slice gives the pixel the warp gives its
    /// base-plane point), its slices run away from the eye from the near
    /// plane on (`σ ≤ 1` at every slice in front of the near plane), and the
    /// pyramids are distinct, the image centre's first.
    #[test]
    fn perspective_pyramids_follow_the_camera() {
        let mut seed = 17u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let (dims, sp) = ([20, 26, 17], [1.0f32, 0.8, 1.5]);
        let c = DVec3::new(9.5, 12.5, 8.0);
        let s = DVec3::new(1.0, 0.8, 1.5);
        let mut views = 0;
        for _ in 0..200 {
            let r = DMat3::from_euler(glam::EulerRot::XYZ, rnd() * 7.0, rnd() * 7.0, rnd() * 7.0);
            let cam = Camera { rotation: r, zoom: Some(2.0), size: [96, 80] };
            let eye = [rnd() * 40.0 - 20.0, rnd() * 40.0 - 20.0, rnd() * 40.0 - 20.0];
            let f = 20.0 + rnd() * 100.0;
            let vs = PerspectiveView::frame_at(&cam, f, eye, dims, sp, 0.5).unwrap();
            let mut seen = vec![];
            for p in &vs {
                assert!(!seen.contains(&(p.axis, p.ascending)));
                seen.push((p.axis, p.ascending));
                views += 1;
                for _ in 0..5 {
                    let (a, b) = (rnd() * 30.0 - 5.0, rnd() * 30.0 - 5.0);
                    let ahead = |k: f64| if p.ascending { k - p.eye[2] } else { p.eye[2] - k };
                    let k = (rnd() * (p.n[2] - 1) as f64).round();
                    if ahead(k) < 0.5 {
                        continue;
                    }
                    if p.window.is_some() {
                        assert!(p.scale(k) <= 1.0 + 1e-12 && p.scale(k) > 0.0);
                    }
                    let x = DVec3::from_array(p.sheared_to_voxel(a, b, k));
                    let e = r * ((x - c) * s);
                    let h = eye[2] - e.z;
                    let Some(got) = p.warp.to_output(a, b) else {
                        assert!(h <= 1e-9, "the warp says behind the eye, the camera {h}");
                        continue;
                    };
                    if h < 1.0 {
                        // (near the eye plane both blow up)
                        continue;
                    }
                    let want = [47.5 + f * (e.x - eye[0]) / h, 39.5 - f * (e.y - eye[1]) / h];
                    assert!((got[0] - want[0]).abs() < 1e-4 * (1.0 + want[0].abs()), "{got:?} vs {want:?}");
                    assert!((got[1] - want[1]).abs() < 1e-4 * (1.0 + want[1].abs()), "{got:?} vs {want:?}");
                }
            }
            if let Some(p) = vs.first().filter(|p| p.window.is_some()) {
                let rays = EyeGeometry::at(&cam, f, DVec3::from_array(eye), dims, sp).unwrap().rays;
                let own = rays.owner(47.5, 39.5);
                // the first pyramid owns the centre, if any pyramid does
                if vs.iter().any(|v| (v.axis, v.ascending) == own) {
                    assert_eq!((p.axis, p.ascending), own);
                }
            }
        }
        assert!(views > 100, "{views}");
    }

    /// A volume entirely behind the eye has no view (an empty image, not an
    /// error); with the eye inside it, the pyramids the screen sees.
    #[test]
    fn perspective_volume_behind_the_eye_has_no_view() {
        let cam = Camera::new(DMat3::IDENTITY, [64, 48]);
        let (dims, sp) = ([20, 20, 20], [1.0f32; 3]);
        // the eye past the volume's far face (z = −9.5), looking away from it
        for eye in [[0.0, 0.0, -15.0], [3.0, -2.0, -10.5], [0.0, 0.0, -9.7]] {
            let v = PerspectiveView::frame_at(&cam, 40.0, eye, dims, sp, 0.5).unwrap();
            assert!(v.is_empty(), "{eye:?}: {} views", v.len());
        }
        // the eye inside, a 90° view: the −z pyramid, and no other at the centre
        let v = PerspectiveView::frame_at(&cam, 24.0, [0.0, 0.0, 1.0], dims, sp, 0.5).unwrap();
        assert!(!v.is_empty() && (v[0].axis, v[0].ascending) == (2, false));
        assert!(v.iter().all(|p| p.window.is_some()));
        // and a wide view from inside sees the side pyramids too
        let v = PerspectiveView::frame_at(&cam, 10.0, [0.0, 0.0, 1.0], dims, sp, 0.5).unwrap();
        assert!(v.len() >= 3, "{}", v.len());
    }

    #[test]
    fn perspective_refuses_what_needs_the_pyramid_split() {
        let cam = Camera::new(DMat3::IDENTITY, [64, 64]);
        // the eye inside the volume
        assert!(PerspectiveView::new(&cam, 2.0, [20, 20, 20], [1.0; 3]).is_err());
        // close enough that the corner rays pass slope 2 (9.5 across, 4.5 deep), and not
        assert!(PerspectiveView::new(&cam, 14.0, [20, 20, 20], [1.0; 3]).is_err());
        assert!(PerspectiveView::new(&cam, 15.0, [20, 20, 20], [1.0; 3]).is_ok());
        assert!(PerspectiveView::new(&cam, 40.0, [20, 20, 20], [1.0; 3]).is_ok());
        assert!(PerspectiveView::new(&cam, f64::NAN, [20, 20, 20], [1.0; 3]).is_err());
        assert!(PerspectiveView::new(&cam, -5.0, [20, 20, 20], [1.0; 3]).is_err());
    }
}
