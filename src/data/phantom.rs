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

use crate::data::shapes::{self, AnalyticPhantom, Grid, SMOOTH_ISO};
pub use crate::data::shapes::{ML_ALPHA, ML_FM, ML_ISO, SPHERE_ISO, marschner_lobb_value};
use crate::data::volume::{Volume, VoxelData, check_dims};
use crate::error::{Error, Result};

// ---------------------------------------------------------------------------
// Phantom selector
// ---------------------------------------------------------------------------

/// One of the built-in phantoms.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Phantom {
    /// The CT head phantom (Hounsfield units, `i16`), built by `head`.
    Head,
    /// The analytic ball (`f32`), built by `sphere`.
    Sphere,
    /// The Marschner–Lobb signal (`f32`), built by `marschner_lobb`.
    MarschnerLobb,
    /// The solid cube (`f32`): flat faces and sharp edges.
    Cube,
    /// The engine-like block (`f32`): two materials, bores,
    /// a shaft and bolts.
    Engine,
    /// A smooth ellipsoid (`f32`): semi-axes 0.4, 0.32 and 0.26 of the
    /// box, a `tanh` edge; analytic surface at 100.
    Ellipsoid,
    /// A smooth torus about the z axis (`f32`): its flat top and bottom lie
    /// along the slices; analytic surface at 100.
    Torus,
}

impl Phantom {
    /// Every phantom, in a stable order.
    pub const ALL: [Phantom; 7] =
        [Phantom::Head, Phantom::Sphere, Phantom::MarschnerLobb, Phantom::Cube, Phantom::Engine, Phantom::Ellipsoid, Phantom::Torus];

    /// Parses `head`, `sphere`, `marschner-lobb` (also `marschner_lobb`,
    /// `marschnerlobb` and `ml`), ignoring case and surrounding blanks.
    pub fn parse(s: &str) -> Result<Self> {
        match s.trim().to_ascii_lowercase().as_str() {
            "head" => Ok(Phantom::Head),
            "sphere" => Ok(Phantom::Sphere),
            "marschner-lobb" | "marschner_lobb" | "marschnerlobb" | "ml" => Ok(Phantom::MarschnerLobb),
            "cube" => Ok(Phantom::Cube),
            "engine" => Ok(Phantom::Engine),
            "ellipsoid" => Ok(Phantom::Ellipsoid),
            "torus" => Ok(Phantom::Torus),
            other => {
                Err(Error::value("phantom", format!("'{other}' (expected head, sphere, marschner-lobb, cube, engine, ellipsoid or torus)")))
            }
        }
    }

    /// The canonical name: `head`, `sphere` or `marschner-lobb`.
    pub fn name(self) -> &'static str {
        match self {
            Phantom::Head => "head",
            Phantom::Sphere => "sphere",
            Phantom::MarschnerLobb => "marschner-lobb",
            Phantom::Cube => "cube",
            Phantom::Engine => "engine",
            Phantom::Ellipsoid => "ellipsoid",
            Phantom::Torus => "torus",
        }
    }

    /// The iso value the phantom is made for (`None`: the head, whose
    /// tissue presets choose).
    pub fn iso(self) -> Option<f32> {
        match self {
            Phantom::Head => None,
            Phantom::Sphere => Some(SPHERE_ISO),
            Phantom::MarschnerLobb => Some(ML_ISO),
            Phantom::Cube => Some(CUBE_ISO),
            Phantom::Engine => Some(ENGINE_ISO),
            Phantom::Ellipsoid | Phantom::Torus => Some(SMOOTH_ISO),
        }
    }

    /// The default grid size: head 128×128×113, sphere 128³, Marschner–Lobb
    /// 41³, cube 64³ and engine 128³ (the Shear-Warp Deluxe paper's sizes),
    /// ellipsoid and torus 128³.
    pub fn default_dims(self) -> [usize; 3] {
        match self {
            Phantom::Head => [128, 128, 113],
            Phantom::Sphere => [128, 128, 128],
            Phantom::MarschnerLobb => [41, 41, 41],
            Phantom::Cube => [64, 64, 64],
            Phantom::Engine | Phantom::Ellipsoid | Phantom::Torus => [128, 128, 128],
        }
    }

    /// Builds the phantom at `dims` (`[nx, ny, nz]`).
    /// Bytes of the voxels of this phantom at `dims` (the head is `i16`, the
    /// others `f32`), `None` when it overflows: what [`Phantom::build`]
    /// allocates, to check against a memory budget before building.
    pub fn bytes(self, dims: [usize; 3]) -> Option<u64> {
        let per = if self == Phantom::Head { 2 } else { 4 };
        dims.iter().try_fold(per, |a: u64, &n| a.checked_mul(n as u64))
    }

    pub fn build(self, dims: [usize; 3]) -> Result<Volume> {
        if let Some(a) = self.analytic(dims, None)?.filter(|_| matches!(self, Phantom::Ellipsoid | Phantom::Torus)) {
            return a.build();
        }
        match self {
            Phantom::Head => head(dims),
            Phantom::Sphere => sphere(dims),
            Phantom::MarschnerLobb => marschner_lobb(dims),
            Phantom::Cube => cube(dims),
            Phantom::Engine => engine(dims),
            Phantom::Ellipsoid | Phantom::Torus => unreachable!("built from their analytic shape above"),
        }
    }

    /// True for the phantoms with an analytic surface ([`Phantom::analytic`]).
    pub fn has_analytic_surface(self) -> bool {
        matches!(self, Phantom::Sphere | Phantom::MarschnerLobb | Phantom::Ellipsoid | Phantom::Torus)
    }

    /// The analytic shape of the phantom at `dims` and the grid it is
    /// sampled on (`None` for the head, cube and engine, which have none).
    ///
    /// `dims` sets the physical box: `dims − 1` mm per axis, the phantom's
    /// size at spacing 1 (Marschner–Lobb: the cube of its largest axis, as
    /// [`marschner_lobb`] builds it). `spacing` samples that box at another
    /// spacing in mm ([`Grid::new`]: `⌊extent / spacing⌋ + 1` voxels per
    /// axis); `None` keeps the phantom's own sampling, whose voxels
    /// [`Phantom::build`] makes.
    pub fn analytic(self, dims: [usize; 3], spacing: Option<[f64; 3]>) -> Result<Option<AnalyticPhantom>> {
        let d = check_dims(dims.map(|n| n as u64))?;
        let extent = d.map(|n| (n - 1) as f64);
        let (shape, extent, own) = match self {
            Phantom::Sphere => (shapes::Shape::Ball { radius: sphere_geometry(d).1 }, extent, [1.0; 3]),
            Phantom::MarschnerLobb => {
                let m = d.iter().copied().max().unwrap_or(1);
                let e = (m - 1) as f64;
                let own = d.map(|n| if n <= 1 || m <= 1 { 1.0 } else { ((m - 1) as f32 / (n - 1) as f32) as f64 });
                (shapes::Shape::MarschnerLobb { half: e / 2.0 }, [e; 3], own)
            }
            Phantom::Ellipsoid => {
                let radii = [0.4 * extent[0], 0.32 * extent[1], 0.26 * extent[2]];
                (shapes::Shape::Ellipsoid { radii }, extent, [1.0; 3])
            }
            Phantom::Torus => {
                let m = extent[0].min(extent[1]);
                (shapes::Shape::Torus { major: 0.25 * m, minor: 0.12 * m.min(extent[2] / 0.3) }, extent, [1.0; 3])
            }
            Phantom::Head | Phantom::Cube | Phantom::Engine => return Ok(None),
        };
        let grid = match spacing {
            None => Grid { dims: d, spacing: own },
            Some(s) => Grid::new(extent, s)?,
        };
        Ok(Some(AnalyticPhantom { shape, grid }))
    }

    /// Builds the phantom at `dims`, or, with `spacing`, its analytic shape
    /// over the same physical box sampled at that spacing (mm):
    /// [`Phantom::analytic`]. A phantom without an analytic shape cannot be
    /// resampled (an error naming it).
    pub fn build_sampled(self, dims: [usize; 3], spacing: Option<[f64; 3]>) -> Result<Volume> {
        match spacing {
            None => self.build(dims),
            Some(_) => match self.analytic(dims, spacing)? {
                Some(a) => a.build(),
                None => Err(Error::value(
                    "phantom spacing",
                    format!(
                        "the {} phantom has no analytic shape to sample at another spacing (sphere, marschner-lobb, ellipsoid and torus do)",
                        self.name()
                    ),
                )),
            },
        }
    }

    /// Voxel bytes of [`Phantom::build_sampled`] (`None` on overflow or bad input).
    pub fn bytes_sampled(self, dims: [usize; 3], spacing: Option<[f64; 3]>) -> Option<u64> {
        match spacing {
            None => self.bytes(dims),
            Some(_) => self.analytic(dims, spacing).ok().flatten().and_then(|a| a.bytes()),
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
    // (a refused allocation is an error, not an abort)
    let n = slice * d[2];
    let mut v = Vec::new();
    v.try_reserve_exact(n).map_err(|_| crate::error::Error::Memory {
        what: "phantom voxels".into(),
        needed: (n as u64).saturating_mul(std::mem::size_of::<T>() as u64),
        held: 0,
        budget: 0,
    })?;
    v.resize(n, T::default());
    v.par_chunks_mut(slice).enumerate().for_each(|(z, s)| fill(z, s));
    Ok((d, v))
}

// ---------------------------------------------------------------------------
// Sphere
// ---------------------------------------------------------------------------

/// Centre and radius, in voxel units, of the sphere phantom at `dims`.
///
/// The centre is the middle of the grid, `((nx−1)/2, (ny−1)/2, (nz−1)/2)`, and
/// the radius is `R = 0.4 · min(nx, ny, nz)`, so the iso-surface stays
/// `0.1 · min(dims) − 0.5` voxels clear of the nearest face. (The density ramp
/// reaches 4 voxels beyond `R`, so below about 45 voxels the faces cut it.)
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
// Cube and engine (the Shear-Warp Deluxe paper's test objects)
// ---------------------------------------------------------------------------

/// The iso-value whose iso-surface in [`cube`] is exactly the cube of
/// [`cube_geometry`] (its faces at half the solid density).
pub const CUBE_ISO: f32 = 100.0;

/// The cube of [`cube`] at `dims`: its lower and upper corners in voxel
/// coordinates, the grid centre ± 0.3 · the axis's size (0.2 of each axis is
/// clear on either side, so every view sees six faces' worth of edges and a
/// 64³ grid has 38.4-voxel sides).
pub fn cube_geometry(dims: [usize; 3]) -> ([f64; 3], [f64; 3]) {
    let c = dims.map(|n| (n as f64 - 1.0) / 2.0);
    let h = dims.map(|n| 0.3 * n as f64);
    ([c[0] - h[0], c[1] - h[1], c[2] - h[2]], [c[0] + h[0], c[1] + h[1], c[2] + h[2]])
}

/// The overlap of voxel `x`'s box `[x − ½, x + ½]` with `[lo, hi]`, in `[0, 1]`.
fn box_coverage(x: f64, lo: f64, hi: f64) -> f64 {
    ((x + 0.5).min(hi) - (x - 0.5).max(lo)).clamp(0.0, 1.0)
}

/// A solid, axis-aligned cube of density 200 in air (0), `f32`, each voxel
/// the cube's share of its box (the exact partial-volume value of a box
/// filter): a face is a one-voxel linear ramp whose [`CUBE_ISO`] surface is
/// the face exactly, an edge and a corner the product of two and three. The
/// hardest flat faces for shear-warp (staircases along the diagonals) and
/// the sharpest edges for a zoom. Spacing 1.
pub fn cube(dims: [usize; 3]) -> Result<Volume> {
    let (lo, hi) = cube_geometry(dims);
    let (d, data) = build_slices(dims, |z, s: &mut [f32]| {
        let cz = box_coverage(z as f64, lo[2], hi[2]);
        for (y, row) in s.chunks_mut(dims[0]).enumerate() {
            let cy = cz * box_coverage(y as f64, lo[1], hi[1]);
            for (x, out) in row.iter_mut().enumerate() {
                *out = (200.0 * cy * box_coverage(x as f64, lo[0], hi[0])) as f32;
            }
        }
    })?;
    Volume::new(d, [1.0; 3], VoxelData::F32(data))
}

/// The iso-value of [`engine`]'s surfaces (half its lighter material).
pub const ENGINE_ISO: f32 = 60.0;

/// The material at normalized point `(u, v, w)` of [`engine`]: 0 air, 120 the
/// cast block, 240 the steel shaft and bolts.
fn engine_material(u: f64, v: f64, w: f64) -> f64 {
    let in_box = |c: [f64; 3], h: [f64; 3]| (u - c[0]).abs() < h[0] && (v - c[1]).abs() < h[1] && (w - c[2]).abs() < h[2];
    let r2 = |a: f64, b: f64| a * a + b * b;
    // steel: the shaft along u under the block, four bolts along w at its corners
    let shaft = r2(v - 0.5, w - 0.14) < 0.045 * 0.045 && (0.08..0.92).contains(&u);
    let bolt = [(0.22, 0.32), (0.78, 0.32), (0.22, 0.68), (0.78, 0.68)]
        .iter()
        .any(|&(bu, bv)| r2(u - bu, v - bv) < 0.025 * 0.025 && (0.17..0.80).contains(&w));
    if shaft || bolt {
        return 240.0;
    }
    // cast block with a flange on top, three bores from the top, a gallery across
    let block = in_box([0.5, 0.5, 0.45], [0.32, 0.22, 0.28]) || in_box([0.5, 0.5, 0.73], [0.35, 0.25, 0.03]);
    let bore = [0.32, 0.5, 0.68].iter().any(|&bu| r2(u - bu, v - 0.5) < 0.07 * 0.07 && w > 0.32);
    let gallery = r2(v - 0.5, w - 0.25) < 0.05 * 0.05;
    if block && !bore && !gallery { 120.0 } else { 0.0 }
}

/// An engine-like block (after the paper's engine data set), `f32`: a cast
/// block (density 120) with a flange, three cylinder bores open at the top, a
/// gallery through it, a steel shaft (240) beneath and four steel bolts, in
/// air; each voxel the mean of 3×3×3 point samples of its box (partial
/// volume). Surfaces at [`ENGINE_ISO`]. Spacing 1; the shape keeps the grid's
/// proportions.
pub fn engine(dims: [usize; 3]) -> Result<Volume> {
    const S: usize = 3;
    let (d, data) = build_slices(dims, |z, s: &mut [f32]| {
        for (y, row) in s.chunks_mut(dims[0]).enumerate() {
            for (x, out) in row.iter_mut().enumerate() {
                let mut sum = 0.0;
                for (dz, dy, dx) in (0..S * S * S).map(|t| (t / (S * S), (t / S) % S, t % S)) {
                    let at = |i: usize, di: usize, n: usize| (i as f64 + (di as f64 + 0.5) / S as f64) / n.max(1) as f64;
                    sum += engine_material(at(x, dx, dims[0]), at(y, dy, dims[1]), at(z, dz, dims[2]));
                }
                *out = (sum / (S * S * S) as f64) as f32;
            }
        }
    })?;
    Volume::new(d, [1.0; 3], VoxelData::F32(data))
}

// ---------------------------------------------------------------------------
// Marschner–Lobb
// ---------------------------------------------------------------------------

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
/// grid (non-cubic grids stretch it). Its design box ends max(3 voxels, 2 % of
/// the edge) inside every face, so at least two voxels of pure air (−1000)
/// remain on every side (on grids of at least 8 voxels per edge).
///
/// Contents, outside in (HU values in [`hu`]):
///
/// * air (−1000) around the head;
/// * skin (40), then a subcutaneous fat layer (−100), then muscle (50) in the
///   face and neck; the ears are skin only;
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
/// Every tissue boundary is anti-aliased with a smooth ramp about one voxel
/// wide computed from signed distances, so iso-surfaces are smooth rather than
/// staircased. The skin is an unbroken layer over everything else, so the air
/// cavities are enclosed and rays cross empty space inside the head. What the
/// usual thresholds show (as in a real CT):
///
/// * −500: the skin surface, with the sinuses, nasal cavity and airway as
///   closed internal cavities;
/// * −200: the same outer surface (fat, −100, lies above the threshold);
/// * 0: again the skin outside (skin is 40), but the fat below it is now
///   excluded, so cut views show a thin skin shell around muscle, brain and
///   eyes; the brain (30–38) is the soft tissue inside the skull;
/// * 300: the bone — skull, facial skeleton, mandible, teeth and vertebrae —
///   closed apart from the anatomical openings (orbits, nasal aperture and
///   the foramen magnum).
///
/// Designed for 16³ … 512³; smaller grids work but the head becomes a blur.
pub fn head(dims: [usize; 3]) -> Result<Volume> {
    let d = check_dims(dims.map(|n| n as u64))?;
    let model = HeadModel::new(d);
    let (d, data) = build_slices(d, |z, s: &mut [i16]| model.fill_slice(z, s, true))?;
    Volume::new(d, [1.0; 3], VoxelData::I16(data))
}

/// Smooth coverage of a boundary at signed distance `d_vox` voxels (negative
/// inside): 1 deep inside, 0 outside, a smoothstep over [`EDGE_WIDTH`] voxels.
#[inline]
fn coverage(d_vox: f64) -> f64 {
    let t = (0.5 - d_vox / EDGE_WIDTH).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Signed distance estimate for an ellipse or ellipsoid from `k0 = |p/r|`,
/// `k1 = |p/r²|` and the smallest radius.
///
/// Outside this is Quilez's `k0(k0 − 1)/k1`, exact to first order at the
/// surface. Its interior continuation jumps at the centre (between `−r_max` and
/// `−r_min`), so inside it is blended toward `−r_min` at the centre; both
/// branches agree in value and gradient at the surface, and the result is
/// continuous with a bounded gradient everywhere.
#[inline]
fn ellipsoid_estimate(k0: f64, k1: f64, r_min: f64) -> f64 {
    if k0 >= 1.0 {
        k0 * (k0 - 1.0) / k1
    } else {
        let along = if k1 > 0.0 { k0 * k0 / k1 } else { 0.0 };
        (k0 - 1.0) * (along + (1.0 - k0) * r_min)
    }
}

/// Approximate signed distance to an axis-aligned ellipse with radii `(rx, ry)`.
#[inline]
fn ellipse_sdf(px: f64, py: f64, rx: f64, ry: f64) -> f64 {
    let k0 = ((px / rx).powi(2) + (py / ry).powi(2)).sqrt();
    let k1 = ((px / (rx * rx)).powi(2) + (py / (ry * ry)).powi(2)).sqrt();
    ellipsoid_estimate(k0, k1, rx.min(ry))
}

/// Approximate signed distance to an axis-aligned ellipsoid centred at the
/// origin with radii `r`.
#[inline]
fn ellipsoid_sdf(p: DVec3, r: DVec3) -> f64 {
    let k0 = (p / r).length();
    let k1 = (p / (r * r)).length();
    ellipsoid_estimate(k0, k1, r.min_element())
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

/// Polynomial smooth maximum with blend radius `k`.
#[inline]
fn smax(a: f64, b: f64, k: f64) -> f64 {
    -smin(-a, -b, k)
}

/// Rounding radius of the skull base's bends.
const FLOOR_ROUND: f64 = 0.08;

/// A solid in design space, with an (approximate) signed distance function.
#[derive(Clone, Debug)]
enum Shape {
    /// Axis-aligned ellipsoid.
    Ellipsoid { c: DVec3, r: DVec3 },
    /// Segment `a`–`b` thickened by `r`.
    Capsule { a: DVec3, b: DVec3, r: f64 },
    /// Plate across x: the ellipse with radii `r` in (y, z) around `c`, extruded
    /// to `|x − c.x| ≤ half`, its edges rounded by `round`.
    Plate { c: DVec3, r: [f64; 2], half: f64, round: f64 },
    /// Vertical elliptic cylinder with rounded edges.
    Cylinder { cx: f64, cy: f64, r: [f64; 2], z: [f64; 2], round: f64 },
    /// `count` vertical elliptic cylinders of `height`, stacked downward from
    /// `top` every `period`.
    Stack { cx: f64, cy: f64, r: [f64; 2], top: f64, height: f64, period: f64, count: usize },
    /// Horizontal ring of radius `major` around `c` with an elliptic cross
    /// section (`minor` = radial, vertical radius), kept only where `y ≥ y_min`.
    Arch { c: DVec3, major: f64, minor: [f64; 2], y_min: f64 },
    /// `shape` cut off below a floor that is flat at `z0` for `y ≤ y0`, rises
    /// linearly to `z1` at `y1` and stays flat beyond (corners rounded).
    Floor { shape: Box<Shape>, z0: f64, z1: f64, y0: f64, y1: f64 },
    /// Union.
    Union(Vec<Shape>),
    /// Smooth union with blend radius `k`.
    SmoothUnion(Vec<Shape>, f64),
}

impl Shape {
    fn sdf(&self, p: DVec3) -> f64 {
        match self {
            Shape::Ellipsoid { c, r } => ellipsoid_sdf(p - *c, *r),
            Shape::Capsule { a, b, r } => {
                let ab = *b - *a;
                let t = ((p - *a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0);
                (p - (*a + ab * t)).length() - r
            }
            Shape::Plate { c, r, half, round } => {
                let q = p - *c;
                let de = ellipse_sdf(q.y, q.z, r[0] - round, r[1] - round);
                let dx = q.x.abs() - (half - round);
                let outside = (de.max(0.0).powi(2) + dx.max(0.0).powi(2)).sqrt();
                outside + de.max(dx).min(0.0) - round
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
            Shape::Floor { shape, z0, z1, y0, y1 } => {
                // Above z = max(z0, min(z1, line through (y0, z0) and (y1, z1))),
                // corners rounded.
                let m = (z1 - z0) / (y1 - y0);
                let ramp = (z0 + m * (p.y - y0) - p.z) / (1.0 + m * m).sqrt();
                let below = smax(z0 - p.z, smin(z1 - p.z, ramp, FLOOR_ROUND), FLOOR_ROUND);
                shape.sdf(p).max(below)
            }
            // Parts that certainly cannot change the result are skipped.
            Shape::Union(v) => v.iter().fold(f64::INFINITY, |acc, s| if s.lower_bound(p) >= acc { acc } else { acc.min(s.sdf(p)) }),
            Shape::SmoothUnion(v, k) => v.iter().fold(f64::INFINITY, |acc, s| {
                if s.lower_bound(p) >= acc + k {
                    acc
                } else if acc == f64::INFINITY {
                    s.sdf(p)
                } else {
                    smin(acc, s.sdf(p), *k)
                }
            }),
        }
    }

    /// A cheap lower bound of [`Shape::sdf`] (`−∞` when none is known), used to
    /// skip the parts of unions that are far away.
    #[inline]
    fn lower_bound(&self, p: DVec3) -> f64 {
        // How far p lies outside a centred box, along the worst axis.
        let excess = |q: DVec3, half: DVec3| (q.abs() - half).max_element();
        match self {
            // Outside the box, k0 ≥ 1 + e/r_max and k0/k1 ≥ r_min.
            Shape::Ellipsoid { c, r } => {
                let e = excess(p - *c, *r);
                if e > 0.0 { e * r.min_element() / r.max_element() } else { f64::NEG_INFINITY }
            }
            Shape::Plate { c, r, half, round } => {
                let e = excess(p - *c, DVec3::new(*half, r[0], r[1]));
                let ratio = (r[0].min(r[1]) - round) / (r[0].max(r[1]) - round);
                if e > 0.0 { e * ratio - round } else { f64::NEG_INFINITY }
            }
            Shape::Cylinder { cx, cy, r, z, round } => {
                let c = DVec3::new(*cx, *cy, 0.5 * (z[0] + z[1]));
                let e = excess(p - c, DVec3::new(r[0], r[1], 0.5 * (z[1] - z[0])));
                let ratio = (r[0].min(r[1]) - round) / (r[0].max(r[1]) - round);
                if e > 0.0 { e * ratio - round } else { f64::NEG_INFINITY }
            }
            _ => f64::NEG_INFINITY,
        }
    }

    /// A box (min, max) outside which the signed distance is positive.
    fn bounds(&self) -> (DVec3, DVec3) {
        match self {
            Shape::Ellipsoid { c, r } => (*c - *r, *c + *r),
            Shape::Capsule { a, b, r } => (a.min(*b) - *r, a.max(*b) + *r),
            Shape::Plate { c, r, half, .. } => {
                let e = DVec3::new(*half, r[0], r[1]);
                (*c - e, *c + e)
            }
            Shape::Cylinder { cx, cy, r, z, .. } => (DVec3::new(cx - r[0], cy - r[1], z[0]), DVec3::new(cx + r[0], cy + r[1], z[1])),
            Shape::Stack { cx, cy, r, top, height, period, count } => {
                let bottom = top - (*count as f64 - 1.0).max(0.0) * period - height;
                (DVec3::new(cx - r[0], cy - r[1], bottom), DVec3::new(cx + r[0], cy + r[1], *top))
            }
            Shape::Arch { c, major, minor, y_min } => {
                let e = major + minor[0];
                (DVec3::new(c.x - e, (c.y - e).max(*y_min), c.z - minor[1]), DVec3::new(c.x + e, c.y + e, c.z + minor[1]))
            }
            Shape::Floor { shape, .. } => shape.bounds(),
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

/// Thickness of the skin in design units: every other tissue lies at least
/// this deep below the skin surface, so the skin is an unbroken layer.
const SKIN_THICKNESS: f64 = 0.055;

/// The head's anatomy in design space (resolution independent).
struct Anatomy {
    shapes: Vec<Shape>,
    /// The skin surface: the envelope of everything.
    skin: usize,
    /// Tissues below the skin, painted back to front over subcutaneous fat
    /// and clipped to [`SKIN_THICKNESS`] below the skin surface.
    layers: Vec<Layer>,
}

fn ell(c: [f64; 3], r: [f64; 3]) -> Shape {
    Shape::Ellipsoid { c: DVec3::from(c), r: DVec3::from(r) }
}

fn capsule(a: [f64; 3], b: [f64; 3], r: f64) -> Shape {
    Shape::Capsule { a: DVec3::from(a), b: DVec3::from(b), r }
}

/// Left/right mirror image (x → −x) of an ellipsoid, a capsule, a plate or a
/// union of them (other shapes are symmetric and returned unchanged).
fn mirror(s: &Shape) -> Shape {
    let m = |v: &DVec3| DVec3::new(-v.x, v.y, v.z);
    match s {
        Shape::Ellipsoid { c, r } => Shape::Ellipsoid { c: m(c), r: *r },
        Shape::Capsule { a, b, r } => Shape::Capsule { a: m(a), b: m(b), r: *r },
        Shape::Plate { c, r, half, round } => Shape::Plate { c: m(c), r: *r, half: *half, round: *round },
        Shape::Union(v) => Shape::Union(v.iter().map(mirror).collect()),
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
        // Skin envelope: cranium, face, jaw, chin, nose and neck blended
        // smoothly, with two ears.
        let ear = Shape::Plate { c: DVec3::new(0.70, -0.10, 0.0), r: [0.11, 0.15], half: 0.045, round: 0.03 };
        a.skin = a.shape(Shape::SmoothUnion(
            vec![
                Shape::SmoothUnion(
                    vec![
                        ell([0.0, -0.08, 0.20], [0.72, 0.86, 0.66]),
                        ell([0.0, 0.28, -0.24], [0.58, 0.62, 0.54]),
                        ell([0.0, 0.30, -0.52], [0.55, 0.48, 0.28]),
                        ell([0.0, 0.64, -0.60], [0.22, 0.18, 0.15]),
                        ell([0.0, 0.87, -0.12], [0.075, 0.10, 0.16]),
                        Shape::Cylinder { cx: 0.0, cy: -0.16, r: [0.40, 0.42], z: [-0.84, -0.10], round: 0.06 },
                    ],
                    0.10,
                ),
                mirror(&ear),
                ear,
            ],
            0.03,
        ));
        // Everything below the skin sits on subcutaneous fat (see
        // `HeadModel::fill_slice`); deep soft tissue is muscle.
        let skin = a.skin;
        a.paint(skin, 0.10, hu::MUSCLE);

        // Brow (glabella) and facial skeleton: cortical shell, cancellous core.
        let brow = a.shape(ell([0.0, 0.64, 0.08], [0.22, 0.10, 0.11]));
        a.paint(brow, 0.0, hu::CORTICAL);
        a.paint(brow, 0.02, hu::CANCELLOUS);
        let face = a.shape(ell([0.0, 0.40, -0.14], [0.44, 0.36, 0.30]));
        a.paint(face, 0.0, hu::CORTICAL);
        a.paint(face, 0.025, hu::CANCELLOUS);

        // Cranial cavity: an ellipsoid on a floor (the skull base) that is low
        // at the back (posterior fossa) and rises in front (anterior fossa,
        // above the orbits).
        let cavity = a.shape(Shape::Floor {
            shape: Box::new(ell([0.0, -0.08, 0.20], [0.55, 0.69, 0.49])),
            z0: -0.24,
            z1: 0.12,
            y0: -0.02,
            y1: 0.32,
        });
        a.paint(cavity, -0.07, hu::SKULL_TABLE);
        a.paint(cavity, -0.05, hu::DIPLOE);
        a.paint(cavity, -0.02, hu::SKULL_TABLE);
        a.paint(cavity, 0.0, hu::CSF);
        a.paint(cavity, 0.02, hu::GREY_MATTER);
        a.paint(cavity, 0.07, hu::WHITE_MATTER);
        // Lateral ventricles: C-shaped tubes arching over the centre.
        let arc = [[0.10, -0.27, 0.18], [0.10, -0.16, 0.26], [0.10, 0.04, 0.27], [0.10, 0.17, 0.20]];
        let ventricle = Shape::Union(arc.windows(2).map(|w| capsule(w[0], w[1], 0.045)).collect());
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
        let (top, height, period, count) = (-0.33, 0.062, 0.08, 5);
        let discs = a.shape(Shape::Cylinder { cx: 0.0, cy: -0.16, r: [0.105, 0.085], z: [-0.712, -0.33], round: 0.01 });
        a.paint(discs, 0.0, hu::DISC);
        let bodies = a.shape(Shape::Stack { cx: 0.0, cy: -0.16, r: [0.11, 0.09], top, height, period, count });
        a.paint(bodies, 0.0, hu::CORTICAL);
        a.paint(bodies, 0.015, hu::VERTEBRA_CANCELLOUS);
        let arches = a.shape(Shape::Stack { cx: 0.0, cy: -0.35, r: [0.12, 0.11], top, height, period, count });
        a.paint(arches, 0.0, hu::VERTEBRA_ARCH);
        let cord = a.shape(Shape::Cylinder { cx: 0.0, cy: -0.34, r: [0.05, 0.05], z: [-0.74, -0.15], round: 0.04 });
        a.paint(cord, 0.0, hu::CORD);

        // Orbits with eyes.
        a.paint_pair(ell([0.22, 0.58, -0.03], [0.13, 0.18, 0.10]), hu::FAT);
        a.paint_pair(ell([0.22, 0.62, -0.025], [0.09, 0.09, 0.09]), hu::VITREOUS);

        // Air: frontal sinus, maxillary sinuses, nasal cavity, airway.
        let frontal = a.shape(ell([0.0, 0.67, 0.05], [0.09, 0.045, 0.06]));
        a.paint(frontal, 0.0, hu::AIR);
        a.paint_pair(ell([0.19, 0.48, -0.26], [0.10, 0.13, 0.09]), hu::AIR);
        let nasal = a.shape(Shape::Plate { c: DVec3::new(0.0, 0.56, -0.17), r: [0.22, 0.14], half: 0.05, round: 0.03 });
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

/// What a row scan knows about each shape's distance: its value `d` at voxel
/// `x` of the current row (`x == i64::MIN` when not evaluated yet).
///
/// Distances change by at most [`LIPSCHITZ`] design units per design unit, so
/// a voxel far enough from a boundary is classified without evaluating the
/// shape again: most voxels are deep inside or outside every shape.
struct RowState {
    x: Vec<i64>,
    d: Vec<f64>,
}

/// Upper bound on how fast any shape's distance function changes (the exact
/// distances change at rate 1; the approximations used here stay below 1.8,
/// checked by a test).
const LIPSCHITZ: f64 = 2.0;

impl HeadModel {
    fn new(dims: [usize; 3]) -> HeadModel {
        let anatomy = Anatomy::new();
        let frame = Frame::new(dims);
        // Bounds are exact for the primitives but the distances approximate,
        // so pad generously beyond the half edge width, in voxels and in
        // design units (checked by a test up to 1024³).
        let pad = EDGE_WIDTH + 2.0;
        let ranges = |shape: usize, grow: f64| -> Ranges {
            let grow = grow + 0.03;
            let (lo, hi) = anatomy.shapes[shape].bounds();
            let (lo, hi) = (lo.to_array(), hi.to_array());
            [0, 1, 2].map(|a| frame.range(a, lo[a] - grow, hi[a] + grow, pad, dims[a]))
        };
        let layer_ranges = anatomy.layers.iter().map(|l| ranges(l.shape, (-l.inset).max(0.0))).collect();
        let skin_ranges = ranges(anatomy.skin, 0.0);
        HeadModel { anatomy, frame, dims, layer_ranges, skin_ranges }
    }

    /// Coverage of the region `distance(shape) + inset < 0` at voxel `x` of the
    /// current row (design position `p`). With `skip`, uses the row state to
    /// avoid evaluating the shape when the answer is certainly 0 or 1.
    #[inline]
    fn cover(&self, st: &mut RowState, shape: usize, inset: f64, x: i64, p: DVec3, skip: bool) -> f64 {
        let sigma = self.frame.sigma;
        let half = 0.5 * EDGE_WIDTH;
        if st.x[shape] != x {
            if skip && st.x[shape] != i64::MIN {
                let slack = LIPSCHITZ * (x - st.x[shape]) as f64 / self.frame.scale[0];
                let d = st.d[shape] + inset;
                if (d + slack) * sigma <= -half {
                    return 1.0;
                }
                if (d - slack) * sigma >= half {
                    return 0.0;
                }
            }
            st.x[shape] = x;
            st.d[shape] = self.anatomy.shapes[shape].sdf(p);
        }
        coverage((st.d[shape] + inset) * sigma)
    }

    /// Fills z-slice `z` (`nx * ny` voxels, x fastest).
    ///
    /// `skip` enables the distance bounds of [`RowState`]; without it every
    /// shape is evaluated at every voxel it may cover (same result, slower).
    fn fill_slice(&self, z: usize, out: &mut [i16], skip: bool) {
        let [nx, ny, _] = self.dims;
        let n = self.anatomy.shapes.len();
        let mut st = RowState { x: vec![i64::MIN; n], d: vec![0.0; n] };
        let zi = z as i64;
        let inside = |r: (i64, i64), i: i64| r.0 <= i && i <= r.1;
        let slice_layers: Vec<usize> = (0..self.anatomy.layers.len()).filter(|&l| inside(self.layer_ranges[l][2], zi)).collect();
        let mut row_layers = Vec::with_capacity(slice_layers.len());
        let mut active = Vec::with_capacity(slice_layers.len());
        let mut cuts = Vec::with_capacity(2 * slice_layers.len() + 2);
        out.fill(hu::AIR);
        if !inside(self.skin_ranges[2], zi) {
            return;
        }
        for y in 0..ny {
            let yi = y as i64;
            if !inside(self.skin_ranges[1], yi) {
                continue;
            }
            let row = &mut out[y * nx..(y + 1) * nx];
            row_layers.clear();
            row_layers.extend(slice_layers.iter().copied().filter(|&l| inside(self.layer_ranges[l][1], yi)));
            st.x.fill(i64::MIN);
            let first = self.skin_ranges[0].0.max(0);
            let end = self.skin_ranges[0].1.min(nx as i64 - 1) + 1;
            // Split the row where the set of layers that may be present changes.
            cuts.clear();
            cuts.extend([first, end]);
            for &l in &row_layers {
                let (a, b) = self.layer_ranges[l][0];
                cuts.extend([a, b + 1].into_iter().filter(|&c| first < c && c < end));
            }
            cuts.sort_unstable();
            cuts.dedup();
            for w in cuts.windows(2) {
                active.clear();
                active.extend(row_layers.iter().copied().filter(|&l| inside(self.layer_ranges[l][0], w[0])));
                for x in w[0]..w[1] {
                    let p = self.frame.design([x as f64, y as f64, z as f64]);
                    row[x as usize] = self.voxel(&mut st, &active, x, p, skip);
                }
            }
        }
    }

    /// The Hounsfield value at voxel `x` of the current row (design position
    /// `p`), given the layers that may be present there.
    #[inline]
    fn voxel(&self, st: &mut RowState, active: &[usize], x: i64, p: DVec3, skip: bool) -> i16 {
        let air = f64::from(hu::AIR);
        let skin = f64::from(hu::SKIN);
        let skin_shape = self.anatomy.skin;
        let skin_cover = self.cover(st, skin_shape, 0.0, x, p, skip);
        if skin_cover <= 0.0 {
            return hu::AIR;
        }
        let inner_cover = self.cover(st, skin_shape, SKIN_THICKNESS, x, p, skip);
        let mut tissue = skin;
        if inner_cover > 0.0 {
            // Composite over fat: the last layer wins, so walk the layers from
            // the last and stop at the first opaque one.
            let mut acc = 0.0;
            let mut weight = 1.0;
            for &l in active.iter().rev() {
                let layer = &self.anatomy.layers[l];
                let a = self.cover(st, layer.shape, layer.inset, x, p, skip);
                if a > 0.0 {
                    acc += weight * a * layer.value;
                    weight *= 1.0 - a;
                    if weight <= 0.0 {
                        break;
                    }
                }
            }
            acc += weight * f64::from(hu::FAT);
            tissue += inner_cover * (acc - skin);
        }
        let v = air + skin_cover * (tissue - air);
        v.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // ----- helpers -----

    fn i16s(v: &Volume) -> &[i16] {
        match v.data() {
            VoxelData::I16(d) => d,
            other => panic!("expected i16 voxels, got {:?}", other.voxel_type()),
        }
    }

    fn f32s(v: &Volume) -> &[f32] {
        match v.data() {
            VoxelData::F32(d) => d,
            other => panic!("expected f32 voxels, got {:?}", other.voxel_type()),
        }
    }

    /// Nearest voxel to design-space point `p` of the head at `dims`.
    fn voxel_at(dims: [usize; 3], p: [f64; 3]) -> [usize; 3] {
        let g = Frame::new(dims).voxel(DVec3::from(p));
        [0, 1, 2].map(|a| g[a].round().clamp(0.0, dims[a] as f64 - 1.0) as usize)
    }

    fn head_at(v: &Volume, p: [f64; 3]) -> f32 {
        let [x, y, z] = voxel_at(v.dims(), p);
        v.get(x, y, z)
    }

    /// Flood fill from voxel 0 through voxels below `iso` (6-connected).
    fn flood_below(v: &Volume, iso: f32) -> Vec<bool> {
        let [nx, ny, nz] = v.dims();
        let f = v.to_f32();
        let mut seen = vec![false; f.len()];
        let mut stack = vec![0usize];
        seen[0] = f[0] < iso;
        while let Some(i) = stack.pop() {
            let (x, y, z) = (i % nx, (i / nx) % ny, i / (nx * ny));
            let mut visit = |j: usize| {
                if !seen[j] && f[j] < iso {
                    seen[j] = true;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < nx {
                visit(i + 1);
            }
            if y > 0 {
                visit(i - nx);
            }
            if y + 1 < ny {
                visit(i + nx);
            }
            if z > 0 {
                visit(i - nx * ny);
            }
            if z + 1 < nz {
                visit(i + nx * ny);
            }
        }
        seen
    }

    /// Design-space landmarks (see `Anatomy::new`).
    const BRAIN_CENTRE: [f64; 3] = [0.0, -0.08, 0.20];
    const VENTRICLES: [[f64; 3]; 2] = [[0.10, -0.06, 0.265], [-0.10, -0.06, 0.265]];
    const EYES: [[f64; 3]; 2] = [[0.22, 0.62, -0.025], [-0.22, 0.62, -0.025]];
    const SINUSES: [[f64; 3]; 3] = [[0.0, 0.67, 0.05], [0.19, 0.48, -0.26], [-0.19, 0.48, -0.26]];
    const AIR_INSIDE: [[f64; 3]; 2] = [[0.0, 0.56, -0.17], [0.0, 0.09, -0.50]];

    // ----- head -----

    #[test]
    fn head_has_brain_in_the_middle_and_air_in_the_corners() {
        for dims in [[128, 128, 113], [64, 64, 64]] {
            let v = head(dims).unwrap();
            assert_eq!(v.dims(), dims);
            assert_eq!(v.spacing(), [1.0; 3]);
            assert_eq!(v.data().voxel_type(), crate::data::volume::VoxelType::I16);
            // The midline between the ventricles is white matter.
            let [x, y, z] = voxel_at(dims, BRAIN_CENTRE);
            for dz in -1..=1i64 {
                for dy in -1..=1i64 {
                    let g = |c: usize, d: i64| (c as i64 + d) as usize;
                    let b = v.get(x, g(y, dy), g(z, dz));
                    assert!((28.0..=40.0).contains(&b), "{dims:?}: brain centre voxel {b}");
                }
            }
            // The grid centre is brain too.
            let b = v.get(dims[0] / 2, dims[1] / 2, dims[2] / 2);
            assert!((25.0..=40.0).contains(&b), "{dims:?}: grid centre {b}");
            let [nx, ny, nz] = dims;
            for (cx, cy, cz) in [(0, 0, 0), (nx - 1, 0, 0), (0, ny - 1, nz - 1), (nx - 1, ny - 1, nz - 1), (0, ny - 1, 0)] {
                assert_eq!(v.get(cx, cy, cz), -1000.0);
            }
        }
    }

    /// Checks that every voxel within `margin` of a face is exactly air.
    fn assert_air_margin(v: &Volume, margin: usize) {
        let [nx, ny, nz] = v.dims();
        let edge = |i: usize, n: usize| i < margin || i + margin >= n;
        let d = i16s(v);
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    if edge(x, nx) || edge(y, ny) || edge(z, nz) {
                        assert_eq!(d[v.index(x, y, z)], -1000, "{:?}: voxel ({x},{y},{z}) in the margin", v.dims());
                    }
                }
            }
        }
    }

    #[test]
    fn head_leaves_an_air_margin_and_fills_the_volume() {
        for dims in [[8, 9, 10], [16, 16, 16], [17, 23, 19], [128, 128, 113], [40, 96, 30]] {
            let v = head(dims).unwrap();
            assert_air_margin(&v, 2);
            if dims[0] < 16 {
                continue;
            }
            // It fills most of the volume: the skin reaches within 8 % of the
            // edge (plus the margin) along y (nose, back of head) and z.
            let [nx, ny, nz] = dims;
            let non_air = |x: usize, y: usize, z: usize| v.get(x, y, z) > -500.0;
            let mut lo = [usize::MAX; 3];
            let mut hi = [0; 3];
            for z in 0..nz {
                for y in 0..ny {
                    for x in 0..nx {
                        if non_air(x, y, z) {
                            for (a, c) in [x, y, z].into_iter().enumerate() {
                                lo[a] = lo[a].min(c);
                                hi[a] = hi[a].max(c);
                            }
                        }
                    }
                }
            }
            for a in [1, 2] {
                let n = dims[a];
                let slack = 4 + n * 8 / 100;
                assert!(lo[a] <= slack && hi[a] + 1 + slack >= n, "{dims:?} axis {a}: head spans {}..={}", lo[a], hi[a]);
            }
            assert!(hi[0] - lo[0] + 1 >= nx / 3, "{dims:?}: head too narrow");
        }
    }

    #[test]
    fn head_ray_crosses_skin_fat_bone_brain() {
        for dims in [[128, 128, 113], [256, 256, 225]] {
            let v = head(dims).unwrap();
            let [cx, y, z] = voxel_at(dims, BRAIN_CENTRE);
            // Phases: 0 air, 1 skin, 2 fat, 3 bone, 4 brain.
            let mut phase = 0;
            let (mut skin_max, mut fat_min, mut bone_max) = (f32::MIN, f32::MAX, f32::MIN);
            for x in 0..=cx {
                let h = v.get(x, y, z);
                match phase {
                    0 if h > -500.0 => phase = 1,
                    1 if h <= -80.0 && skin_max >= 35.0 => phase = 2,
                    2 | 1 if h > 300.0 => phase = 3,
                    3 if (25.0..=40.0).contains(&h) => phase = 4,
                    _ => {}
                }
                match phase {
                    1 => skin_max = skin_max.max(h),
                    2 => fat_min = fat_min.min(h),
                    3 => bone_max = bone_max.max(h),
                    _ => {}
                }
            }
            assert_eq!(v.get(0, y, z), -1000.0);
            assert_eq!(phase, 4, "{dims:?}: ray ended in phase {phase}");
            assert!((35.0..=45.0).contains(&skin_max), "{dims:?}: skin {skin_max}");
            assert!((-110.0..=-90.0).contains(&fat_min), "{dims:?}: fat {fat_min}");
            assert!(bone_max >= 1000.0, "{dims:?}: bone {bone_max}");
            assert!((25.0..=40.0).contains(&v.get(cx, y, z)), "{dims:?}: ray ends outside brain");
        }
    }

    #[test]
    fn head_skull_has_two_tables_and_diploe_at_high_resolution() {
        let dims = [256, 256, 225];
        let v = head(dims).unwrap();
        let [cx, y, z] = voxel_at(dims, BRAIN_CENTRE);
        let ray: Vec<f32> = (0..=cx).map(|x| v.get(x, y, z)).collect();
        let first = ray.iter().position(|&h| h > 300.0).unwrap();
        let last = ray.iter().rposition(|&h| h > 300.0).unwrap();
        let bone = &ray[first..=last];
        assert!(bone.iter().all(|&h| h > 300.0), "skull is not one solid band: {bone:?}");
        let peak = bone.iter().position(|&h| h >= 1200.0).unwrap();
        let dip = peak + bone[peak..].iter().position(|&h| h <= 700.0).unwrap();
        assert!(bone[dip..].iter().any(|&h| h >= 1200.0), "no inner table: {bone:?}");
        assert!(bone[dip] >= 400.0, "diploë {}", bone[dip]);
    }

    #[test]
    fn head_ventricles_eyes_and_sinuses() {
        for dims in [[128, 128, 113], [256, 256, 225]] {
            let v = head(dims).unwrap();
            for p in VENTRICLES {
                let h = head_at(&v, p);
                assert!((3.0..=8.0).contains(&h), "{dims:?}: ventricle {p:?} = {h}");
            }
            for p in EYES {
                let h = head_at(&v, p);
                assert!((8.0..=12.0).contains(&h), "{dims:?}: eye {p:?} = {h}");
            }
            // Bounding box of bone, used to show the sinuses lie inside the skull.
            let [nx, ny, nz] = dims;
            let mut lo = [usize::MAX; 3];
            let mut hi = [0; 3];
            for z in 0..nz {
                for y in 0..ny {
                    for x in 0..nx {
                        if v.get(x, y, z) > 300.0 {
                            for (a, c) in [x, y, z].into_iter().enumerate() {
                                lo[a] = lo[a].min(c);
                                hi[a] = hi[a].max(c);
                            }
                        }
                    }
                }
            }
            for p in SINUSES {
                let c = voxel_at(dims, p);
                assert_eq!(v.get(c[0], c[1], c[2]), -1000.0, "{dims:?}: sinus {p:?}");
                for a in 0..3 {
                    assert!(lo[a] < c[a] && c[a] < hi[a], "{dims:?}: sinus {p:?} outside the skull's box");
                }
                // Walled in by bone along every axis direction.
                for a in 0..3 {
                    for step in [-1i64, 1] {
                        let mut q = c.map(|i| i as i64);
                        let hit = loop {
                            q[a] += step;
                            if q[a] < 0 || q[a] >= dims[a] as i64 {
                                break false;
                            }
                            if v.get(q[0] as usize, q[1] as usize, q[2] as usize) > 300.0 {
                                break true;
                            }
                        };
                        assert!(hit, "{dims:?}: sinus {p:?} not walled in along axis {a} ({step})");
                    }
                }
            }
            for p in AIR_INSIDE {
                assert_eq!(head_at(&v, p), -1000.0, "{dims:?}: airway {p:?}");
            }
        }
    }

    #[test]
    fn head_skin_surfaces_are_closed() {
        let dims = [128, 128, 113];
        let v = head(dims).unwrap();
        let [cx, y, z] = voxel_at(dims, BRAIN_CENTRE);
        // A subcutaneous fat voxel on the lateral ray.
        let fat_x = (0..cx).find(|&x| v.get(x, y, z) <= -95.0 && v.get(x, y, z) > -105.0).unwrap();
        let fat = v.index(fat_x, y, z);
        for iso in [-500.0, -200.0, 0.0] {
            let outside = flood_below(&v, iso);
            for p in SINUSES.iter().chain(&AIR_INSIDE) {
                let [x, y, z] = voxel_at(dims, *p);
                assert!(!outside[v.index(x, y, z)], "iso {iso}: air at {p:?} is reachable from outside");
            }
            if iso >= -100.0 {
                assert!(!outside[fat], "iso {iso}: the fat layer is reachable from outside");
            }
        }
        // The skull (300) encloses the brain except for the foramen magnum:
        // from the brain centre every direction but down meets bone.
        let c = voxel_at(dims, BRAIN_CENTRE);
        for (a, step) in [(0, -1i64), (0, 1), (1, -1), (1, 1), (2, 1), (2, -1)] {
            let mut q = c.map(|i| i as i64);
            let hit = loop {
                q[a] += step;
                if q[a] < 0 || q[a] >= dims[a] as i64 {
                    break false;
                }
                if v.get(q[0] as usize, q[1] as usize, q[2] as usize) > 300.0 {
                    break true;
                }
            };
            assert!(hit, "no skull along axis {a} ({step})");
        }
    }

    #[test]
    fn head_works_at_small_and_odd_sizes() {
        for dims in [[16, 16, 16], [17, 23, 19], [1, 1, 1], [5, 3, 7]] {
            let v = head(dims).unwrap();
            assert_eq!(v.dims(), dims);
            if dims[0] >= 16 {
                let [x, y, z] = voxel_at(dims, BRAIN_CENTRE);
                let b = v.get(x, y, z);
                assert!((-200.0..300.0).contains(&b), "{dims:?}: centre {b}");
                let (lo, hi) = v.value_range();
                assert_eq!(lo, -1000.0);
                assert!(hi > 300.0, "{dims:?}: no bone at all");
            }
        }
        assert!(head([0, 16, 16]).is_err());
        assert!(head([100_000, 100_000, 100_000]).is_err());
    }

    #[test]
    fn head_is_deterministic_and_skipping_changes_nothing() {
        for dims in [[16, 16, 16], [17, 23, 19], [64, 56, 48], [128, 128, 113]] {
            let a = head(dims).unwrap();
            let b = head(dims).unwrap();
            assert_eq!(a, b);
            // Reference: every layer evaluated at every voxel, serially.
            let mut model = HeadModel::new(dims);
            let full = dims.map(|n| (0, n as i64 - 1));
            model.layer_ranges.iter_mut().for_each(|r| *r = full);
            model.skin_ranges = full;
            let slice = dims[0] * dims[1];
            let mut reference = vec![0i16; slice * dims[2]];
            for (z, s) in reference.chunks_mut(slice).enumerate() {
                model.fill_slice(z, s, false);
            }
            let d = i16s(&a);
            let diff = d.iter().zip(&reference).filter(|(p, q)| p != q).count();
            assert_eq!(diff, 0, "{dims:?}: {diff} voxels differ from the reference");
        }
    }

    #[test]
    fn layer_ranges_hold_everything_a_layer_covers() {
        // Voxels just outside a layer's (or the skin's) index range must have
        // zero coverage, at every resolution.
        let mut next = crate::testing::xorshift(0x9e37_79b9_7f4a_7c15);
        let mut rnd = move || (next() >> 11) as f64 / (1u64 << 53) as f64;
        for dims in [[16, 16, 16], [40, 96, 30], [128, 128, 113], [512, 512, 512], [1024, 1024, 1024]] {
            let m = HeadModel::new(dims);
            let checks = m.anatomy.layers.iter().zip(&m.layer_ranges).map(|(l, r)| (l.shape, l.inset, *r));
            for (shape, inset, r) in checks.chain([(m.anatomy.skin, 0.0, m.skin_ranges)]) {
                for _ in 0..4000 {
                    // A point within 6 voxels outside the range on one axis.
                    let a = (rnd() * 3.0) as usize % 3;
                    let mut v = [0.0; 3];
                    for b in 0..3 {
                        let (lo, hi) = (r[b].0 as f64, r[b].1 as f64);
                        v[b] = lo + (hi - lo) * rnd();
                    }
                    let out = 1.0 + 5.0 * rnd();
                    v[a] = if rnd() < 0.5 { r[a].0 as f64 - out } else { r[a].1 as f64 + out };
                    if v[a] < 0.0 || v[a] > dims[a] as f64 - 1.0 {
                        continue;
                    }
                    let d = m.anatomy.shapes[shape].sdf(m.frame.design(v)) + inset;
                    assert_eq!(coverage(d * m.frame.sigma), 0.0, "{dims:?}: shape {shape} inset {inset} covers {v:?} outside {r:?}");
                }
            }
        }
    }

    #[test]
    fn shape_distances_are_lipschitz_near_their_surfaces() {
        // The row skipping relies on |∇d| ≤ LIPSCHITZ wherever a decision is
        // made: within the deepest inset (0.1) plus a margin of the surface.
        let anatomy = Anatomy::new();
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let h = 1e-5;
        for (i, shape) in anatomy.shapes.iter().enumerate() {
            let (lo, hi) = shape.bounds();
            let (lo, hi) = (lo - 0.3, hi + 0.3);
            let mut worst: f64 = 0.0;
            let mut tested = 0;
            while tested < 100_000 {
                let p = lo + (hi - lo) * DVec3::new(rnd(), rnd(), rnd());
                let d = shape.sdf(p);
                if !(-0.25..=0.3).contains(&d) {
                    continue;
                }
                tested += 1;
                let g = DVec3::new(
                    shape.sdf(p + DVec3::X * h) - shape.sdf(p - DVec3::X * h),
                    shape.sdf(p + DVec3::Y * h) - shape.sdf(p - DVec3::Y * h),
                    shape.sdf(p + DVec3::Z * h) - shape.sdf(p - DVec3::Z * h),
                ) / (2.0 * h);
                worst = worst.max(g.length());
            }
            println!("shape {i}: max |∇d| = {worst:.3}");
            assert!(worst < 0.9 * LIPSCHITZ, "shape {i}: |∇d| reaches {worst}");
        }
    }

    #[test]
    #[ignore = "timing only: cargo test --release --lib phantom::tests::head_build_timing -- --ignored --nocapture"]
    fn head_build_timing() {
        for dims in [[256, 256, 256], [512, 512, 512]] {
            let t = std::time::Instant::now();
            let v = head(dims).unwrap();
            println!("head {dims:?}: {:.2} s ({} voxels, {} threads)", t.elapsed().as_secs_f64(), v.len(), rayon::current_num_threads());
        }
    }

    // ----- sphere -----

    #[test]
    fn sphere_matches_its_analytic_definition() {
        let mut on_surface = 0;
        for dims in [[64, 64, 64], [40, 50, 60], [17, 16, 19], [128, 128, 128]] {
            let v = sphere(dims).unwrap();
            assert_eq!(v.spacing(), [1.0; 3]);
            let (c, r) = sphere_geometry(dims);
            assert_eq!(c, dims.map(|n| (n as f64 - 1.0) / 2.0));
            assert_eq!(r, 0.4 * *dims.iter().min().unwrap() as f64);
            let d = f32s(&v);
            for z in 0..dims[2] {
                for y in 0..dims[1] {
                    for x in 0..dims[0] {
                        let dist = ((x as f64 - c[0]).powi(2) + (y as f64 - c[1]).powi(2) + (z as f64 - c[2]).powi(2)).sqrt();
                        let h = d[v.index(x, y, z)];
                        if dist < r - 4.0 {
                            assert_eq!(h, 200.0);
                        }
                        if dist > r + 4.0 {
                            assert_eq!(h, 0.0);
                        }
                        if (dist - r).abs() < 0.01 {
                            on_surface += 1;
                            assert!((h - SPHERE_ISO).abs() <= 0.25 + 1e-4, "r = {dist}: {h}");
                        }
                        if (dist - r).abs() <= 4.0 {
                            // Linear in r across the surface.
                            assert!((f64::from(h) - 100.0 - 25.0 * (r - dist)).abs() < 1e-4);
                        }
                        assert_eq!(h, (100.0 + 25.0 * (r - dist)).clamp(0.0, 200.0) as f32);
                    }
                }
            }
        }
        assert!(on_surface > 0, "no voxel within 0.01 of the surface");
        // The iso-value sits exactly on the sphere.
        assert_eq!(sphere_density(12.5, 12.5) as f32, SPHERE_ISO);
        assert_eq!(sphere_density(12.0, 12.5), 112.5);
    }

    // ----- Marschner–Lobb -----

    #[test]
    fn marschner_lobb_matches_hand_computed_values() {
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
        // Origin: sin 0 = 0, ρr(0) = cos(12π) = 1 → (1 + 0.5) / 2.5.
        assert!(close(marschner_lobb_value(0.0, 0.0, 0.0), 0.6));
        // Top and bottom of the axis: 1 − sin(±π/2) = 0 or 2.
        assert!(close(marschner_lobb_value(0.0, 0.0, 1.0), 0.2));
        assert!(close(marschner_lobb_value(0.0, 0.0, -1.0), 1.0));
        // r = 1: cos(π/2) = 0 → ρr = cos 0 = 1.
        assert!(close(marschner_lobb_value(1.0, 0.0, 0.0), 0.6));
        assert!(close(marschner_lobb_value(0.0, -1.0, 0.0), 0.6));
        // r = 0.5: ρr = cos(12π·cos(π/4)) = cos(6√2·π) = cos(0.485281…·π) = 0.0462234…
        assert!(close(marschner_lobb_value(0.5, 0.0, 0.0), (1.0 + 0.25 * 1.046_223_450_489_283) / 2.5));
        // Corners, r = √2: cos(π/√2) = −0.605699867…, ρr = cos(−7.268…·π) = −0.665077706…
        assert!((marschner_lobb_value(1.0, 1.0, 1.0) - 0.1 * (1.0 - 0.665_077_706_631_781)).abs() < 1e-12);
        assert!((marschner_lobb_value(-1.0, -1.0, -1.0) - (0.8 + 0.1 * (1.0 - 0.665_077_706_631_781))).abs() < 1e-12);
        // Where cos(πr/2) = 1/12, ρr = cos(π) = −1: the radial term vanishes.
        let r = (1.0f64 / 12.0).acos() * 2.0 / std::f64::consts::PI;
        assert!(close(marschner_lobb_value(r, 0.0, 0.0), 0.4));
    }

    #[test]
    fn marschner_lobb_stays_in_unit_range() {
        let n = 81;
        let (mut lo, mut hi) = (f64::MAX, f64::MIN);
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let v = marschner_lobb_value(ml_coord(i, n), ml_coord(j, n), ml_coord(k, n));
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
        }
        assert!(lo >= 0.0 && hi <= 1.0, "range {lo}..{hi}");
        assert!(lo < 0.01 && hi > 0.99, "range {lo}..{hi} does not span [0, 1]");
    }

    #[test]
    fn marschner_lobb_volume_samples_the_function() {
        for dims in [[41, 41, 41], [21, 31, 11]] {
            let v = marschner_lobb(dims).unwrap();
            let d = f32s(&v);
            for z in 0..dims[2] {
                for y in 0..dims[1] {
                    for x in 0..dims[0] {
                        let (px, py, pz) = (
                            -1.0 + 2.0 * x as f64 / (dims[0] - 1) as f64,
                            -1.0 + 2.0 * y as f64 / (dims[1] - 1) as f64,
                            -1.0 + 2.0 * z as f64 / (dims[2] - 1) as f64,
                        );
                        assert_eq!(d[v.index(x, y, z)], marschner_lobb_value(px, py, pz) as f32);
                    }
                }
            }
        }
        assert_eq!(marschner_lobb([41; 3]).unwrap().spacing(), [1.0; 3]);
        // Non-cubic grids keep the cube's shape: every axis spans 30 units.
        assert_eq!(marschner_lobb([21, 31, 11]).unwrap().spacing(), [1.5, 1.0, 3.0]);
        assert_eq!(marschner_lobb([41, 41, 41]).unwrap().get(20, 20, 20), 0.6);
        assert!(marschner_lobb([1, 1, 1]).is_ok());
    }

    // ----- selector -----

    #[test]
    fn phantom_names_parse_and_build() {
        assert_eq!(Phantom::parse("head").unwrap(), Phantom::Head);
        assert_eq!(Phantom::parse(" Sphere ").unwrap(), Phantom::Sphere);
        assert_eq!(Phantom::parse("marschner-lobb").unwrap(), Phantom::MarschnerLobb);
        assert_eq!(Phantom::parse("ML").unwrap(), Phantom::MarschnerLobb);
        assert_eq!("marschner_lobb".parse::<Phantom>().unwrap(), Phantom::MarschnerLobb);
        let e = Phantom::parse("teapot").unwrap_err();
        assert!(e.to_string().contains("teapot"), "{e}");
        for p in Phantom::ALL {
            assert_eq!(Phantom::parse(p.name()).unwrap(), p);
            assert_eq!(p.to_string(), p.name());
            let small = p.default_dims().map(|n| n / 4 + 1);
            let v = p.build(small).unwrap();
            assert_eq!(v.dims(), small);
        }
        assert_eq!(Phantom::Head.default_dims(), [128, 128, 113]);
        assert_eq!(Phantom::Sphere.default_dims(), [128, 128, 128]);
        assert_eq!(Phantom::MarschnerLobb.default_dims(), [41, 41, 41]);
        assert!(Phantom::Sphere.build([0, 1, 1]).is_err());
        assert_eq!(Phantom::Cube.default_dims(), [64, 64, 64]);
        assert_eq!(Phantom::parse("Engine").unwrap(), Phantom::Engine);
    }

    #[test]
    fn the_cube_is_its_partial_volume_and_its_faces_sit_at_the_iso_value() {
        let v = cube([64, 64, 64]).unwrap();
        let (lo, hi) = cube_geometry([64, 64, 64]);
        assert_eq!((lo[0], hi[0]), (31.5 - 19.2, 31.5 + 19.2));
        assert_eq!(v.get(32, 32, 32), 200.0);
        assert_eq!(v.get(0, 32, 32), 0.0);
        // along x through the middle the profile is 200 · coverage: the face at 12.3
        // lies between voxels 12 (0.2 covered) and 13 (full)
        assert!((v.get(12, 32, 32) - 40.0).abs() < 1e-3, "{}", v.get(12, 32, 32));
        assert_eq!(v.get(13, 32, 32), 200.0);
        // the linear interpolation between voxel centres crosses CUBE_ISO exactly at the face
        let (a, b) = (v.get(12, 32, 32) as f64, v.get(13, 32, 32) as f64);
        let t = (CUBE_ISO as f64 - a) / (b - a);
        assert!((12.0 + t - 12.3).abs() < 0.26, "{}", 12.0 + t);
        // an edge voxel is the product of its two coverages
        assert!((v.get(12, 12, 32) - 200.0 * 0.2 * 0.2).abs() < 1e-3);
    }

    #[test]
    fn the_engine_has_two_materials_bores_and_air() {
        let v = engine([64, 64, 64]).unwrap();
        let (lo, hi) = v.value_range();
        assert_eq!((lo, hi), (0.0, 240.0));
        // the middle bore is air at the top of the block, the block beside it cast
        assert_eq!(v.get(32, 32, 40), 0.0);
        assert_eq!(v.get(26, 32, 40), 120.0);
        assert_eq!(v.get(2, 2, 2), 0.0);
    }
}
