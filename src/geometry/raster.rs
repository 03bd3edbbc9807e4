//! The CPU rasterizer: meshes into a colour and depth buffer at the output
//! resolution, in the renderer's image coordinates.
//!
//! A voxel `v` projects as the renderer's frame does ([`Projector`]): eye
//! coordinates `e = R·S·(v − c)` (`c` the centre of the voxel box), pixel
//! `u = (W − 1)/2 + zoom·e.x`, `v = (H − 1)/2 − zoom·e.y` in parallel, and with
//! `zoom·D/(D − e.z)` in place of `zoom` in perspective (the eye `D` world
//! units in front of the centre). Pixel `(x, y)`'s centre is the point
//! `(x, y)`. Depth is the reference renderer's: `−e.z`, world units along the
//! view from the plane through the centre (interpolated perspective-correctly).
//!
//! Triangles are clipped against the near plane (perspective), culled by
//! their winding on screen ([`Cull`]; counter-clockwise as seen is the front,
//! as the primitives of [`super::mesh`] are wound), filled with the top-left
//! rule (a pixel centre on an edge shared by two triangles belongs to exactly
//! one of them), and flat-shaded with the renderer's headlight material
//! ([`Shading`]): `colour·(ambient + diffuse·ndl) + specular·ndl^n`, with
//! `ndl = |n·l|` (two-sided).

use glam::{DMat3, DVec3};

use super::mesh::Mesh;
use crate::classify::shading::Shading;
use crate::error::{Error, Result};
use crate::view::{Camera, Factorization, Projection};

/// Which triangles are drawn, by their winding as seen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cull {
    /// Only front faces (counter-clockwise as seen): a closed mesh's outside.
    Back,
    /// Only back faces: a closed mesh's far side (a clip region's exit).
    Front,
    /// Both.
    None,
}

/// A surface's colour and the headlight material it is shaded with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    pub color: [f32; 3],
    pub shading: Shading,
}

impl Default for Material {
    fn default() -> Self {
        Material { color: [0.85, 0.75, 0.3], shading: Shading::default() }
    }
}

/// A colour and depth buffer at the output resolution: the colour is opaque
/// (`α = 1`) where a triangle covers the pixel centre, `[0; 4]` elsewhere;
/// [`GeometryImage::depth`] the nearest surface's depth, `+∞` where none.
///
/// Colour and depth are written only by [`rasterize`], which also keeps each row's
/// covered span ([`GeometryImage::row_span`]): the inverse warp reads the
/// covered pixels without scanning the whole buffer.
#[derive(Clone, Debug, PartialEq)]
pub struct GeometryImage {
    pub width: usize,
    pub height: usize,
    pub(crate) color: Vec<[f32; 4]>,
    pub(crate) depth: Vec<f64>,
    /// Per row, the first and last covered pixel (`[1, 0]`: none).
    spans: Vec<[u32; 2]>,
}

impl GeometryImage {
    /// An empty buffer.
    pub fn new(width: usize, height: usize) -> Self {
        GeometryImage {
            width,
            height,
            color: vec![[0.0; 4]; width * height],
            depth: vec![f64::INFINITY; width * height],
            spans: vec![[1, 0]; height],
        }
    }

    /// Empties the buffer for a frame of `width × height`, keeping its memory:
    /// only the pixels the last drawing covered are reset (a needle's frame
    /// does not rewrite 6 MB at 512²). Another size allocates anew.
    pub fn clear(&mut self, width: usize, height: usize) {
        if (width, height) != (self.width, self.height) {
            *self = GeometryImage::new(width, height);
            return;
        }
        for y in 0..height {
            if let Some([a, b]) = self.row_span(y) {
                let r = y * width;
                self.color[r + a..=r + b].fill([0.0; 4]);
                self.depth[r + a..=r + b].fill(f64::INFINITY);
            }
            self.spans[y] = [1, 0];
        }
    }

    /// The colour buffer, row-major (premultiplied, `[0; 4]` where no triangle covers a pixel centre).
    pub fn color(&self) -> &[[f32; 4]] {
        &self.color
    }

    /// The depth buffer, row-major (`+∞` where no triangle covers a pixel centre).
    pub fn depth(&self) -> &[f64] {
        &self.depth
    }

    /// Row `y`'s covered pixels lie in `x0 ..= x1` (None: the row has none).
    #[inline]
    pub fn row_span(&self, y: usize) -> Option<[usize; 2]> {
        let [a, b] = self.spans[y];
        (a <= b).then_some([a as usize, b as usize])
    }

    /// Fraction of pixels covered.
    pub fn coverage(&self) -> f64 {
        self.depth.iter().filter(|d| d.is_finite()).count() as f64 / self.depth.len().max(1) as f64
    }
}

/// How voxel coordinates land on the output image: the renderer's camera
/// mapping for one volume ([`Factorization`]'s zoom, [`Projection::resolve`]'s
/// eye distance).
#[derive(Clone, Copy, Debug)]
pub struct Projector {
    rot: DMat3,
    spacing: DVec3,
    centre: DVec3,
    zoom: f64,
    size: [usize; 2],
    /// Perspective: the eye's distance from the centre (world units) and the near plane's distance from the eye.
    eye: Option<(f64, f64)>,
}

/// The near plane of a perspective [`Projector`], in world units in front of the eye.
pub const NEAR: f64 = 0.05;

impl Projector {
    /// The projection of `camera` under `projection` for a volume of `dims`
    /// voxels with `spacing`, as the renderer and the reference make it.
    pub fn new(camera: &Camera, projection: &Projection, dims: [usize; 3], spacing: [f32; 3]) -> Result<Self> {
        let (cam, eye) = match projection.resolve(camera, dims, spacing)? {
            None => (*camera, None),
            Some((c, d)) => (c, Some((d, NEAR))),
        };
        let f = Factorization::new(&cam, dims, spacing)?;
        let sp = DVec3::new(spacing[0] as f64, spacing[1] as f64, spacing[2] as f64);
        let nd = DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64);
        Ok(Projector { rot: cam.rotation, spacing: sp, centre: (nd - 1.0) / 2.0, zoom: f.zoom, size: cam.size, eye })
    }

    /// Eye coordinates of voxel point `v`.
    pub fn eye_space(&self, v: DVec3) -> DVec3 {
        self.rot * ((v - self.centre) * self.spacing)
    }

    /// Image position `(u, v)` and depth `−e.z` of eye-space point `e`, and
    /// its perspective weight `1/w` (`w = D − e.z`; 1 in parallel). `None`
    /// behind the near plane.
    pub fn to_screen(&self, e: DVec3) -> Option<(f64, f64, f64, f64)> {
        match self.eye {
            Some((d, near)) if d - e.z < near => None,
            _ => Some(self.project(e)),
        }
    }

    /// [`Projector::to_screen`] of a point known to be in front of the eye
    /// (a vertex the near clip kept or made).
    fn project(&self, e: DVec3) -> (f64, f64, f64, f64) {
        let [w, h] = self.size;
        let (cx, cy) = ((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
        match self.eye {
            None => (cx + self.zoom * e.x, cy - self.zoom * e.y, -e.z, 1.0),
            Some((d, _)) => {
                let wd = d - e.z;
                let s = self.zoom * d / wd;
                (cx + s * e.x, cy - s * e.y, -e.z, 1.0 / wd)
            }
        }
    }

    /// Perspective: the eye's distance from the volume centre (world units;
    /// `w = D − e.z`). None in parallel.
    pub fn eye_distance(&self) -> Option<f64> {
        self.eye.map(|(d, _)| d)
    }

    /// Output size.
    pub fn size(&self) -> [usize; 2] {
        self.size
    }
}

/// A clipped vertex: eye-space position.
type Vert = DVec3;

/// The triangle `[a, b, c]` (eye space) clipped against the near plane:
/// up to four vertices of a convex polygon, in order.
fn clip_near(p: &Projector, tri: [Vert; 3], out: &mut Vec<Vert>) {
    out.clear();
    let Some((d, near)) = p.eye else {
        out.extend(tri);
        return;
    };
    // signed distance in front of the near plane: w − near = d − e.z − near
    let s = |e: Vert| d - e.z - near;
    for i in 0..3 {
        let (a, b) = (tri[i], tri[(i + 1) % 3]);
        let (sa, sb) = (s(a), s(b));
        if sa >= 0.0 {
            out.push(a);
        }
        if (sa >= 0.0) != (sb >= 0.0) {
            let t = sa / (sa - sb);
            let mut x = a + (b - a) * t;
            // exactly on the plane, never a hair behind it
            x.z = d - near;
            out.push(x);
        }
    }
}

/// The edge function of `p` against edge `a → b` (twice the signed area),
/// evaluated from the edge's lexicographically smaller end whichever way it
/// is traversed, so the two triangles sharing an edge get exactly opposite
/// values at every pixel (no pixel on both sides, none on neither).
#[inline]
fn edge(a: (f64, f64), b: (f64, f64), p: (f64, f64)) -> f64 {
    Edge::new(a, b).at(p)
}

/// [`edge`] with what does not depend on the pixel set up once: the smaller
/// end, the edge's extent from it, and the sign (the same operations in the
/// same order: the same value, bit for bit).
#[derive(Clone, Copy)]
struct Edge {
    from: (f64, f64),
    d: (f64, f64),
    flip: bool,
}

impl Edge {
    #[inline(always)]
    fn new(a: (f64, f64), b: (f64, f64)) -> Edge {
        let flip = (a.0, a.1) > (b.0, b.1);
        let (a, b) = if flip { (b, a) } else { (a, b) };
        Edge { from: a, d: (b.0 - a.0, b.1 - a.1), flip }
    }

    #[inline(always)]
    fn at(&self, p: (f64, f64)) -> f64 {
        let f = self.d.0 * (p.1 - self.from.1) - self.d.1 * (p.0 - self.from.0);
        if self.flip { -f } else { f }
    }
}

/// Draws `mesh` (voxel coordinates) into `out` with `material`, keeping the
/// nearer surface at every pixel. `out` must have the projector's size.
pub fn rasterize(mesh: &Mesh, material: &Material, cull: Cull, proj: &Projector, out: &mut GeometryImage) -> Result<()> {
    let [w, h] = proj.size();
    if out.width != w || out.height != h {
        return Err(Error::value("geometry image", format!("{}×{} for a {w}×{h} view", out.width, out.height)));
    }
    let eye: Vec<DVec3> = mesh.vertices.iter().map(|&v| proj.eye_space(v)).collect();
    let mut poly = Vec::with_capacity(4);
    for t in &mesh.triangles {
        let tri = t.map(|i| eye[i as usize]);
        // the flat normal in eye space (a world-space cross product: the eye frame is a rotation of it)
        let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]);
        // (a degenerate triangle, or one with a NaN corner, has no normal and covers nothing)
        if n.length().is_nan() || n.length() == 0.0 {
            continue;
        }
        clip_near(proj, tri, &mut poly);
        if poly.len() < 3 {
            continue;
        }
        let ndl = match proj.eye {
            // the headlight: along the view in parallel, from the eye in perspective
            None => (n.z / n.length()).abs(),
            Some((d, _)) => {
                let to_eye = DVec3::new(0.0, 0.0, d) - tri[0];
                (n.dot(to_eye) / (n.length() * to_eye.length())).abs()
            }
        } as f32;
        let c = material.shading.shade(material.color, ndl);
        let color = [c[0], c[1], c[2], 1.0];
        let s: Vec<(f64, f64, f64, f64)> = poly.iter().map(|&e| proj.project(e)).collect();
        for i in 1..s.len() - 1 {
            fill::<true>(out, [s[0], s[i], s[i + 1]], cull, color);
        }
    }
    Ok(())
}

/// `⌊x⌋` for `|x|` well inside the `i64` range (a clamped pixel position),
/// without a library call (the default x86-64 target has no rounding
/// instruction).
#[inline(always)]
fn floor_small(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x { t - 1.0 } else { t }
}

/// `⌈x⌉`, as [`floor_small`].
#[inline(always)]
fn ceil_small(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t < x { t + 1.0 } else { t }
}

/// Fills one screen triangle (each vertex `(u, v, depth, 1/w)`); `NARROW`:
/// each row's pixels only between the edges' lines (false: every pixel of
/// the bounding box, the reference the narrowing is tested against).
#[allow(clippy::neg_cmp_op_on_partial_ord)] // NaN fails the test too
fn fill<const NARROW: bool>(out: &mut GeometryImage, v: [(f64, f64, f64, f64); 3], cull: Cull, color: [f32; 4]) {
    let p = v.map(|x| (x.0, x.1));
    let area = edge(p[0], p[1], p[2]);
    if !(area.is_finite() && area != 0.0) {
        return;
    }
    // image y grows downward: counter-clockwise as seen has negative area here
    let front = area < 0.0;
    match cull {
        Cull::Back if !front => return,
        Cull::Front if front => return,
        _ => {}
    }
    // orient positively (interior where every edge function is > 0)
    let (v, p, area) = if area > 0.0 { (v, p, area) } else { ([v[0], v[2], v[1]], [p[0], p[2], p[1]], -area) };
    // top-left rule in y-down coordinates: a top edge is horizontal going
    // right, a left edge goes up; a pixel centre exactly on an edge is inside
    // only for those
    let top_left = |a: (f64, f64), b: (f64, f64)| (a.1 == b.1 && b.0 > a.0) || b.1 < a.1;
    let edges = [(p[1], p[2]), (p[2], p[0]), (p[0], p[1])];
    let tl = edges.map(|(a, b)| top_left(a, b));
    let (w, h) = (out.width as f64, out.height as f64);
    let x0 = p.iter().map(|q| q.0).fold(f64::INFINITY, f64::min).ceil().max(0.0);
    let x1 = p.iter().map(|q| q.0).fold(f64::NEG_INFINITY, f64::max).floor().min(w - 1.0);
    let y0 = p.iter().map(|q| q.1).fold(f64::INFINITY, f64::min).ceil().max(0.0);
    let y1 = p.iter().map(|q| q.1).fold(f64::NEG_INFINITY, f64::max).floor().min(h - 1.0);
    if !(x0 <= x1 && y0 <= y1) {
        return;
    }
    // each edge's line as x = ax + slope·(y − ay), for the rows' ranges: the
    // edges bounding the rows on the left (going up) and on the right, with
    // a tolerance far above the rounding of the line or of the exact edge
    // test below, which decides each pixel of the range (none: an edge that
    // cannot narrow it, horizontal or out of range)
    let (mut left, mut right) = ([(0.0f64, 0.0f64, 0.0f64, 0.0f64); 3], [(0.0f64, 0.0f64, 0.0f64, 0.0f64); 3]);
    let (mut nl, mut nr) = (0, 0);
    for &(a, b) in &edges {
        let dy = b.1 - a.1;
        if dy == 0.0 {
            continue;
        }
        let slope = (b.0 - a.0) / dy;
        let reach = slope.abs() * (y0 - a.1).abs().max((y1 - a.1).abs());
        let tol = 1e-9 * (1.0 + a.0.abs() + reach);
        if !(slope.is_finite() && tol.is_finite()) {
            continue;
        }
        // inside lies where −dy·(x − at) > 0
        if dy < 0.0 {
            left[nl] = (a.0, a.1, slope, tol);
            nl += 1;
        } else {
            right[nr] = (a.0, a.1, slope, tol);
            nr += 1;
        }
    }
    let e = edges.map(|(a, b)| Edge::new(a, b));
    for y in y0 as usize..=y1 as usize {
        // the row's pixels inside every edge, solved on the edges' lines (a
        // long thin triangle's box is mostly outside it); bounds kept within
        // [x0 − 1, x1 + 1], whole numbers by an exact conversion
        let yf = y as f64;
        let (mut lo, mut hi) = (x0, x1);
        let (nl, nr) = if NARROW { (nl, nr) } else { (0, 0) };
        for &(ax, ay, slope, tol) in &left[..nl] {
            lo = lo.max(ceil_small((ax + slope * (yf - ay) - tol).clamp(x0 - 1.0, x1 + 1.0)));
        }
        for &(ax, ay, slope, tol) in &right[..nr] {
            hi = hi.min(floor_small((ax + slope * (yf - ay) + tol).clamp(x0 - 1.0, x1 + 1.0)));
        }
        if !(lo <= hi) {
            continue;
        }
        let (mut first, mut last) = (u32::MAX, 0u32);
        for x in lo as usize..=hi as usize {
            let q = (x as f64, yf);
            let b = e.map(|e| e.at(q));
            if !(0..3).all(|i| b[i] > 0.0 || (b[i] == 0.0 && tl[i])) {
                continue;
            }
            // perspective-correct depth: barycentrics weighted by 1/w
            let l = b.map(|x| x / area);
            let iw = l[0] * v[0].3 + l[1] * v[1].3 + l[2] * v[2].3;
            let depth = (l[0] * v[0].2 * v[0].3 + l[1] * v[1].2 * v[1].3 + l[2] * v[2].2 * v[2].3) / iw;
            let i = y * out.width + x;
            if depth < out.depth[i] {
                out.depth[i] = depth;
                out.color[i] = color;
                first = first.min(x as u32);
                last = x as u32;
            }
        }
        if first <= last {
            let s = &mut out.spans[y];
            *s = if s[0] > s[1] { [first, last] } else { [s[0].min(first), s[1].max(last)] };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::view::{NamedView, rotate_eye};

    fn projector(size: usize, rot: DMat3, projection: Projection) -> Projector {
        Projector::new(&Camera::new(rot, [size, size]), &projection, [64, 64, 64], [1.0; 3]).unwrap()
    }

    /// The rows' covered spans kept while rasterizing are exactly the first
    /// and last covered pixel of each row (what the inverse warp reads
    /// instead of the whole buffer).
    #[test]
    fn row_spans_are_the_covered_pixels() {
        let rot = rotate_eye(NamedView::Anterior.rotation(), 1, 37.0);
        for projection in [Projection::Parallel, Projection::perspective(40.0, 2.0).unwrap()] {
            let p = projector(96, rot, projection);
            let mut img = GeometryImage::new(96, 96);
            let a = Mesh::cylinder(DVec3::new(2.0, 5.0, 3.0), DVec3::new(60.0, 50.0, 40.0), 1.5, 16).unwrap();
            let b = Mesh::sphere(DVec3::new(45.0, 20.0, 30.0), 9.0, 64).unwrap();
            for m in [&a, &b] {
                rasterize(m, &Material::default(), Cull::None, &p, &mut img).unwrap();
            }
            for y in 0..96 {
                let row = &img.depth()[y * 96..(y + 1) * 96];
                let want = row.iter().position(|d| d.is_finite()).map(|x0| [x0, row.iter().rposition(|d| d.is_finite()).unwrap()]);
                assert_eq!(img.row_span(y), want, "{projection:?} row {y}");
            }
            assert!(img.coverage() > 0.002, "{projection:?}: something drawn ({})", img.coverage());
        }
    }

    /// Each row's range solved on the edges' lines loses no pixel: random
    /// triangles (long and thin, tiny, huge, partly off screen, either
    /// orientation) drawn row range by row range equal the same triangles
    /// with every pixel of their boxes tested, bit for bit.
    #[test]
    fn raster_row_ranges_equal_the_whole_box() {
        let mut rnd = crate::geometry::test_rng(0x853c49e6748fea9bu64);
        let (w, h) = (61, 47);
        let mut drawn = 0;
        for round in 0..400 {
            let (mut a, mut b) = (GeometryImage::new(w, h), GeometryImage::new(w, h));
            for _ in 0..6 {
                let scale = [1.5, 20.0, 80.0, 1e6][round % 4];
                let c = (rnd(-10.0, 70.0), rnd(-10.0, 55.0));
                let mut v = [(0.0, 0.0, 0.0, 0.0); 3];
                for x in &mut v {
                    *x = (c.0 + rnd(-scale, scale), c.1 + rnd(-scale, scale) * [1.0, 0.05][round % 2], rnd(1.0, 9.0), rnd(0.2, 1.0));
                }
                if round % 5 == 0 {
                    // (a long thin sliver along a random direction)
                    v[2] = (v[1].0 + rnd(-0.3, 0.3), v[1].1 + rnd(-0.3, 0.3), v[2].2, v[2].3);
                }
                fill::<true>(&mut a, v, Cull::None, [1.0; 4]);
                fill::<false>(&mut b, v, Cull::None, [1.0; 4]);
            }
            assert!(a.depth().iter().zip(b.depth()).all(|(x, y)| x.to_bits() == y.to_bits()), "round {round}");
            assert_eq!(a.spans, b.spans, "round {round}");
            drawn += a.depth().iter().filter(|d| d.is_finite()).count();
        }
        assert!(drawn > 100_000, "only {drawn} pixels drawn");
    }

    /// A sphere's rasterized depth is the analytic depth of the nearer
    /// hemisphere within the tessellation's sag, in parallel and in
    /// perspective; back-face culling keeps exactly that surface and front
    /// culling shows the far side.
    #[test]
    fn sphere_depth_matches_the_analytic_sphere() {
        let (c, r) = (DVec3::new(30.0, 33.0, 31.5), 20.0);
        let mesh = Mesh::sphere(c, r, 256).unwrap();
        let sag = r * (1.0 - (std::f64::consts::PI / 128.0).cos()) + 1e-9;
        let rot = rotate_eye(NamedView::Anterior.rotation(), 1, 30.0);
        for projection in [Projection::Parallel, Projection::perspective(40.0, 2.0).unwrap()] {
            let p = projector(96, rot, projection);
            let mut img = GeometryImage::new(96, 96);
            rasterize(&mesh, &Material::default(), Cull::Back, &p, &mut img).unwrap();
            let mut all = GeometryImage::new(96, 96);
            rasterize(&mesh, &Material::default(), Cull::None, &p, &mut all).unwrap();
            assert_eq!(img.depth, all.depth, "culling back faces changes no visible pixel");
            let mut back = GeometryImage::new(96, 96);
            rasterize(&mesh, &Material::default(), Cull::Front, &p, &mut back).unwrap();
            let rays = crate::accuracy::reference::Rays::with_projection(&Camera::new(rot, [96, 96]), &projection, [64, 64, 64], [1.0; 3])
                .unwrap();
            let mut hits = 0;
            for y in 0..96 {
                for x in 0..96 {
                    let (o, d) = rays.ray(x as f64, y as f64);
                    // the ray against the exact sphere: |o + t·d − c| = r
                    let oc = o - c;
                    let (a, b, cc) = (d.dot(d), oc.dot(d), oc.dot(oc) - r * r);
                    let disc = b * b - a * cc;
                    let i = y * 96 + x;
                    if disc < 0.0 {
                        // outside the exact sphere: so outside the inscribed mesh
                        assert!(img.depth[i].is_infinite(), "({x}, {y}) covered outside the sphere");
                        continue;
                    }
                    let (t0, t1) = ((-b - disc.sqrt()) / a, (-b + disc.sqrt()) / a);
                    let (near, far) = (rays.depth_of(o + t0 * d), rays.depth_of(o + t1 * d));
                    // half the chord, over the radius: the cosine of the ray's incidence
                    let cos = (disc.sqrt() / a) / r;
                    if img.depth[i].is_finite() {
                        hits += 1;
                        // faces lie inside the sphere by at most the sag: along the ray by sag / cos
                        assert!(img.depth[i] >= near - 1e-9, "{projection:?} ({x}, {y}): {} in front of {near}", img.depth[i]);
                        assert!(back.depth[i] <= far + 1e-9);
                        if cos > 0.2 {
                            let tol = 1.5 * sag / cos + 1e-9;
                            assert!(img.depth[i] <= near + tol, "{projection:?} ({x}, {y}): {} vs {near}", img.depth[i]);
                            assert!(back.depth[i] >= far - tol, "{projection:?} ({x}, {y}): back {} vs {far}", back.depth[i]);
                        }
                    } else {
                        // uncovered inside the sphere only within the sag of its silhouette
                        assert!(disc.sqrt() / a.sqrt() < 2.0 * (2.0 * r * sag).sqrt() + 1.0, "({x}, {y}) missed inside the sphere");
                    }
                }
            }
            assert!(hits > 300, "{hits}");
        }
    }

    /// The top-left rule: a grid of quads sharing edges through pixel
    /// centres covers every pixel inside exactly once.
    #[test]
    fn shared_edges_cover_each_pixel_once() {
        let p = projector(32, NamedView::Anterior.rotation(), Projection::Parallel);
        let mut count = vec![0u32; 32 * 32];
        // triangles given in image space: build each as a one-triangle mesh mapped back to voxels
        let e = |u: f64, v: f64| {
            // image (u, v) at depth 0 → eye (x, y, 0) → voxel
            let ex = DVec3::new((u - 15.5) / p.zoom, (15.5 - v) / p.zoom, 0.0);
            p.rot.transpose() * ex / p.spacing + p.centre
        };
        // outer edges between pixel centres, inner ones through columns and rows of them
        let pts = [1.5, 9.0, 13.5, 20.0, 27.5];
        for (gi, xs) in pts.windows(2).enumerate() {
            for ys in pts.windows(2) {
                let (a, b, c, d) = (e(xs[0], ys[0]), e(xs[1], ys[0]), e(xs[1], ys[1]), e(xs[0], ys[1]));
                let tris = if gi % 2 == 0 { [[0, 1, 2], [0, 2, 3]] } else { [[0, 1, 3], [1, 2, 3]] };
                for t in tris {
                    let m = Mesh::new(vec![a, b, c, d], vec![t]).unwrap();
                    let mut img = GeometryImage::new(32, 32);
                    rasterize(&m, &Material::default(), Cull::None, &p, &mut img).unwrap();
                    for (k, d) in img.depth.iter().enumerate() {
                        count[k] += d.is_finite() as u32;
                    }
                }
            }
        }
        for y in 0..32 {
            for x in 0..32 {
                let inside = (2..=27).contains(&x) && (2..=27).contains(&y);
                assert_eq!(count[y * 32 + x], inside as u32, "pixel ({x}, {y})");
            }
        }
    }

    /// A triangle through the eye plane is clipped at the near plane: what is
    /// drawn is finite and in front of the eye; one wholly behind draws nothing.
    #[test]
    fn the_near_plane_clips() {
        let projection = Projection::perspective(60.0, 0.1).unwrap();
        let p = projector(64, NamedView::Anterior.rotation(), projection);
        let (d, _) = p.eye.unwrap();
        let to_voxel = |e: DVec3| p.rot.transpose() * e / p.spacing + p.centre;
        let big = Mesh::new(
            vec![
                to_voxel(DVec3::new(-40.0, -5.0, -20.0)),
                to_voxel(DVec3::new(40.0, -5.0, -20.0)),
                to_voxel(DVec3::new(0.0, 30.0, d + 50.0)),
            ],
            vec![[0, 1, 2]],
        )
        .unwrap();
        let mut img = GeometryImage::new(64, 64);
        rasterize(&big, &Material::default(), Cull::None, &p, &mut img).unwrap();
        assert!(img.coverage() > 0.1);
        assert!(img.depth.iter().filter(|x| x.is_finite()).all(|&z| z >= -(d - NEAR) - 1e-9 && z.is_finite()));
        let behind = Mesh::new(
            vec![
                to_voxel(DVec3::new(-1.0, 0.0, d + 1.0)),
                to_voxel(DVec3::new(1.0, 0.0, d + 1.0)),
                to_voxel(DVec3::new(0.0, 1.0, d + 2.0)),
            ],
            vec![[0, 1, 2]],
        )
        .unwrap();
        let mut img = GeometryImage::new(64, 64);
        rasterize(&behind, &Material::default(), Cull::None, &p, &mut img).unwrap();
        assert_eq!(img.coverage(), 0.0);
        assert!(rasterize(&big, &Material::default(), Cull::None, &p, &mut GeometryImage::new(8, 8)).is_err());
    }
}
