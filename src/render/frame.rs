//! A renderer's frame set-up: the projection, the intermediate image's
//! quality, the producer of per-pixel ray limits, the plan reused from frame
//! to frame, and the key of the last frame written (an unchanged frame is
//! skipped).
//! The [`super::Renderer`] methods that set them, and the steps every plan
//! and every frame end with (finishing a plan, stamping the image), live
//! here too.

use super::settings::Settings;
use super::{Footprint, FrameStats, MAX_INTERMEDIATE_PIXELS, MAX_QUALITY, MIN_QUALITY, Renderer};

use std::sync::Arc;

use crate::composite::Mode;
use crate::error::{Error, Result};
use crate::view::plan::{FramePlan, Limiter, RayLimits};
use crate::view::{Camera, PerspectiveView, Projection};
use crate::warp::{Canvas, Texel};

/// The frame set-up of a renderer.
pub(super) struct FrameSetup {
    /// Parallel or perspective.
    pub(super) projection: Projection,
    /// Intermediate pixels per voxel (the adaptive image size; 1 by default).
    pub(super) quality: f64,
    /// The producer of per-pixel ray limits, if any, and a counter bumped when it changes.
    pub(super) limiter: Option<(Arc<dyn Limiter>, u64)>,
    /// The plan of the last frame (its arrays reused by the next).
    pub(super) plan: Option<FramePlan>,
    /// The perspective views of the last frame (a buffer reused).
    pub(super) views: Vec<PerspectiveView>,
    /// The inputs and stamp of the last frame written.
    pub(super) last_frame: Option<(FrameKey, u64)>,
}

impl Default for FrameSetup {
    fn default() -> Self {
        FrameSetup { projection: Projection::Parallel, quality: 1.0, limiter: None, plan: None, views: vec![], last_frame: None }
    }
}

/// Everything a frame depends on besides the volume.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct FrameKey {
    pub(super) camera: Camera,
    pub(super) projection: Projection,
    pub(super) quality: f64,
    pub(super) settings: Settings,
    pub(super) generation: u64,
    pub(super) tissue: Option<usize>,
    pub(super) limiter: Option<u64>,
    pub(super) focus: Option<(u64, usize)>,
}

pub(super) static NEXT_STAMP: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

impl Renderer {
    /// Sets the projection of the following frames (checked: a field of view
    /// in (0°, 180°), an eye distance finite and > 0). A perspective frame
    /// renders with [`Method::Rle`](super::Method::Rle) or [`Method::BruteRle`](super::Method::BruteRle); the raycast paths
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

    /// Runs limiter `l` on `plan` as a frame does: on the renderer's thread
    /// pool when it asks for it ([`Limiter::parallel`]), else on this thread.
    pub fn run_limiter(&self, l: &dyn Limiter, plan: &FramePlan, limits: &mut RayLimits) {
        self.install_if(l.parallel(plan), || l.limit(plan, limits));
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
    /// Deluxe M sets `ns_a` and `ns_b` samples per voxel along the two
    /// sheared axes ([`FramePlan::matched_samples`]: from the warp's
    /// magnification along each; a perspective plan's largest, at its base
    /// plane, the front slice): a pitch per axis ([`Grid::pitch`]), so a
    /// warp that magnifies one axis only (the slices of a thick-slice scan
    /// seen from the side) takes `ns_a·ns_b` samples a voxel square, not
    /// `max(ns_a, ns_b)²`. With `--quality` the finer pitch wins on each
    /// axis: M never samples coarser than matched, a quality above it still
    /// refines. A grid past [`MAX_INTERMEDIATE_PIXELS`] is an error naming it.
    pub(super) fn finish_plan(&self, plan: &mut FramePlan, limits: Option<RayLimits>, focus: Option<RayLimits>) -> Result<()> {
        plan.set_ray_opacity(self.settings.mode == Mode::Blend);
        let mut pitch = [1.0 / self.frame.quality; 2];
        if self.settings.deluxe.matched {
            let ns = plan.matched_samples();
            pitch = [0, 1].map(|a| pitch[a].min(1.0 / ns[a] as f64));
        }
        if pitch != [1.0; 2] {
            plan.set_pitch(pitch);
        }
        let [w, h] = plan.grid.size;
        if w as u64 * h as u64 > MAX_INTERMEDIATE_PIXELS {
            return Err(Error::value(
                "intermediate image",
                format!(
                    "{w}×{h} pixels at {:.3}×{:.3} samples per voxel (limit {MAX_INTERMEDIATE_PIXELS}): lower the zoom, --quality or matched sampling (Deluxe M)",
                    1.0 / pitch[0],
                    1.0 / pitch[1]
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

    /// Stamps `out` as this frame's image (see [`Renderer::render`]'s skip).
    pub(super) fn finish_frame<T: Texel>(&mut self, key: FrameKey, out: &mut Canvas<T>, stats: FrameStats) -> FrameStats {
        let stamp = NEXT_STAMP.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        out.stamp = stamp;
        self.frame.last_frame = Some((key, stamp));
        stats
    }
}
