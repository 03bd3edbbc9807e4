//! Geometry and clip regions from the command line, per frame: meshes
//! (`--mesh FILE` placed with `--mesh-scale`, `--mesh-rotate`,
//! `--mesh-translate`, in voxel indices or with `--mesh-world` in world
//! millimetres from the volume centre), convex clip regions (`--clip-box`,
//! `--clip-sphere`, `--clip-mesh` placed as the meshes are, `--clip-keep
//! inside|outside`) and the clip planes (`--clip-plane`).
//!
//! The clip regions and planes are one limiter set once; a mesh is drawn
//! every frame at the output resolution (the library's rasterizer), its depth
//! inverse-warped into the frame plan's ray limits beside the clip regions,
//! and the volume composited over its colour (see `shearwarp::geometry`).

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::Result;
use clap::{Args, ValueEnum};
use glam::{DAffine3, DMat3, DVec3, EulerRot};

use shearwarp::composite::Mode;
use shearwarp::geometry::{
    ConvexMesh, Cull, GeometryImage, GeometryLimits, Material, Mesh, MeshClip, Projector, composite_iso_over_geometry,
    composite_over_geometry, load_mesh_within, rasterize,
};
use shearwarp::render::{FrameStats, Method, Renderer};
use shearwarp::view::Camera;
use shearwarp::view::clip::{self, ClipRegion, Limiters, Region};
use shearwarp::view::plan::Limiter;
use shearwarp::warp::Image;

use crate::app::Usage;

/// Which side of a convex clip region is kept.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum Keep {
    /// The samples inside the region.
    #[default]
    Inside,
    /// The samples outside it (the volume cut open).
    Outside,
}

/// Geometry and clip-region arguments (flattened into `render`, `rotate`, `view`).
#[derive(Args, Debug, Clone, Default)]
pub struct SceneArgs {
    /// A triangle mesh (OBJ, STL or PLY) drawn inside the volume: the rays
    /// stop at it and the volume in front is composited over it (repeatable).
    /// Coordinates are voxel indices unless --mesh-world.
    #[arg(long, value_name = "FILE")]
    pub mesh: Vec<PathBuf>,
    /// Scale the meshes by S about their own origin (before rotating and moving).
    #[arg(long, value_name = "S", default_value_t = 1.0, allow_negative_numbers = true)]
    pub mesh_scale: f64,
    /// Rotate the meshes by RX,RY,RZ degrees about their origin's x, y, z axes (after scaling).
    #[arg(long, value_name = "RX,RY,RZ", value_parser = parse_triple_f64, allow_hyphen_values = true)]
    pub mesh_rotate: Option<[f64; 3]>,
    /// Move the meshes by TX,TY,TZ (after scaling and rotating).
    #[arg(long, value_name = "TX,TY,TZ", value_parser = parse_triple_f64, allow_hyphen_values = true)]
    pub mesh_translate: Option<[f64; 3]>,
    /// The meshes' coordinates are world millimetres from the volume centre
    /// along the volume's x, y, z axes (default: voxel indices).
    #[arg(long)]
    pub mesh_world: bool,
    /// A needle: a closed cylinder from (x0,y0,z0) to (x1,y1,z1) in voxel
    /// indices, of radius r in voxels of the smallest spacing (round in world
    /// space, as --clip-sphere); with --mesh-world, ends and radius in world
    /// millimetres from the volume centre. Drawn like --mesh (repeatable;
    /// not moved by --mesh-scale / --mesh-rotate / --mesh-translate).
    #[arg(long, value_name = "X0,Y0,Z0,X1,Y1,Z1,R", value_parser = parse_needle, allow_hyphen_values = true)]
    pub needle: Vec<[f64; 7]>,
    /// Mesh colour R,G,B in [0, 1].
    #[arg(long, value_name = "R,G,B", value_parser = parse_triple_f64, default_value = "0.85,0.75,0.3")]
    pub mesh_color: [f64; 3],
    /// A convex clip box x0,y0,z0,x1,y1,z1 in voxel indices (see --clip-keep).
    #[arg(long, value_name = "X0,Y0,Z0,X1,Y1,Z1", value_parser = parse_box, allow_hyphen_values = true)]
    pub clip_box: Option<[f64; 6]>,
    /// A convex clip sphere x,y,z,r: centre in voxel indices, radius in
    /// voxels of the smallest spacing (round in world space; see --clip-keep).
    #[arg(long, value_name = "X,Y,Z,R", value_parser = parse_sphere, allow_hyphen_values = true)]
    pub clip_sphere: Option<[f64; 4]>,
    /// A closed convex mesh (OBJ, STL or PLY) clipping the volume like
    /// --clip-box (see --clip-keep), placed with the --mesh-scale,
    /// --mesh-rotate, --mesh-translate and --mesh-world flags (as --mesh).
    #[arg(long, value_name = "FILE")]
    pub clip_mesh: Option<PathBuf>,
    /// Which side of --clip-box / --clip-sphere / --clip-mesh is rendered
    /// (outside: the region is cut out of the volume; one such region at most).
    #[arg(long, value_enum, default_value = "inside")]
    pub clip_keep: Keep,
    /// Focus+context: inside this region the volume is classified by
    /// --focus-tissue, outside by --tissue: `sphere:x,y,z,r` (centre in voxel
    /// indices, radius in voxels of the smallest spacing),
    /// `box:x0,y0,z0,x1,y1,z1` (voxel indices) or `mesh:FILE` (a closed
    /// convex OBJ, STL or PLY mesh placed with the --mesh-scale,
    /// --mesh-rotate, --mesh-translate and --mesh-world flags, as --clip-mesh).
    #[arg(long, value_name = "sphere:X,Y,Z,R|box:X0,Y0,Z0,X1,Y1,Z1|mesh:FILE", value_parser = parse_focus, allow_hyphen_values = true)]
    pub focus: Option<FocusArg>,
    /// The tissue preset inside --focus (a name as --tissue takes; default bone).
    #[arg(long, value_name = "NAME")]
    pub focus_tissue: Option<String>,
}

/// The region of `--focus`: an analytic one or a convex mesh's file.
#[derive(Clone, Debug, PartialEq)]
pub enum FocusArg {
    Region(Region),
    Mesh(PathBuf),
}

fn parse_focus(s: &str) -> std::result::Result<FocusArg, String> {
    const KINDS: &str = "sphere:x,y,z,r, box:x0,y0,z0,x1,y1,z1 or mesh:FILE";
    let (kind, rest) = s.split_once(':').ok_or_else(|| format!("expected {KINDS}, got '{s}'"))?;
    match kind.trim() {
        "sphere" => {
            let v = parse_sphere(rest)?;
            Ok(FocusArg::Region(Region::Sphere { centre: [v[0], v[1], v[2]], radius: v[3] }))
        }
        "box" => {
            let b = parse_box(rest)?;
            Ok(FocusArg::Region(Region::Box { lo: [b[0], b[1], b[2]], hi: [b[3], b[4], b[5]] }))
        }
        "mesh" if !rest.is_empty() => Ok(FocusArg::Mesh(PathBuf::from(rest))),
        "mesh" => Err("mesh: needs a file (mesh:FILE)".into()),
        k => Err(format!("unknown focus region '{k}' ({KINDS})")),
    }
}

/// The region and tissue of `--focus` / `--focus-tissue` (None without
/// --focus; an error for --focus-tissue alone).
pub fn focus_of(args: &SceneArgs) -> Result<Option<(FocusArg, String)>> {
    match (&args.focus, &args.focus_tissue) {
        (None, Some(_)) => Err(usage("--focus-tissue needs --focus (the region it classifies)".into())),
        (None, None) => Ok(None),
        (Some(region), t) => Ok(Some((region.clone(), t.as_deref().unwrap_or("bone").to_string()))),
    }
}

/// Gives `r` the focus of `--focus` / `--focus-tissue`, if any (a bad
/// region or tissue is a usage error). A mesh focus is set per frame by
/// [`Scene::render`] (its faces drawn with each frame's camera); here its
/// tissue is checked.
pub fn install_focus(args: &SceneArgs, r: &mut Renderer) -> Result<()> {
    match focus_of(args)? {
        None => {}
        Some((FocusArg::Region(region), t)) => {
            r.set_focus(Some(shearwarp::render::Focus::new(region, t))).map_err(|e| usage(format!("--focus: {e}")))?;
        }
        Some((FocusArg::Mesh(_), t)) => {
            // until the first frame draws the mesh, a focus holding no sample
            // (the focus tissue known before anything is built)
            let none = |plan: &shearwarp::view::plan::FramePlan, l: &mut shearwarp::view::plan::RayLimits| {
                let [w, h] = plan.grid.size;
                (0..h).for_each(|q| (0..w).for_each(|p| l.set(p, q, [1, 0])));
            };
            r.set_focus_limiter(Arc::new(none), &t).map_err(|e| usage(format!("--focus-tissue: {e}")))?;
        }
    }
    Ok(())
}

fn parse_numbers<const N: usize>(s: &str, what: &str) -> std::result::Result<[f64; N], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != N {
        return Err(format!("expected {what} ({N} numbers separated by commas), got '{s}'"));
    }
    let mut v = [0.0; N];
    for (o, p) in v.iter_mut().zip(&parts) {
        *o = p.parse::<f64>().map_err(|_| format!("'{p}' is not a number"))?;
        if !o.is_finite() {
            return Err(format!("'{p}' is not a finite number"));
        }
    }
    Ok(v)
}

fn parse_triple_f64(s: &str) -> std::result::Result<[f64; 3], String> {
    parse_numbers::<3>(s, "three values")
}

fn parse_box(s: &str) -> std::result::Result<[f64; 6], String> {
    let b = parse_numbers::<6>(s, "x0,y0,z0,x1,y1,z1")?;
    if (0..3).any(|a| b[a] >= b[a + 3]) {
        return Err(format!("the box's first corner must be below its second on every axis, got '{s}'"));
    }
    Ok(b)
}

fn parse_needle(s: &str) -> std::result::Result<[f64; 7], String> {
    let v = parse_numbers::<7>(s, "x0,y0,z0,x1,y1,z1,r")?;
    if v[6] <= 0.0 {
        return Err(format!("the radius must be > 0, got '{s}'"));
    }
    if v[..3] == v[3..6] {
        return Err(format!("the needle's two ends must differ, got '{s}'"));
    }
    Ok(v)
}

/// The cylinder of `--needle` in voxel indices: built in world units (round
/// there) and mapped back by the spacing. `world`: the ends and radius are
/// millimetres from the volume centre; else voxel indices, the radius in
/// voxels of the smallest spacing.
fn needle_mesh(n: [f64; 7], world: bool, dims: [usize; 3], spacing: [f32; 3]) -> shearwarp::Result<Mesh> {
    let (sp, centre) = spacing_and_centre(dims, spacing);
    let (a, b) = (DVec3::new(n[0], n[1], n[2]), DVec3::new(n[3], n[4], n[5]));
    // (millimetres from the volume centre)
    let (a, b, r) = if world { (a, b, n[6]) } else { ((a - centre) * sp, (b - centre) * sp, n[6] * sp.min_element()) };
    let to_voxels = DAffine3::from_translation(centre) * DAffine3::from_scale(1.0 / sp);
    Mesh::cylinder(a, b, r, 32)?.transformed(to_voxels)
}

fn parse_sphere(s: &str) -> std::result::Result<[f64; 4], String> {
    let v = parse_numbers::<4>(s, "x,y,z,r")?;
    if v[3] <= 0.0 {
        return Err(format!("the radius must be > 0, got '{s}'"));
    }
    Ok(v)
}

fn usage(msg: String) -> anyhow::Error {
    anyhow::Error::new(Usage(msg))
}

/// A focus mesh's faces drawn for one camera and projection (its limiter).
type DrawnFocus = (Camera, shearwarp::view::Projection, Arc<dyn Limiter>);

/// The geometry and clip regions of a run, for a volume of `dims` voxels with `spacing`.
pub struct Scene {
    meshes: Vec<Mesh>,
    material: Material,
    /// The clip planes and regions (None: none).
    clip: Option<Arc<dyn Limiter>>,
    /// The convex clip mesh and the side it keeps (drawn every frame).
    clip_mesh: Option<(ConvexMesh, clip::Keep)>,
    /// The convex focus mesh (`--focus mesh:FILE`) and its tissue, and its
    /// faces as drawn for the last camera (a frame of the same camera, e.g.
    /// after a tissue switch, draws nothing again).
    focus_mesh: Option<(ConvexMesh, String)>,
    focus_drawn: std::sync::Mutex<Option<DrawnFocus>>,
    /// The meshes' colour and depth buffer, kept from frame to frame (cleared
    /// where the last frame drew, not reallocated).
    drawn: std::sync::Mutex<Option<GeometryImage>>,
    dims: [usize; 3],
    spacing: [f32; 3],
}

/// What the geometry cost in one frame.
#[derive(Clone, Copy, Debug, Default)]
pub struct GeometryCost {
    /// Drawing the meshes into the colour and depth buffer.
    pub raster_ms: f64,
    /// The inverse warp: the depth buffer into the plan's ray limits.
    pub inverse_warp_ms: f64,
    /// The volume over the geometry's colour.
    pub composite_ms: f64,
}

impl Scene {
    /// The scene of `args` plus the clip planes `planes` (already a limiter, or None).
    pub fn new(args: &SceneArgs, planes: Option<Arc<dyn Limiter>>, dims: [usize; 3], spacing: [f32; 3]) -> Result<Scene> {
        let mut limiters: Vec<Arc<dyn Limiter>> = planes.into_iter().collect();
        let region = match (args.clip_box, args.clip_sphere) {
            (Some(_), Some(_)) => return Err(usage("give one of --clip-box and --clip-sphere".into())),
            (Some(b), None) => Some(Region::Box { lo: [b[0], b[1], b[2]], hi: [b[3], b[4], b[5]] }),
            (None, Some(s)) => Some(Region::Sphere { centre: [s[0], s[1], s[2]], radius: s[3] }),
            (None, None) => None,
        };
        let keep = match args.clip_keep {
            Keep::Inside => clip::Keep::Inside,
            Keep::Outside => clip::Keep::Outside,
        };
        if let Some(region) = region {
            limiters.push(Arc::new(ClipRegion::new(region, spacing).map_err(|e| usage(format!("clip region: {e}")))?.keeping(keep)));
        }
        if !(args.mesh_scale.is_finite() && args.mesh_scale != 0.0) {
            return Err(usage(format!("--mesh-scale must be a finite number other than 0, got {}", args.mesh_scale)));
        }
        if args.mesh_color.iter().any(|c| !(0.0..=1.0).contains(c)) {
            return Err(usage(format!("--mesh-color components must be in [0, 1], got {:?}", args.mesh_color)));
        }
        let place = placement(args, dims, spacing);
        let clip_mesh = match &args.clip_mesh {
            None => None,
            Some(path) => {
                let m = load_mesh_within(path, crate::app::budget()).map_err(|e| usage(format!("--clip-mesh: {e}")))?;
                let m = m.transformed(place).map_err(|e| usage(format!("--clip-mesh {}: {e}", path.display())))?;
                Some((ConvexMesh::new(&m).map_err(|e| usage(format!("--clip-mesh {}: {e}", path.display())))?, keep))
            }
        };
        if clip_mesh.is_some() && region.is_some() && keep == clip::Keep::Outside {
            return Err(usage(
                "--clip-keep outside with --clip-mesh and a --clip-box / --clip-sphere: a ray holds one hole, so at most one region may keep its outside"
                    .into(),
            ));
        }
        let focus_mesh = match focus_of(args)? {
            Some((FocusArg::Mesh(path), tissue)) => {
                let what = |e: &dyn std::fmt::Display| usage(format!("--focus mesh:{}: {e}", path.display()));
                let m = load_mesh_within(&path, crate::app::budget()).map_err(|e| what(&e))?;
                let m = m.transformed(place).map_err(|e| what(&e))?;
                Some((ConvexMesh::new(&m).map_err(|e| what(&e))?, tissue))
            }
            _ => None,
        };
        let mut meshes = vec![];
        for n in &args.needle {
            meshes.push(needle_mesh(*n, args.mesh_world, dims, spacing).map_err(|e| usage(format!("--needle: {e}")))?);
        }
        for path in &args.mesh {
            let m = load_mesh_within(path, crate::app::budget()).map_err(|e| usage(e.to_string()))?;
            meshes.push(m.transformed(place).map_err(|e| usage(format!("{}: {e}", path.display())))?);
        }
        let clip: Option<Arc<dyn Limiter>> = match limiters.len() {
            0 => None,
            1 => limiters.pop(),
            _ => Some(Arc::new(Limiters::new(limiters).map_err(|e| usage(e.to_string()))?)),
        };
        let material = Material { color: args.mesh_color.map(|c| c as f32), ..Material::default() };
        Ok(Scene {
            meshes,
            material,
            clip,
            clip_mesh,
            focus_mesh,
            focus_drawn: Default::default(),
            drawn: Default::default(),
            dims,
            spacing,
        })
    }

    /// True when the scene has meshes (drawn every frame).
    pub fn has_meshes(&self) -> bool {
        !self.meshes.is_empty()
    }

    /// Gives `r` the clip planes and regions (the whole job when there are
    /// no meshes and no clip mesh).
    pub fn install(&self, r: &mut Renderer) {
        if self.clip.is_some() && self.clip_mesh.is_none() {
            r.set_limiter(self.clip.clone());
        }
    }

    /// Whether every frame draws something (meshes or the clip mesh): a
    /// frame then goes through [`Scene::render_geometry`]; otherwise the
    /// limiter of [`Scene::install`] (or [`Scene::clip`] in a chain of the
    /// caller's) is the whole job.
    pub fn draws(&self) -> bool {
        !self.meshes.is_empty() || self.clip_mesh.is_some()
    }

    /// The clip planes and regions as one limiter (None: none): what
    /// [`Scene::install`] gives a renderer, for a caller that chains it with
    /// limiters of its own (the viewer's interactive plane).
    pub fn clip(&self) -> Option<Arc<dyn Limiter>> {
        self.clip.clone()
    }

    /// Renders one frame of `cam` into `img`: with meshes, draws them, stops
    /// the rays at them and composites the volume over them.
    pub fn render(&self, r: &mut Renderer, cam: &Camera, img: &mut Image) -> Result<(FrameStats, GeometryCost)> {
        if let Some((m, tissue)) = &self.focus_mesh {
            // the focus mesh's front and back faces, drawn for this camera (once per camera)
            let projection = r.projection();
            let mut drawn = self.focus_drawn.lock().unwrap_or_else(|e| e.into_inner());
            let limiter = match &*drawn {
                Some((c, p, l)) if c == cam && *p == projection => l.clone(),
                _ => {
                    let proj = Projector::new(cam, &projection, self.dims, self.spacing)?;
                    let l: Arc<dyn Limiter> = Arc::new(MeshClip::new(m, proj, clip::Keep::Inside)?);
                    *drawn = Some((*cam, projection, l.clone()));
                    l
                }
            };
            r.set_focus_limiter(limiter, tissue)?;
        }
        if !self.draws() {
            return Ok((r.render(cam, img)?, GeometryCost::default()));
        }
        Ok(self.render_geometry(r, cam, img, self.clip.clone(), true)?)
    }

    /// The per-frame geometry stage of a scene that [`Scene::draws`]
    /// (`render`, `rotate` and the viewer): draws the clip mesh's faces and
    /// the meshes at `cam`'s size for `cam` and `r`'s projection, chains the
    /// clip mesh and the meshes' inverse warp ([`GeometryLimits`], keeping
    /// the iso crossing in iso mode on the raycaster) after `base` (the clip
    /// planes and regions: [`Scene::clip`], or the caller's chain holding
    /// it), installs that limiter in `r`, renders, and composites the volume
    /// over the meshes' colour. `measure`: time the inverse warp once more
    /// on its own (the cost figures of `render` and `rotate`; a frame's work
    /// more).
    pub fn render_geometry(
        &self,
        r: &mut Renderer,
        cam: &Camera,
        img: &mut Image,
        base: Option<Arc<dyn Limiter>>,
        measure: bool,
    ) -> shearwarp::Result<(FrameStats, GeometryCost)> {
        let mut cost = GeometryCost::default();
        let t = Instant::now();
        let proj = Projector::new(cam, &r.projection(), self.dims, self.spacing)?;
        let mut limiters: Vec<Arc<dyn Limiter>> = base.into_iter().collect();
        // the clip mesh's front and back faces, drawn for this frame
        if let Some((m, keep)) = &self.clip_mesh {
            limiters.push(Arc::new(MeshClip::new(m, proj, *keep)?));
        }
        if self.meshes.is_empty() {
            cost.raster_ms = t.elapsed().as_secs_f64() * 1e3;
            r.set_limiter(Some(Arc::new(Limiters::new(limiters)?)));
            return Ok((r.render(cam, img)?, cost));
        }
        let mut kept = self.drawn.lock().unwrap_or_else(|e| e.into_inner());
        let geo = kept.get_or_insert_with(|| GeometryImage::new(cam.size[0], cam.size[1]));
        geo.clear(cam.size[0], cam.size[1]);
        for m in &self.meshes {
            rasterize(m, &self.material, Cull::None, &proj, geo)?;
        }
        cost.raster_ms = t.elapsed().as_secs_f64() * 1e3;
        // iso on the raycaster: keep the crossing slice and depth-test the hits at composition
        let settings = r.settings();
        let crossing = settings.mode == Mode::Iso && matches!(settings.method, Method::Binary | Method::Brute);
        let geometry = Arc::new(GeometryLimits::new(proj, geo).with_iso_crossing(crossing));
        limiters.push(geometry.clone());
        let limiter: Arc<dyn Limiter> = if limiters.len() == 1 { geometry.clone() } else { Arc::new(Limiters::new(limiters)?) };
        r.set_limiter(Some(limiter));
        // (a split perspective frame keeps each pyramid's iso depth for the depth test)
        r.set_keep_depths(crossing);
        let st = r.render(cam, img)?;
        if measure {
            // the inverse warp's own cost, on this frame's plan(s), measured once
            // more from the start: reading the depth buffer, then the limiter (its
            // output buffers made first; anything it makes per frame, such as
            // a table of row minima, made again)
            let mut bufs: Vec<_> = r.last_plans().iter().map(|p| shearwarp::view::plan::RayLimits::open(p.grid.size, p.slices())).collect();
            let t = Instant::now();
            let again = GeometryLimits::new(proj, geo).with_iso_crossing(crossing);
            for (plan, l) in r.last_plans().iter().zip(&mut bufs) {
                r.run_limiter(&again, plan, l);
            }
            cost.inverse_warp_ms = t.elapsed().as_secs_f64() * 1e3;
        }
        let t = Instant::now();
        if crossing {
            composite_iso_over_geometry(img, geo, r, &geometry);
        } else {
            composite_over_geometry(img, geo);
        }
        // the geometry drawn outside the volume's spans: cleared by the next
        // warp into `img` (a reused image showed the last frames' needles)
        for y in 0..geo.height {
            if let Some([x0, x1]) = geo.row_span(y) {
                img.mark_written(y, x0, x1 + 1);
            }
        }
        cost.composite_ms = t.elapsed().as_secs_f64() * 1e3;
        Ok((st, cost))
    }
}

impl Clone for Scene {
    /// The same scene with buffers of its own (the viewer's two render
    /// threads draw at once: each its own colour and depth buffer).
    fn clone(&self) -> Self {
        Scene {
            meshes: self.meshes.clone(),
            material: self.material,
            clip: self.clip.clone(),
            clip_mesh: self.clip_mesh.clone(),
            focus_mesh: self.focus_mesh.clone(),
            focus_drawn: Default::default(),
            drawn: Default::default(),
            dims: self.dims,
            spacing: self.spacing,
        }
    }
}

/// Mesh coordinates → voxel indices: scale, rotate, translate in the
/// meshes' units, then (with --mesh-world) millimetres from the volume
/// centre to voxel indices.
fn placement(args: &SceneArgs, dims: [usize; 3], spacing: [f32; 3]) -> DAffine3 {
    let [rx, ry, rz] = args.mesh_rotate.unwrap_or([0.0; 3]).map(f64::to_radians);
    let rot = DMat3::from_euler(EulerRot::XYZ, rx, ry, rz);
    let t = DVec3::from_array(args.mesh_translate.unwrap_or([0.0; 3]));
    let local = DAffine3::from_translation(t) * DAffine3::from_mat3(rot) * DAffine3::from_scale(DVec3::splat(args.mesh_scale));
    if !args.mesh_world {
        return local;
    }
    let (sp, centre) = spacing_and_centre(dims, spacing);
    DAffine3::from_translation(centre) * DAffine3::from_scale(1.0 / sp) * local
}

/// The voxel spacing (mm) and the volume centre (voxel indices) that map
/// world millimetres from the centre to voxel indices and back.
fn spacing_and_centre(dims: [usize; 3], spacing: [f32; 3]) -> (DVec3, DVec3) {
    let sp = DVec3::new(spacing[0] as f64, spacing[1] as f64, spacing[2] as f64);
    (sp, DVec3::new(dims[0] as f64 - 1.0, dims[1] as f64 - 1.0, dims[2] as f64 - 1.0) / 2.0)
}
