//! Built-in phantom volumes: synthetic test data with known ground truth.
//!
//! This module owns every volume the crate can make without a file:
//!
//! * [`head`] — a CT-like human head in Hounsfield units (`i16`): skin, a
//!   subcutaneous fat layer, a layered skull (cortical tables around diploë),
//!   grey and white matter, lateral ventricles, eyes in fat-filled orbits, air
//!   filled frontal and maxillary sinuses, nasal cavity and airway, a mandible
//!   with teeth, and a cervical spine in the neck.
//! * [`sphere`] — an `f32` ball whose iso-surface [`SPHERE_ISO`] is exactly the
//!   sphere returned by [`sphere_geometry`], for measuring geometric error.
//! * [`marschner_lobb`] — the Marschner–Lobb (1994) reconstruction test signal,
//!   with the continuous function [`marschner_lobb_value`] as ground truth.
//!
//! [`Phantom`] names them for the command line. Every phantom works at any size
//! accepted by [`check_dims`] (it is designed for 16³ … 512³, non-cubic dims
//! included), is fully deterministic, is generated in parallel over z-slices
//! with rayon, and is defined in normalised coordinates so that it looks the
//! same at every resolution.

use std::fmt;
use std::str::FromStr;

use glam::DVec3;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::volume::{Volume, VoxelData, check_dims};

// ---------------------------------------------------------------------------
// Phantom selector
// ---------------------------------------------------------------------------

/// One of the built-in phantoms.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Phantom {
    /// The CT head of [`head`] (Hounsfield units, `i16`).
    Head,
    /// The analytic ball of [`sphere`] (`f32`).
    Sphere,
    /// The Marschner–Lobb signal of [`marschner_lobb`] (`f32`).
    MarschnerLobb,
}

impl Phantom {
    /// Every phantom, in a stable order.
    pub const ALL: [Phantom; 3] = [Phantom::Head, Phantom::Sphere, Phantom::MarschnerLobb];

    /// Parses `head`, `sphere`, `marschner-lobb` (also `marschner_lobb`,
    /// `marschnerlobb` and `ml`), ignoring case and surrounding blanks.
    pub fn parse(s: &str) -> Result<Self> {
        match s.trim().to_ascii_lowercase().as_str() {
            "head" => Ok(Phantom::Head),
            "sphere" => Ok(Phantom::Sphere),
            "marschner-lobb" | "marschner_lobb" | "marschnerlobb" | "ml" => Ok(Phantom::MarschnerLobb),
            other => Err(Error::value("phantom", format!("'{other}' (expected head, sphere or marschner-lobb)"))),
        }
    }

    /// The canonical name: `head`, `sphere` or `marschner-lobb`.
    pub fn name(self) -> &'static str {
        match self {
            Phantom::Head => "head",
            Phantom::Sphere => "sphere",
            Phantom::MarschnerLobb => "marschner-lobb",
        }
    }

    /// The default grid size: head 128×128×113, sphere 128³, Marschner–Lobb 41³.
    pub fn default_dims(self) -> [usize; 3] {
        match self {
            Phantom::Head => [128, 128, 113],
            Phantom::Sphere => [128, 128, 128],
            Phantom::MarschnerLobb => [41, 41, 41],
        }
    }

    /// Builds the phantom at `dims` (`[nx, ny, nz]`).
    pub fn build(self, dims: [usize; 3]) -> Result<Volume> {
        match self {
            Phantom::Head => head(dims),
            Phantom::Sphere => sphere(dims),
            Phantom::MarschnerLobb => marschner_lobb(dims),
        }
    }
}

impl FromStr for Phantom {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Phantom::parse(s)
    }
}

impl fmt::Display for Phantom {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Checks `dims` and allocates the voxels, filling each z-slice in parallel:
/// `fill(z, slice)` receives slice `z` (x-fastest, `nx * ny` voxels).
fn build_slices<T: Copy + Default + Send>(dims: [usize; 3], fill: impl Fn(usize, &mut [T]) + Sync) -> Result<([usize; 3], Vec<T>)> {
    let d = check_dims(dims.map(|n| n as u64))?;
    let slice = d[0] * d[1];
    let mut v = vec![T::default(); slice * d[2]];
    v.par_chunks_mut(slice).enumerate().for_each(|(z, s)| fill(z, s));
    Ok((d, v))
}

// ---------------------------------------------------------------------------
// Sphere
// ---------------------------------------------------------------------------

/// The iso-value whose iso-surface in [`sphere`] is exactly the sphere of
/// [`sphere_geometry`].
pub const SPHERE_ISO: f32 = 100.0;

/// Centre and radius, in voxel units, of the sphere phantom at `dims`.
///
/// The centre is the middle of the grid, `((nx−1)/2, (ny−1)/2, (nz−1)/2)`, and
/// the radius is `R = 0.4 · min(nx, ny, nz)`, so the ball stays at least
/// `0.1 · min(dims) − 0.5` voxels clear of every face.
pub fn sphere_geometry(dims: [usize; 3]) -> ([f64; 3], f64) {
    let centre = dims.map(|n| (n as f64 - 1.0) / 2.0);
    let min = dims.iter().copied().min().unwrap_or(0);
    (centre, 0.4 * min as f64)
}

/// Density of the sphere phantom at distance `r` from the centre of a sphere of
/// radius `radius`.
fn sphere_density(r: f64, radius: f64) -> f64 {
    (100.0 + 25.0 * (radius - r)).clamp(0.0, 200.0)
}

/// A ball with a linear density ramp: `f32` voxels equal to
/// `clamp(100 + 25·(R − r), 0, 200)`.
///
/// `r` is the distance of the voxel from the grid centre and `R` the radius,
/// both in voxel units as given by [`sphere_geometry`]. Inside `r < R − 4` the
/// density is 200, outside `r > R + 4` it is 0, and in between it is linear in
/// `r`, so the [`SPHERE_ISO`] = 100 iso-surface is exactly the sphere of radius
/// `R` and the gradient has magnitude 25 along the radial direction there.
/// Spacing is 1 (isotropic).
pub fn sphere(dims: [usize; 3]) -> Result<Volume> {
    let (centre, radius) = sphere_geometry(dims);
    let (d, data) = build_slices(dims, |z, s: &mut [f32]| {
        let dz = z as f64 - centre[2];
        for (y, row) in s.chunks_mut(dims[0]).enumerate() {
            let dy = y as f64 - centre[1];
            for (x, out) in row.iter_mut().enumerate() {
                let dx = x as f64 - centre[0];
                *out = sphere_density((dx * dx + dy * dy + dz * dz).sqrt(), radius) as f32;
            }
        }
    })?;
    Volume::new(d, [1.0; 3], VoxelData::F32(data))
}

// ---------------------------------------------------------------------------
// Marschner–Lobb
// ---------------------------------------------------------------------------

/// The usual iso-value for rendering the Marschner–Lobb signal.
pub const ML_ISO: f32 = 0.5;
/// Marschner–Lobb modulation frequency `f_M`.
pub const ML_FM: f64 = 6.0;
/// Marschner–Lobb modulation amplitude `α`.
pub const ML_ALPHA: f64 = 0.25;

/// The continuous Marschner–Lobb (1994) test signal on `[−1, 1]³`:
///
/// `ρ(x,y,z) = (1 − sin(πz/2) + α(1 + ρr(√(x²+y²)))) / (2(1 + α))` with
/// `ρr(r) = cos(2π f_M cos(πr/2))`, `f_M` = [`ML_FM`] and `α` = [`ML_ALPHA`].
/// Its range is `[0, 1]`.
pub fn marschner_lobb_value(x: f64, y: f64, z: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, TAU};
    let r = (x * x + y * y).sqrt();
    let rho_r = (TAU * ML_FM * (FRAC_PI_2 * r).cos()).cos();
    (1.0 - (FRAC_PI_2 * z).sin() + ML_ALPHA * (1.0 + rho_r)) / (2.0 * (1.0 + ML_ALPHA))
}

/// Normalised coordinate of grid index `i` on an axis of `n` samples:
/// `−1 + 2i/(n−1)`, or 0 when the axis has a single sample.
fn ml_coord(i: usize, n: usize) -> f64 {
    if n <= 1 { 0.0 } else { -1.0 + 2.0 * i as f64 / (n - 1) as f64 }
}

/// The Marschner–Lobb signal sampled on a grid over `[−1, 1]³` (`f32` voxels).
///
/// Voxel `i` on an axis of `n` samples sits at `−1 + 2i/(n−1)` (0 when `n` is
/// 1), so 41³ is the classic 20 samples per unit. The spacing is
/// `(m − 1)/(n − 1)` per axis with `m` the largest dimension: 1 for cubic grids,
/// and the cube keeps its shape on non-cubic ones.
pub fn marschner_lobb(dims: [usize; 3]) -> Result<Volume> {
    let (d, data) = build_slices(dims, |z, s: &mut [f32]| {
        let zc = ml_coord(z, dims[2]);
        for (y, row) in s.chunks_mut(dims[0]).enumerate() {
            let yc = ml_coord(y, dims[1]);
            for (x, out) in row.iter_mut().enumerate() {
                *out = marschner_lobb_value(ml_coord(x, dims[0]), yc, zc) as f32;
            }
        }
    })?;
    let m = d.iter().copied().max().unwrap_or(1);
    let spacing = d.map(|n| if n <= 1 || m <= 1 { 1.0 } else { (m - 1) as f32 / (n - 1) as f32 });
    Volume::new(d, spacing, VoxelData::F32(data))
}

// ---------------------------------------------------------------------------
// Head
// ---------------------------------------------------------------------------

/// Hounsfield values of the tissues in the [`head`] phantom.
pub mod hu {
    /// Air outside the head and in the sinuses, nasal cavity and airway.
    pub const AIR: i16 = -1000;
    /// Subcutaneous fat and orbital fat.
    pub const FAT: i16 = -100;
    /// Cerebrospinal fluid around the brain and in the ventricles.
    pub const CSF: i16 = 5;
    /// Vitreous body of the eyes.
    pub const VITREOUS: i16 = 10;
    /// White matter.
    pub const WHITE_MATTER: i16 = 30;
    /// Spinal cord.
    pub const CORD: i16 = 32;
    /// Grey matter (cortex).
    pub const GREY_MATTER: i16 = 38;
    /// Skin and scalp.
    pub const SKIN: i16 = 40;
    /// Muscle and other deep soft tissue of face and neck.
    pub const MUSCLE: i16 = 50;
    /// Intervertebral discs.
    pub const DISC: i16 = 80;
    /// Cancellous bone of the vertebral bodies.
    pub const VERTEBRA_CANCELLOUS: i16 = 400;
    /// Cancellous bone of the facial skeleton and the mandible.
    pub const CANCELLOUS: i16 = 450;
    /// Diploë between the skull tables.
    pub const DIPLOE: i16 = 550;
    /// Vertebral arches.
    pub const VERTEBRA_ARCH: i16 = 900;
    /// Cortical bone of the face, mandible and vertebral bodies.
    pub const CORTICAL: i16 = 1150;
    /// The skull's outer and inner cortical tables.
    pub const SKULL_TABLE: i16 = 1350;
    /// Teeth (dentine and enamel).
    pub const TEETH: i16 = 2200;
}

/// Design-space half-extents of the head's box: x (left–right), y
/// (posterior–anterior), z (inferior–superior). The head is modelled in a box
/// with the 128:128:113 aspect of the default dims.
const HEAD_EXTENT: [f64; 3] = [1.0, 1.0, 0.88];

/// Full width, in voxels, of the smooth edge ramp between two tissues.
const EDGE_WIDTH: f64 = 1.5;

/// A CT-like head in Hounsfield units (`i16` voxels, spacing 1).
///
/// Orientation (RAS): +x is the patient's right, +y anterior (the face looks
/// toward +y), +z superior (the top of the skull is at high z, the neck at low
/// z). The head is symmetric in x.
///
/// The anatomy is defined in normalised coordinates and mapped onto the grid
/// per axis, so it looks the same at every resolution and fills most of any
/// grid (non-cubic grids stretch it), always leaving an air margin of at least
/// two voxels (three at 128 and up to 4 % of the edge at large sizes) on every
/// face. Contents, outside in (HU values in [`hu`]):
///
/// * air (−1000) around the head;
/// * skin (40), then a subcutaneous fat layer (−100), then muscle (50) in the
///   face and neck;
/// * the skull: outer and inner cortical tables (1350) around diploë (550),
///   closed below by a skull base, with a thickened brow;
/// * the brain: a thin CSF layer (5), grey matter (38) and white matter (30),
///   with two lateral ventricles (CSF, 5);
/// * the face: cancellous facial bone (450) in a cortical shell (1150), eyes
///   (vitreous, 10) in fat-filled orbits, air-filled frontal and maxillary
///   sinuses, nasal cavity and an airway down the neck;
/// * a mandible (cortical around cancellous bone) carrying teeth (2200);
/// * the cervical spine: five vertebral bodies (cortical shell, cancellous
///   core 400) on discs (80), vertebral arches (900) and the spinal cord (32),
///   which passes through the skull base.
///
/// All cavities are enclosed, so the skin (iso-value −500), the tissue below
/// it (−200 and 0) and the skull (300) are closed surfaces, and rays cross
/// empty space inside the head. Every tissue boundary is anti-aliased with a
/// smooth ramp about one voxel wide computed from signed distances, so
/// iso-surfaces are smooth rather than staircased.
///
/// Designed for 16³ … 512³; smaller grids work but the head becomes a blur.
pub fn head(dims: [usize; 3]) -> Result<Volume> {
    let d = check_dims(dims.map(|n| n as u64))?;
    let model = HeadModel::new(d);
    let (d, data) = build_slices(d, |z, s: &mut [i16]| model.fill_slice(z, s))?;
    Volume::new(d, [1.0; 3], VoxelData::I16(data))
}

/// Smooth coverage of a boundary at signed distance `d_vox` voxels (negative
/// inside): 1 deep inside, 0 outside, a smoothstep over [`EDGE_WIDTH`] voxels.
#[inline]
fn coverage(d_vox: f64) -> f64 {
    let t = (0.5 - d_vox / EDGE_WIDTH).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Approximate signed distance to an axis-aligned ellipse with radii `(rx, ry)`
/// (exact to first order near the boundary).
#[inline]
fn ellipse_sdf(px: f64, py: f64, rx: f64, ry: f64) -> f64 {
    let k0 = ((px / rx).powi(2) + (py / ry).powi(2)).sqrt();
    let k1 = ((px / (rx * rx)).powi(2) + (py / (ry * ry)).powi(2)).sqrt();
    if k1 > 0.0 { k0 * (k0 - 1.0) / k1 } else { -rx.min(ry) }
}

/// Approximate signed distance to an axis-aligned ellipsoid centred at the
/// origin with radii `r`.
#[inline]
fn ellipsoid_sdf(p: DVec3, r: DVec3) -> f64 {
    let k0 = (p / r).length();
    let k1 = (p / (r * r)).length();
    if k1 > 0.0 { k0 * (k0 - 1.0) / k1 } else { -r.min_element() }
}

/// Signed distance to a vertical (z-aligned) elliptic cylinder with radii `r`
/// between heights `z0 < z1`, its edges rounded by `round`.
#[inline]
fn cylinder_sdf(p: DVec3, cx: f64, cy: f64, r: [f64; 2], z0: f64, z1: f64, round: f64) -> f64 {
    let dxy = ellipse_sdf(p.x - cx, p.y - cy, r[0] - round, r[1] - round);
    let dz = (z0 + round - p.z).max(p.z - (z1 - round));
    let outside = (dxy.max(0.0).powi(2) + dz.max(0.0).powi(2)).sqrt();
    outside + dxy.max(dz).min(0.0) - round
}

/// Polynomial smooth minimum with blend radius `k`.
#[inline]
fn smin(a: f64, b: f64, k: f64) -> f64 {
    let h = (k - (a - b).abs()).max(0.0) / k;
    a.min(b) - h * h * k * 0.25
}

/// A solid in design space, with an (approximate) signed distance function.
#[derive(Clone, Debug)]
enum Shape {
    /// Axis-aligned ellipsoid.
    Ellipsoid { c: DVec3, r: DVec3 },
    /// Ellipsoid whose long y axis bends down by `bend · (y − c.y)²`.
    BentEllipsoid { c: DVec3, r: DVec3, bend: f64 },
    /// Segment `a`–`b` thickened by `r`.
    Capsule { a: DVec3, b: DVec3, r: f64 },
    /// Vertical elliptic cylinder with rounded edges.
    Cylinder { cx: f64, cy: f64, r: [f64; 2], z: [f64; 2], round: f64 },
    /// `count` vertical elliptic cylinders of `height`, stacked downward from
    /// `top` every `period`.
    Stack { cx: f64, cy: f64, r: [f64; 2], top: f64, height: f64, period: f64, count: usize },
    /// Horizontal ring of radius `major` around `c` with an elliptic cross
    /// section (`minor` = radial, vertical radius), kept only where `y ≥ y_min`.
    Arch { c: DVec3, major: f64, minor: [f64; 2], y_min: f64 },
    /// `shape` cut to the side of the plane `n·p = off` that `n` points away from
    /// (`n` unit length).
    Cut { shape: Box<Shape>, n: DVec3, off: f64 },
    /// Union.
    Union(Vec<Shape>),
    /// Smooth union with blend radius `k`.
    SmoothUnion(Vec<Shape>, f64),
}

impl Shape {
    fn sdf(&self, p: DVec3) -> f64 {
        match self {
            Shape::Ellipsoid { c, r } => ellipsoid_sdf(p - *c, *r),
            Shape::BentEllipsoid { c, r, bend } => {
                let mut q = p - *c;
                q.z += bend * q.y * q.y;
                ellipsoid_sdf(q, *r)
            }
            Shape::Capsule { a, b, r } => {
                let ab = *b - *a;
                let t = ((p - *a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0);
                (p - (*a + ab * t)).length() - r
            }
            Shape::Cylinder { cx, cy, r, z, round } => cylinder_sdf(p, *cx, *cy, *r, z[0], z[1], *round),
            Shape::Stack { cx, cy, r, top, height, period, count } => {
                let k = ((top - 0.5 * height - p.z) / period).round().clamp(0.0, (*count as f64 - 1.0).max(0.0));
                let z1 = top - k * period;
                cylinder_sdf(p, *cx, *cy, *r, z1 - height, z1, 0.01)
            }
            Shape::Arch { c, major, minor, y_min } => {
                let q = p - *c;
                let radial = (q.x * q.x + q.y * q.y).sqrt() - major;
                ellipse_sdf(radial, q.z, minor[0], minor[1]).max(y_min - p.y)
            }
            Shape::Cut { shape, n, off } => shape.sdf(p).max(n.dot(p) - off),
            Shape::Union(v) => v.iter().map(|s| s.sdf(p)).fold(f64::INFINITY, f64::min),
            Shape::SmoothUnion(v, k) => v.iter().map(|s| s.sdf(p)).reduce(|a, b| smin(a, b, *k)).unwrap_or(f64::INFINITY),
        }
    }

    /// A box (min, max) outside which the signed distance is positive.
    fn bounds(&self) -> (DVec3, DVec3) {
        match self {
            Shape::Ellipsoid { c, r } => (*c - *r, *c + *r),
            Shape::BentEllipsoid { c, r, bend } => {
                let drop = bend.abs() * r.y * r.y;
                (*c - *r - DVec3::new(0.0, 0.0, drop), *c + *r + DVec3::new(0.0, 0.0, drop))
            }
            Shape::Capsule { a, b, r } => (a.min(*b) - *r, a.max(*b) + *r),
            Shape::Cylinder { cx, cy, r, z, .. } => (DVec3::new(cx - r[0], cy - r[1], z[0]), DVec3::new(cx + r[0], cy + r[1], z[1])),
            Shape::Stack { cx, cy, r, top, height, period, count } => {
                let bottom = top - (*count as f64 - 1.0).max(0.0) * period - height;
                (DVec3::new(cx - r[0], cy - r[1], bottom), DVec3::new(cx + r[0], cy + r[1], *top))
            }
            Shape::Arch { c, major, minor, y_min } => {
                let e = major + minor[0];
                (DVec3::new(c.x - e, (c.y - e).max(*y_min), c.z - minor[1]), DVec3::new(c.x + e, c.y + e, c.z + minor[1]))
            }
            Shape::Cut { shape, .. } => shape.bounds(),
            Shape::Union(v) => union_bounds(v, 0.0),
            Shape::SmoothUnion(v, k) => union_bounds(v, k * 0.25),
        }
    }
}

fn union_bounds(v: &[Shape], grow: f64) -> (DVec3, DVec3) {
    let init = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    let (lo, hi) = v.iter().map(Shape::bounds).fold(init, |(a, b), (c, d)| (a.min(c), b.max(d)));
    (lo - grow, hi + grow)
}

/// One tissue: the region where `shape`'s distance plus `inset` is negative,
/// painted with `value` over everything listed before it.
#[derive(Clone, Debug)]
struct Layer {
    shape: usize,
    inset: f64,
    value: f64,
}

/// The head's anatomy in design space (resolution independent).
struct Anatomy {
    shapes: Vec<Shape>,
    /// The skin surface: the envelope of everything.
    skin: usize,
    /// Tissues inside the skin, back to front.
    layers: Vec<Layer>,
}

fn ell(c: [f64; 3], r: [f64; 3]) -> Shape {
    Shape::Ellipsoid { c: DVec3::from(c), r: DVec3::from(r) }
}

fn capsule(a: [f64; 3], b: [f64; 3], r: f64) -> Shape {
    Shape::Capsule { a: DVec3::from(a), b: DVec3::from(b), r }
}

/// Left/right mirror image (x → −x) of `s`'s ellipsoid or capsule parameters.
fn mirror(s: &Shape) -> Shape {
    let m = |v: &DVec3| DVec3::new(-v.x, v.y, v.z);
    match s {
        Shape::Ellipsoid { c, r } => Shape::Ellipsoid { c: m(c), r: *r },
        Shape::BentEllipsoid { c, r, bend } => Shape::BentEllipsoid { c: m(c), r: *r, bend: *bend },
        Shape::Capsule { a, b, r } => Shape::Capsule { a: m(a), b: m(b), r: *r },
        other => other.clone(),
    }
}

impl Anatomy {
    fn shape(&mut self, s: Shape) -> usize {
        self.shapes.push(s);
        self.shapes.len() - 1
    }

    fn paint(&mut self, shape: usize, inset: f64, value: i16) {
        self.layers.push(Layer { shape, inset, value: f64::from(value) });
    }

    /// Adds `s` and its mirror image, both painted with `value`.
    fn paint_pair(&mut self, s: Shape, value: i16) {
        let m = mirror(&s);
        let a = self.shape(s);
        let b = self.shape(m);
        self.paint(a, 0.0, value);
        self.paint(b, 0.0, value);
    }

    /// The anatomy. Design units: the head's box is ±1 in x and y, ±0.88 in z
    /// ([`HEAD_EXTENT`]); one unit is roughly 10 cm.
    fn new() -> Anatomy {
        let mut a = Anatomy { shapes: Vec::new(), skin: 0, layers: Vec::new() };
        // Skin envelope: cranium, face, jaw, chin, nose and neck blended smoothly.
        a.skin = a.shape(Shape::SmoothUnion(
            vec![
                ell([0.0, -0.08, 0.20], [0.72, 0.86, 0.66]),
                ell([0.0, 0.28, -0.24], [0.58, 0.62, 0.54]),
                ell([0.0, 0.30, -0.52], [0.55, 0.48, 0.28]),
                ell([0.0, 0.64, -0.60], [0.22, 0.18, 0.15]),
                ell([0.0, 0.87, -0.12], [0.075, 0.10, 0.16]),
                Shape::Cylinder { cx: 0.0, cy: -0.16, r: [0.40, 0.42], z: [-0.84, -0.10], round: 0.06 },
            ],
            0.10,
        ));
        let skin = a.skin;
        a.paint(skin, 0.045, hu::FAT);
        a.paint(skin, 0.10, hu::MUSCLE);

        // Brow (glabella) and facial skeleton: cortical shell, cancellous core.
        let brow = a.shape(ell([0.0, 0.64, 0.08], [0.22, 0.10, 0.11]));
        a.paint(brow, 0.0, hu::CORTICAL);
        a.paint(brow, 0.02, hu::CANCELLOUS);
        let face = a.shape(ell([0.0, 0.40, -0.14], [0.44, 0.36, 0.30]));
        a.paint(face, 0.0, hu::CORTICAL);
        a.paint(face, 0.025, hu::CANCELLOUS);

        // Cranial cavity: an ellipsoid whose floor (the skull base) rises
        // toward the face: z ≥ −0.118 + 0.456·y.
        let (fa, fb): (f64, f64) = (-0.118, 0.456);
        let norm = (1.0 + fb * fb).sqrt();
        let cavity = a.shape(Shape::Cut {
            shape: Box::new(ell([0.0, -0.08, 0.20], [0.55, 0.69, 0.49])),
            n: DVec3::new(0.0, fb, -1.0) / norm,
            off: -fa / norm,
        });
        a.paint(cavity, -0.07, hu::SKULL_TABLE);
        a.paint(cavity, -0.05, hu::DIPLOE);
        a.paint(cavity, -0.02, hu::SKULL_TABLE);
        a.paint(cavity, 0.0, hu::CSF);
        a.paint(cavity, 0.02, hu::GREY_MATTER);
        a.paint(cavity, 0.07, hu::WHITE_MATTER);
        let ventricle = Shape::BentEllipsoid { c: DVec3::new(0.10, -0.06, 0.24), r: DVec3::new(0.05, 0.24, 0.075), bend: 0.8 };
        a.paint_pair(ventricle, hu::CSF);

        // Mandible (body and rami) with teeth.
        let ramus = capsule([0.34, 0.31, -0.57], [0.42, 0.12, -0.22], 0.045);
        let mandible = a.shape(Shape::Union(vec![
            Shape::Arch { c: DVec3::new(0.0, 0.34, -0.58), major: 0.34, minor: [0.05, 0.085], y_min: 0.30 },
            mirror(&ramus),
            ramus,
        ]));
        a.paint(mandible, 0.0, hu::CORTICAL);
        a.paint(mandible, 0.02, hu::CANCELLOUS);
        let teeth = a.shape(Shape::Arch { c: DVec3::new(0.0, 0.34, -0.45), major: 0.33, minor: [0.03, 0.07], y_min: 0.34 });
        a.paint(teeth, 0.0, hu::TEETH);

        // Cervical spine: discs, vertebral bodies, arches, spinal cord.
        let (top, height, period, count) = (-0.31, 0.065, 0.085, 5);
        let discs = a.shape(Shape::Cylinder { cx: 0.0, cy: -0.16, r: [0.105, 0.085], z: [-0.715, -0.31], round: 0.01 });
        a.paint(discs, 0.0, hu::DISC);
        let bodies = a.shape(Shape::Stack { cx: 0.0, cy: -0.16, r: [0.11, 0.09], top, height, period, count });
        a.paint(bodies, 0.0, hu::CORTICAL);
        a.paint(bodies, 0.015, hu::VERTEBRA_CANCELLOUS);
        let arches = a.shape(Shape::Stack { cx: 0.0, cy: -0.35, r: [0.12, 0.11], top, height, period, count });
        a.paint(arches, 0.0, hu::VERTEBRA_ARCH);
        let cord = a.shape(Shape::Cylinder { cx: 0.0, cy: -0.34, r: [0.05, 0.05], z: [-0.74, -0.15], round: 0.04 });
        a.paint(cord, 0.0, hu::CORD);

        // Orbits with eyes.
        a.paint_pair(ell([0.22, 0.58, -0.01], [0.13, 0.18, 0.12]), hu::FAT);
        a.paint_pair(ell([0.22, 0.62, 0.0], [0.095, 0.095, 0.095]), hu::VITREOUS);

        // Air: frontal sinus, maxillary sinuses, nasal cavity, airway.
        let frontal = a.shape(ell([0.0, 0.655, 0.07], [0.12, 0.045, 0.06]));
        a.paint(frontal, 0.0, hu::AIR);
        a.paint_pair(ell([0.19, 0.48, -0.26], [0.10, 0.13, 0.09]), hu::AIR);
        let nasal = a.shape(ell([0.0, 0.56, -0.17], [0.05, 0.22, 0.14]));
        a.paint(nasal, 0.0, hu::AIR);
        let airway = a.shape(Shape::Union(vec![
            capsule([0.0, 0.34, -0.20], [0.0, 0.10, -0.36], 0.05),
            capsule([0.0, 0.10, -0.36], [0.0, 0.08, -0.70], 0.055),
        ]));
        a.paint(airway, 0.0, hu::AIR);
        a
    }
}

/// Maps design space onto a grid.
#[derive(Clone, Copy, Debug)]
struct Frame {
    /// Grid position of the design origin.
    centre: [f64; 3],
    /// Voxels per design unit, per axis.
    scale: [f64; 3],
    /// Voxels per design unit for distances (geometric mean of `scale`).
    sigma: f64,
}

impl Frame {
    fn new(dims: [usize; 3]) -> Frame {
        let centre = dims.map(|n| (n as f64 - 1.0) / 2.0);
        let mut scale = [0.0; 3];
        for a in 0..3 {
            // The design box spans 96 % of the half-width, but at least 3 voxels
            // stay outside it (the smooth edge needs 0.75 of them).
            let usable = (0.96 * centre[a]).min(centre[a] - 3.0).max(0.5);
            scale[a] = usable / HEAD_EXTENT[a];
        }
        let sigma = (scale[0] * scale[1] * scale[2]).cbrt();
        Frame { centre, scale, sigma }
    }

    /// Design-space position of voxel `(x, y, z)`.
    #[inline]
    fn design(&self, v: [f64; 3]) -> DVec3 {
        DVec3::new(
            (v[0] - self.centre[0]) / self.scale[0],
            (v[1] - self.centre[1]) / self.scale[1],
            (v[2] - self.centre[2]) / self.scale[2],
        )
    }

    /// Grid position of design-space point `p`.
    #[cfg(test)]
    fn voxel(&self, p: DVec3) -> [f64; 3] {
        let p = p.to_array();
        [0, 1, 2].map(|a| self.centre[a] + self.scale[a] * p[a])
    }

    /// Inclusive voxel range along axis `a` covering design interval
    /// `[lo, hi]`, padded by `pad` voxels; empty when `first > last`.
    fn range(&self, a: usize, lo: f64, hi: f64, pad: f64, n: usize) -> (i64, i64) {
        let first = (self.centre[a] + self.scale[a] * lo - pad).floor().max(0.0);
        let last = (self.centre[a] + self.scale[a] * hi + pad).ceil().min(n as f64 - 1.0);
        (first as i64, last as i64)
    }
}

/// Voxel index ranges `[x, y, z]` where a shape may have non-zero coverage.
type Ranges = [(i64, i64); 3];

/// The anatomy placed on a particular grid.
struct HeadModel {
    anatomy: Anatomy,
    frame: Frame,
    dims: [usize; 3],
    /// Per layer: where it can be non-zero.
    layer_ranges: Vec<Ranges>,
    skin_ranges: Ranges,
}

/// Per-voxel memo of shape distances (shapes are shared by several layers).
struct Memo {
    value: Vec<f64>,
    stamp: Vec<u64>,
    now: u64,
}

impl HeadModel {
    fn new(dims: [usize; 3]) -> HeadModel {
        let anatomy = Anatomy::new();
        let frame = Frame::new(dims);
        // Bounds are exact for the primitives; the distances are approximate,
        // so pad generously beyond the half edge width.
        let pad = EDGE_WIDTH + 2.0;
        let ranges = |shape: usize, grow: f64| -> Ranges {
            let (lo, hi) = anatomy.shapes[shape].bounds();
            let (lo, hi) = (lo.to_array(), hi.to_array());
            [0, 1, 2].map(|a| frame.range(a, lo[a] - grow, hi[a] + grow, pad, dims[a]))
        };
        let layer_ranges = anatomy.layers.iter().map(|l| ranges(l.shape, (-l.inset).max(0.0))).collect();
        let skin_ranges = ranges(anatomy.skin, 0.0);
        HeadModel { anatomy, frame, dims, layer_ranges, skin_ranges }
    }

    #[inline]
    fn distance(&self, shape: usize, p: DVec3, memo: &mut Memo) -> f64 {
        if memo.stamp[shape] != memo.now {
            memo.stamp[shape] = memo.now;
            memo.value[shape] = self.anatomy.shapes[shape].sdf(p);
        }
        memo.value[shape]
    }

    /// Fills z-slice `z` (`nx * ny` voxels, x fastest).
    fn fill_slice(&self, z: usize, out: &mut [i16]) {
        let [nx, ny, _] = self.dims;
        let n = self.anatomy.shapes.len();
        let mut memo = Memo { value: vec![0.0; n], stamp: vec![0; n], now: 0 };
        let zi = z as i64;
        let inside = |r: (i64, i64), i: i64| r.0 <= i && i <= r.1;
        let slice_layers: Vec<usize> = (0..self.anatomy.layers.len()).filter(|&l| inside(self.layer_ranges[l][2], zi)).collect();
        let mut row_layers = Vec::with_capacity(slice_layers.len());
        let sigma = self.frame.sigma;
        let air = f64::from(hu::AIR);
        let skin = f64::from(hu::SKIN);
        for y in 0..ny {
            let row = &mut out[y * nx..(y + 1) * nx];
            row.fill(hu::AIR);
            let yi = y as i64;
            if !inside(self.skin_ranges[2], zi) || !inside(self.skin_ranges[1], yi) {
                continue;
            }
            row_layers.clear();
            row_layers.extend(slice_layers.iter().copied().filter(|&l| inside(self.layer_ranges[l][1], yi)));
            let (x0, x1) = self.skin_ranges[0];
            for x in x0.max(0)..=x1.min(nx as i64 - 1) {
                memo.now += 1;
                let p = self.frame.design([x as f64, y as f64, z as f64]);
                let skin_cover = coverage(self.distance(self.anatomy.skin, p, &mut memo) * sigma);
                if skin_cover <= 0.0 {
                    continue;
                }
                // Composite front to back over the skin: the last layer wins.
                let mut acc = 0.0;
                let mut weight = 1.0;
                for &l in row_layers.iter().rev() {
                    if !inside(self.layer_ranges[l][0], x) {
                        continue;
                    }
                    let layer = &self.anatomy.layers[l];
                    let a = coverage((self.distance(layer.shape, p, &mut memo) + layer.inset) * sigma);
                    if a > 0.0 {
                        acc += weight * a * layer.value;
                        weight *= 1.0 - a;
                        if weight <= 0.0 {
                            break;
                        }
                    }
                }
                acc += weight * skin;
                let v = air + skin_cover * (acc - air);
                row[x as usize] = v.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16;
            }
        }
    }
}
