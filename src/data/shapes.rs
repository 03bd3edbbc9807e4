//! Analytic phantoms in physical space, sampled at any voxel spacing.
//!
//! A [`Shape`] is a density defined in millimetres from the volume's centre
//! whose iso-surface is known exactly: its [`Shape::density`], its analytic
//! [`Shape::gradient`] (the surface normal is its direction) and a Lipschitz
//! bound of the density ([`Shape::lipschitz`]) that lets a root finder step
//! along a ray without jumping over the surface. A [`Grid`] samples it: voxel
//! `i` of an axis of `n` at `(i − (n − 1)/2) · spacing` mm, so the grid is
//! centred on the shape at any spacing and the volume's voxel spacing is the
//! sampling's, which the renderers scale back to the same physical shape.
//!
//! An [`AnalyticPhantom`] is the pair: what [`crate::data::phantom::Phantom::analytic`]
//! describes for the phantoms with an analytic surface (the ball,
//! Marschner–Lobb, the ellipsoid and the torus), and what the truth of
//! [`crate::accuracy::truth`] traces. Samples are points of the continuous
//! density (no slice-profile averaging): a thick slice sees the same shape,
//! only more coarsely.
//!
//! * **Ball** — `clamp(100 + 25·(R − r), 0, 200)`, `r` the distance from the
//!   centre in mm: the [`crate::data::phantom::sphere`] phantom's linear ramp, its
//!   iso-surface 100 the sphere of radius `R`.
//! * **Ellipsoid** — `100 + 100·tanh(σ/W)` with `σ = m·(1 − |p ⊘ r|)`, `r` the
//!   semi-axes, `m` the smallest of them and `W` = [`EDGE_WIDTH`] mm: a smooth
//!   edge about `2W` wide whose iso-surface 100 is the ellipsoid exactly.
//! * **Torus** — `100 + 100·tanh(σ/W)` with `σ = a − √((ρ − R)² + z²)`, `ρ` the
//!   distance from the z axis, `R` the major and `a` the minor radius: the
//!   signed distance of the torus, whose top and bottom lie nearly parallel to
//!   the slices of a scan along z.
//! * **Marschner–Lobb** — [`crate::data::phantom::marschner_lobb_value`] of
//!   `p / h`, `h` the half-width of its cube in mm; iso 0.5.

use glam::DVec3;
use rayon::prelude::*;

use crate::data::volume::{Volume, VoxelData, check_dims};
use crate::error::{Error, Result};

/// Width `W` of the smooth shapes' `tanh` edge, in mm.
pub const EDGE_WIDTH: f64 = 3.0;

/// The iso value of the smooth shapes (half their inside density).
pub const SMOOTH_ISO: f32 = 100.0;

/// An analytic density in physical space (mm from the volume centre).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    /// The ball of radius `radius` mm with the linear ramp of the sphere phantom.
    Ball { radius: f64 },
    /// The ellipsoid with these semi-axes (mm) and a `tanh` edge.
    Ellipsoid { radii: [f64; 3] },
    /// The torus about the z axis, major radius `major`, minor `minor` (mm), with a `tanh` edge.
    Torus { major: f64, minor: f64 },
    /// The Marschner–Lobb signal on the cube `[−half, half]³` mm.
    MarschnerLobb { half: f64 },
}

impl Shape {
    /// The iso value whose iso-surface is the shape's surface.
    pub fn iso(&self) -> f32 {
        match self {
            Shape::Ball { .. } => SPHERE_ISO,
            Shape::Ellipsoid { .. } | Shape::Torus { .. } => SMOOTH_ISO,
            Shape::MarschnerLobb { .. } => ML_ISO,
        }
    }

    /// The density at `p` (mm from the centre).
    pub fn density(&self, p: DVec3) -> f64 {
        match *self {
            Shape::Ball { radius } => (100.0 + 25.0 * (radius - p.length())).clamp(0.0, 200.0),
            Shape::Ellipsoid { radii } => 100.0 + 100.0 * (ellipsoid_sigma(p, radii) / EDGE_WIDTH).tanh(),
            Shape::Torus { major, minor } => 100.0 + 100.0 * (torus_sigma(p, major, minor) / EDGE_WIDTH).tanh(),
            Shape::MarschnerLobb { half } => {
                let q = p / half;
                marschner_lobb_value(q.x, q.y, q.z)
            }
        }
    }

    /// The analytic gradient of [`Shape::density`] at `p` (per mm): on the
    /// iso-surface it points inwards along the surface normal. Zero where the
    /// density is flat or the gradient is undefined (the ball's centre, the
    /// torus's core circle).
    pub fn gradient(&self, p: DVec3) -> DVec3 {
        match *self {
            Shape::Ball { radius } => {
                let r = p.length();
                let v = 100.0 + 25.0 * (radius - r);
                if r <= 0.0 || !(0.0..=200.0).contains(&v) { DVec3::ZERO } else { -25.0 * p / r }
            }
            Shape::Ellipsoid { radii } => {
                let r = DVec3::from_array(radii);
                let q = (p / r).length();
                if q <= 0.0 {
                    return DVec3::ZERO;
                }
                let m = r.min_element();
                let s = ellipsoid_sigma(p, radii) / EDGE_WIDTH;
                let sech2 = 1.0 - s.tanh().powi(2);
                // dσ/dp = −m·(p ⊘ r²)/q
                -(100.0 / EDGE_WIDTH) * sech2 * m * (p / (r * r)) / q
            }
            Shape::Torus { major, minor } => {
                let rho = (p.x * p.x + p.y * p.y).sqrt();
                let d = ((rho - major).powi(2) + p.z * p.z).sqrt();
                if rho <= 0.0 || d <= 0.0 {
                    return DVec3::ZERO;
                }
                let s = torus_sigma(p, major, minor) / EDGE_WIDTH;
                let sech2 = 1.0 - s.tanh().powi(2);
                // dσ/dp = −((ρ − R)/d · (x, y)/ρ, z/d)
                let k = (rho - major) / (d * rho);
                -(100.0 / EDGE_WIDTH) * sech2 * DVec3::new(k * p.x, k * p.y, p.z / d)
            }
            Shape::MarschnerLobb { half } => ml_gradient(p / half) / half,
        }
    }

    /// A bound of `|∇ density|` (per mm) everywhere: along a ray, no crossing
    /// of the iso value lies closer than `|density − iso| / lipschitz` mm.
    pub fn lipschitz(&self) -> f64 {
        match *self {
            Shape::Ball { .. } => 25.0,
            // |∇σ| ≤ 1 for both (m·|∇|p ⊘ r|| ≤ m / min r = 1; a distance), tanh' ≤ 1
            Shape::Ellipsoid { .. } | Shape::Torus { .. } => 100.0 / EDGE_WIDTH,
            Shape::MarschnerLobb { half } => crate::data::shapes::ML_LIPSCHITZ / half,
        }
    }

    /// A short name for reports.
    pub fn name(&self) -> &'static str {
        match self {
            Shape::Ball { .. } => "ball",
            Shape::Ellipsoid { .. } => "ellipsoid",
            Shape::Torus { .. } => "torus",
            Shape::MarschnerLobb { .. } => "marschner-lobb",
        }
    }
}

/// A Lipschitz bound of [`marschner_lobb_value`] in its normalised units:
/// `|∂ρ/∂r| ≤ α·2π f_M·(π/2) / (2(1 + α)) = 6π²/10 ≈ 5.922` (with `|∇r| = 1`)
/// and `|∂ρ/∂z| ≤ (π/2) / (2(1 + α)) ≈ 0.628`, so `|∇ρ| ≤ 5.955`; rounded up.
pub const ML_LIPSCHITZ: f64 = 6.0;

/// `m·(1 − |p ⊘ r|)`: zero exactly on the ellipsoid, positive inside, 1-Lipschitz.
fn ellipsoid_sigma(p: DVec3, radii: [f64; 3]) -> f64 {
    let r = DVec3::from_array(radii);
    r.min_element() * (1.0 - (p / r).length())
}

/// The signed distance of the torus (positive inside).
fn torus_sigma(p: DVec3, major: f64, minor: f64) -> f64 {
    let rho = (p.x * p.x + p.y * p.y).sqrt();
    minor - ((rho - major).powi(2) + p.z * p.z).sqrt()
}

/// The analytic gradient of [`marschner_lobb_value`] at normalised `q`.
pub fn ml_gradient(q: DVec3) -> DVec3 {
    use std::f64::consts::{FRAC_PI_2, TAU};
    let k = 2.0 * (1.0 + ML_ALPHA);
    let dz = -FRAC_PI_2 * (FRAC_PI_2 * q.z).cos() / k;
    let r = (q.x * q.x + q.y * q.y).sqrt();
    if r <= 0.0 {
        return DVec3::new(0.0, 0.0, dz);
    }
    // d/dr cos(2π f cos(πr/2)) = sin(2π f cos(πr/2)) · 2π f · sin(πr/2) · π/2
    let dr = ML_ALPHA * (TAU * ML_FM * (FRAC_PI_2 * r).cos()).sin() * TAU * ML_FM * (FRAC_PI_2 * r).sin() * FRAC_PI_2 / k;
    DVec3::new(dr * q.x / r, dr * q.y / r, dz)
}

/// A sampling grid over a physical box centred on the origin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    /// Voxels per axis.
    pub dims: [usize; 3],
    /// Voxel spacing in mm.
    pub spacing: [f64; 3],
}

impl Grid {
    /// The grid of `spacing` over the box of `extent` mm (per axis, between
    /// the first and the last voxel centre): `⌊extent / spacing⌋ + 1` voxels
    /// per axis, centred (so the box covered is at most one spacing shorter
    /// than `extent` when the spacing does not divide it). The spacing is
    /// kept at `f32` precision, the volume's.
    pub fn new(extent: [f64; 3], spacing: [f64; 3]) -> Result<Self> {
        for a in 0..3 {
            let s = spacing[a];
            if !(s.is_finite() && s > 0.0) {
                return Err(Error::value("phantom spacing", format!("{s} along {} (must be finite and > 0 mm)", ["x", "y", "z"][a])));
            }
            if !(extent[a].is_finite() && extent[a] >= 0.0) {
                return Err(Error::value("phantom extent", format!("{} mm along {}", extent[a], ["x", "y", "z"][a])));
            }
        }
        let n = [0, 1, 2].map(|a| {
            let v = (extent[a] / spacing[a] + 1e-9).floor();
            if v < u32::MAX as f64 { v as u64 + 1 } else { u64::MAX }
        });
        let dims = check_dims(n).map_err(|e| {
            Error::value("phantom spacing", format!("{:?} mm over {:?} mm gives {}×{}×{} voxels: {e}", spacing, extent, n[0], n[1], n[2]))
        })?;
        // (at the precision the volume stores its spacing, so the volume and its truth are one shape)
        Ok(Grid { dims, spacing: spacing.map(|s| s as f32 as f64) })
    }

    /// The physical position (mm from the centre) of voxel `(i, j, k)`.
    pub fn position(&self, i: usize, j: usize, k: usize) -> DVec3 {
        let at = |i: usize, a: usize| (i as f64 - (self.dims[a] as f64 - 1.0) / 2.0) * self.spacing[a];
        DVec3::new(at(i, 0), at(j, 1), at(k, 2))
    }

    /// The physical position of a voxel-space point (fractional indices).
    pub fn to_physical(&self, v: DVec3) -> DVec3 {
        let c = DVec3::from_array(self.dims.map(|n| (n as f64 - 1.0) / 2.0));
        (v - c) * DVec3::from_array(self.spacing)
    }

    /// The spacing as the volume stores it.
    pub fn spacing_f32(&self) -> [f32; 3] {
        self.spacing.map(|s| s as f32)
    }
}

/// An analytic shape and the grid it is sampled on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnalyticPhantom {
    pub shape: Shape,
    pub grid: Grid,
}

impl AnalyticPhantom {
    /// Bytes of its `f32` voxels (`None` on overflow).
    pub fn bytes(&self) -> Option<u64> {
        self.grid.dims.iter().try_fold(4u64, |a, &n| a.checked_mul(n as u64))
    }

    /// Samples the shape at every voxel centre (`f32`, in parallel over
    /// z-slices), with the grid's spacing.
    pub fn build(&self) -> Result<Volume> {
        let [nx, ny, nz] = self.grid.dims;
        let n = nx * ny * nz;
        let mut data: Vec<f32> = Vec::new();
        data.try_reserve_exact(n).map_err(|_| Error::Memory {
            what: "phantom voxels".into(),
            needed: (n as u64).saturating_mul(4),
            held: 0,
            budget: 0,
        })?;
        data.resize(n, 0.0);
        data.par_chunks_mut(nx * ny).enumerate().for_each(|(k, s)| {
            for (j, row) in s.chunks_mut(nx).enumerate() {
                for (i, out) in row.iter_mut().enumerate() {
                    *out = self.shape.density(self.grid.position(i, j, k)) as f32;
                }
            }
        });
        Volume::new(self.grid.dims, self.grid.spacing_f32(), VoxelData::F32(data))
    }
}

/// The iso-value whose iso-surface in [`crate::data::phantom::sphere`] is exactly the sphere of
/// [`crate::data::phantom::sphere_geometry`].
pub const SPHERE_ISO: f32 = 100.0;

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

#[cfg(test)]
mod tests {
    use super::*;

    fn shapes() -> [Shape; 4] {
        [
            Shape::Ball { radius: 20.0 },
            Shape::Ellipsoid { radii: [25.0, 20.0, 15.0] },
            Shape::Torus { major: 16.0, minor: 7.0 },
            Shape::MarschnerLobb { half: 20.0 },
        ]
    }

    #[test]
    fn gradients_match_finite_differences() {
        for s in shapes() {
            for i in 0..400 {
                let t = i as f64 * 0.37;
                let p = DVec3::new(18.0 * t.sin(), 17.0 * (1.3 * t).cos(), 14.0 * (0.7 * t).sin());
                let h = 1e-5;
                let fd = DVec3::new(
                    s.density(p + DVec3::X * h) - s.density(p - DVec3::X * h),
                    s.density(p + DVec3::Y * h) - s.density(p - DVec3::Y * h),
                    s.density(p + DVec3::Z * h) - s.density(p - DVec3::Z * h),
                ) / (2.0 * h);
                let g = s.gradient(p);
                // (the ball's kinks at the clamp: skip points within h of them)
                let v = s.density(p);
                if matches!(s, Shape::Ball { .. }) && !(1e-3..=200.0 - 1e-3).contains(&v) {
                    continue;
                }
                assert!((fd - g).length() <= 1e-5 * (1.0 + g.length()), "{s:?} at {p}: {g} vs {fd}");
                assert!(g.length() <= s.lipschitz() * (1.0 + 1e-9), "{s:?} at {p}");
            }
        }
    }

    #[test]
    fn grids_cover_the_extent_at_any_spacing() {
        let g = Grid::new([127.0; 3], [1.0, 1.0, 3.0]).unwrap();
        assert_eq!(g.dims, [128, 128, 43]);
        assert_eq!(g.position(0, 127, 21), DVec3::new(-63.5, 63.5, 0.0));
        let g = Grid::new([127.0; 3], [0.6, 0.6, 5.0]).unwrap();
        assert_eq!(g.dims, [212, 212, 26]);
        assert!(Grid::new([127.0; 3], [0.0, 1.0, 1.0]).is_err());
        assert!(Grid::new([127.0; 3], [1.0, f64::NAN, 1.0]).is_err());
        let e = Grid::new([127.0; 3], [1e-6, 1e-6, 1e-6]).unwrap_err().to_string();
        assert!(e.contains("phantom spacing"), "{e}");
    }
}
