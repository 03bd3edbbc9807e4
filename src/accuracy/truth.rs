//! Analytic ground truth: where the iso-surface of a phantom really is.
//!
//! For the phantoms whose iso-surface is known in closed form or as a
//! continuous function, this module gives the depth of the first iso hit along
//! every viewing ray of a [`Camera`] — in the convention of
//! [`crate::accuracy::reference`] (world units along the view from the plane through the
//! volume centre, NaN where the ray misses), so fast paths, the reference and
//! the truth compare pixel for pixel:
//!
//! * [`sphere_depth`]: the exact ray–sphere intersection with the sphere of
//!   [`sphere_geometry`] (the [`SPHERE_ISO`](crate::data::phantom::SPHERE_ISO) surface of
//!   [`crate::data::phantom::sphere`]);
//! * [`marschner_lobb_depth`]: the first crossing of
//!   [`marschner_lobb_value`] = iso along the ray, bracketed by a march whose
//!   steps a Lipschitz bound of the signal proves cannot jump over a crossing
//!   (never finer than a tiny floor step), and refined by bisection.
//!
//! Both are restricted to the rendered domain, the box of voxel centres: a ray
//! that enters the box already inside the surface hits at its entry, as the
//! renderers do.
//!
//! [`surface_truth`] is the general form, for every phantom with an analytic
//! surface ([`AnalyticPhantom`]: the ball, Marschner–Lobb, the ellipsoid and
//! the torus, sampled at any spacing) in both projections: per pixel the
//! first-hit depth *and* the unit surface normal in world space (the volume's
//! axes in mm, as [`crate::view`] places it; NaN where the ray misses, and
//! where it enters the box already inside, whose hit is a face of the box,
//! not the surface). The ball and the ellipsoid intersect in closed form;
//! the torus and Marschner–Lobb are marched with the shape's Lipschitz bound
//! and refined by bisection.

use glam::DVec3;
use rayon::prelude::*;

use crate::accuracy::reference::Rays;
use crate::data::phantom::{marschner_lobb_value, sphere_geometry};
use crate::data::shapes::{AnalyticPhantom, Shape};
use crate::error::{Error, Result};
use crate::view::{Camera, Projection};

/// Default floor of the bracketing step of [`marschner_lobb_depth`], in the
/// signal's normalised units (the cube is `[−1, 1]³`; 41³ samples it every
/// 0.05): only a crossing thinner than this along the ray can be missed.
pub const ML_BRACKET_STEP: f64 = 1e-4;

pub use crate::data::shapes::ML_LIPSCHITZ;

/// Floor of [`surface_truth`]'s marching step, in mm of the phantom: only a
/// crossing thinner than this along a ray can be missed.
pub const SURFACE_BRACKET_MM: f64 = 1e-3;

/// Bisection iterations (the bracket shrinks far below 1e-12).
const BISECTIONS: u32 = 64;

/// Exact first-hit depth of the sphere phantom's iso-surface per pixel.
///
/// `dims` and `spacing` are the volume's: the sphere lives in voxel space
/// (centre and radius from [`sphere_geometry`]), so with an anisotropic spacing
/// it is an ellipsoid in the world, exactly as the sampled volume is.
pub fn sphere_depth(dims: [usize; 3], spacing: [f32; 3], camera: &Camera) -> Result<Vec<f64>> {
    let rays = Rays::new(camera, dims, spacing)?;
    let (c, radius) = sphere_geometry(dims);
    let c = DVec3::from_array(c);
    let d = rays.direction();
    Ok(per_pixel(&rays, |o| {
        let (t0, t1) = rays.clip(o)?;
        // |o + t·d − c|² = R²
        let oc = o - c;
        let (a, b, cc) = (d.dot(d), 2.0 * d.dot(oc), oc.dot(oc) - radius * radius);
        let disc = b * b - 4.0 * a * cc;
        if disc < 0.0 {
            return None;
        }
        // the numerically stable pair of roots
        let q = -0.5 * (b + b.signum() * disc.sqrt());
        let (r0, r1) = if q == 0.0 { (0.0, 0.0) } else { (q / a, cc / q) };
        let (near, far) = (r0.min(r1), r0.max(r1));
        let t = near.max(t0);
        (t <= far.min(t1)).then_some(t)
    }))
}

/// First-hit depth of the Marschner–Lobb iso-surface `ρ = iso` per pixel, for
/// the grid of [`crate::data::phantom::marschner_lobb`] at `dims` (voxel `i` of an
/// axis of `n` at `−1 + 2i/(n−1)`): marched in steps of `|ρ − iso| / L` (the
/// Lipschitz bound [`ML_LIPSCHITZ`] proves no crossing lies within), never
/// shorter than `step` normalised units ([`ML_BRACKET_STEP`] is a good
/// choice), and refined by bisection.
pub fn marschner_lobb_depth(dims: [usize; 3], spacing: [f32; 3], camera: &Camera, iso: f64, step: f64) -> Result<Vec<f64>> {
    if !(step.is_finite() && step > 1e-6) {
        return Err(Error::value("bracketing step", format!("{step} (must be > 1e-6)")));
    }
    if !iso.is_finite() {
        return Err(Error::value("iso value", format!("{iso}")));
    }
    let scale = DVec3::from_array(dims.map(|n| if n <= 1 { 0.0 } else { 2.0 / (n - 1) as f64 }));
    let norm = move |v: DVec3| v * scale - DVec3::from_array(dims.map(|n| if n <= 1 { 0.0 } else { 1.0 }));
    let rays = Rays::new(camera, dims, spacing)?;
    // normalised units per world unit along the ray
    let speed = (rays.direction() * scale).length();
    let dt = if speed > 0.0 { step / speed } else { f64::INFINITY };
    let f = move |v: DVec3| {
        let p = norm(v);
        marschner_lobb_value(p.x, p.y, p.z)
    };
    Ok(first_crossing(&rays, f, iso, dt, ML_LIPSCHITZ * speed))
}

/// First `t` along each pixel's ray (inside the box of voxel centres) where
/// `f(voxel) ≥ iso`: the entry point if already there, else the first sample of
/// a march that reaches iso, refined by bisection. `lipschitz` bounds `|df/dt|`
/// along the ray (world units): each step is `max(dt, (iso − f) / lipschitz)`,
/// so only a crossing shorter than `dt` can be stepped over (pass 0 for plain
/// steps of `dt`).
pub fn first_crossing(rays: &Rays, f: impl Fn(DVec3) -> f64 + Sync, iso: f64, dt: f64, lipschitz: f64) -> Vec<f64> {
    let d = rays.direction();
    per_pixel(rays, |o| {
        let (t0, t1) = rays.clip(o)?;
        let fa = f(o + t0 * d);
        if fa >= iso {
            return Some(t0);
        }
        march(&f, (o, d), [t0, t1], fa, Steps { iso, dt, lipschitz })
    })
}

/// The analytic surface seen by one camera: per pixel, row-major.
#[derive(Clone, Debug)]
pub struct SurfaceTruth {
    /// First-hit depth in the convention of [`crate::accuracy::reference`]
    /// (world units along the view from the plane through the volume centre;
    /// NaN where the ray misses).
    pub depth: Vec<f64>,
    /// Unit normal of the surface at the hit, in world space (the volume's
    /// axes, scaled by its spacing), pointing outwards (down the density);
    /// NaN where the ray misses or the hit is the box's entry face.
    pub normal: Vec<DVec3>,
}

/// The first hit and surface normal of `phantom`'s iso-surface at `iso`
/// (its surface at [`Shape::iso`]; another level of the same density
/// otherwise) along every ray of `camera` under `projection`, for the volume
/// `phantom.grid` sampled, stored with `spacing` (the volume's spacing: the
/// phantom's own, or another one given to the volume later, which stretches
/// the shape as it stretches the rendered volume). `near` is the perspective
/// near clip in voxels ([`crate::accuracy::reference::ReferenceOptions::near`]).
pub fn surface_truth(
    phantom: &AnalyticPhantom,
    spacing: [f32; 3],
    camera: &Camera,
    projection: &Projection,
    iso: f64,
    near: f64,
) -> Result<SurfaceTruth> {
    if !(near.is_finite() && near >= 0.0) {
        return Err(Error::value("truth near clip", format!("{near} (must be finite and ≥ 0)")));
    }
    if !iso.is_finite() {
        return Err(Error::value("iso value", format!("{iso}")));
    }
    let dims = phantom.grid.dims;
    let rays = Rays::with_projection(camera, projection, dims, spacing)?;
    let perspective = projection.is_perspective();
    let grid = phantom.grid;
    let shape = phantom.shape;
    let sg = DVec3::from_array(grid.spacing);
    let sv = DVec3::new(spacing[0] as f64, spacing[1] as f64, spacing[2] as f64);
    // (the closed forms hold for the shape's own surface only)
    let closed = iso == shape.iso() as f64;
    let f = |v: DVec3| shape.density(grid.to_physical(v));
    let [w, h] = rays.size();
    let mut depth = vec![f64::NAN; w * h];
    let mut normal = vec![DVec3::NAN; w * h];
    depth.par_chunks_mut(w).zip(normal.par_chunks_mut(w)).enumerate().for_each(|(v, (drow, nrow))| {
        for u in 0..w {
            let (o, d) = rays.ray(u as f64, v as f64);
            let Some((t0, t1)) = rays.clip_ray(o, d) else { continue };
            let t0 = if perspective { t0.max(near / d.abs().max_element()) } else { t0 };
            if t0 > t1 {
                continue;
            }
            // mm of the phantom per world unit along the ray
            let speed = (d * sg).length();
            let entry = f(o + t0 * d);
            let hit = if entry >= iso {
                Some((t0, false))
            } else {
                let t = match shape {
                    Shape::Ball { radius } => quadric_hit(grid.to_physical(o), d * sg, DVec3::splat(radius)),
                    Shape::Ellipsoid { radii } => quadric_hit(grid.to_physical(o), d * sg, DVec3::from_array(radii)),
                    _ => None,
                };
                match shape {
                    Shape::Ball { .. } | Shape::Ellipsoid { .. } if closed => t.filter(|&t| t >= t0 && t <= t1).map(|t| (t, true)),
                    _ => {
                        let dt = if speed > 0.0 { SURFACE_BRACKET_MM / speed } else { f64::INFINITY };
                        march(&f, (o, d), [t0, t1], entry, Steps { iso, dt, lipschitz: shape.lipschitz() * speed }).map(|t| (t, true))
                    }
                }
            };
            let Some((t, on_surface)) = hit else { continue };
            let p = o + t * d;
            drow[u] = if perspective { rays.depth_of(p) } else { t };
            if on_surface {
                // ∂ρ/∂(world) = ∇ρ ⊙ (phantom spacing) ⊘ (volume spacing); outwards = −∇ρ
                let g = shape.gradient(grid.to_physical(p)) * sg / sv;
                nrow[u] = if g.length() > 0.0 { -g.normalize() } else { DVec3::NAN };
            }
        }
    });
    Ok(SurfaceTruth { depth, normal })
}

/// The smaller root `t` of `|(p0 + t·d) ⊘ r| = 1`: where the line enters the
/// ellipsoid of semi-axes `r` (`None` when it misses).
fn quadric_hit(p0: DVec3, d: DVec3, r: DVec3) -> Option<f64> {
    let (p, d) = (p0 / r, d / r);
    let (a, b, c) = (d.dot(d), 2.0 * d.dot(p), p.dot(p) - 1.0);
    if a <= 0.0 {
        return None;
    }
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return None;
    }
    let q = -0.5 * (b + b.signum() * disc.sqrt());
    let (r0, r1) = if q == 0.0 { (0.0, 0.0) } else { (q / a, c / q) };
    Some(r0.min(r1))
}

/// How [`march`] steps toward the crossing of `iso`: by at least `dt`, and
/// by as much as a density of this Lipschitz bound allows.
#[derive(Clone, Copy, Debug)]
struct Steps {
    iso: f64,
    dt: f64,
    lipschitz: f64,
}

/// The first crossing of `f = iso` along `o + t·d` (`line = (o, d)`) in
/// `[t0, t1]` from a point below iso at `t0` (`f0 = f(o + t0·d)`): steps of
/// `max(dt, (iso − f)/lipschitz)`, then bisection.
fn march(f: &impl Fn(DVec3) -> f64, (o, d): (DVec3, DVec3), [t0, t1]: [f64; 2], f0: f64, steps: Steps) -> Option<f64> {
    let Steps { iso, dt, lipschitz } = steps;
    let (mut ta, mut fa) = (t0, f0);
    if !dt.is_finite() {
        return None;
    }
    loop {
        let safe = if lipschitz > 0.0 { (iso - fa) / lipschitz } else { 0.0 };
        let tb = (ta + dt.max(safe)).min(t1);
        let fb = f(o + tb * d);
        if fb >= iso {
            let (mut lo, mut hi) = (ta, tb);
            for _ in 0..BISECTIONS {
                let m = 0.5 * (lo + hi);
                if m <= lo || m >= hi {
                    break;
                }
                if f(o + m * d) >= iso {
                    hi = m;
                } else {
                    lo = m;
                }
            }
            return Some(hi);
        }
        if tb >= t1 {
            return None;
        }
        (ta, fa) = (tb, fb);
    }
}

/// Evaluates `hit(origin)` for every pixel's ray in parallel over rows.
fn per_pixel(rays: &Rays, hit: impl Fn(DVec3) -> Option<f64> + Sync) -> Vec<f64> {
    let [w, h] = rays.size();
    let mut out = vec![f64::NAN; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(v, row)| {
        for (u, o) in row.iter_mut().enumerate() {
            *o = hit(rays.origin(u as f64, v as f64)).unwrap_or(f64::NAN);
        }
    });
    out
}

/// The first `t ≥ t_min` where `o + t·d` meets the closed cylinder `(a, b, r)`
/// (side or caps), if any: the analytic depth of a needle.
pub fn cylinder_hit(o: DVec3, d: DVec3, a: DVec3, b: DVec3, r: f64, t_min: f64) -> Option<f64> {
    let w = (b - a).normalize();
    let len = (b - a).length();
    let mut best: Option<f64> = None;
    let mut take = |t: f64| {
        if t >= t_min {
            best = Some(best.map_or(t, |x: f64| x.min(t)))
        }
    };
    // side: |(p − a) − ((p − a)·w) w| = r
    let (oa, dp) = (o - a, d - w * d.dot(w));
    let op = oa - w * oa.dot(w);
    let (qa, qb, qc) = (dp.dot(dp), 2.0 * dp.dot(op), op.dot(op) - r * r);
    let disc = qb * qb - 4.0 * qa * qc;
    if qa > 0.0 && disc >= 0.0 {
        for t in [(-qb - disc.sqrt()) / (2.0 * qa), (-qb + disc.sqrt()) / (2.0 * qa)] {
            let s = (o + t * d - a).dot(w);
            if (0.0..=len).contains(&s) {
                take(t);
            }
        }
    }
    // caps
    for (c, n) in [(a, -w), (b, w)] {
        let den = d.dot(n);
        if den != 0.0 {
            let t = (c - o).dot(n) / den;
            if (o + t * d - c).length() <= r {
                take(t);
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::view::rotate_eye;
    use glam::DMat3;

    #[test]
    fn sphere_hit_at_the_centre_pixel_is_the_radius() {
        let dims = [41, 41, 41];
        let cam = Camera { rotation: rotate_eye(DMat3::IDENTITY, 1, 33.0), zoom: Some(1.0), size: [41, 41] };
        let d = sphere_depth(dims, [1.0; 3], &cam).unwrap();
        let (_, r) = sphere_geometry(dims);
        // the centre pixel looks through the sphere's centre: the front is R nearer than the centre
        assert!((d[20 * 41 + 20] + r).abs() < 1e-12, "{}", d[20 * 41 + 20]);
        // a corner pixel misses
        assert!(d[0].is_nan());
        // pixel (20 + 10, 20): offset 10 from the axis, depth −sqrt(R² − 100)
        assert!((d[20 * 41 + 30] + (r * r - 100.0).sqrt()).abs() < 1e-9);
    }

    #[test]
    fn root_finding_agrees_with_the_closed_form_sphere() {
        let dims = [30, 34, 38];
        let cam = Camera { rotation: DMat3::from_euler(glam::EulerRot::XYZ, 0.3, 0.7, -0.2), zoom: None, size: [48, 40] };
        let exact = sphere_depth(dims, [1.0; 3], &cam).unwrap();
        let (c, r) = sphere_geometry(dims);
        let c = DVec3::from_array(c);
        let rays = Rays::new(&cam, dims, [1.0; 3]).unwrap();
        // inside ⇔ r − |p − c| ≥ 0
        let found = first_crossing(&rays, |p| r - (p - c).length(), 0.0, 0.05, 0.0);
        // with the Lipschitz bound of a distance (1 per voxel, spacing 1) and a tiny floor
        let fast = first_crossing(&rays, |p| r - (p - c).length(), 0.0, 1e-6, 1.0);
        for (a, (b, c)) in exact.iter().zip(found.iter().zip(&fast)) {
            assert_eq!(a.is_nan(), b.is_nan());
            assert_eq!(a.is_nan(), c.is_nan());
            if a.is_finite() {
                assert!((a - b).abs() < 1e-9 && (a - c).abs() < 1e-9, "{a} vs {b}, {c}");
            }
        }
    }

    #[test]
    fn the_marschner_lobb_lipschitz_bound_holds() {
        // the steepest places: where the radial phase changes fastest (r = 1) and z = 0
        let mut worst = 0f64;
        let h = 1e-6;
        for i in 0..2000 {
            let t = i as f64 / 2000.0;
            let (r, phi, z) = (0.5 + 0.5 * t, t * 7.0, (t * 13.0).sin() * 0.3);
            let (x, y) = (r * phi.cos(), r * phi.sin());
            let g = DVec3::new(
                marschner_lobb_value(x + h, y, z) - marschner_lobb_value(x - h, y, z),
                marschner_lobb_value(x, y + h, z) - marschner_lobb_value(x, y - h, z),
                marschner_lobb_value(x, y, z + h) - marschner_lobb_value(x, y, z - h),
            ) / (2.0 * h);
            worst = worst.max(g.length());
        }
        assert!(worst <= ML_LIPSCHITZ && worst > 5.5, "{worst}");
    }

    #[test]
    fn marschner_lobb_hits_lie_on_the_surface_or_the_box() {
        let dims = [41, 41, 41];
        let cam = Camera { rotation: rotate_eye(rotate_eye(DMat3::IDENTITY, 0, -60.0), 1, 20.0), zoom: None, size: [64, 64] };
        let d = marschner_lobb_depth(dims, [1.0; 3], &cam, 0.5, ML_BRACKET_STEP).unwrap();
        let rays = Rays::new(&cam, dims, [1.0; 3]).unwrap();
        let mut on_surface = 0;
        for v in 0..64 {
            for u in 0..64 {
                let t = d[v * 64 + u];
                if t.is_nan() {
                    continue;
                }
                let o = rays.origin(u as f64, v as f64);
                let p = (o + t * rays.direction()) / 20.0 - 1.0;
                let val = marschner_lobb_value(p.x, p.y, p.z);
                let (t0, _) = rays.clip(o).unwrap();
                assert!(val >= 0.5 - 1e-9 && ((val - 0.5).abs() < 1e-9 || (t - t0).abs() < 1e-12), "pixel ({u},{v}): {val}");
                on_surface += ((val - 0.5).abs() < 1e-9) as usize;
            }
        }
        assert!(on_surface > 500, "{on_surface}");
    }
}
