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

use rayon::prelude::*;

use crate::error::Result;
use crate::volume::{Volume, VoxelData, check_dims};

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

#[cfg(test)]
mod tests {
    use super::*;

    // ----- helpers -----

    fn f32s(v: &Volume) -> &[f32] {
        match v.data() {
            VoxelData::F32(d) => d,
            other => panic!("expected f32 voxels, got {:?}", other.voxel_type()),
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
}
