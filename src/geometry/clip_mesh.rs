//! Convex clipping by a mesh: a closed convex triangle mesh clips the volume
//! like a [`crate::view::clip::ClipRegion`], its inside or its outside kept.
//!
//! A straight ray meets a convex solid in one interval: it enters through a
//! front face and leaves through a back face. Per frame the mesh is drawn
//! twice at the output resolution with the frame's own [`Projector`]: its
//! front faces ([`Cull::Back`]) into one depth buffer, its back faces
//! ([`Cull::Front`]) into another. Each intermediate pixel reads both at the
//! output position of its ray (the plan's warp of the pixel centre):
//! bilinearly between the four output pixels around it where all four hold
//! the surface, else (the silhouette) through the inverse warp's gather
//! (`GeometryLimits::min_depth`, the nearest depth over a pixel-sized box
//! about the point, then two pixels) — a clip face is read at the ray, where the occlusion
//! gather takes the minimum over the whole footprint. Its samples — whose depth is affine in the
//! slice index in both projections — are kept from the first slice at or
//! after the front depth to the last at or before the back depth (solved,
//! then checked on the samples themselves). A ray whose front face is not
//! drawn within two pixels but whose back face is (a perspective eye inside
//! the solid) enters at the eye. [`Keep::Inside`] narrows the ray's interval to those slices;
//! [`Keep::Outside`] cuts them out as the ray's hole
//! ([`crate::view::plan::cut_ray`]).
//!
//! The mesh is checked once ([`ConvexMesh::new`]): vertices at the same
//! position are welded, every edge must be shared by exactly two triangles
//! wound in opposite directions (closed and consistently oriented; the
//! winding is turned outward by the sign of the enclosed volume), and every
//! vertex must lie on the inner side of every face's plane within a
//! tolerance of `1e-6` of the mesh's size (convex). The check costs
//! triangles × vertices: meant for clip solids of a few thousand triangles.
//!
//! Accuracy: the limits follow the rasterized faces, interpolated between
//! output pixel centres (exact on a flat face in parallel; second order
//! across a curved or perspective one), and at the silhouette the nearest
//! face over a pixel: a limit can differ by one slice from the analytic
//! region's (tested against [`crate::view::clip::ClipRegion`] boxes and
//! balls).

use std::collections::HashMap;

use glam::DVec3;
use rayon::prelude::*;

use super::inverse_warp::GeometryLimits;
use super::mesh::Mesh;
use super::raster::{Cull, GeometryImage, Material, Projector, rasterize};
use crate::error::{Error, Result};
use crate::view::clip::{Keep, ends_on_samples, limit_convex};
use crate::view::plan::{FramePlan, Limiter, RayLimits};
use crate::view::unpermute;

/// A closed convex mesh (voxel-index coordinates), welded and wound outward.
#[derive(Clone, Debug, PartialEq)]
pub struct ConvexMesh {
    mesh: Mesh,
}

impl ConvexMesh {
    /// `mesh` checked to be closed, consistently oriented and convex (see
    /// the [module docs](self)); a clear error otherwise.
    pub fn new(mesh: &Mesh) -> Result<Self> {
        let what = "clip mesh";
        if mesh.triangles.len() < 4 {
            return Err(Error::value(what, format!("{} triangles cannot close a solid (a tetrahedron has 4)", mesh.triangles.len())));
        }
        // weld: one index per distinct position
        let mut index: HashMap<[u64; 3], u32> = HashMap::new();
        let mut vertices = vec![];
        let remap: Vec<u32> = mesh
            .vertices
            .iter()
            .map(|v| {
                // (+0.0 and −0.0 are one position)
                let key = [v.x + 0.0, v.y + 0.0, v.z + 0.0].map(f64::to_bits);
                *index.entry(key).or_insert_with(|| {
                    vertices.push(*v);
                    (vertices.len() - 1) as u32
                })
            })
            .collect();
        let mut triangles: Vec<[u32; 3]> = mesh.triangles.iter().map(|t| t.map(|i| remap[i as usize])).collect();
        if let Some(t) = triangles.iter().find(|t| t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) {
            return Err(Error::value(what, format!("a triangle {t:?} has two corners at the same position")));
        }
        // closed and consistently oriented: every directed edge once, its reverse once
        let mut edges: HashMap<(u32, u32), usize> = HashMap::new();
        for t in &triangles {
            for e in 0..3 {
                *edges.entry((t[e], t[(e + 1) % 3])).or_default() += 1;
            }
        }
        for (&(a, b), &n) in &edges {
            let back = edges.get(&(b, a)).copied().unwrap_or(0);
            if n != 1 || back != 1 {
                let (pa, pb) = (vertices[a as usize], vertices[b as usize]);
                return Err(Error::value(
                    what,
                    if n + back == 1 {
                        format!("the mesh is not closed: the edge {pa} – {pb} belongs to one triangle")
                    } else if n > 1 || back > 1 {
                        format!(
                            "the edge {pa} – {pb} is wound the same way by {} triangles (not closed and consistently oriented, or not a manifold)",
                            n.max(back)
                        )
                    } else {
                        format!("the edge {pa} – {pb} belongs to {} triangles", n + back)
                    },
                ));
            }
        }
        // outward: the enclosed volume positive
        let size = vertices.iter().fold([vertices[0], vertices[0]], |[lo, hi], &v| [lo.min(v), hi.max(v)]);
        let diameter = (size[1] - size[0]).length();
        let c = (size[0] + size[1]) / 2.0;
        let volume: f64 = triangles
            .iter()
            .map(|t| (vertices[t[0] as usize] - c).dot((vertices[t[1] as usize] - c).cross(vertices[t[2] as usize] - c)))
            .sum::<f64>()
            / 6.0;
        if volume.is_nan() || volume.abs() <= 1e-9 * diameter.powi(3) {
            return Err(Error::value(what, format!("the mesh encloses no volume ({volume})")));
        }
        if volume < 0.0 {
            for t in &mut triangles {
                t.swap(1, 2);
            }
        }
        // convex: every vertex on the inner side of every face's plane
        let tol = 1e-6 * diameter;
        let bad = triangles.par_iter().find_map_any(|t| {
            let [a, b, cc] = t.map(|i| vertices[i as usize]);
            let n = (b - a).cross(cc - a);
            let len = n.length();
            if len == 0.0 {
                return None; // (a sliver: its neighbours' planes decide)
            }
            let n = n / len;
            vertices.iter().find(|&&v| n.dot(v - a) > tol).map(|&v| (a, b, cc, v, n.dot(v - a)))
        });
        if let Some((a, b, cc, v, d)) = bad {
            return Err(Error::value(
                what,
                format!(
                    "the mesh is not convex: the vertex {v} lies {d:.3e} outside the plane of the face {a}, {b}, {cc} (tolerance {tol:.1e})"
                ),
            ));
        }
        Ok(ConvexMesh { mesh: Mesh { vertices, triangles } })
    }

    /// The welded, outward-wound mesh.
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }
}

/// A convex mesh's clip in one frame (its faces drawn with the frame's
/// projector), as a producer of ray limits: see the [module docs](self).
#[derive(Clone, Debug)]
pub struct MeshClip {
    projector: Projector,
    /// The front and back faces' depth buffers, and each as the inverse
    /// warp's gather (the fallback at the silhouette).
    front: (Vec<f64>, GeometryLimits),
    back: (Vec<f64>, GeometryLimits),
    size: [usize; 2],
    keep: Keep,
}

impl MeshClip {
    /// The clip of `mesh` keeping `keep`, drawn with `projector` (the frame's camera).
    pub fn new(mesh: &ConvexMesh, projector: Projector, keep: Keep) -> Result<Self> {
        let [w, h] = projector.size();
        let draw = |cull| -> Result<(Vec<f64>, GeometryLimits)> {
            let mut img = GeometryImage::new(w, h);
            rasterize(&mesh.mesh, &Material::default(), cull, &projector, &mut img)?;
            let g = GeometryLimits::new(projector, &img);
            Ok((img.depth, g))
        };
        Ok(MeshClip { projector, front: draw(Cull::Back)?, back: draw(Cull::Front)?, size: [w, h], keep })
    }

    /// The depth of buffer `d` at output point `(u, v)`: interpolated
    /// between the four pixel centres around it where all four hold the
    /// surface (bilinearly in the screen-linear quantity: the depth in
    /// parallel, `1/w = 1/(D + depth)` in perspective, so a flat face is
    /// exact); else (the silhouette) the inverse warp's gather over the
    /// pixel-sized box about the point, then over a box `reach` pixels wide
    /// (the nearest depth there, `+∞` for none).
    fn depth_at(&self, (d, gather): &(Vec<f64>, GeometryLimits), u: f64, v: f64, reach: f64) -> f64 {
        let [w, h] = self.size;
        let (x0, y0) = (u.floor(), v.floor());
        if x0 >= 0.0 && y0 >= 0.0 && x0 + 1.0 < w as f64 && y0 + 1.0 < h as f64 {
            let i = y0 as usize * w + x0 as usize;
            let c = [d[i], d[i + 1], d[i + w], d[i + w + 1]];
            if c.iter().all(|x| x.is_finite()) {
                let (fx, fy) = (u - x0, v - y0);
                let lerp = |c: [f64; 4]| (c[0] * (1.0 - fx) + c[1] * fx) * (1.0 - fy) + (c[2] * (1.0 - fx) + c[3] * fx) * fy;
                return match self.projector.eye_distance() {
                    None => lerp(c),
                    Some(e) => 1.0 / lerp(c.map(|z| 1.0 / (e + z))) - e,
                };
            }
        }
        let near = gather.min_depth(u - 0.5, u + 0.5, v - 0.5, v + 0.5);
        if near.is_finite() || reach <= 0.5 { near } else { gather.min_depth(u - reach, u + reach, v - reach, v + reach) }
    }

    /// The slices `[a, b]` (`a > b`: none) of `0 ..= last` of pixel `(p, q)`
    /// inside the mesh.
    fn inside_interval(&self, plan: &FramePlan, last: i64, p: usize, q: usize) -> [i64; 2] {
        const NONE: [i64; 2] = [1, 0];
        let [a, b] = plan.intermediate_to_sheared(p as f64, q as f64);
        let Some([u, v]) = plan.warp.to_output(a, b) else { return NONE };
        let back = self.depth_at(&self.back, u, v, 0.5);
        if !back.is_finite() {
            return NONE;
        }
        // (at the silhouette the nearest front face within two pixels; none
        // there where a back face is drawn: the eye inside the solid)
        let front = self.depth_at(&self.front, u, v, 2.0);
        let front = if front.is_finite() { front } else { f64::NEG_INFINITY };
        let depth = |k: i64| {
            let s = unpermute(plan.view.perm, DVec3::new(plan.sample_at(k as usize, 0, p), plan.sample_at(k as usize, 1, q), k as f64));
            -self.projector.eye_space(s).z
        };
        let inside = |k: i64| {
            let d = depth(k);
            front <= d && d <= back
        };
        let (d0, d1) = (depth(0), depth(last));
        let (t0, t1) = if last == 0 || d0 == d1 {
            if inside(0) { (0.0, last as f64) } else { return NONE }
        } else {
            let t = |x: f64| (x - d0) / (d1 - d0) * last as f64;
            let (ta, tb) = (t(front), t(back));
            (ta.min(tb), ta.max(tb))
        };
        // a one-sample margin for rounding, then the ends checked on the samples
        ends_on_samples(t0, t1, last, inside)
    }
}

impl Limiter for MeshClip {
    fn limit(&self, plan: &FramePlan, limits: &mut RayLimits) {
        limit_convex(self.keep, plan, limits, |last, p, q| self.inside_interval(plan, last, p, q));
    }

    fn holes(&self) -> usize {
        (self.keep == Keep::Outside) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clip_mesh_primitives_are_convex_and_open_or_dented_meshes_are_not() {
        let cube = Mesh::cuboid(DVec3::ZERO, DVec3::new(3.0, 4.0, 5.0)).unwrap();
        assert!(ConvexMesh::new(&cube).is_ok());
        assert!(ConvexMesh::new(&Mesh::sphere(DVec3::splat(5.0), 4.0, 24).unwrap()).is_ok());
        assert!(ConvexMesh::new(&Mesh::cylinder(DVec3::ZERO, DVec3::new(1.0, 2.0, 9.0), 2.0, 12).unwrap()).is_ok());
        // wound inward: turned outward
        let mut inward = cube.clone();
        inward.triangles.iter_mut().for_each(|t| t.swap(1, 2));
        assert_eq!(ConvexMesh::new(&inward).unwrap().mesh().triangles, ConvexMesh::new(&cube).unwrap().mesh().triangles);
        // one face missing: open
        let mut open = cube.clone();
        open.triangles.truncate(10);
        let e = ConvexMesh::new(&open).unwrap_err().to_string();
        assert!(e.contains("not closed"), "{e}");
        // one corner pushed in: closed, not convex
        let mut dent = cube.clone();
        dent.vertices[7] = DVec3::new(2.0, 3.0, 4.0);
        let e = ConvexMesh::new(&dent).unwrap_err().to_string();
        assert!(e.contains("not convex"), "{e}");
        // one triangle flipped: not consistently oriented
        let mut flip = cube.clone();
        flip.triangles[3].swap(1, 2);
        assert!(ConvexMesh::new(&flip).is_err());
        // a plane is not a solid
        assert!(ConvexMesh::new(&Mesh::plane(DVec3::ZERO, DVec3::Z, 2.0).unwrap()).is_err());
    }
}
