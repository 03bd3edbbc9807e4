//! The renderer: one frame through every stage, from the volume to the image.
//!
//! Owns [`Renderer`], which holds the volume, the classification (one transfer
//! function, or a set of tissue presets sharing one threshold-coded mask), one
//! [`SliceStack`](crate::data::slices::SliceStack), one
//! [`NormalStack`](crate::data::normals::NormalStack) (table shading) and one
//! sheared mask per principal axis (each built only when a
//! view first needs it, and rebuilt only when the classification or cell size
//! changes; with tissue presets, also the current preset's one-bit mask
//! packed from it, which that preset's frames read), the reusable intermediate image and per-slice parameters, and a rayon
//! pool of the requested size. [`Renderer::render`] runs one frame and reports how
//! long each stage took. The output is the same for any thread count: every pixel
//! is computed by exactly one task from the same inputs. The pre-classified paths
//! ([`Method::Rle`], [`Method::BruteRle`]) keep their classification and per-axis
//! run-length encodings in a [`RleCache`](crate::encode::rle::RleCache), encoded lazily like the masks and
//! re-encoded when the classification (transfer function, iso value, tissue or
//! mode) changes.

mod axes;
mod brick;
pub mod checks;
mod classes;
mod frame;
mod paths;
mod pyramids;
mod settings;
mod stats;

pub use axes::estimate_axis;
pub use brick::{BrickFrame, BrickView};
pub use classes::Focus;
pub use settings::{
    Deluxe, Footprint, Lattice, MAX_INTERMEDIATE_PIXELS, MAX_MASK_BYTES, MAX_QUALITY, MIN_QUALITY, Method, NEAR_SLICES, Normals, Settings,
    WordSize,
};
pub use stats::{BuildTimes, FrameStats};

use axes::Axes;
use classes::{Classes, TissueSet};
use frame::{FrameKey, FrameSetup};
use pyramids::Pyramids;
use settings::{build_pool, check_settings};

use crate::classify::presets::Tissue;
use crate::classify::shade_table::ShadeTable;
use crate::classify::{Classifier, TransferFunction};
use crate::composite::Intermediate;
use crate::composite::lean::LeanFrame;
use crate::composite::lean_cubic::LeanCubic;
use crate::data::bcc::BccLattice;
use crate::data::volume::Volume;
use crate::encode::depth::Matcher;
use crate::error::{Error, Result};
use crate::view::plan::FramePlan;
use crate::view::{Camera, Factorization, PerspectiveView};
use crate::warp::{Canvas, Texel, warp};

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
    /// The lean binary iso frames' per-slice tables (linear and cubic, kept
    /// across frames), and whether the frames they cover take them.
    lean: LeanFrame,
    lean_cubic: LeanCubic,
    lean_on: bool,
    /// Whether frames of a tissue preset read its own one-bit mask when it
    /// is built ([`Renderer::set_preset_masks`]).
    preset_masks: bool,
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
            lean: LeanFrame::default(),
            lean_cubic: LeanCubic::default(),
            lean_on: true,
            preset_masks: true,
            inter: Intermediate::default(),
            pool,
        })
    }

    /// A renderer that switches between `tissues` (1..=15 presets with distinct
    /// lower thresholds) in O(1): one mask of adaptive threshold codes serves
    /// them all, so a switch changes a table, never the mask. The current
    /// preset's frames read its own one-bit mask, packed from the code mask
    /// when that is built and by [`Renderer::prefetch_axis`] after a switch
    /// (the same image from a code width's fraction of the words;
    /// [`Renderer::set_preset_masks`]). Starts at tissue 0.
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

    /// Whether the binary frames the lean paths cover take them
    /// ([`crate::composite::lean`], [`crate::composite::lean_cubic`]; `true`,
    /// the default) or the general ray
    /// loop (`false`): the same image either way, a knob for comparisons.
    pub fn set_lean_frame(&mut self, on: bool) {
        self.lean_on = on;
    }

    /// Whether a tissue preset's frames read its own one-bit mask, packed
    /// from the presets' threshold-coded mask when that is built and by
    /// [`Renderer::prefetch_axis`] after a switch (`true`, the default), or
    /// always the threshold-coded mask (`false`): the same image either way,
    /// a knob for comparisons. Off, the one-bit masks are freed.
    pub fn set_preset_masks(&mut self, on: bool) {
        self.preset_masks = on;
        if !on {
            self.axes.preset = [None, None, None];
        }
    }

    /// Current settings.
    pub fn settings(&self) -> Settings {
        self.settings
    }

    /// The cell size a rotation of this volume takes by default
    /// ([`crate::encode::mask::auto_cell`]): for its longest axis, the current
    /// classification's code width (one bit, or two or four for tissue
    /// presets) and the settings' word size. Every cell size renders the same
    /// image; this one balances the shear's memory traffic against the
    /// render's false candidates.
    pub fn auto_cell(&self) -> usize {
        let nk = self.volume.dims().into_iter().max().unwrap_or(1);
        let word_bits = match self.settings.word {
            WordSize::U32 => 32,
            WordSize::U64 => 64,
        };
        crate::encode::mask::auto_cell(nk, self.code_bits(), word_bits)
    }

    /// Changes settings (rebuilding the thread pool if the count changed; masks
    /// follow on the next frame if the word size or cell size changed, normal
    /// codes if the packing or the reconstruction did).
    pub fn set_settings(&mut self, s: Settings) -> Result<()> {
        check_settings(&s)?;
        if s.threads != self.settings.threads {
            self.pool = build_pool(s.threads)?;
        }
        // the normal codes follow the packing and the reconstruction (the
        // cubic's are its B-spline gradient at each voxel)
        if s.pack != self.settings.pack || s.reconstruction != self.settings.reconstruction {
            self.unpark()?;
            self.axes.normals = [None, None, None];
        }
        self.settings = s;
        Ok(())
    }

    /// The intermediate image of the last frame.
    pub fn intermediate(&self) -> &Intermediate {
        &self.inter
    }

    /// The factorization of the last frame.
    pub fn last_factorization(&self) -> Option<&Factorization> {
        self.last_plan().map(|p| &p.view)
    }

    /// Runs `f` on the renderer's thread pool (where its frames' limiters
    /// run: to time one as a frame does).
    pub fn install<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        self.pool.install(f)
    }

    /// Runs `f` on the renderer's thread pool if `on`, else on this thread.
    pub(super) fn install_if<R: Send>(&self, on: bool, f: impl FnOnce() -> R + Send) -> R {
        if on { self.pool.install(f) } else { f() }
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::composite::Mode;
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
