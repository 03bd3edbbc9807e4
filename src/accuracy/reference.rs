//! The reference renderer: what every fast path approximates, computed slowly
//! and carefully, so that their error can be measured pixel for pixel.
//!
//! [`ReferenceRenderer`] casts the *true* viewing ray of every output pixel (not
//! a sheared ray of the intermediate image followed by a 2-D warp) through the
//! same [`Camera`], so its image has exactly the geometry of the warp output:
//! pixel `(u, v)` is the ray through `u = (W − 1)/2 + zoom·e.x`,
//! `v = (H − 1)/2 − zoom·e.y` (see [`crate::view`]), with the same zoom.
//!
//! Conventions, chosen to match the fast paths wherever that is meaningful:
//!
//! * **Domain.** The closed box of voxel centres `[0, nx−1] × [0, ny−1] × [0, nz−1]`:
//!   the fast paths sample the same box (slices `0..nk`, bilinear samples inside
//!   the cell grid of each slice). Along an axis with a single voxel the box is
//!   flat and a ray meets it in at most one point, so such a volume renders as a
//!   zero-thickness sheet (iso: a hit where the density reaches iso; blend: one
//!   sample). The fast paths render a flat axis as one slab (or nothing), so the
//!   comparison is not meaningful there.
//! * **Density.** Under [`Reconstruction::Linear`] (the default), trilinear
//!   interpolation of the voxels in double precision, clamped to the range of
//!   the eight corners (as the fast paths clamp their bilinear samples;
//!   mathematically a no-op). Under [`Reconstruction::Cubic`], bilinear in
//!   each z slice and the Catmull–Rom cubic through the four slices around
//!   the point along z, the volume's slice axis ([`crate::kernels::reconstruct`];
//!   not clamped: the cubic may overshoot its samples by an eighth of their
//!   spread).
//! * **Samples.** Along each ray at `t₀, t₀ + Δ, t₀ + 2Δ, …` from the ray's entry
//!   `t₀` into the box, `Δ = step · min(spacing)` in world units;
//!   [`DEFAULT_STEP`] is 0.05 voxel.
//! * **Classification.** The renderer's own [`Classifier`] table (colour and
//!   opacity), its opacities taken uncorrected (for one minimum spacing) and
//!   corrected per reference step in double precision:
//!   `α' = 1 − (1 − α)^(Δ / min_spacing)` — the fast paths' correction with the
//!   reference's spacing.
//! * **Shading.** [`Shading`] with the headlight; the gradient is the trilinear
//!   blend of the central differences at the eight corners (one-sided at the
//!   borders), the 3-D form of the fast paths' bilinear blend. Under
//!   [`Reconstruction::Cubic`], the gradient of the cubic B-spline smoothing
//!   of the same four slices: along z the derivative of the B-spline, in x
//!   and y the central differences blended bilinearly in each slice and by
//!   the B-spline's weights across slices — C² across slices, so the normal
//!   has no ring at a slice (why the B-spline and not Catmull–Rom's own
//!   derivative: [`crate::kernels::reconstruct`]).
//! * **Iso mode.** The first sample whose density is ≥ iso, refined by bisection
//!   on the reconstructed density between it and the previous sample (no refinement
//!   when the entry point is already inside); shaded opaque in the iso colour.
//!   [`ReferenceImage::normal`] is the unit normal it is shaded with.
//!   The hit's depth is reported in world units along the view, measured from
//!   the plane through the volume centre (`depth = −e.z`, larger is farther).
//! * **Blend mode.** Front-to-back "over" until the accumulated opacity reaches
//!   [`ReferenceOptions::opacity_cutoff`] (default 0.999, so what is left out is
//!   below 10⁻³ of full scale).
//!
//! The only shortcut is exact: blocks of 8³ cells whose corner range cannot be
//! visible (iso: every corner below iso; blend: the classifier proves the range
//! transparent) are stepped over, which skips only samples whose opacity is 0 or
//! whose density is below iso. Under [`Reconstruction::Cubic`] a block's range
//! is that of its neighbours along z as well (the cubic's support), widened
//! by the cubic's overshoot ([`reconstruct::widened`]). Rows are rendered in parallel (rayon) and every
//! pixel depends on its ray alone, so the output is deterministic.
//!
//! [`fast_path_depth`] converts a fast path's intermediate iso depth (fractional
//! slice index) into the same per-pixel depth, for comparing hit positions.

use glam::{DMat3, DVec3};
use rayon::prelude::*;

use crate::classify::Classifier;
use crate::classify::shading::Shading;
use crate::composite::Mode;
use crate::data::bcc::BccLattice;
use crate::data::normals::{decode_normal, encode_normal};
use crate::data::volume::Volume;
use crate::error::{Error, Result};
use crate::kernels::reconstruct::{self, Reconstruction};
use crate::render::{Lattice, Normals, Renderer};
use crate::view::{Camera, Factorization, PerspectiveView, Projection};
use crate::warp::Image;

/// Default reference step along a ray, in units of the smallest voxel spacing.
pub const DEFAULT_STEP: f64 = 0.05;
/// Default accumulated opacity at which a blend ray stops.
pub const DEFAULT_OPACITY_CUTOFF: f64 = 0.999;
/// Smallest accepted step (voxels): finer steps would take days on real volumes.
pub const MIN_STEP: f64 = 1e-4;
/// Edge of the empty-space blocks, in cells.
const BLOCK: usize = 8;
/// Bisection iterations for an iso hit (the bracket shrinks far below 1e-12).
const BISECTIONS: u32 = 64;

/// How finely the reference samples.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReferenceOptions {
    /// Step along each ray in units of the smallest voxel spacing (> 0, ≤ 1).
    pub step: f64,
    /// Blend rays stop when the accumulated opacity reaches this (in (0, 1]; 1 never stops early).
    pub opacity_cutoff: f64,
    /// Worker threads (0 = rayon's global pool).
    pub threads: usize,
    /// Perspective: the near clip, in voxels (≥ 0). A ray starts where it is
    /// `near` voxels from the eye along its largest voxel-space component —
    /// the fast paths' near plane ([`crate::render::NEAR_SLICES`] slices in
    /// front of the eye along each pyramid's axis), so the same camera sees
    /// the same part of the volume when the eye is inside it. 0: from the eye.
    pub near: f64,
    /// How densities between slices are reconstructed (linear: trilinear).
    pub reconstruction: Reconstruction,
}

impl Default for ReferenceOptions {
    fn default() -> Self {
        ReferenceOptions {
            step: DEFAULT_STEP,
            opacity_cutoff: DEFAULT_OPACITY_CUTOFF,
            threads: 0,
            near: crate::render::NEAR_SLICES,
            reconstruction: Reconstruction::Linear,
        }
    }
}

impl ReferenceOptions {
    /// Checks the options.
    pub fn check(&self) -> Result<()> {
        if !(self.step.is_finite() && (MIN_STEP..=1.0).contains(&self.step)) {
            return Err(Error::value("reference step", format!("{} (must be {MIN_STEP}..=1 voxel)", self.step)));
        }
        if !(self.opacity_cutoff > 0.0 && self.opacity_cutoff <= 1.0) {
            return Err(Error::value("reference opacity cutoff", format!("{} (must be in (0, 1])", self.opacity_cutoff)));
        }
        if !(self.near.is_finite() && self.near >= 0.0) {
            return Err(Error::value("reference near clip", format!("{} (must be finite and ≥ 0)", self.near)));
        }
        Ok(())
    }
}

/// What to render: the classification, mode and shading of a fast path.
#[derive(Clone, Debug)]
pub struct Scene {
    pub mode: Mode,
    /// The classification table, with opacities uncorrected (sample ratio 1).
    pub classifier: Classifier,
    /// Iso value (iso mode).
    pub iso: f32,
    pub shading: Shading,
}

impl Scene {
    /// A scene with `classifier`'s table (any spacing correction it carries is undone).
    pub fn new(mode: Mode, classifier: &Classifier, iso: f32, shading: Shading) -> Self {
        let mut c = classifier.clone();
        c.set_sample_ratio(1.0);
        Scene { mode, classifier: c, iso, shading }
    }

    /// Exactly what `renderer` renders now: its mode, current classifier, iso
    /// value and shading.
    pub fn from_renderer(renderer: &Renderer) -> Self {
        let s = renderer.settings();
        Scene::new(s.mode, renderer.classifier(), renderer.iso(), s.shading)
    }
}

/// A reference frame.
#[derive(Clone, Debug)]
pub struct ReferenceImage {
    /// Premultiplied RGBA, same geometry as the warp output.
    pub image: Image,
    /// Iso hit depth per pixel: world units along the view from the plane
    /// through the volume centre (NaN where no hit, and always NaN in blend mode).
    pub depth: Vec<f64>,
    /// The unit normal the iso hit is shaded with per pixel, in world space
    /// (the volume's axes scaled by its spacing), pointing down the density
    /// (NaN where no hit or the gradient vanishes, and always NaN in blend mode).
    pub normal: Vec<DVec3>,
    /// Density samples evaluated (a measure of work).
    pub samples: u64,
}

/// The viewing rays of a camera, in voxel coordinates.
///
/// The ray of pixel `(u, v)` is `p(t) = origin(u, v) + t · direction()`, with `t`
/// the world distance along the view from the plane through the volume centre.
#[derive(Clone, Debug)]
pub struct Rays {
    dims: [usize; 3],
    rot: DMat3,
    spacing: DVec3,
    centre: DVec3,
    zoom: f64,
    size: [usize; 2],
    dir: DVec3,
    /// Perspective: the eye in voxel coordinates and its distance from the
    /// volume centre in world units (None: parallel rays).
    eye: Option<(DVec3, f64)>,
}

impl Rays {
    /// The rays of `camera` for a volume of `dims` voxels with `spacing` (the
    /// camera is checked exactly as [`Factorization::new`] checks it, and the
    /// zoom is the one the fast paths use).
    pub fn new(camera: &Camera, dims: [usize; 3], spacing: [f32; 3]) -> Result<Self> {
        let f = Factorization::new(camera, dims, spacing)?;
        let sp = DVec3::new(spacing[0] as f64, spacing[1] as f64, spacing[2] as f64);
        let nd = DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64);
        let rot = camera.rotation;
        Ok(Rays {
            dims,
            rot,
            spacing: sp,
            centre: (nd - 1.0) / 2.0,
            zoom: f.zoom,
            size: camera.size,
            dir: rot.transpose() * DVec3::NEG_Z / sp,
            eye: None,
        })
    }

    /// The rays of `camera` under `projection`: for a perspective projection
    /// the true perspective rays, from the eye through every output pixel,
    /// with the image scale its field of view gives (as the fast paths
    /// resolve it, [`Projection::resolve`]).
    pub fn with_projection(camera: &Camera, projection: &Projection, dims: [usize; 3], spacing: [f32; 3]) -> Result<Self> {
        match projection.resolve(camera, dims, spacing)? {
            None => Rays::new(camera, dims, spacing),
            Some((cam, distance)) => {
                let mut r = Rays::new(&cam, dims, spacing)?;
                r.eye = Some((r.rot.transpose() * DVec3::new(0.0, 0.0, distance) / r.spacing + r.centre, distance));
                Ok(r)
            }
        }
    }

    /// The ray of pixel `(u, v)`: `p(t) = o + t·d` in voxel coordinates, `t` in
    /// world units (parallel: along the view from the plane through the centre;
    /// perspective: from the eye along the ray).
    pub fn ray(&self, u: f64, v: f64) -> (DVec3, DVec3) {
        match self.eye {
            None => (self.origin(u, v), self.dir),
            Some((eye, distance)) => {
                // the eye-space direction through the pixel: (x, y) at depth D
                // in front of the eye lands on the pixel, as in the fast paths
                let [w, h] = self.size;
                let f = self.zoom * distance;
                let e = DVec3::new((u - (w as f64 - 1.0) / 2.0) / f, ((h as f64 - 1.0) / 2.0 - v) / f, -1.0).normalize();
                (eye, self.rot.transpose() * e / self.spacing)
            }
        }
    }

    /// The `t` interval where the ray `o + t·d` lies in the box of voxel
    /// centres (and, for a perspective ray, in front of the eye), or `None`.
    pub fn clip_ray(&self, o: DVec3, d: DVec3) -> Option<(f64, f64)> {
        let hi = DVec3::new(self.dims[0] as f64 - 1.0, self.dims[1] as f64 - 1.0, self.dims[2] as f64 - 1.0);
        let (t0, t1) = clip_box(o, d, DVec3::ZERO, hi)?;
        match self.eye {
            None => Some((t0, t1)),
            Some(_) => (t1 >= 0.0).then_some((t0.max(0.0), t1)),
        }
    }

    /// Output image size.
    pub fn size(&self) -> [usize; 2] {
        self.size
    }

    /// Voxel coordinates of pixel `(u, v)`'s ray at `t = 0`.
    pub fn origin(&self, u: f64, v: f64) -> DVec3 {
        let [w, h] = self.size;
        let e = DVec3::new((u - (w as f64 - 1.0) / 2.0) / self.zoom, ((h as f64 - 1.0) / 2.0 - v) / self.zoom, 0.0);
        self.rot.transpose() * e / self.spacing + self.centre
    }

    /// Voxel-space change per world unit along the view.
    pub fn direction(&self) -> DVec3 {
        self.dir
    }

    /// Depth (world units along the view from the plane through the centre) of a voxel-space point.
    pub fn depth_of(&self, voxel: DVec3) -> f64 {
        -(self.rot * ((voxel - self.centre) * self.spacing)).z
    }

    /// The `t` interval where the ray from `origin` lies in the box of voxel
    /// centres, or `None` when it misses.
    pub fn clip(&self, origin: DVec3) -> Option<(f64, f64)> {
        let hi = DVec3::new(self.dims[0] as f64 - 1.0, self.dims[1] as f64 - 1.0, self.dims[2] as f64 - 1.0);
        clip_box(origin, self.dir, DVec3::ZERO, hi)
    }
}

/// Slab test: the `t` interval where `o + t·d` lies in the closed box `[lo, hi]`.
fn clip_box(o: DVec3, d: DVec3, lo: DVec3, hi: DVec3) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for a in 0..3 {
        if d[a] == 0.0 {
            if o[a] < lo[a] || o[a] > hi[a] {
                return None;
            }
            continue;
        }
        let (x, y) = ((lo[a] - o[a]) / d[a], (hi[a] - o[a]) / d[a]);
        t0 = t0.max(x.min(y));
        t1 = t1.min(x.max(y));
    }
    (t0 <= t1 && t0.is_finite() && t1.is_finite()).then_some((t0, t1))
}

/// Exit `t` of the ray `o + t·d` from the closed box `[lo, hi]` (the ray is inside it).
fn exit_box(o: DVec3, d: DVec3, lo: DVec3, hi: DVec3) -> f64 {
    let mut t = f64::INFINITY;
    for a in 0..3 {
        if d[a] > 0.0 {
            t = t.min((hi[a] - o[a]) / d[a]);
        } else if d[a] < 0.0 {
            t = t.min((lo[a] - o[a]) / d[a]);
        }
    }
    t
}

/// The reference renderer of one volume.
#[derive(Clone, Debug)]
pub struct ReferenceRenderer {
    dims: [usize; 3],
    spacing: [f32; 3],
    data: Vec<f32>,
    /// Blocks along x, y, z.
    nblocks: [usize; 3],
    /// Smallest and largest voxel of each block (voxels `[8b, min(8b + 8, n − 1)]` per axis).
    ranges: Vec<(f32, f32)>,
}

/// Index, next index and weight of coordinate `x` on an axis of `n` voxels.
#[inline(always)]
fn locate(x: f64, n: usize) -> (usize, usize, f64) {
    if n <= 1 {
        return (0, 0, 0.0);
    }
    let i = (x.floor().max(0.0) as usize).min(n - 2);
    (i, i + 1, (x - i as f64).clamp(0.0, 1.0))
}

#[inline(always)]
fn lerp(a: f64, b: f64, t: f64) -> f64 {
    a + (b - a) * t
}

impl ReferenceRenderer {
    /// Prepares `volume` (densities as f32, empty-space block ranges).
    pub fn new(volume: &Volume) -> Self {
        let dims = volume.dims();
        let data = volume.to_f32();
        let nblocks = dims.map(|n| if n <= 1 { 1 } else { (n - 1).div_ceil(BLOCK) });
        let span = |b: usize, n: usize| (b * BLOCK, (b * BLOCK + BLOCK).min(n - 1));
        let mut ranges = vec![(0f32, 0f32); nblocks[0] * nblocks[1] * nblocks[2]];
        ranges.par_chunks_mut(nblocks[0] * nblocks[1]).enumerate().for_each(|(bz, plane)| {
            let (z0, z1) = span(bz, dims[2]);
            for by in 0..nblocks[1] {
                let (y0, y1) = span(by, dims[1]);
                for bx in 0..nblocks[0] {
                    let (x0, x1) = span(bx, dims[0]);
                    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
                    for z in z0..=z1 {
                        for y in y0..=y1 {
                            let row = &data[dims[0] * (y + dims[1] * z)..];
                            for &v in &row[x0..=x1] {
                                lo = lo.min(v);
                                hi = hi.max(v);
                            }
                        }
                    }
                    plane[by * nblocks[0] + bx] = (lo, hi);
                }
            }
        });
        ReferenceRenderer { dims, spacing: volume.spacing(), data, nblocks, ranges }
    }

    /// Volume size.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    #[inline(always)]
    fn at(&self, x: usize, y: usize, z: usize) -> f64 {
        self.data[x + self.dims[0] * (y + self.dims[1] * z)] as f64
    }

    /// Trilinear density at voxel-space point `p` (inside the box), clamped to
    /// the range of the cell's corners.
    pub fn density(&self, p: DVec3) -> f64 {
        let (x0, x1, fx) = locate(p.x, self.dims[0]);
        let (y0, y1, fy) = locate(p.y, self.dims[1]);
        let (z0, z1, fz) = locate(p.z, self.dims[2]);
        let c = [self.at(x0, y0, z0), self.at(x1, y0, z0), self.at(x0, y1, z0), self.at(x1, y1, z0)];
        let e = [self.at(x0, y0, z1), self.at(x1, y0, z1), self.at(x0, y1, z1), self.at(x1, y1, z1)];
        let front = lerp(lerp(c[0], c[1], fx), lerp(c[2], c[3], fx), fy);
        let back = lerp(lerp(e[0], e[1], fx), lerp(e[2], e[3], fx), fy);
        let d = lerp(front, back, fz);
        let lo = c.iter().chain(&e).fold(f64::INFINITY, |a, &b| a.min(b));
        let hi = c.iter().chain(&e).fold(f64::NEG_INFINITY, |a, &b| a.max(b));
        d.clamp(lo, hi)
    }

    /// Central-difference gradient at voxel `(x, y, z)` in voxel units (one-sided
    /// at the borders, zero along a single-voxel axis) — as [`crate::data::slices::SliceStack::gradient_at`].
    fn gradient_at(&self, x: usize, y: usize, z: usize) -> DVec3 {
        let n = self.dims;
        let d = |lo: f64, hi: f64, span: usize| if span > 0 { (hi - lo) / span as f64 } else { 0.0 };
        let (x0, x1) = (x.saturating_sub(1), (x + 1).min(n[0] - 1));
        let (y0, y1) = (y.saturating_sub(1), (y + 1).min(n[1] - 1));
        let (z0, z1) = (z.saturating_sub(1), (z + 1).min(n[2] - 1));
        DVec3::new(
            d(self.at(x0, y, z), self.at(x1, y, z), x1 - x0),
            d(self.at(x, y0, z), self.at(x, y1, z), y1 - y0),
            d(self.at(x, y, z0), self.at(x, y, z1), z1 - z0),
        )
    }

    /// Gradient at `p` (voxel units): the trilinear blend of the corners' central differences.
    pub fn gradient(&self, p: DVec3) -> DVec3 {
        let (x0, x1, fx) = locate(p.x, self.dims[0]);
        let (y0, y1, fy) = locate(p.y, self.dims[1]);
        let (z0, z1, fz) = locate(p.z, self.dims[2]);
        let g = |x, y, z| self.gradient_at(x, y, z);
        let front = g(x0, y0, z0).lerp(g(x1, y0, z0), fx).lerp(g(x0, y1, z0).lerp(g(x1, y1, z0), fx), fy);
        let back = g(x0, y0, z1).lerp(g(x1, y0, z1), fx).lerp(g(x0, y1, z1).lerp(g(x1, y1, z1), fx), fy);
        front.lerp(back, fz)
    }

    /// The four slices `z₀ − 1 … z₀ + 2` (clamped) around `p.z` and the
    /// fraction of the way from `z₀` to `z₀ + 1`.
    fn cubic_slices(&self, z: f64) -> ([usize; 4], f64) {
        let (z0, z1, fz) = locate(z, self.dims[2]);
        let last = self.dims[2] - 1;
        ([z0.saturating_sub(1), z0, z1, (z1 + 1).min(last)], fz)
    }

    /// [`Reconstruction::Cubic`]'s density at `p`: bilinear in each z slice,
    /// Catmull–Rom across the four slices around `p.z`.
    pub fn density_cubic(&self, p: DVec3) -> f64 {
        let (x0, x1, fx) = locate(p.x, self.dims[0]);
        let (y0, y1, fy) = locate(p.y, self.dims[1]);
        let (zs, fz) = self.cubic_slices(p.z);
        let slice = |z| lerp(lerp(self.at(x0, y0, z), self.at(x1, y0, z), fx), lerp(self.at(x0, y1, z), self.at(x1, y1, z), fx), fy);
        reconstruct::eval(zs.map(slice), fz)
    }

    /// [`Reconstruction::Cubic`]'s gradient at `p` (voxel units), the
    /// gradient of the cubic B-spline smoothing of the four slices of
    /// [`ReferenceRenderer::density_cubic`]: along z the B-spline's
    /// derivative of the bilinear samples; in x and y the corners' central
    /// differences, bilinear in each slice and blended across the four
    /// slices by the B-spline's weights.
    pub fn gradient_cubic(&self, p: DVec3) -> DVec3 {
        let (x0, x1, fx) = locate(p.x, self.dims[0]);
        let (y0, y1, fy) = locate(p.y, self.dims[1]);
        let (zs, fz) = self.cubic_slices(p.z);
        let (w, dw) = (reconstruct::b_spline(fz), reconstruct::b_spline_derivative(fz));
        let mut g = DVec3::ZERO;
        for (j, &z) in zs.iter().enumerate() {
            let value = lerp(lerp(self.at(x0, y0, z), self.at(x1, y0, z), fx), lerp(self.at(x0, y1, z), self.at(x1, y1, z), fx), fy);
            let c = |x, y| self.gradient_at(x, y, z);
            let cd = c(x0, y0).lerp(c(x1, y0), fx).lerp(c(x0, y1).lerp(c(x1, y1), fx), fy);
            g += DVec3::new(w[j] * cd.x, w[j] * cd.y, dw[j] * value);
        }
        if self.dims[2] < 2 { DVec3::new(g.x, g.y, 0.0) } else { g }
    }

    /// Density under `recon`.
    #[inline(always)]
    pub fn density_with(&self, recon: Reconstruction, p: DVec3) -> f64 {
        match recon {
            Reconstruction::Linear => self.density(p),
            Reconstruction::Cubic => self.density_cubic(p),
        }
    }

    /// Gradient (voxel units) under `recon`.
    #[inline(always)]
    pub fn gradient_with(&self, recon: Reconstruction, p: DVec3) -> DVec3 {
        match recon {
            Reconstruction::Linear => self.gradient(p),
            Reconstruction::Cubic => self.gradient_cubic(p),
        }
    }

    /// The unit normal (world space, down the density) the linear
    /// reconstruction shades a hit with, a fraction `frac` of the way
    /// between the points `slices` of its ray: the linear blend of
    /// [`ReferenceRenderer::blended_normal`] at the two. NaN where it is zero.
    pub fn shading_normal(&self, slices: [DVec3; 2], frac: f64, codes: bool) -> DVec3 {
        let a = self.blended_normal(slices[0], codes);
        let n = if frac > 0.0 { a.lerp(self.blended_normal(slices[1], codes), frac) } else { a };
        if n.length() > 0.0 { -n.normalize() } else { DVec3::NAN }
    }

    /// [`ReferenceRenderer::shading_normal`] with the cubic reconstruction's
    /// normal codes ([`crate::data::normals::cubic_voxel_normal`], the
    /// B-spline gradient at each voxel): what a hit of the cubic crossing
    /// ([`crate::composite::raycast::RayContext::with_cubic_crossing`]) is
    /// shaded with.
    pub fn shading_normal_cubic_codes(&self, slices: [DVec3; 2], frac: f64) -> DVec3 {
        let a = self.blended_cubic_codes(slices[0]);
        let n = if frac > 0.0 { a.lerp(self.blended_cubic_codes(slices[1]), frac) } else { a };
        if n.length() > 0.0 { -n.normalize() } else { DVec3::NAN }
    }

    /// The trilinear blend at `p` of the corners' decoded cubic normal codes
    /// (the B-spline gradient at each corner voxel, [`ReferenceRenderer::gradient_cubic`]
    /// there), each unit and turned to the side of the B-spline gradient at `p`.
    fn blended_cubic_codes(&self, p: DVec3) -> DVec3 {
        let sp = DVec3::new(self.spacing[0] as f64, self.spacing[1] as f64, self.spacing[2] as f64);
        let g = self.gradient_cubic(p) / sp;
        if g.length() <= 0.0 || g.is_nan() {
            return g;
        }
        self.blend_corner_codes(p, g, |x, y, z| self.gradient_cubic(DVec3::new(x as f64, y as f64, z as f64)) / sp)
    }

    /// The trilinear blend at `p` of the decoded codes of the corners'
    /// gradients `corner(x, y, z)` (world space), each unit and turned to the
    /// side of `g`.
    fn blend_corner_codes(&self, p: DVec3, g: DVec3, corner: impl Fn(usize, usize, usize) -> DVec3) -> DVec3 {
        let (x0, x1, fx) = locate(p.x, self.dims[0]);
        let (y0, y1, fy) = locate(p.y, self.dims[1]);
        let (z0, z1, fz) = locate(p.z, self.dims[2]);
        let mut sum = DVec3::ZERO;
        for (x, wx) in [(x0, 1.0 - fx), (x1, fx)] {
            for (y, wy) in [(y0, 1.0 - fy), (y1, fy)] {
                for (z, wz) in [(z0, 1.0 - fz), (z1, fz)] {
                    let c = corner(x, y, z);
                    let code = encode_normal([c.x as f32, c.y as f32, c.z as f32]);
                    // (a zero gradient's code shades as facing the viewer: it adds no direction)
                    if let Some(n) = decode_normal(code) {
                        let n = DVec3::new(n[0] as f64, n[1] as f64, n[2] as f64);
                        sum += wx * wy * wz * if n.dot(g) < 0.0 { -n } else { n };
                    }
                }
            }
        }
        sum
    }

    /// The unit normal (world space, down the density) the cubic
    /// reconstruction's fast paths shade a hit at `p` with: the gradient of
    /// the B-spline smoothing ([`ReferenceRenderer::gradient_cubic`]). NaN
    /// where it is zero.
    pub fn cubic_shading_normal(&self, p: DVec3) -> DVec3 {
        let sp = DVec3::new(self.spacing[0] as f64, self.spacing[1] as f64, self.spacing[2] as f64);
        let n = self.gradient_cubic(p) / sp;
        if n.length() > 0.0 { -n.normalize() } else { DVec3::NAN }
    }

    /// The gradient the linear reconstruction shades point `p` with, in world
    /// space (up the density, not normalized): [`ReferenceRenderer::gradient`]
    /// divided by the spacing, or with `codes` the same trilinear blend of the
    /// corners' decoded normal codes ([`crate::data::normals`]), each unit
    /// and turned to the gradient's side.
    pub fn blended_normal(&self, p: DVec3, codes: bool) -> DVec3 {
        let sp = DVec3::new(self.spacing[0] as f64, self.spacing[1] as f64, self.spacing[2] as f64);
        let g = self.gradient(p) / sp;
        if !codes || g.length() <= 0.0 || g.is_nan() {
            return g;
        }
        self.blend_corner_codes(p, g, |x, y, z| self.gradient_at(x, y, z) / sp)
    }

    /// Block of a point inside the box.
    #[inline(always)]
    fn block_of(&self, p: DVec3) -> [usize; 3] {
        [0, 1, 2].map(|a| ((p[a].max(0.0) as usize) / BLOCK).min(self.nblocks[a] - 1))
    }

    /// Closed voxel-space box of block `b`.
    fn block_box(&self, b: [usize; 3]) -> (DVec3, DVec3) {
        let lo = DVec3::new((b[0] * BLOCK) as f64, (b[1] * BLOCK) as f64, (b[2] * BLOCK) as f64);
        let hi = [0, 1, 2].map(|a| ((b[a] * BLOCK + BLOCK).min(self.dims[a].saturating_sub(1))) as f64);
        (lo, DVec3::from_array(hi))
    }

    /// Renders `scene` from `camera`.
    pub fn render(&self, scene: &Scene, camera: &Camera, opts: &ReferenceOptions) -> Result<ReferenceImage> {
        self.render_projected(scene, camera, &Projection::Parallel, opts)
    }

    /// Renders `scene` from `camera` under `projection`: perspective rays from
    /// the eye through each output pixel for a perspective projection (the
    /// headlight stays the central view direction, as in the fast paths; the
    /// iso depth is still measured along the view from the plane through the
    /// volume centre).
    pub fn render_projected(
        &self,
        scene: &Scene,
        camera: &Camera,
        projection: &Projection,
        opts: &ReferenceOptions,
    ) -> Result<ReferenceImage> {
        opts.check()?;
        if scene.iso.is_nan() {
            return Err(Error::value("iso value", "NaN"));
        }
        let rays = Rays::with_projection(camera, projection, self.dims, self.spacing)?;
        let sp = DVec3::new(self.spacing[0] as f64, self.spacing[1] as f64, self.spacing[2] as f64);
        let min_sp = sp.min_element();
        let cls = &scene.classifier;
        let recon = opts.reconstruction;
        let [nbx, nby, nbz] = self.nblocks;
        let visible: Vec<bool> = (0..self.ranges.len())
            .map(|i| {
                let (lo, hi) = match recon {
                    Reconstruction::Linear => self.ranges[i],
                    Reconstruction::Cubic => {
                        // the cubic reaches one slice beyond the block along z, and overshoots
                        let bz = i / (nbx * nby);
                        let (mut lo, mut hi) = self.ranges[i];
                        for b in [bz.wrapping_sub(1), bz + 1].into_iter().filter(|&b| b < nbz) {
                            let (l, h) = self.ranges[i - bz * nbx * nby + b * nbx * nby];
                            (lo, hi) = (lo.min(l), hi.max(h));
                        }
                        // (rounded outwards to f32)
                        let (l, h) = reconstruct::widened(lo as f64, hi as f64);
                        let (l, h) = (l - l.abs() * 1e-6, h + h.abs() * 1e-6);
                        ((l as f32).min(lo), (h as f32).max(hi))
                    }
                };
                match scene.mode {
                    Mode::Iso => hi >= scene.iso,
                    Mode::Blend => cls.may_be_visible(lo, hi),
                }
            })
            .collect();
        let light = rays.rot.row(2);
        let iso_c = cls.classify(scene.iso);
        let tracer = Tracer {
            vol: self,
            rays: &rays,
            scene,
            visible: &visible,
            delta: opts.step * min_sp,
            ratio: opts.step,
            cutoff: opts.opacity_cutoff,
            near: opts.near,
            light_m: light / sp,
            light_s: DVec3::ONE / sp,
            iso_rgb: [iso_c.r, iso_c.g, iso_c.b],
            recon,
            spacing: sp,
        };
        let [w, h] = camera.size;
        let mut data = vec![[0f32; 4]; w * h];
        let mut depth = vec![f64::NAN; w * h];
        let mut normal = vec![DVec3::NAN; w * h];
        let run = |data: &mut [[f32; 4]], depth: &mut [f64], normal: &mut [DVec3]| -> u64 {
            data.par_chunks_mut(w)
                .zip(depth.par_chunks_mut(w))
                .zip(normal.par_chunks_mut(w))
                .enumerate()
                .map(|(v, ((row, drow), nrow))| {
                    let mut n = 0;
                    for u in 0..w {
                        let r = tracer.trace(u as f64, v as f64);
                        row[u] = r.0;
                        drow[u] = r.1;
                        nrow[u] = r.3;
                        n += r.2;
                    }
                    n
                })
                .sum()
        };
        let samples = if opts.threads == 0 {
            run(&mut data, &mut depth, &mut normal)
        } else {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(opts.threads)
                .build()
                .map_err(|e| Error::Other(format!("cannot start {} worker threads: {e}", opts.threads)))?;
            pool.install(|| run(&mut data, &mut depth, &mut normal))
        };
        Ok(ReferenceImage { image: Image::from_data(w, h, data), depth, normal, samples })
    }
}

/// Everything one ray needs.
struct Tracer<'a> {
    vol: &'a ReferenceRenderer,
    rays: &'a Rays,
    scene: &'a Scene,
    visible: &'a [bool],
    /// Step in world units.
    delta: f64,
    /// Step in minimum spacings (the opacity-correction exponent).
    ratio: f64,
    cutoff: f64,
    /// The near clip in voxels (perspective).
    near: f64,
    light_m: DVec3,
    light_s: DVec3,
    iso_rgb: [f32; 3],
    recon: Reconstruction,
    /// Voxel spacing (world units per voxel).
    spacing: DVec3,
}

impl Tracer<'_> {
    /// `|n · l|` of the headlight for a voxel-space gradient (zero faces the viewer).
    fn ndl(&self, g: DVec3) -> f32 {
        let len = (g * self.light_s).length();
        if len > 1e-300 { (g.dot(self.light_m).abs() / len).min(1.0) as f32 } else { 1.0 }
    }

    /// Colour, depth, sample count and iso normal of the ray through pixel `(u, v)`.
    fn trace(&self, u: f64, v: f64) -> ([f32; 4], f64, u64, DVec3) {
        let none = DVec3::NAN;
        let (o, d) = self.rays.ray(u, v);
        let Some((t0, t1)) = self.rays.clip_ray(o, d) else {
            return ([0.0; 4], f64::NAN, 0, none);
        };
        // a perspective ray starts at the near clip
        let t0 = if self.rays.eye.is_some() { t0.max(self.near / d.abs().max_element()) } else { t0 };
        if t0 > t1 {
            return ([0.0; 4], f64::NAN, 0, none);
        }
        let vol = self.vol;
        let hi = DVec3::new(vol.dims[0] as f64 - 1.0, vol.dims[1] as f64 - 1.0, vol.dims[2] as f64 - 1.0);
        let at = |i: u64| -> (f64, DVec3) {
            let t = t0 + i as f64 * self.delta;
            (t, (o + t * d).clamp(DVec3::ZERO, hi))
        };
        let last = ((t1 - t0) / self.delta).floor() as u64;
        let [nbx, nby, _] = vol.nblocks;
        let mut acc = [0f64; 4];
        let mut samples = 0u64;
        let mut i = 0u64;
        while i <= last {
            let (_, p) = at(i);
            let b = vol.block_of(p);
            let (blo, bhi) = vol.block_box(b);
            let te = exit_box(o, d, blo, bhi);
            let rel = (te - t0) / self.delta;
            if !self.visible[(b[2] * nby + b[1]) * nbx + b[0]] {
                // every sample strictly inside this block is invisible (or below iso)
                let next = if rel.is_finite() { (rel - 1e-9).floor() as i64 + 1 } else { last as i64 + 1 };
                i = (next.max(i as i64 + 1)) as u64;
                continue;
            }
            let end = if rel.is_finite() { (rel.floor().max(0.0) as u64).clamp(i, last) } else { last };
            for j in i..=end {
                let (t, p) = at(j);
                let dens = vol.density_with(self.recon, p);
                samples += 1;
                match self.scene.mode {
                    Mode::Iso => {
                        if dens >= self.scene.iso as f64 {
                            let (th, ph) = if j == 0 { (t, p) } else { self.bisect(at(j - 1).0, t, o, d, hi) };
                            let grad = vol.gradient_with(self.recon, ph);
                            let ndl = self.ndl(grad);
                            let [r, g, b] = self.scene.shading.shade(self.iso_rgb, ndl);
                            // the depth convention: along the view from the plane through the centre
                            let depth = if self.rays.eye.is_some() { self.rays.depth_of(ph) } else { th };
                            let world = grad / self.spacing;
                            let n = if world.length() > 0.0 { -world.normalize() } else { none };
                            return ([r, g, b, 1.0], depth, samples, n);
                        }
                    }
                    Mode::Blend => {
                        let df = dens as f32;
                        let a = self.scene.classifier.alpha(df) as f64;
                        if a <= 0.0 {
                            continue;
                        }
                        let a = if a >= 1.0 { 1.0 } else { 1.0 - (1.0 - a).powf(self.ratio) };
                        let c = self.scene.classifier.classify(df);
                        let rgb = self.scene.shading.shade([c.r, c.g, c.b], self.ndl(vol.gradient_with(self.recon, p)));
                        let tr = (1.0 - acc[3]) * a;
                        for k in 0..3 {
                            acc[k] += tr * rgb[k] as f64;
                        }
                        acc[3] += tr;
                        if acc[3] >= self.cutoff {
                            return (acc.map(|x| x as f32), f64::NAN, samples, none);
                        }
                    }
                }
            }
            i = end + 1;
        }
        (acc.map(|x| x as f32), f64::NAN, samples, none)
    }

    /// Bisection for the iso crossing in `[ta, tb]` (density below iso at `ta`,
    /// at or above it at `tb`): the smallest `t` found at or above iso, and its point.
    fn bisect(&self, mut ta: f64, mut tb: f64, o: DVec3, d: DVec3, hi: DVec3) -> (f64, DVec3) {
        let iso = self.scene.iso as f64;
        let p = |t: f64| (o + t * d).clamp(DVec3::ZERO, hi);
        for _ in 0..BISECTIONS {
            let tm = 0.5 * (ta + tb);
            if tm <= ta || tm >= tb {
                break;
            }
            if self.vol.density_with(self.recon, p(tm)) >= iso {
                tb = tm;
            } else {
                ta = tm;
            }
        }
        (tb, p(tb))
    }
}

/// The iso depth of `renderer`'s last frame (rendered with `camera`) per output
/// pixel, in the reference's convention (world units along the view from the
/// plane through the volume centre; NaN where no hit).
///
/// Each output pixel maps through the inverse warp to a point of the
/// intermediate image; its fractional slice index is the bilinear blend of the
/// neighbouring hits, weighted over those neighbours that hit (NaN when they
/// carry less than half the weight, the same 0.5 coverage rule as the
/// silhouette metric). The hit point is where the pixel's own ray meets that
/// fractional slice ([`Factorization::sheared_to_voxel`]; under perspective,
/// [`PerspectiveView::sheared_to_voxel`]).
pub fn fast_path_depth(renderer: &Renderer, camera: &Camera) -> Result<Vec<f64>> {
    let (points, rays) = fast_path_hits(renderer, camera)?;
    Ok(points.iter().map(|p| p.map_or(f64::NAN, |p| rays.depth_of(p.point))).collect())
}

/// Where a fast path's iso hit is, for one output pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FastHit {
    /// The hit, in voxel coordinates.
    pub point: DVec3,
    /// The pixel's ray in the slices before and after the hit (both the hit
    /// when it lies on a slice), and the hit's fraction of the way between them.
    pub slices: [DVec3; 2],
    pub frac: f64,
}

/// The iso hit of `renderer`'s last frame (rendered with `camera`) per output
/// pixel (`None` where no hit), found as [`fast_path_depth`] describes, and
/// the rays of the frame.
pub fn fast_path_hits(renderer: &Renderer, camera: &Camera) -> Result<(Vec<Option<FastHit>>, Rays)> {
    if renderer.last_plans().len() > 1 {
        return split_frame_hits(renderer, camera);
    }
    let plan = renderer.last_plan().ok_or_else(|| Error::value("fast path depth", "the renderer has not rendered a frame yet"))?;
    let (dims, spacing, proj) = (renderer.dims(), renderer.spacing(), renderer.projection());
    // a perspective frame's camera (scaled by its field of view) and view
    let (cam, pv) = match proj.resolve(camera, dims, spacing)? {
        None => (*camera, None),
        Some((cam, distance)) => (cam, Some(PerspectiveView::new(&cam, distance, dims, spacing)?)),
    };
    let f = &plan.view;
    // the BCC grid's plan is that of its interleaved slices, whose sheared
    // coordinates are moved onto sub-grid A's samples (see `crate::data::bcc`)
    let bcc = match renderer.settings().lattice {
        Lattice::Bcc if pv.is_none() => Some(BccLattice::new(dims)?),
        _ => None,
    };
    let expected = match &bcc {
        None => {
            // (the permutation the frame was rendered with: the RLE paths' reuse mirrors y)
            let perms = [0, 1, 2].map(|a| if a == f.axis { f.perm } else { crate::view::permutation(a) });
            Factorization::with_permutations(&cam, dims, spacing, perms)?
        }
        Some(lattice) => {
            let cartesian = Factorization::with_axis(&cam, dims, spacing, f.axis)?;
            lattice.factorization(&cam, spacing, f.axis, cartesian.zoom)?
        }
    };
    if *f != expected || pv.is_some() != plan.perspective.is_some() {
        return Err(Error::value("fast path depth", "the last frame was rendered with a different camera"));
    }
    let shift = plan.perspective.map_or([0.0; 2], |r| r.shift);
    let rays = Rays::with_projection(camera, &proj, dims, spacing)?;
    let inter = renderer.intermediate();
    if inter.size != plan.grid.size {
        return Err(Error::value("fast path depth", "the intermediate image does not match the last frame's geometry"));
    }
    let [w, h] = camera.size;
    let (grid, pad) = (plan.grid.size, plan.grid.pad as f64);
    let mut out: Vec<Option<FastHit>> = vec![None; w * h];
    let slices = dims[f.axis];
    out.par_chunks_mut(w).enumerate().for_each(|(v, row)| {
        for (u, o) in row.iter_mut().enumerate() {
            let Some([a, b]) = plan.warp.to_sheared(u as f64, v as f64) else { continue };
            let (p, q) = (a / plan.grid.pitch[0] + pad, b / plan.grid.pitch[1] + pad);
            if let Some(k) = mean_depth(p, q, grid, |x, y| inter.depth_at(x, y)) {
                let at = |k: f64| {
                    DVec3::from_array(match (&pv, &bcc) {
                        (None, None) => f.sheared_to_voxel(a, b, k),
                        (None, Some(lattice)) => {
                            let [da, db] = BccLattice::SHEARED_SHIFT;
                            lattice.slice_volume_to_voxel(dims, f.axis, f.sheared_to_voxel(a - da, b - db, k))
                        }
                        // the plan's sheared point is the view's, shifted
                        (Some(pv), _) => pv.sheared_to_voxel(a + shift[0], b + shift[1], k),
                    })
                };
                // the slices around the hit along the pixel's ray (the BCC grid's interleaved
                // slices are not the volume's: there, the hit point alone)
                let (k0, frac) = match &bcc {
                    None => {
                        let k0 = k.floor().min(slices.saturating_sub(2) as f64).max(0.0);
                        (k0, (k - k0).clamp(0.0, 1.0))
                    }
                    Some(_) => (k, 0.0),
                };
                let slices = if frac > 0.0 { [at(k0), at(k0 + 1.0)] } else { [at(k); 2] };
                *o = Some(FastHit { point: at(k), slices, frac });
            }
        }
    });
    Ok((out, rays))
}

/// The iso depth (fractional slice) of the intermediate image at the
/// fractional pixel `(p, q)` of a `grid`-sized plan whose depths `depth_at`
/// reads: the bilinear weights' mean over the neighbouring pixels that hit,
/// `None` where those carry less than half the weight.
fn mean_depth(p: f64, q: f64, grid: [usize; 2], depth_at: impl Fn(usize, usize) -> f32) -> Option<f64> {
    let (x0, y0) = (p.floor(), q.floor());
    let (fx, fy) = (p - x0, q - y0);
    let (mut wsum, mut ksum) = (0.0, 0.0);
    for (dx, dy, wt) in [(0, 0, (1.0 - fx) * (1.0 - fy)), (1, 0, fx * (1.0 - fy)), (0, 1, (1.0 - fx) * fy), (1, 1, fx * fy)] {
        let (x, y) = (x0 + dx as f64, y0 + dy as f64);
        if x < 0.0 || y < 0.0 || x >= grid[0] as f64 || y >= grid[1] as f64 || wt <= 0.0 {
            continue;
        }
        let k = depth_at(x as usize, y as usize);
        if k.is_finite() {
            wsum += wt;
            ksum += wt * k as f64;
        }
    }
    (wsum >= 0.5).then(|| ksum / wsum)
}

/// [`fast_path_hits`] of a perspective frame split into pyramids (the eye
/// near the volume): each output pixel's hit found the same way in the plan
/// of the pyramid that owns its ray ([`Renderer::last_owner`]), from the
/// intermediate depths the renderer kept ([`Renderer::set_keep_depths`]; an
/// error without them), the sample positions read from that plan (affine
/// in the pixel within a slice, and along the ray between two slices).
fn split_frame_hits(renderer: &Renderer, camera: &Camera) -> Result<(Vec<Option<FastHit>>, Rays)> {
    let plans = renderer.last_plans();
    if (0..plans.len()).any(|i| !renderer.last_depth_image(i).is_some_and(|d| d.holds_depths_of(plans[i].grid.size))) {
        return Err(Error::value(
            "fast path depth",
            "the last frame was split into pyramids without keeping their depths (Renderer::set_keep_depths)",
        ));
    }
    let rays = Rays::with_projection(camera, &renderer.projection(), renderer.dims(), renderer.spacing())?;
    let [w, h] = camera.size;
    let mut out: Vec<Option<FastHit>> = vec![None; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(v, row)| {
        for (u, o) in row.iter_mut().enumerate() {
            let (uf, vf) = (u as f64, v as f64);
            let Some(i) = renderer.last_owner(uf, vf) else { continue };
            let plan = &plans[i];
            let Some([p, q]) = plan.output_to_intermediate(uf, vf) else { continue };
            let nk = plan.slices();
            let Some(k) = mean_depth(p, q, plan.grid.size, |x, y| renderer.last_depth_at(i, x, y)).filter(|_| nk > 0) else {
                continue;
            };
            // pixel (p, q)'s sample in slice k, then on the ray between two slices
            let in_slice = |k: usize| {
                let along = |axis: usize, x: f64| {
                    let a = plan.sample_at(k, axis, 0);
                    a + (plan.sample_at(k, axis, 1) - a) * x
                };
                crate::view::unpermute(plan.view.perm, DVec3::new(along(0, p), along(1, q), k as f64))
            };
            let at = |k: f64| {
                let k0 = (k.max(0.0).floor() as usize).min(nk - 1);
                let (a, b) = (in_slice(k0), in_slice((k0 + 1).min(nk - 1)));
                a + (b - a) * (k - k0 as f64)
            };
            let k0 = k.floor().min(nk.saturating_sub(2) as f64).max(0.0);
            let frac = (k - k0).clamp(0.0, 1.0);
            let slices = if frac > 0.0 { [at(k0), at(k0 + 1.0)] } else { [at(k); 2] };
            *o = Some(FastHit { point: at(k), slices, frac });
        }
    });
    Ok((out, rays))
}

/// The normal the renderer shades the iso hit of its last frame with, per
/// output pixel: unit, in world space (the volume's axes scaled by its
/// spacing), pointing down the density (NaN where no hit). It is the
/// renderer's own shading model evaluated at its own hit
/// ([`fast_path_hits`]), since the frame keeps colours and depths but no
/// normals: the linear reconstruction's gradient — the bilinear blends of
/// the central differences where the pixel's ray crosses the slices before
/// and after the hit, interpolated linearly between them, what the binary
/// and brute paths shade with under [`Normals::Gradient`] — or, under
/// [`Normals::Codes`], the same blend of the corners' decoded normal codes
/// (each turned to the gradient's side), the direction whose shade their
/// blend of the corners' shade entries approximates; under the cubic
/// reconstruction (iso mode, raycast paths) with [`Normals::Gradient`] the
/// gradient of its B-spline smoothing at the hit
/// ([`ReferenceRenderer::cubic_shading_normal`]), with [`Normals::Codes`] the
/// blend of the cubic's codes ([`ReferenceRenderer::shading_normal_cubic_codes`]). `model` must be the
/// [`ReferenceRenderer`] of the renderer's volume.
pub fn fast_path_normals(renderer: &Renderer, camera: &Camera, model: &ReferenceRenderer) -> Result<Vec<DVec3>> {
    if model.dims != renderer.dims() || model.spacing != renderer.spacing() {
        return Err(Error::value("fast path normals", "the model volume is not the renderer's"));
    }
    let (points, _) = fast_path_hits(renderer, camera)?;
    let s = renderer.settings();
    if s.cubic_rays() {
        return Ok(points.par_iter().map(|p| p.map_or(DVec3::NAN, |h| model.cubic_shading_normal(h.point))).collect());
    }
    if s.cubic_crossing() {
        return Ok(points.par_iter().map(|p| p.map_or(DVec3::NAN, |h| model.shading_normal_cubic_codes(h.slices, h.frac))).collect());
    }
    let codes = s.normals == Normals::Codes;
    Ok(points.par_iter().map(|p| p.map_or(DVec3::NAN, |h| model.shading_normal(h.slices, h.frac, codes))).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classify::TransferFunction;
    use crate::view::rotate_eye;

    fn linear_volume() -> Volume {
        Volume::from_fn([6, 5, 7], [1.0, 2.0, 0.5], |x, y, z| 3.0 * x as f32 - 2.0 * y as f32 + 0.5 * z as f32).unwrap()
    }

    #[test]
    fn trilinear_and_gradient_are_exact_for_a_linear_field() {
        let r = ReferenceRenderer::new(&linear_volume());
        let p = DVec3::new(2.25, 1.5, 3.75);
        assert!((r.density(p) - (3.0 * 2.25 - 2.0 * 1.5 + 0.5 * 3.75)).abs() < 1e-12);
        let g = r.gradient(p);
        assert!((g - DVec3::new(3.0, -2.0, 0.5)).length() < 1e-12, "{g}");
        // corners of the box
        assert_eq!(r.density(DVec3::ZERO), 0.0);
        assert!((r.density(DVec3::new(5.0, 4.0, 6.0)) - (15.0 - 8.0 + 3.0)).abs() < 1e-12);
    }

    #[test]
    fn block_ranges_cover_their_voxels() {
        let dims = [19, 9, 17];
        let v = Volume::from_fn(dims, [1.0; 3], |x, y, z| ((x * 31 + y * 17 + z * 7) % 23) as f32).unwrap();
        let r = ReferenceRenderer::new(&v);
        assert_eq!(r.nblocks, [3, 1, 2]);
        // block b holds voxels [8b, min(8b + 8, n − 1)]: a voxel on a face is in both blocks
        let holds = |b: usize, x: usize, n: usize| b * BLOCK <= x && x <= (b * BLOCK + BLOCK).min(n - 1);
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    let d = v.get(x, y, z);
                    for bz in (0..2).filter(|&b| holds(b, z, dims[2])) {
                        for bx in (0..3).filter(|&b| holds(b, x, dims[0])) {
                            let (lo, hi) = r.ranges[bz * 3 + bx];
                            assert!(lo <= d && d <= hi, "voxel ({x},{y},{z}) block ({bx},0,{bz})");
                        }
                    }
                }
            }
        }
    }

    /// The normal model of [`fast_path_normals`] is the renderer's: under
    /// gradient shading, every intermediate pixel the binary and brute paths
    /// hit shades exactly as the model's normal at its hit point does; under
    /// normal codes, within the codes' quantization.
    #[test]
    fn the_shading_normal_model_reproduces_the_fast_paths_shading() {
        use crate::render::{Method, Settings};
        let vol = crate::data::phantom::sphere([36, 30, 40]).unwrap();
        let vol = {
            let mut v = vol;
            v.set_spacing([0.8, 1.0, 1.7]).unwrap();
            v
        };
        let model = ReferenceRenderer::new(&vol);
        let tf = TransferFunction::threshold(100.0, [0.9, 0.8, 0.7]);
        for (normals, tol) in [(Normals::Gradient, 1e-5f32), (Normals::Codes, 0.03)] {
            for method in [Method::Binary, Method::Brute] {
                let settings = Settings { method, mode: Mode::Iso, normals, threads: 1, ..Settings::default() };
                let mut r = Renderer::new(vol.clone(), &tf, settings).unwrap();
                r.set_iso(100.0).unwrap();
                let scene = Scene::from_renderer(&r);
                let rgb = scene.classifier.classify(100.0);
                for (k, deg) in [(0usize, 20.0), (1, 35.0), (2, -50.0)] {
                    let cam = Camera {
                        rotation: rotate_eye(rotate_eye(DMat3::IDENTITY, 0, 30.0 * k as f64), 1, deg),
                        zoom: None,
                        size: [64, 64],
                    };
                    let mut img = Image::new(64, 64);
                    r.render(&cam, &mut img).unwrap();
                    let plan = r.last_plan().unwrap();
                    let light = cam.rotation.row(2);
                    let inter = r.intermediate();
                    let [w, h] = inter.size;
                    let mut seen = 0;
                    let mut worst = 0f32;
                    for q in 0..h {
                        for p in 0..w {
                            let depth = inter.depth_at(p, q);
                            if !depth.is_finite() {
                                continue;
                            }
                            let [a, b] = plan.intermediate_to_sheared(p as f64, q as f64);
                            let k0 = (depth as f64).floor().min(vol.dims()[plan.view.axis] as f64 - 2.0);
                            let at = |k: f64| DVec3::from_array(plan.view.sheared_to_voxel(a, b, k));
                            let n = model.shading_normal([at(k0), at(k0 + 1.0)], depth as f64 - k0, normals == Normals::Codes);
                            let ndl = n.dot(light).abs().min(1.0) as f32;
                            let want = scene.shading.shade([rgb.r, rgb.g, rgb.b], ndl);
                            let got = inter.rgba[q * w + p];
                            for c in 0..3 {
                                worst = worst.max((got[c] - want[c]).abs());
                            }
                            seen += 1;
                        }
                    }
                    assert!(seen > 300, "{seen}");
                    assert!(worst <= tol, "{normals:?} {method:?} view {k}: {worst}");
                }
            }
        }
    }

    #[test]
    fn ray_depth_convention() {
        // identity view: eye z = world z, depth = −z_world
        let cam = Camera { rotation: DMat3::IDENTITY, zoom: Some(2.0), size: [9, 9] };
        let rays = Rays::new(&cam, [5, 5, 5], [1.0; 3]).unwrap();
        let o = rays.origin(4.0, 4.0);
        assert!((o - DVec3::splat(2.0)).length() < 1e-12);
        assert!((rays.direction() - DVec3::NEG_Z).length() < 1e-12);
        assert_eq!(rays.clip(o), Some((-2.0, 2.0)));
        assert!((rays.depth_of(DVec3::new(2.0, 2.0, 0.0)) - 2.0).abs() < 1e-12);
        // pixel (u, v) = (cu + zoom·x, cv − zoom·y)
        let o = rays.origin(6.0, 0.0);
        assert!((o - DVec3::new(3.0, 4.0, 2.0)).length() < 1e-12, "{o}");
    }

    #[test]
    fn iso_hit_of_a_linear_ramp_is_exact() {
        // density = z: iso 2.25 is the plane z = 2.25, seen from +z (front = high z)
        let v = Volume::from_fn([8, 8, 8], [1.0; 3], |_, _, z| z as f32).unwrap();
        let tf = TransferFunction::threshold(0.5, [1.0; 3]);
        let cls = Classifier::new(&tf, 0.0, 7.0);
        let r = ReferenceRenderer::new(&v);
        // looking down −z from +z hits the high densities first: the entry point (z = 7)
        let cam = Camera { rotation: DMat3::IDENTITY, zoom: Some(1.0), size: [5, 5] };
        let out = r.render(&Scene::new(Mode::Iso, &cls, 2.25, Shading::default()), &cam, &ReferenceOptions::default()).unwrap();
        assert!((out.depth[12] - (-3.5)).abs() < 1e-12, "{}", out.depth[12]);
        // from below (rotated 180° about y): the plane z = 2.25 at depth 2.25 − 3.5
        let cam = Camera { rotation: rotate_eye(DMat3::IDENTITY, 1, 180.0), ..cam };
        let out = r.render(&Scene::new(Mode::Iso, &cls, 2.25, Shading::default()), &cam, &ReferenceOptions::default()).unwrap();
        assert!((out.depth[12] - (2.25 - 3.5)).abs() < 1e-9, "{}", out.depth[12]);
        assert_eq!(out.image.at(2, 2)[3], 1.0);
    }

    #[test]
    fn blend_opacity_is_independent_of_the_step() {
        // a constant slab of opacity 0.1 per voxel, 7 voxels deep: 1 − 0.9^7
        let v = Volume::from_fn([8, 8, 8], [1.0; 3], |_, _, _| 1.0).unwrap();
        let tf = TransferFunction::new(vec![(0.0, 0.1)], vec![(0.0, [1.0; 3])]).unwrap();
        let cls = Classifier::new(&tf, 0.0, 2.0);
        let r = ReferenceRenderer::new(&v);
        let cam = Camera { rotation: DMat3::IDENTITY, zoom: Some(1.0), size: [5, 5] };
        for step in [0.05, 0.01, 1.0] {
            let opts = ReferenceOptions { step, opacity_cutoff: 1.0, threads: 1, ..Default::default() };
            let out = r.render(&Scene::new(Mode::Blend, &cls, 0.0, Shading::default()), &cam, &opts).unwrap();
            // samples at 0, Δ, …, 7: 7/Δ + 1 of them, each α' = 1 − 0.9^Δ
            let n = (7.0 / step).floor() + 1.0;
            let want = 1.0 - 0.9f64.powf(step * n);
            assert!((out.image.at(2, 2)[3] as f64 - want).abs() < 1e-5, "step {step}: {} vs {want}", out.image.at(2, 2)[3]);
        }
    }

    #[test]
    fn rejects_bad_options() {
        let r = ReferenceRenderer::new(&linear_volume());
        let cls = Classifier::new(&TransferFunction::threshold(1.0, [1.0; 3]), 0.0, 20.0);
        let cam = Camera::new(DMat3::IDENTITY, [4, 4]);
        let s = Scene::new(Mode::Iso, &cls, 1.0, Shading::default());
        for step in [0.0, -1.0, f64::NAN, 2.0, 1e-9] {
            assert!(r.render(&s, &cam, &ReferenceOptions { step, ..Default::default() }).is_err());
        }
        assert!(r.render(&s, &cam, &ReferenceOptions { opacity_cutoff: 0.0, ..Default::default() }).is_err());
        assert!(r.render(&s, &Camera::new(DMat3::IDENTITY, [0, 4]), &ReferenceOptions::default()).is_err());
    }
}
