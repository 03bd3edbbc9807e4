//! Triangle meshes in voxel-index coordinates and the analytic primitives.
//!
//! Every primitive is closed (apart from the plane) and wound counter-clockwise
//! seen from outside, so its triangles' right-handed normals point outward:
//! what back-face culling and one-sided shading rely on.

use std::f64::consts::TAU;

use glam::{DAffine3, DVec3};

use crate::error::{Error, Result};

/// A triangle mesh: vertex positions (voxel-index coordinates unless a
/// transform says otherwise) and triangles as vertex indices.
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    pub vertices: Vec<DVec3>,
    pub triangles: Vec<[u32; 3]>,
}

impl Mesh {
    /// A mesh, checked: finite vertices, indices in range.
    pub fn new(vertices: Vec<DVec3>, triangles: Vec<[u32; 3]>) -> Result<Self> {
        if let Some(v) = vertices.iter().find(|v| !v.is_finite()) {
            return Err(Error::value("mesh vertex", format!("{v} is not finite")));
        }
        if let Some(t) = triangles.iter().find(|t| t.iter().any(|&i| i as usize >= vertices.len())) {
            return Err(Error::value("mesh triangle", format!("{t:?} indexes past the {} vertices", vertices.len())));
        }
        Ok(Mesh { vertices, triangles })
    }

    /// The mesh moved by `m` (e.g. from world millimetres into voxel indices).
    pub fn transformed(&self, m: DAffine3) -> Result<Self> {
        Mesh::new(self.vertices.iter().map(|&v| m.transform_point3(v)).collect(), self.triangles.clone())
    }

    /// The axis-aligned bounding box `[lo, hi]` (None for no vertices).
    pub fn bounds(&self) -> Option<[DVec3; 2]> {
        let first = *self.vertices.first()?;
        Some(self.vertices.iter().fold([first, first], |[lo, hi], &v| [lo.min(v), hi.max(v)]))
    }

    /// A sphere of `radius` about `centre`, as a UV sphere of `segments`
    /// around (at least 3) and `segments / 2` rings: its vertices lie on the
    /// sphere, its faces at most `radius·(1 − cos(π/segments))` inside it.
    pub fn sphere(centre: DVec3, radius: f64, segments: usize) -> Result<Self> {
        check_size("sphere radius", radius)?;
        let (nu, nv) = (segments.max(3), (segments / 2).max(2));
        let mut v = vec![centre + DVec3::new(0.0, 0.0, radius)];
        for r in 1..nv {
            let th = std::f64::consts::PI * r as f64 / nv as f64;
            for s in 0..nu {
                let ph = TAU * s as f64 / nu as f64;
                v.push(centre + radius * DVec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()));
            }
        }
        v.push(centre - DVec3::new(0.0, 0.0, radius));
        let ring = |r: usize, s: usize| (1 + (r - 1) * nu + s % nu) as u32;
        let (top, bottom) = (0u32, (v.len() - 1) as u32);
        let mut t = vec![];
        for s in 0..nu {
            t.push([top, ring(1, s), ring(1, s + 1)]);
            for r in 1..nv - 1 {
                t.push([ring(r, s), ring(r + 1, s), ring(r + 1, s + 1)]);
                t.push([ring(r, s), ring(r + 1, s + 1), ring(r, s + 1)]);
            }
            t.push([ring(nv - 1, s), bottom, ring(nv - 1, s + 1)]);
        }
        Mesh::new(v, t)
    }

    /// The box `[lo, hi]` (12 triangles).
    pub fn cuboid(lo: DVec3, hi: DVec3) -> Result<Self> {
        if !(lo.is_finite() && hi.is_finite() && lo.cmplt(hi).all()) {
            return Err(Error::value("box", format!("{lo} .. {hi} (needs finite corners, lo < hi on every axis)")));
        }
        let c = |i: usize| {
            DVec3::new(if i & 1 == 0 { lo.x } else { hi.x }, if i & 2 == 0 { lo.y } else { hi.y }, if i & 4 == 0 { lo.z } else { hi.z })
        };
        let v: Vec<DVec3> = (0..8).map(c).collect();
        // each face as a quad counter-clockwise seen from outside
        let faces = [[0, 4, 6, 2], [1, 3, 7, 5], [0, 1, 5, 4], [2, 6, 7, 3], [0, 2, 3, 1], [4, 5, 7, 6]];
        let t = faces.iter().flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]]).collect();
        Mesh::new(v, t)
    }

    /// A closed cylinder ("needle") of `radius` from `a` to `b`, `segments`
    /// around (at least 3), capped at both ends.
    pub fn cylinder(a: DVec3, b: DVec3, radius: f64, segments: usize) -> Result<Self> {
        check_size("cylinder radius", radius)?;
        let axis = b - a;
        if !(axis.is_finite() && axis.length() > 0.0) {
            return Err(Error::value("cylinder", format!("from {a} to {b} (needs two distinct finite ends)")));
        }
        let n = segments.max(3);
        let w = axis.normalize();
        let u = w.any_orthonormal_vector();
        let vv = w.cross(u);
        let mut v = vec![a, b];
        for end in [a, b] {
            for s in 0..n {
                let ph = TAU * s as f64 / n as f64;
                v.push(end + radius * (ph.cos() * u + ph.sin() * vv));
            }
        }
        let (lo, hi) = (|s: usize| (2 + s % n) as u32, |s: usize| (2 + n + s % n) as u32);
        let mut t = vec![];
        for s in 0..n {
            t.push([0, lo(s + 1), lo(s)]);
            t.push([1, hi(s), hi(s + 1)]);
            t.push([lo(s), lo(s + 1), hi(s + 1)]);
            t.push([lo(s), hi(s + 1), hi(s)]);
        }
        Mesh::new(v, t)
    }

    /// A square of side `2·half` through `point` facing `normal` (two
    /// triangles wound counter-clockwise seen from the side `normal` points to).
    pub fn plane(point: DVec3, normal: DVec3, half: f64) -> Result<Self> {
        check_size("plane half size", half)?;
        if !(point.is_finite() && normal.is_finite() && normal.length() > 0.0) {
            return Err(Error::value("plane", format!("through {point} facing {normal} (needs a finite point and a non-zero normal)")));
        }
        let w = normal.normalize();
        let u = w.any_orthonormal_vector();
        let v = w.cross(u);
        let c = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)].map(|(x, y)| point + half * (x * u + y * v));
        Mesh::new(c.to_vec(), vec![[0, 1, 2], [0, 2, 3]])
    }
}

fn check_size(what: &'static str, x: f64) -> Result<()> {
    if x.is_finite() && x > 0.0 { Ok(()) } else { Err(Error::value(what, format!("{x} (must be finite and > 0)"))) }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every closed primitive is wound outward: its signed volume (sum of
    /// the triangles' tetrahedra from the origin) is positive and close to
    /// the analytic volume.
    #[test]
    fn primitives_are_closed_and_wound_outward() {
        let vol = |m: &Mesh| {
            m.triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| m.vertices[i as usize]);
                    a.dot(b.cross(c)) / 6.0
                })
                .sum::<f64>()
        };
        let c = DVec3::new(3.0, -2.0, 5.0);
        let s = Mesh::sphere(c, 10.0, 96).unwrap();
        let want = 4.0 / 3.0 * std::f64::consts::PI * 1000.0;
        assert!((vol(&s) / want - 1.0).abs() < 0.01, "sphere {} vs {want}", vol(&s));
        let b = Mesh::cuboid(DVec3::new(1.0, 2.0, 3.0), DVec3::new(4.0, 6.0, 8.0)).unwrap();
        assert!((vol(&b) - 60.0).abs() < 1e-9, "box {}", vol(&b));
        let n = Mesh::cylinder(c, c + DVec3::new(0.0, 3.0, 4.0), 2.0, 128).unwrap();
        let want = std::f64::consts::PI * 4.0 * 5.0;
        assert!((vol(&n) / want - 1.0).abs() < 0.01, "cylinder {} vs {want}", vol(&n));
        // every edge of a closed mesh is shared by exactly two triangles, in opposite directions
        for m in [&s, &b, &n] {
            let mut edges = std::collections::HashMap::new();
            for t in &m.triangles {
                for e in 0..3 {
                    *edges.entry((t[e], t[(e + 1) % 3])).or_insert(0) += 1;
                }
            }
            assert!(edges.iter().all(|(&(a, b), &k)| k == 1 && edges.get(&(b, a)) == Some(&1)));
        }
    }

    #[test]
    fn bad_meshes_and_primitives_are_errors() {
        assert!(Mesh::new(vec![DVec3::ZERO], vec![[0, 0, 1]]).is_err());
        assert!(Mesh::new(vec![DVec3::NAN], vec![]).is_err());
        assert!(Mesh::sphere(DVec3::ZERO, 0.0, 8).is_err());
        assert!(Mesh::sphere(DVec3::ZERO, f64::NAN, 8).is_err());
        assert!(Mesh::cuboid(DVec3::ONE, DVec3::ZERO).is_err());
        assert!(Mesh::cylinder(DVec3::ONE, DVec3::ONE, 1.0, 8).is_err());
        assert!(Mesh::plane(DVec3::ZERO, DVec3::ZERO, 1.0).is_err());
        let m = Mesh::cuboid(DVec3::ZERO, DVec3::ONE).unwrap();
        let t = m.transformed(DAffine3::from_translation(DVec3::splat(2.0))).unwrap();
        assert_eq!(t.bounds().unwrap(), [DVec3::splat(2.0), DVec3::splat(3.0)]);
    }
}
