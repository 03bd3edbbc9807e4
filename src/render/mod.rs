//! The renderer: one frame through every stage, from the volume to the image.
//!
//! Owns [`Renderer`], which holds the volume, the classification (one transfer
//! function, or a set of tissue presets sharing one threshold-coded mask), one
//! [`SliceStack`], one [`NormalStack`] (table shading) and one sheared mask per principal axis (each built only when a
//! view first needs it, and rebuilt only when the classification or cell size
//! changes), the reusable intermediate image and per-slice parameters, and a rayon
//! pool of the requested size. [`Renderer::render`] runs one frame and reports how
//! long each stage took. The output is the same for any thread count: every pixel
//! is computed by exactly one task from the same inputs. The pre-classified paths
//! ([`Method::Rle`], [`Method::BruteRle`]) keep their classification and per-axis
//! run-length encodings in a [`RleCache`], encoded lazily like the masks and
//! re-encoded when the classification (transfer function, iso value, tissue or
//! mode) changes.

mod axes;
pub mod checks;
mod classes;
mod frame;
mod pyramids;
mod settings;
mod stats;

pub use axes::estimate_axis;
pub use classes::Focus;
pub use settings::{
    Deluxe, Footprint, Lattice, MAX_INTERMEDIATE_PIXELS, MAX_MASK_BYTES, MAX_QUALITY, MIN_QUALITY, Method, NEAR_SLICES, Normals, Settings,
    WordSize,
};
pub use stats::{BuildTimes, FrameStats};

use axes::{AnyMask, Axes, AxisMask, MaskKey, compact_binary, missing};
use classes::{Classes, FocusShape, TissueSet, next_focus_stamp};
use frame::{FrameKey, FrameSetup, NEXT_STAMP};
use pyramids::Pyramids;
use settings::{build_pool, check_settings};

use std::time::Instant;

use crate::classify::presets::Tissue;
use crate::classify::shade_table::{ShadeTable, headlight_object};
use crate::classify::{Classifier, TransferFunction};
use crate::composite::Mode;
use crate::composite::raycast::{RayContext, occupied_scaled_rays, render_binary, render_brute, volume_rect, volume_rect_with_mids};
use crate::composite::{Intermediate, Rect};
use crate::data::bcc::{BccLattice, BccStack};
use crate::data::normals::CellSource;
use crate::data::normals::NormalStack;
use crate::data::slices::{Densities, SliceStack};
use crate::data::volume::Volume;
use crate::encode::depth::{Matcher, binary_matcher};
use crate::encode::mask::{BinaryMask, CellCodes, ShearWork};
use crate::encode::rle::{ClassKey, RleCache};
use crate::encode::walk::Drift;
use crate::error::{Error, Result};
use crate::memory::Memory;
use crate::view::clip::ClipRegion;
use crate::view::perspective::RayDirections;
use crate::view::plan::{FramePlan, Grid, Limiter, MapKind, RayLimits};
use crate::view::{Camera, Factorization, PerspectiveView, Projection};
use crate::warp::{Canvas, Owned, Texel, clear_for_pyramids, warp, warp_owned};

/// An image a frame renders into: [`crate::warp::Image`] (f32) or
/// [`crate::warp::Image8`] (8 bits).
///
/// The frame is compiled once, in this crate, for each of them: a caller's
/// `render` call links to it instead of instantiating the whole pipeline again
/// in every crate that renders (the binary, the examples, the tests).
pub trait Target {
    /// Renders one frame of `camera` into `out` (what [`Renderer::render`] does).
    fn render_frame(renderer: &mut Renderer, camera: &Camera, out: &mut Self) -> Result<FrameStats>;
}

impl Target for Canvas<[f32; 4]> {
    fn render_frame(renderer: &mut Renderer, camera: &Camera, out: &mut Self) -> Result<FrameStats> {
        renderer.render_texel(camera, out)
    }
}

impl Target for Canvas<[u8; 4]> {
    fn render_frame(renderer: &mut Renderer, camera: &Camera, out: &mut Self) -> Result<FrameStats> {
        renderer.render_texel(camera, out)
    }
}

/// Renders frames of one volume.
pub struct Renderer {
    volume: Volume,
    range: (f32, f32),
    settings: Settings,
    /// What the samples are classified by: one transfer function or a tissue set, and the focus.
    classes: Classes,
    /// The per-axis structures and the memory budget they are built under.
    axes: Axes,
    /// The projection, quality, limiter and plan of the frames, and the last frame's key.
    frame: FrameSetup,
    /// The split perspective frame's pyramids and their kept depths.
    pyramids: Pyramids,
    /// The shade table of the raycast paths' table shading (kept across frames,
    /// rebuilt when the light direction or the material changes).
    shade: ShadeTable,
    inter: Intermediate,
    pool: rayon::ThreadPool,
}

impl Renderer {
    /// A renderer for `volume` with transfer function `tf`; the iso value starts
    /// at the transfer function's lower threshold.
    pub fn new(volume: Volume, tf: &TransferFunction, settings: Settings) -> Result<Self> {
        let range = volume.value_range();
        let classifier = Classifier::new(tf, range.0, range.1);
        let iso = tf.lower_threshold().unwrap_or(f32::INFINITY);
        let pool = build_pool(settings.threads)?;
        check_settings(&settings)?;
        Ok(Renderer {
            volume,
            range,
            settings,
            classes: Classes { classifier, iso, tissues: None, generation: 0, focus: None },
            axes: Axes::default(),
            frame: FrameSetup::default(),
            pyramids: Pyramids::default(),
            shade: ShadeTable::default(),
            inter: Intermediate::default(),
            pool,
        })
    }

    /// A renderer that switches between `tissues` (1..=15 presets with distinct
    /// lower thresholds) in O(1): one mask of adaptive threshold codes serves
    /// them all, so a switch changes a table, never the mask. Starts at tissue 0.
    pub fn with_tissues(volume: Volume, tissues: &[Tissue], settings: Settings) -> Result<Self> {
        let first = tissues.first().ok_or_else(|| Error::value("tissues", "need at least one preset"))?;
        let mut r = Self::new(volume, &first.tf, settings)?;
        let mut ts: Vec<Tissue> = tissues.to_vec();
        ts.sort_by(|a, b| a.threshold.total_cmp(&b.threshold));
        let thresholds: Vec<f32> = ts.iter().map(|t| t.threshold).collect();
        if thresholds.windows(2).any(|w| w[0] >= w[1]) || thresholds.iter().any(|t| !t.is_finite()) {
            return Err(Error::value("tissues", format!("thresholds must be finite and distinct, got {thresholds:?}")));
        }
        for t in &ts {
            // the code mask is conservative only if each tissue is transparent below its threshold
            if let Some(lt) = t.tf.lower_threshold()
                && lt < t.threshold
            {
                return Err(Error::value("tissues", format!("{} has opacity below its threshold {}", t.name, t.threshold)));
            }
        }
        let nb = crate::encode::depth::code_width_for(ts.len()).ok_or_else(|| Error::value("tissues", "at most 15 presets"))?;
        let (lo, hi) = r.range;
        r.classes.tissues = Some(TissueSet {
            iso_cls: ts.iter().map(|t| Classifier::new(&t.iso_tf(), lo, hi)).collect(),
            blend_cls: ts.iter().map(|t| Classifier::new(&t.tf, lo, hi)).collect(),
            matchers: (1..=ts.len() as u32).map(|c| Matcher::new(nb, c)).collect(),
            thresholds,
            tissues: ts,
            current: 0,
        });
        r.classes.generation += 1;
        Ok(r)
    }

    /// The tissue presets (sorted by threshold) and the index of the current one.
    pub fn tissues(&self) -> Option<(&[Tissue], usize)> {
        self.classes.tissues.as_ref().map(|t| (t.tissues.as_slice(), t.current))
    }

    /// Switches to tissue `i` of the set: O(1), no mask rebuild and no re-shear.
    pub fn select_tissue(&mut self, i: usize) -> Result<()> {
        let ts = self.classes.tissues.as_mut().ok_or_else(|| Error::value("tissue", "this renderer has no tissue presets"))?;
        if i >= ts.tissues.len() {
            return Err(Error::value("tissue", format!("index {i} (have {})", ts.tissues.len())));
        }
        ts.current = i;
        Ok(())
    }

    /// Selects a tissue by name.
    pub fn select_tissue_named(&mut self, name: &str) -> Result<()> {
        let i = self.classes.tissues.as_ref().and_then(|t| t.tissues.iter().position(|x| x.name == name));
        self.select_tissue(i.ok_or_else(|| Error::value("tissue", format!("'{name}' is not in this renderer's presets")))?)
    }

    /// The volume: borrowed, or rebuilt from the packed cells when this
    /// renderer let go of its voxels (see [`Renderer::memory`]; then this
    /// allocates a copy, or fails with [`Error::Memory`]).
    pub fn volume(&self) -> Result<std::borrow::Cow<'_, Volume>> {
        if !self.volume.is_parked() {
            return Ok(std::borrow::Cow::Borrowed(&self.volume));
        }
        let mut v = self.volume.clone();
        v.unpark(self.parked_voxels()?);
        Ok(std::borrow::Cow::Owned(v))
    }
    /// The volume's size in voxels.
    pub fn dims(&self) -> [usize; 3] {
        self.volume.dims()
    }
    /// The volume's voxel spacing.
    pub fn spacing(&self) -> [f32; 3] {
        self.volume.spacing()
    }
    /// The volume's smallest and largest density.
    pub fn value_range(&self) -> (f32, f32) {
        self.range
    }

    /// The voxels of a parked volume, from any packed cells that hold them.
    fn parked_voxels(&self) -> Result<std::sync::Arc<crate::data::volume::VoxelData>> {
        let lost = || Error::Other("internal: the volume's voxels were let go with no packed cells holding them".into());
        let ns = self.axes.normals.iter().flatten().find(|n| n.holds_voxels()).ok_or_else(lost)?;
        Ok(std::sync::Arc::new(ns.voxels_in_volume_order()?.ok_or_else(lost)?))
    }

    /// Gives the volume its voxels back if this renderer let go of them.
    fn unpark(&mut self) -> Result<()> {
        if self.volume.is_parked() {
            let data = self.pool.install(|| self.parked_voxels())?;
            self.volume.unpark(data);
        }
        Ok(())
    }

    /// Lets go of the volume's voxels when packed cells of this renderer hold
    /// them (or a build of them is under way: `building`) and nothing outside
    /// it shares them: the binary path of an integer scan then holds the
    /// voxels once, in its cells, instead of twice ([`Renderer::volume`] and
    /// the builds of other paths get them back from the cells).
    fn park(&mut self, building: bool) {
        let held = building || self.axes.normals.iter().flatten().any(NormalStack::holds_voxels);
        if held && self.can_let_go() {
            self.volume.park();
        }
    }

    /// True when the volume's voxels are resident and only this renderer holds them.
    fn can_let_go(&self) -> bool {
        !self.volume.is_parked() && self.volume.data_handles() == 1
    }
    /// Current settings.
    pub fn settings(&self) -> Settings {
        self.settings
    }
    /// Changes settings (rebuilding the thread pool if the count changed; masks
    /// follow on the next frame if the word size or cell size changed, normal
    /// codes if the packing did).
    pub fn set_settings(&mut self, s: Settings) -> Result<()> {
        check_settings(&s)?;
        if s.threads != self.settings.threads {
            self.pool = build_pool(s.threads)?;
        }
        if s.pack != self.settings.pack {
            self.unpark()?;
            self.axes.normals = [None, None, None];
        }
        self.settings = s;
        Ok(())
    }
    /// Replaces the classification by one transfer function (leaves any tissue
    /// set; masks are rebuilt on the next frame).
    pub fn set_transfer_function(&mut self, tf: &TransferFunction) {
        self.classes.classifier = Classifier::new(tf, self.range.0, self.range.1);
        self.classes.iso = tf.lower_threshold().unwrap_or(f32::INFINITY);
        self.classes.tissues = None;
        self.classes.generation += 1;
    }
    /// Sets a custom iso value for the preview (leaves any tissue set; masks are
    /// rebuilt on the next frame).
    pub fn set_iso(&mut self, iso: f32) -> Result<()> {
        if iso.is_nan() {
            return Err(Error::value("iso value", "NaN"));
        }
        if let Some(ts) = self.classes.tissues.take() {
            self.classes.classifier = ts.blend_cls[ts.current].clone();
        }
        self.classes.iso = iso;
        self.classes.generation += 1;
        Ok(())
    }
    /// The iso value of the preview.
    pub fn iso(&self) -> f32 {
        match &self.classes.tissues {
            Some(ts) => ts.thresholds[ts.current],
            None => self.classes.iso,
        }
    }
    /// Name of the current classification (tissue name or "custom").
    pub fn classification_name(&self) -> &str {
        match &self.classes.tissues {
            Some(ts) => ts.tissues[ts.current].name,
            None => "custom",
        }
    }
    /// The classifier the current mode uses.
    pub fn classifier(&self) -> &Classifier {
        match (&self.classes.tissues, self.settings.mode) {
            (Some(ts), Mode::Iso) => &ts.iso_cls[ts.current],
            (Some(ts), Mode::Blend) => &ts.blend_cls[ts.current],
            (None, _) => &self.classes.classifier,
        }
    }
    /// Sets the projection of the following frames (checked: a field of view
    /// in (0°, 180°), an eye distance finite and > 0). A perspective frame
    /// renders with [`Method::Rle`] or [`Method::BruteRle`]; the raycast paths
    /// refuse it with an error.
    pub fn set_projection(&mut self, projection: Projection) -> Result<()> {
        projection.check()?;
        self.frame.projection = projection;
        Ok(())
    }
    /// The projection of the following frames.
    pub fn projection(&self) -> Projection {
        self.frame.projection
    }
    /// Sets the intermediate image's resolution of the following frames:
    /// `q` intermediate pixels per voxel, in `[MIN_QUALITY, MAX_QUALITY]`
    /// (0.25–2; 1, the default, is the classic one pixel per voxel). Below 1
    /// the frame composites fewer rays (a coarser, faster preview, each slice
    /// point-sampled bilinearly at the coarser pitch); above 1 it samples the
    /// slices finer (less blur where the output magnifies). Both projections;
    /// the plan is the projection's own, resampled ([`FramePlan::set_pitch`]).
    pub fn set_quality(&mut self, q: f64) -> Result<()> {
        if !(q.is_finite() && (MIN_QUALITY..=MAX_QUALITY).contains(&q)) {
            return Err(Error::value(
                "quality",
                format!("intermediate pixels per voxel must be in [{MIN_QUALITY}, {MAX_QUALITY}], got {q}"),
            ));
        }
        self.frame.quality = q;
        Ok(())
    }
    /// Intermediate pixels per voxel of the following frames.
    pub fn quality(&self) -> f64 {
        self.frame.quality
    }
    /// Sets (or, with `None`, removes) the producer of per-pixel ray limits
    /// that narrows every following frame's plan: a clip region or geometry.
    pub fn set_limiter(&mut self, limiter: Option<std::sync::Arc<dyn Limiter>>) {
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
        self.frame.limiter = limiter.map(|l| (l, NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)));
    }
    /// Sets (or, with `None`, removes) focus+context: inside the focus
    /// region every following frame classifies its samples by the focus's
    /// tissue preset, outside it by the current one ([`Renderer::select_tissue`]).
    /// O(1) like a tissue switch: the binary path's walks visit the union of
    /// the two presets' codes of the one threshold-coded mask; the RLE paths'
    /// tables are per-view (a pre-classified encoding holds the voxels either
    /// preset shows, so it is rebuilt when the focus tissue changes, as for a
    /// tissue switch; Deluxe P's keeps every preset's already). Needs a
    /// renderer with tissue presets ([`Renderer::with_tissues`]); the region
    /// is checked as [`ClipRegion::new`] checks it.
    pub fn set_focus(&mut self, focus: Option<Focus>) -> Result<()> {
        let Some(f) = focus else {
            self.classes.focus = None;
            return Ok(());
        };
        let i = self.focus_tissue_index(&f.tissue)?;
        let region = ClipRegion::new(f.region, self.volume.spacing())?;
        // the same region keeps its stamp (a focus tissue switch alone redraws nothing twice)
        let stamp = match &self.classes.focus {
            Some((FocusShape::Region(r), _, s)) if *r == region => *s,
            _ => next_focus_stamp(),
        };
        self.classes.focus = Some((FocusShape::Region(region), i, stamp));
        Ok(())
    }

    /// Focus+context in a region given as a producer of focus intervals
    /// (for example a convex mesh's [`crate::geometry::MeshClip`] keeping its
    /// inside, drawn with each frame's camera and set again per frame): as
    /// [`Renderer::set_focus`], the samples each ray's interval
    /// ([`FramePlan::apply_focus`]) holds are classified by tissue preset
    /// `tissue`. The same `Arc` set again keeps the frame's key (nothing is
    /// redrawn for a tissue switch); a limiter that cuts holes (an outside
    /// region) is refused: a focus is one interval per ray.
    pub fn set_focus_limiter(&mut self, limiter: std::sync::Arc<dyn Limiter>, tissue: &str) -> Result<()> {
        let i = self.focus_tissue_index(tissue)?;
        if limiter.holes() > 0 {
            return Err(Error::value("focus", "a focus region is one interval per ray: a limiter keeping an outside is not one"));
        }
        let stamp = match &self.classes.focus {
            Some((FocusShape::Limiter(l), _, s)) if std::sync::Arc::ptr_eq(l, &limiter) => *s,
            _ => next_focus_stamp(),
        };
        self.classes.focus = Some((FocusShape::Limiter(limiter), i, stamp));
        Ok(())
    }

    /// The index of focus tissue `name` in the tissue set (an error without
    /// presets or for a name not among them).
    fn focus_tissue_index(&self, name: &str) -> Result<usize> {
        let ts = self.classes.tissues.as_ref().ok_or_else(|| {
            Error::value("focus", "focus+context needs a renderer with tissue presets (not a custom iso value or transfer function)")
        })?;
        ts.tissues.iter().position(|t| t.name == name).ok_or_else(|| {
            let names: Vec<&str> = ts.tissues.iter().map(|t| t.name).collect();
            Error::value("focus tissue", format!("'{name}' is not in this renderer's presets ({})", names.join(", ")))
        })
    }

    /// The focus region and the name of its tissue preset, if any (`None`
    /// too for a focus set by [`Renderer::set_focus_limiter`]).
    pub fn focus(&self) -> Option<Focus> {
        let (FocusShape::Region(r), i, _) = self.classes.focus.as_ref()? else { return None };
        let ts = self.classes.tissues.as_ref()?;
        Some(Focus { region: r.region(), tissue: ts.tissues.get(*i)?.name.to_string() })
    }

    /// The focus tissue's index in the tissue set (when both exist).
    fn focus_tissue(&self) -> Option<usize> {
        self.classes.focus.as_ref().filter(|_| self.classes.tissues.is_some()).map(|f| f.1)
    }

    /// The intermediate image of the last frame.
    pub fn intermediate(&self) -> &Intermediate {
        &self.inter
    }
    /// The factorization of the last frame.
    pub fn last_factorization(&self) -> Option<&Factorization> {
        self.last_plan().map(|p| &p.view)
    }
    /// The frame plan of the last frame (of a frame split into pyramids, the
    /// plan of the pyramid owning the image centre, if any).
    pub fn last_plan(&self) -> Option<&FramePlan> {
        if self.pyramids.last_split { self.pyramids.plans[..self.pyramids.count].first() } else { self.frame.plan.as_ref() }
    }

    /// The frame plans of the last frame: one, or one per pyramid of a split
    /// perspective frame (the pyramid owning the image centre first).
    pub fn last_plans(&self) -> &[FramePlan] {
        if self.pyramids.last_split { &self.pyramids.plans[..self.pyramids.count] } else { self.frame.plan.as_slice() }
    }

    /// Keeps (`on`) the intermediate iso depth of every pyramid of a split
    /// perspective frame after it is warped (a copy of the depth plane per
    /// pyramid, iso mode only), for [`Renderer::last_depth_at`]: the
    /// volume's hit under an output pixel of any frame
    /// ([`crate::geometry::volume_hit`]). Off by default (a frame that is not
    /// split reads the intermediate image itself and costs nothing either way).
    pub fn set_keep_depths(&mut self, on: bool) {
        self.pyramids.keep_depths = on;
    }

    /// The index in [`Renderer::last_plans`] of the plan whose image holds
    /// output pixel `(u, v)` of the last frame: the one plan, or the pyramid
    /// that owns the pixel's ray ([`crate::view::perspective::ray_owner`]) in a
    /// split frame (`None`: no plan, or no pyramid of the frame owns it).
    pub fn last_owner(&self, u: f64, v: f64) -> Option<usize> {
        let plans = self.last_plans();
        match (self.pyramids.last_split, &self.pyramids.last_rays) {
            (true, Some(rays)) => {
                let owner = rays.owner(u, v);
                plans.iter().position(|p| (p.view.axis, p.view.ascending) == owner)
            }
            (true, None) => None,
            (false, _) => (!plans.is_empty()).then_some(0),
        }
    }

    /// The output pixels' rays of the last frame if it was split into
    /// pyramids (which pyramid owns a pixel: [`Renderer::last_owner`]).
    pub fn last_rays(&self) -> Option<RayDirections> {
        self.pyramids.last_rays.filter(|_| self.pyramids.last_split)
    }

    /// The image whose depth plane [`Renderer::last_depth_at`] reads for plan
    /// `i` (only its `size`, `valid` and `depth`), if any.
    pub(crate) fn last_depth_image(&self, i: usize) -> Option<&Intermediate> {
        if self.pyramids.last_split { self.pyramids.depths.get(i) } else { Some(&self.inter) }
    }

    /// The iso depth (fractional slice index, NaN where none) at intermediate
    /// pixel `(p, q)` of plan `i` of [`Renderer::last_plans`]: the
    /// intermediate image's own for a frame that is not split, the kept copy
    /// for a pyramid of a split one (NaN unless [`Renderer::set_keep_depths`]
    /// was on for that frame), NaN when the image does not match the plan.
    pub fn last_depth_at(&self, i: usize, p: usize, q: usize) -> f32 {
        let Some(plan) = self.last_plans().get(i) else { return f32::NAN };
        match self.last_depth_image(i) {
            Some(d) if d.holds_depths_of(plan.grid.size) => d.depth_at(p, q),
            _ => f32::NAN,
        }
    }

    /// Runs `f` on the renderer's thread pool (where its frames' limiters
    /// run: to time one as a frame does).
    pub fn install<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        self.pool.install(f)
    }

    /// Runs limiter `l` on `plan` as a frame does: on the renderer's thread
    /// pool when it asks for it ([`Limiter::parallel`]), else on this thread.
    pub fn run_limiter(&self, l: &dyn Limiter, plan: &FramePlan, limits: &mut RayLimits) {
        self.install_if(l.parallel(plan), || l.limit(plan, limits));
    }

    /// Runs `f` on the renderer's thread pool if `on`, else on this thread.
    fn install_if<R: Send>(&self, on: bool, f: impl FnOnce() -> R + Send) -> R {
        if on { self.pool.install(f) } else { f() }
    }

    /// Bytes of the packed masks that exist now.
    pub fn mask_bytes(&self) -> usize {
        self.axes.masks.iter().flatten().map(|m| m.mask.bytes()).sum()
    }

    /// Bytes of the run-length encodings that exist now, per axis.
    pub fn rle_axis_bytes(&self) -> [usize; 3] {
        self.axes.rle.bytes()
    }

    /// Bytes of the run-length encodings that exist now.
    pub fn rle_bytes(&self) -> usize {
        self.axes.rle.bytes().iter().sum()
    }

    /// The pre-classified state (classification and encodings) of the RLE paths.
    pub fn rle_cache(&self) -> &RleCache {
        &self.axes.rle
    }

    /// How long the last build of each structure took, per axis.
    pub fn build_times(&self) -> BuildTimes {
        self.axes.build_times
    }

    /// Bytes held now, per structure and axis.
    pub fn memory(&self) -> Memory {
        let per = |f: &dyn Fn(usize) -> usize| [0, 1, 2].map(|a| f(a) as u64);
        Memory {
            volume: self.volume.bytes(),
            stacks: per(&|a| {
                self.axes.stacks[a].as_ref().map_or(0, SliceStack::bytes) + self.axes.bcc[a].as_ref().map_or(0, BccStack::bytes)
            }),
            normals: per(&|a| self.axes.normals[a].as_ref().map_or(0, NormalStack::bytes)),
            cell_codes: per(&|a| self.axes.codes[a].as_ref().map_or(0, |c| c.1.bytes())),
            masks: per(&|a| {
                self.axes.masks[a].as_ref().map_or(0, |m| match &m.mask {
                    AnyMask::W32(m) => m.held_bytes(),
                    AnyMask::W64(m) => m.held_bytes(),
                })
            }),
            rle: self.axes.rle.bytes().map(|b| b as u64),
            intermediate: self.inter.bytes() as u64,
        }
    }

    /// Limits what the renderer may hold ([`Renderer::memory`]'s total): before
    /// it builds the structures a view needs, it predicts their size
    /// ([`estimate_axis`]); when they would not fit it first frees the other
    /// axes' structures (rebuilt when a view needs them again), and when they
    /// still would not fit the frame fails with [`Error::Memory`], before
    /// anything is allocated. `None` (the default) sets no limit.
    pub fn set_memory_budget(&mut self, budget: Option<u64>) {
        self.axes.budget = budget;
    }

    /// The memory budget, if any.
    pub fn memory_budget(&self) -> Option<u64> {
        self.axes.budget
    }

    /// The code width of the current classification's mask.
    fn code_bits(&self) -> u32 {
        self.classes.tissues.as_ref().and_then(|t| crate::encode::depth::code_width_for(t.thresholds.len())).unwrap_or(1)
    }

    /// The bytes `ensure_axis(axis)` would allocate now (structures that exist
    /// and are current count 0), and the intermediate image's growth.
    fn missing_bytes(&self, axis: usize) -> Memory {
        let mut m = estimate_axis(&self.volume, &self.settings, self.code_bits(), axis);
        if self.axes.stacks[axis].as_ref().is_some_and(|s| s.is_resident() && s.perm() == self.axis_perm(axis))
            && self.settings.lattice == Lattice::Cartesian
        {
            m.stacks[axis] = 0;
        }
        if self.axes.bcc[axis].is_some() && self.settings.lattice == Lattice::Bcc {
            m.stacks[axis] = 0;
        }
        if self.axes.normals[axis].is_some() {
            m.normals[axis] = 0;
        }
        if self.axes.masks[axis].as_ref().map(|m| m.key) == Some(self.mask_key()) {
            m.masks[axis] = 0;
            m.cell_codes[axis] = 0;
        }
        m.volume = 0;
        m.intermediate = m.intermediate.saturating_sub(self.inter.bytes() as u64);
        m
    }

    /// Frees every structure of principal axis `axis` (first giving the volume
    /// its voxels back if they were let go).
    fn drop_axis(&mut self, axis: usize) -> Result<()> {
        if self.axes.normals[axis].is_some() {
            self.unpark()?;
        }
        self.axes.stacks[axis] = None;
        self.axes.bcc[axis] = None;
        self.axes.normals[axis] = None;
        self.axes.codes[axis] = None;
        self.axes.masks[axis] = None;
        self.axes.rle.drop_axis(axis);
        Ok(())
    }

    /// True when building `axis` now fits the budget beside everything held
    /// (less the volume, when the build lets go of it). The build allocates
    /// the cell array while the volume is still held, but touches only its
    /// last third (one byte a voxel of an 8-bit scan) before the volume goes,
    /// so what is resident stays below the total counted here; under a
    /// virtual-memory limit (`ulimit -v`) the allocation itself may be refused,
    /// which is [`Error::Memory`], never an abort.
    fn fits_budget(&self, axis: usize) -> bool {
        let needed = self.missing_bytes(axis).total();
        needed == 0 || self.axes.budget.is_none_or(|b| (self.memory().total() + needed).saturating_sub(self.releasable(axis)) <= b)
    }

    /// The bytes of volume that building `axis` lets go of: all of it when the
    /// compact binary path builds packed cells while the volume is resident
    /// and nothing outside this renderer shares the voxels.
    fn releasable(&self, axis: usize) -> u64 {
        let building = compact_binary(&self.volume, &self.settings) && self.axes.normals[axis].is_none();
        if building && self.can_let_go() { self.volume.bytes() } else { 0 }
    }

    /// Checks the budget for building `axis` now; frees the other axes first
    /// if that makes it fit.
    fn fit_budget(&mut self, axis: usize) -> Result<()> {
        let Some(budget) = self.axes.budget else { return Ok(()) };
        if self.fits_budget(axis) {
            return Ok(());
        }
        for a in (0..3).filter(|&a| a != axis) {
            self.drop_axis(a)?;
        }
        if !self.fits_budget(axis) {
            let (needed, held) = (self.missing_bytes(axis).total(), self.memory().total());
            let d = self.volume.dims();
            return Err(Error::Memory {
                what: format!(
                    "rendering the {}×{}×{} volume along {} ({})",
                    d[0],
                    d[1],
                    d[2],
                    ["x", "y", "z"][axis],
                    self.settings.method.name()
                ),
                needed,
                held,
                budget,
            });
        }
        Ok(())
    }

    /// The object axes `(i, j, k)` of principal axis `axis` this renderer's
    /// frames use: the cyclic [`crate::view::permutation`], or with
    /// [`Settings::rle_reuse`] on an RLE path under a parallel projection
    /// [`crate::view::reuse_permutation`] (z mirrored to share x's scanlines).
    fn axis_perm(&self, axis: usize) -> [usize; 3] {
        let rle = self.settings.method.is_rle();
        if self.settings.rle_reuse && rle && !self.frame.projection.is_perspective() {
            crate::view::reuse_permutation(axis)
        } else {
            crate::view::permutation(axis)
        }
    }

    /// What the pre-classified state depends on: classification generation,
    /// tissue, mode and the sampler (pre- or post-classified, Deluxe P).
    fn rle_key(&self) -> ClassKey {
        let tissue = self.classes.tissues.as_ref().map_or(0, |t| t.current as u64 + 1);
        // (a pre-classified encoding holds the voxels the focus tissue shows too)
        let focus = self.focus_tissue().map_or(0, |f| f as u64 + 1);
        self.rle_enc_key() | (tissue << 2) | (focus << 12)
    }

    /// What a post-classified encoding depends on (the key without the
    /// tissue: it keeps the cells every tissue preset may show), and the lattice.
    fn rle_enc_key(&self) -> ClassKey {
        let bcc = (self.settings.lattice == Lattice::Bcc) as u64;
        (self.classes.generation << 20)
            | (bcc << 9)
            | ((self.settings.deluxe.post as u64) << 1)
            | (self.settings.mode == Mode::Blend) as u64
    }

    /// The classifier the pre-classified paths encode: the current mode's, with
    /// a custom iso value as a threshold transfer function in the iso colour.
    fn preclass_classifier(&self) -> std::borrow::Cow<'_, Classifier> {
        match (&self.classes.tissues, self.settings.mode) {
            (None, Mode::Iso) => {
                let c = self.classes.classifier.classify(self.classes.iso);
                let tf = TransferFunction::threshold(self.classes.iso, [c.r, c.g, c.b]);
                std::borrow::Cow::Owned(Classifier::new(&tf, self.range.0, self.range.1))
            }
            _ => std::borrow::Cow::Borrowed(self.classifier()),
        }
    }

    fn mask_key(&self) -> MaskKey {
        MaskKey {
            mode: if self.classes.tissues.is_some() { None } else { Some(self.settings.mode) },
            word: self.settings.word,
            cell: self.settings.cell,
            generation: self.classes.generation,
            half: self.settings.deluxe.intermediate,
        }
    }

    /// Fails when the intermediate image or (binary path) the sheared mask of
    /// principal axis `axis` would exceed [`MAX_INTERMEDIATE_PIXELS`] or
    /// [`MAX_MASK_BYTES`] — very elongated volumes (e.g. 16384×4×4 seen along its
    /// long axis), whose padding for shears up to 45° dwarfs the data. Without
    /// this the allocation fails and aborts the process.
    fn check_axis_size(&self, axis: usize) -> Result<()> {
        let dims = self.volume.dims();
        let p = crate::view::permutation(axis);
        let n = [dims[p[0]], dims[p[1]], dims[p[2]]];
        let cells = [n[0].saturating_sub(1), n[1].saturating_sub(1)];
        let Grid { size: grid, .. } = Grid::parallel(cells, n[2]);
        let too_big = |what: String| {
            Err(Error::value(
                "volume shape",
                format!(
                    "{}×{}×{} seen along {}: {what}; the volume is too elongated for shear-warp along this axis",
                    dims[0],
                    dims[1],
                    dims[2],
                    ["x", "y", "z"][axis]
                ),
            ))
        };
        let px = grid[0] as u64 * grid[1] as u64;
        if px > MAX_INTERMEDIATE_PIXELS {
            return too_big(format!("the intermediate image would need {}×{} pixels (limit {MAX_INTERMEDIATE_PIXELS})", grid[0], grid[1]));
        }
        if self.settings.method.uses_mask() {
            // an upper bound of what BinaryMask::from_codes allocates
            let bytes = estimate_axis(&self.volume, &self.settings, self.code_bits(), axis).masks[axis];
            if bytes > MAX_MASK_BYTES {
                return too_big(format!("its sheared mask would need {bytes} bytes (limit {MAX_MASK_BYTES})"));
            }
        }
        Ok(())
    }

    /// Makes sure the slice stack (and, for the binary path, the mask) of `axis`
    /// exist and are current. Returns the milliseconds spent building.
    fn ensure_axis(&mut self, axis: usize) -> Result<f64> {
        self.check_axis_size(axis)?;
        self.fit_budget(axis)?;
        let t = Instant::now();
        let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
        if self.settings.lattice == Lattice::Bcc {
            // the RLE paths on the BCC grid (check_deluxe allows no other):
            // the interleaved slices, their classification and encoding
            if self.axes.bcc[axis].is_none() {
                let t = Instant::now();
                self.unpark()?;
                let vol = &self.volume;
                self.axes.bcc[axis] = Some(self.pool.install(|| BccStack::try_new(vol, axis))?);
                self.axes.build_times.stacks[axis] = ms(t);
            }
            self.ensure_rle(axis, true);
            return Ok(t.elapsed().as_secs_f64() * 1e3);
        }
        if self.axes.bcc.iter().any(Option::is_some) {
            self.axes.bcc = [None, None, None];
        }
        let compact = compact_binary(&self.volume, &self.settings);
        let raycast = self.settings.method.is_raycast();
        if compact && self.axes.normals[axis].is_none() {
            // the densities and codes packed in 3 (8-bit) or 4 bytes a voxel,
            // no f32 stack, and the volume let go once the cells hold its voxels
            let t = Instant::now();
            let threads = self.pool.current_num_threads();
            let vol = &self.volume;
            let src = match self.axes.normals.iter().flatten().find(|n| n.holds_voxels()) {
                // the volume was let go: re-lay another axis's cells
                Some(ns) if vol.is_parked() => CellSource::Cells(ns),
                _ => CellSource::Volume(vol),
            };
            let build =
                self.pool.install(|| NormalStack::try_cells(src, axis, threads))?.ok_or_else(|| missing("the packed cells", axis))?;
            if self.axes.stacks[axis].is_none() {
                self.axes.stacks[axis] = Some(SliceStack::shell(vol, axis));
            }
            // the build holds the voxels now: the volume can go before the codes are computed
            self.park(true);
            let spacing = self.volume.spacing();
            self.axes.normals[axis] = Some(self.pool.install(|| build.finish(spacing)));
            self.axes.build_times.normals[axis] = ms(t);
        }
        let perm = self.axis_perm(axis);
        if !compact && self.axes.stacks[axis].as_ref().is_none_or(|s| !s.is_resident() || s.perm() != perm) {
            let t = Instant::now();
            self.unpark()?;
            let vol = &self.volume;
            self.axes.stacks[axis] = Some(self.pool.install(|| SliceStack::try_permuted(vol, perm))?);
            self.axes.build_times.stacks[axis] = ms(t);
        }
        if raycast && self.settings.normals == Normals::Codes && self.axes.normals[axis].is_none() {
            let t = Instant::now();
            let (stack, spacing, pack) =
                (self.axes.stacks[axis].as_ref().expect("stack built above"), self.volume.spacing(), self.settings.pack);
            self.axes.normals[axis] = Some(self.pool.install(|| NormalStack::try_with_packing(stack, spacing, pack))?);
            self.axes.build_times.normals[axis] = ms(t);
        }
        if self.settings.method.uses_mask() {
            let key = self.mask_key();
            if self.axes.masks[axis].as_ref().map(|m| m.key) != Some(key) {
                // the densities come from the resident stack, or from the packed cells
                let stack: &dyn Densities = match (&self.axes.stacks[axis], &self.axes.normals[axis]) {
                    (Some(s), _) if s.is_resident() => s,
                    (_, Some(ns)) => ns,
                    _ => return Err(missing("the densities", axis)),
                };
                // cell codes depend only on the classification (and Deluxe I's
                // dilation); cell size and word size reuse them
                let codes_key = key.generation * 4 + key.mode.map_or(0, |m| (m == Mode::Blend) as u64) * 2 + key.half as u64;
                if self.axes.codes[axis].as_ref().map(|c| c.0) != Some(codes_key) {
                    let t = Instant::now();
                    let half = key.half;
                    let codes = self.pool.install(|| match (&self.classes.tissues, self.settings.mode) {
                        (Some(ts), _) if half => {
                            CellCodes::thresholds_half(stack, &ts.thresholds).expect("thresholds validated in with_tissues")
                        }
                        (Some(ts), _) => CellCodes::thresholds(stack, &ts.thresholds).expect("thresholds validated in with_tissues"),
                        (None, Mode::Iso) => {
                            let iso = self.classes.iso;
                            if half {
                                CellCodes::binary_half(stack, |_, hi| hi >= iso)
                            } else {
                                CellCodes::binary(stack, |_, hi| hi >= iso)
                            }
                        }
                        (None, Mode::Blend) => {
                            let cls = &self.classes.classifier;
                            let visible = |lo, hi| cls.may_be_visible(lo, hi);
                            if half { CellCodes::binary_half(stack, visible) } else { CellCodes::binary(stack, visible) }
                        }
                    });
                    self.axes.codes[axis] = Some((codes_key, codes));
                    self.axes.build_times.cell_codes[axis] = ms(t);
                }
                let t = Instant::now();
                let codes = &self.axes.codes[axis].as_ref().expect("built above").1;
                let mask = self.pool.install(|| match key.word {
                    WordSize::U32 => AnyMask::W32(BinaryMask::from_codes(codes, key.cell)),
                    WordSize::U64 => AnyMask::W64(BinaryMask::from_codes(codes, key.cell)),
                });
                self.axes.masks[axis] = Some(AxisMask { key, mask });
                self.axes.build_times.masks[axis] = ms(t);
            }
            // the mask carries the settings' CPU level to its shear kernels and to
            // the ray loop's bit scan (`render_binary`); a mask outlives a settings change
            if let Some(m) = self.axes.masks[axis].as_mut() {
                m.mask.set_cpu_level(self.settings.cpu);
            }
        }
        if self.settings.method.is_rle() {
            self.ensure_rle(axis, false);
        }
        Ok(t.elapsed().as_secs_f64() * 1e3)
    }

    /// The pre-classified state of `axis`: the classification, and (for
    /// [`Method::Rle`]) the encoding of the axis's slices — the cartesian
    /// stack, or the interleaved BCC slices when `bcc` (the classification
    /// key tells the two apart).
    fn ensure_rle(&mut self, axis: usize, bcc: bool) {
        let key = self.rle_key();
        if !self.axes.rle.is_for(key) {
            let cls = self.preclass_classifier().into_owned();
            if self.settings.deluxe.post {
                // the encoding keeps the cells any tissue preset of the mode may show
                let visible: Vec<&Classifier> = match (&self.classes.tissues, self.settings.mode) {
                    (Some(ts), Mode::Iso) => ts.iso_cls.iter().collect(),
                    (Some(ts), Mode::Blend) => ts.blend_cls.iter().collect(),
                    (None, _) => vec![&cls],
                };
                self.axes.rle.reset_post(key, self.rle_enc_key(), &cls, &visible, self.volume.spacing());
            } else {
                self.axes.rle.reset(key, &cls, self.volume.spacing());
            }
            // focus+context: the focus tissue's classification of the mode
            let focus = match (&self.classes.tissues, self.focus_tissue(), self.settings.mode) {
                (Some(ts), Some(f), Mode::Iso) => Some(&ts.iso_cls[f]),
                (Some(ts), Some(f), Mode::Blend) => Some(&ts.blend_cls[f]),
                _ => None,
            };
            self.axes.rle.set_focus(focus, self.volume.spacing());
        }
        if self.settings.method.encodes_runs() {
            // (an encoding, or a pointer table over another axis's: see RleCache::ensure_axis)
            let t = Instant::now();
            let rle = &mut self.axes.rle;
            // (asked first: a frame whose encoding is current sends no job to the pool)
            let built = if bcc {
                let src = self.axes.bcc[axis].as_ref().expect("BCC slices built above");
                !rle.is_current(src) && self.pool.install(|| rle.ensure_axis(src))
            } else {
                let stack = self.axes.stacks[axis].as_ref().expect("stack built above");
                !rle.is_current(stack) && self.pool.install(|| rle.ensure_axis(stack))
            };
            if built {
                self.axes.build_times.rle[axis] = t.elapsed().as_secs_f64() * 1e3;
            }
        }
    }

    /// Builds the stack and mask of every axis now (so frames measure only shear,
    /// render and warp). Returns the milliseconds spent. An axis beyond the
    /// memory limits is skipped; a frame that needs it returns the error.
    pub fn prepare_all_axes(&mut self) -> f64 {
        (0..3).map(|a| self.ensure_axis(a).unwrap_or(0.0)).sum()
    }

    /// Builds the stack and mask of principal axis `axis` (0..3) now if they are
    /// missing or stale, so a later view along it does not pay for it. Returns the
    /// milliseconds spent (0 when current), or the error when the axis is beyond
    /// the memory limits.
    pub fn prepare_axis(&mut self, axis: usize) -> Result<f64> {
        self.ensure_axis(axis.min(2))
    }

    /// Builds principal axis `axis` ahead of need, but only if it fits the
    /// memory budget beside everything held now: unlike [`Renderer::prepare_axis`]
    /// it never frees another axis to make room (a prefetch that evicted the
    /// axis on screen would make the next frame rebuild it). Returns whether
    /// the axis is built now.
    pub fn prefetch_axis(&mut self, axis: usize) -> Result<bool> {
        let axis = axis.min(2);
        if !self.fits_budget(axis) {
            return Ok(false);
        }
        self.ensure_axis(axis).map(|_| true)
    }

    /// Renders one frame of `camera` into `out` (resized if needed).
    ///
    /// When the camera, settings and classification are those of the frame this
    /// renderer last wrote into this same `out`, nothing is rendered and the stats
    /// say `skipped` (the image's pixels are assumed untouched since).
    ///
    /// `out` is a [`crate::warp::Image`] (f32) or a [`crate::warp::Image8`]
    /// (the same pixels rounded to 8 bits, as a display wants them).
    pub fn render<C: Target>(&mut self, camera: &Camera, out: &mut C) -> Result<FrameStats> {
        C::render_frame(self, camera, out)
    }

    /// [`Renderer::render`] for one texel type: instantiated in this crate for
    /// the two [`Target`]s only.
    fn render_texel<T: Texel>(&mut self, camera: &Camera, out: &mut Canvas<T>) -> Result<FrameStats> {
        let key = FrameKey {
            camera: *camera,
            projection: self.frame.projection,
            quality: self.frame.quality,
            settings: self.settings,
            generation: self.classes.generation,
            tissue: self.classes.tissues.as_ref().map(|t| t.current),
            limiter: self.frame.limiter.as_ref().map(|l| l.1),
            focus: self.classes.focus.as_ref().map(|f| (f.2, f.1)),
        };
        if let Some((k, stamp)) = self.frame.last_frame
            && k == key
            && out.stamp == stamp
            && out.width == camera.size[0]
            && out.height == camera.size[1]
        {
            return Ok(FrameStats { skipped: true, axis: self.last_plan().map_or(0, |p| p.view.axis), ..Default::default() });
        }
        let (dims, spacing) = (self.volume.dims(), self.volume.spacing());
        let bcc = self.settings.lattice == Lattice::Bcc;
        if bcc && self.frame.projection.is_perspective() {
            return Err(Error::value("settings", "the BCC grid (--grid bcc) renders parallel projections only"));
        }
        if bcc && self.frame.limiter.is_some() {
            return Err(Error::value("settings", "the BCC grid (--grid bcc) does not take clip regions or geometry"));
        }
        if self.classes.focus.is_some() {
            self.check_focus()?;
        }
        // a perspective frame: the camera scaled by its field of view, and its views
        let persp = match self.frame.projection.resolve(camera, dims, spacing)? {
            None => None,
            Some((cam, distance)) => {
                // (the views' buffer is kept across frames: no allocation per frame)
                let mut views = std::mem::take(&mut self.frame.views);
                let made = PerspectiveView::frame_into(&cam, distance, dims, spacing, NEAR_SLICES, &mut views);
                if made.is_ok() && (views.len() != 1 || views[0].window.is_some()) {
                    // the eye near or inside the volume: Lacroute's pyramid split
                    let stats = self.render_pyramids(camera, &cam, distance, &views, out);
                    self.frame.views = views;
                    return Ok(self.finish_frame(key, out, stats?));
                }
                let one = views.pop();
                self.frame.views = views;
                made?;
                Some((cam, one.expect("one view")))
            }
        };
        let perms = [0, 1, 2].map(|a| self.axis_perm(a));
        let f = Factorization::with_permutations(persp.as_ref().map_or(camera, |p| &p.0), dims, spacing, perms)?;
        if let Some((_, pv)) = &persp {
            // the eye lies on the view axis: same principal axis, same slice order
            if (pv.axis, pv.ascending) != (f.axis, f.ascending) {
                return Err(Error::Other("internal: the perspective and parallel factorizations disagree on the principal axis".into()));
            }
        }
        let mut stats = FrameStats { axis: f.axis, ..Default::default() };
        stats.build_ms = self.ensure_axis(f.axis)?;
        // the frame plan, from the projection's producer
        let mut plan = self.frame.plan.take().unwrap_or_else(|| FramePlan::parallel(&f, spacing));
        let limits = plan.take_limits();
        let focus = plan.take_focus();
        match &persp {
            // the BCC grid: the interleaved slices' factorization (the opacity
            // ratio relative to the volume's own spacing), sub-grid B's slices
            // half a cell off A's, whose samples the sheared grid meets
            None if bcc => {
                let lattice = BccLattice::new(dims)?;
                plan.set_parallel(&lattice.factorization(camera, spacing, f.axis, f.zoom)?, spacing);
                plan.offset_slices(BccLattice::slice_offset);
                plan.shift_sheared(BccLattice::SHEARED_SHIFT);
            }
            None => plan.set_parallel(&f, spacing),
            Some((_, pv)) => plan.set_perspective(pv, &f, spacing, NEAR_SLICES),
        }
        if let Err(e) = self.finish_plan(&mut plan, limits, focus) {
            self.frame.plan = Some(plan);
            return Err(e);
        }
        self.pyramids.last_split = false;
        let result = self.composite_plan(&plan, &mut stats, |inter: &Intermediate| {
            out.prepare(camera.size[0], camera.size[1]);
            warp(inter, &plan, out);
        });
        self.frame.plan = Some(plan);
        result?;
        Ok(self.finish_frame(key, out, stats))
    }

    /// What every plan takes after its projection's producer made it (one
    /// place for the plain frame and each pyramid of a split one): each ray's
    /// opacity correction in blend mode (iso opacities are 0 or 1: never
    /// corrected), the intermediate image's pitch (the same rays resampled:
    /// the adaptive image size of `--quality`, and Deluxe M's matched
    /// sampling), the footprint of minified slices, and the limiter's ray
    /// limits (on the renderer's pool: a limiter may work in parallel), into
    /// `limits`, the buffer the plan held before.
    ///
    /// Deluxe M sets `ns = max(ns_a, ns_b)` samples per voxel along both axes
    /// ([`FramePlan::matched_samples`]: from the warp's magnification; a
    /// perspective plan's largest, at its base plane, the front slice): the
    /// grid is isotropic (one pitch; [`Grid::pitch`] is read by the clip
    /// regions, the reference and the RLE traversal as a scalar), so an
    /// anisotropic warp takes `ns²` rather than `ns_a·ns_b` samples a voxel
    /// square. With `--quality` the finer pitch wins: M never samples coarser
    /// than matched, a quality above it still refines. A grid past
    /// [`MAX_INTERMEDIATE_PIXELS`] is an error naming it.
    fn finish_plan(&self, plan: &mut FramePlan, limits: Option<RayLimits>, focus: Option<RayLimits>) -> Result<()> {
        plan.set_ray_opacity(self.settings.mode == Mode::Blend);
        let mut pitch = 1.0 / self.frame.quality;
        if self.settings.deluxe.matched {
            let ns = plan.matched_samples();
            pitch = pitch.min(1.0 / ns[0].max(ns[1]) as f64);
        }
        if pitch != 1.0 {
            plan.set_pitch(pitch);
        }
        let [w, h] = plan.grid.size;
        if w as u64 * h as u64 > MAX_INTERMEDIATE_PIXELS {
            return Err(Error::value(
                "intermediate image",
                format!(
                    "{w}×{h} pixels at {:.3} samples per voxel (limit {MAX_INTERMEDIATE_PIXELS}): lower the zoom, --quality or matched sampling (Deluxe M)",
                    1.0 / pitch
                ),
            ));
        }
        plan.set_box_footprint(self.settings.footprint == Footprint::Box);
        plan.set_intermediate(self.settings.deluxe.intermediate);
        if let Some((l, _)) = &self.frame.limiter {
            self.install_if(l.parallel(plan), || plan.apply_limiter(l.as_ref(), limits.unwrap_or_default()));
        }
        // focus+context: each ray's slices inside the focus region (the clip
        // region's analytic interval, checked on the samples)
        if let Some((shape, _, _)) = &self.classes.focus {
            self.pool.install(|| plan.apply_focus(shape.limiter(), focus.unwrap_or_default()));
        }
        Ok(())
    }

    /// The settings focus+context renders (an error names what it does not).
    fn check_focus(&self) -> Result<()> {
        let refuse = |what: &str| Err(Error::value("focus", format!("focus+context is not available with {what}")));
        if self.classes.tissues.is_none() {
            return refuse("a custom iso value or transfer function (it needs the tissue presets)");
        }
        if self.settings.lattice == Lattice::Bcc {
            return refuse("the BCC grid (--grid bcc)");
        }
        Ok(())
    }

    /// Stamps `out` as this frame's image (see [`Renderer::render`]'s skip).
    fn finish_frame<T: Texel>(&mut self, key: FrameKey, out: &mut Canvas<T>, stats: FrameStats) -> FrameStats {
        let stamp = NEXT_STAMP.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        out.stamp = stamp;
        self.frame.last_frame = Some((key, stamp));
        stats
    }

    /// A perspective frame split into Lacroute's pyramids (`views`, from
    /// [`PerspectiveView::frame`]; `cam` is `camera` with the perspective
    /// zoom, the eye `distance` world units from the volume centre). The
    /// image is cleared, then each pyramid in turn gets its plan (its own
    /// axis, slices and window), is composited by the one per-plan function
    /// every frame uses ([`Renderer::composite_plan`]) and warped into its own
    /// output pixels only ([`warp_owned`]). No pyramid: an empty image.
    fn render_pyramids<T: Texel>(
        &mut self,
        camera: &Camera,
        cam: &Camera,
        distance: f64,
        views: &[PerspectiveView],
        out: &mut Canvas<T>,
    ) -> Result<FrameStats> {
        let (dims, spacing) = (self.volume.dims(), self.volume.spacing());
        let rays = PerspectiveView::ray_directions(cam, distance, dims, spacing)?;
        let mut stats = FrameStats { axis: views.first().map_or(2, |v| v.axis), ..Default::default() };
        let t = Instant::now();
        clear_for_pyramids(out, camera.size[0], camera.size[1]);
        stats.warp_ms = t.elapsed().as_secs_f64() * 1e3;
        self.pyramids.last_split = true;
        self.pyramids.last_rays = Some(rays);
        self.pyramids.count = 0;
        let mut plans = std::mem::take(&mut self.pyramids.plans);
        // each pyramid's iso depth, kept past the next pyramid's composite (geometry's depth test, the lens)
        let keep = self.pyramids.keep_depths && self.settings.mode == Mode::Iso;
        let mut depths = std::mem::take(&mut self.pyramids.depths);
        if keep && depths.len() < views.len() {
            depths.resize_with(views.len(), Intermediate::default);
        }
        for d in depths.iter_mut() {
            // (a pyramid not kept this frame reads as no hit)
            d.valid = None;
        }
        let mut result = Ok(());
        for (i, pv) in views.iter().enumerate() {
            let step = (|| -> Result<()> {
                let mut f = Factorization::with_axis(cam, dims, spacing, pv.axis)?;
                f.ascending = pv.ascending;
                stats.build_ms += self.ensure_axis(pv.axis)?;
                if plans.len() <= i {
                    plans.push(FramePlan::parallel(&f, spacing));
                }
                let plan = &mut plans[i];
                let limits = plan.take_limits();
                let focus = plan.take_focus();
                plan.set_perspective(pv, &f, spacing, NEAR_SLICES);
                self.finish_plan(plan, limits, focus)?;
                let plan = &plans[i];
                let owned = Owned { rays, pyramid: (pv.axis, pv.ascending) };
                let kept = if keep { depths.get_mut(i) } else { None };
                self.composite_plan(plan, &mut stats, |inter: &Intermediate| {
                    warp_owned(inter, plan, out, &owned);
                    if let Some(k) = kept {
                        k.size = inter.size;
                        k.valid = inter.valid;
                        k.depth.clear();
                        k.depth.extend_from_slice(&inter.depth);
                    }
                })
            })();
            if step.is_err() {
                result = step;
                break;
            }
        }
        // (plans past this frame's pyramids are kept, with their arrays, for later frames)
        self.pyramids.count = views.len().min(plans.len());
        self.pyramids.plans = plans;
        self.pyramids.depths = depths;
        result.map(|_| stats)
    }

    /// Composites one frame plan into the intermediate image by the
    /// renderer's method (its axis's structures must exist: see
    /// [`Renderer::ensure_axis`]), then runs `then_warp` on it (in the same
    /// job on the pool), adding the shear, render and warp times and the
    /// rays to `stats`. The one per-plan step of every frame: a parallel or
    /// one-pyramid frame has one plan, a split perspective frame one per
    /// pyramid.
    fn composite_plan(&mut self, plan: &FramePlan, stats: &mut FrameStats, then_warp: impl FnOnce(&Intermediate) + Send) -> Result<()> {
        let axis = plan.view.axis;
        let mode = self.settings.mode;
        let focus = self.focus_tissue();
        if mode == Mode::Blend {
            match &mut self.classes.tissues {
                Some(ts) => {
                    ts.blend_cls[ts.current].set_sample_ratio(plan.opacity_ratio);
                    if let Some(f) = focus {
                        ts.blend_cls[f].set_sample_ratio(plan.opacity_ratio);
                    }
                }
                None => self.classes.classifier.set_sample_ratio(plan.opacity_ratio),
            }
        }
        // the BCC grid's interleaved slices (RLE paths only), else the cartesian stack
        let bcc = self.axes.bcc[axis].as_ref().filter(|_| self.settings.lattice == Lattice::Bcc);
        let stack = match bcc {
            Some(b) => &b.stack,
            None => self.axes.stacks[axis].as_ref().expect("ensure_axis builds the stack"),
        };
        let (cls, iso, matcher): (&Classifier, f32, &Matcher) = match (&self.classes.tissues, mode) {
            (Some(ts), Mode::Iso) => (&ts.iso_cls[ts.current], ts.thresholds[ts.current], &ts.matchers[ts.current]),
            (Some(ts), Mode::Blend) => (&ts.blend_cls[ts.current], ts.thresholds[ts.current], &ts.matchers[ts.current]),
            (None, _) => (&self.classes.classifier, self.classes.iso, binary_matcher()),
        };
        // focus+context: the focus tissue's classifier and iso value; the walks
        // visit the union of both tissues' codes, the lower threshold's matcher
        // (thresholds ascend, tissue i is "code ≥ i + 1")
        let (focus, matcher): (Option<(&Classifier, f32)>, &Matcher) = match (&self.classes.tissues, focus) {
            (Some(ts), Some(f)) => {
                let fc = if mode == Mode::Iso { &ts.iso_cls[f] } else { &ts.blend_cls[f] };
                (Some((fc, ts.thresholds[f])), &ts.matchers[f.min(ts.current)])
            }
            _ => (None, matcher),
        };
        let settings = self.settings;
        let (inter, masks, rle) = (&mut self.inter, &mut self.axes.masks, &mut self.axes.rle);
        let (normals, shade) = (&self.axes.normals, &mut self.shade);
        // one job on the pool per plan: shear and render run inside it
        let result: Result<()> = self.pool.install(|| {
            let t = Instant::now();
            let rect: Option<Rect> = match settings.method {
                Method::Binary => {
                    let m = masks[axis].as_mut().ok_or_else(|| missing("the sheared mask", axis))?;
                    let w: ShearWork = match &mut m.mask {
                        AnyMask::W32(m) => m.shear_to(&plan.shear),
                        AnyMask::W64(m) => m.shear_to(&plan.shear),
                    };
                    if plan.kind == MapKind::ScaleTranslate {
                        // what the diverging rays' walks skip blocks by (rays
                        // that do not drift read the shear's fractions only)
                        let tables = !Drift::for_plan(plan).is_still();
                        match &mut m.mask {
                            AnyMask::W32(m) => m.update_occupancy(matcher, &plan.shear, tables),
                            AnyMask::W64(m) => m.update_occupancy(matcher, &plan.shear, tables),
                        }
                    }
                    (stats.shear_steps, stats.shear_direct, stats.shear_words) = (w.steps, w.direct, w.words);
                    let scaled = plan.kind == MapKind::ScaleTranslate;
                    let rect = match &m.mask {
                        _ if !settings.occupied_rect => volume_rect(plan, stack.cells()),
                        // the mask's occupied columns are the translated rays'; a
                        // scaled plan's rays meet the occupied cells elsewhere
                        AnyMask::W32(m) if scaled => occupied_scaled_rays(plan, m, stack.cells()),
                        AnyMask::W64(m) if scaled => occupied_scaled_rays(plan, m, stack.cells()),
                        AnyMask::W32(m) => m.occupied_rays(plan.grid.size),
                        AnyMask::W64(m) => m.occupied_rays(plan.grid.size),
                    };
                    stats.shear_ms += t.elapsed().as_secs_f64() * 1e3;
                    let t = Instant::now();
                    inter.prepare(plan.grid.size);
                    let ctx = ray_context(stack, cls, plan, iso, focus, settings, normals[axis].as_ref(), shade);
                    match &m.mask {
                        AnyMask::W32(m) => render_binary(&ctx, m, settings.search, matcher, settings.prefetch, rect, inter),
                        AnyMask::W64(m) => render_binary(&ctx, m, settings.search, matcher, settings.prefetch, rect, inter),
                    }
                    stats.render_ms += t.elapsed().as_secs_f64() * 1e3;
                    rect
                }
                Method::Brute => {
                    let rect = volume_rect(plan, stack.cells());
                    stats.shear_ms += t.elapsed().as_secs_f64() * 1e3;
                    let t = Instant::now();
                    inter.prepare(plan.grid.size);
                    let ctx = ray_context(stack, cls, plan, iso, focus, settings, normals[axis].as_ref(), shade);
                    render_brute(&ctx, rect, inter);
                    stats.render_ms += t.elapsed().as_secs_f64() * 1e3;
                    rect
                }
                Method::Rle | Method::BruteRle => {
                    // the per-view tables, corrected to the plan's sample spacing (half
                    // the slices' with Deluxe I); iso opacities are 0 or 1, so iso needs no correction
                    let ratio = if mode == Mode::Blend { plan.sample_ratio() } else { 1.0 };
                    rle.prepare_view(plan, ratio, settings.shading);
                    let rect = match settings.method {
                        Method::Rle => {
                            rle.axis_for(plan).ok_or_else(|| missing("the run-length encoding", axis))?;
                            rle.rect(plan)
                        }
                        _ => volume_rect_with_mids(plan, stack.cells()),
                    };
                    stats.shear_ms += t.elapsed().as_secs_f64() * 1e3;
                    let t = Instant::now();
                    inter.prepare(plan.grid.size);
                    match (settings.method, bcc) {
                        (Method::Rle, _) => rle.render(plan, settings.ert, rect, inter),
                        (_, Some(b)) => rle.render_brute(b, plan, settings.ert, rect, inter),
                        (_, None) => rle.render_brute(stack, plan, settings.ert, rect, inter),
                    }
                    stats.render_ms += t.elapsed().as_secs_f64() * 1e3;
                    rect
                }
            };
            stats.rays += rect.map_or(0, |r| ((r.p1 - r.p0 + 1) * (r.q1 - r.q0 + 1)) as u64);
            // the warp in the same job (one job sent into the pool per plan)
            let t = Instant::now();
            then_warp(inter);
            stats.warp_ms += t.elapsed().as_secs_f64() * 1e3;
            Ok(())
        });
        result
    }
}

/// The rays' context of a frame of `plan`: the classification, iso value and
/// material, with table shading when the settings ask for it and the normal
/// codes exist (the shade table brought up to date for the view).
#[allow(clippy::too_many_arguments)]
fn ray_context<'a>(
    stack: &'a SliceStack,
    cls: &'a Classifier,
    plan: &'a FramePlan,
    iso: f32,
    focus: Option<(&'a Classifier, f32)>,
    settings: Settings,
    normals: Option<&'a NormalStack>,
    shade: &'a mut ShadeTable,
) -> RayContext<'a> {
    let mut ctx =
        RayContext::new(stack, cls, plan, settings.mode, iso, settings.shading, settings.ert).with_intermediate(plan.intermediate());
    if let Some((fc, fiso)) = focus {
        ctx = ctx.with_focus(fc, fiso);
    }
    match (settings.normals, normals) {
        (Normals::Codes, Some(ns)) => {
            shade.update(headlight_object(&plan.view), settings.shading);
            ctx.with_normals(ns, shade)
        }
        _ => ctx,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::warp::Image;
    use glam::DMat3;

    #[test]
    fn unchanged_frames_are_skipped_and_changes_are_not() {
        let vol = Volume::from_fn([12, 10, 14], [1.0; 3], |x, y, z| ((x + y + z) % 7) as f32 * 30.0).unwrap();
        let tissues = crate::classify::presets::tissues_for(&vol);
        let mut r = Renderer::with_tissues(vol, &tissues, Settings::default()).unwrap();
        let cam = Camera::new(DMat3::from_rotation_y(0.3), [32, 32]);
        let mut img = Image::new(32, 32);
        assert!(!r.render(&cam, &mut img).unwrap().skipped);
        let first = img.clone();
        assert!(r.render(&cam, &mut img).unwrap().skipped);
        assert_eq!(img, first);
        // another image, another camera, another tissue: all render
        let mut other = Image::new(32, 32);
        assert!(!r.render(&cam, &mut other).unwrap().skipped);
        assert!(!r.render(&Camera::new(DMat3::from_rotation_y(0.31), [32, 32]), &mut img).unwrap().skipped);
        r.select_tissue(tissues.len() - 1).unwrap();
        assert!(!r.render(&cam, &mut img).unwrap().skipped);
        assert!(r.render(&cam, &mut img).unwrap().skipped);
        r.set_settings(Settings { mode: Mode::Blend, ..r.settings() }).unwrap();
        assert!(!r.render(&cam, &mut img).unwrap().skipped);
    }
}
