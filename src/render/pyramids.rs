//! The split perspective frame: one plan per pyramid of the volume (an eye
//! inside or beside the volume sees it along several principal axes), the
//! pyramids' intermediate iso depths kept for hit lookups, and the output
//! pixels' rays that say which pyramid owns a pixel.
//! The [`super::Renderer`] methods that render such a frame and read its
//! plans, owners and depths live here too.

use super::{FrameStats, NEAR_SLICES, Renderer};

use std::time::Instant;

use crate::composite::{Intermediate, Mode};
use crate::error::Result;
use crate::view::perspective::RayDirections;
use crate::view::plan::FramePlan;
use crate::view::{Camera, Factorization, PerspectiveView};
use crate::warp::{Canvas, Owned, Texel, clear_for_pyramids, warp_owned};

/// The pyramids of the last split perspective frame.
#[derive(Default)]
pub(super) struct Pyramids {
    /// The plans of the last split perspective frame, one per pyramid (reused
    /// frame to frame), and how many the frame used.
    pub(super) plans: Vec<FramePlan>,
    pub(super) count: usize,
    /// Whether the last frame was split.
    pub(super) last_split: bool,
    /// Each pyramid's intermediate iso depth of the last split frame (only
    /// `depth`, `size` and `valid` are used; kept when
    /// [`super::Renderer::set_keep_depths`] is on, in iso mode).
    pub(super) depths: Vec<Intermediate>,
    pub(super) keep_depths: bool,
    /// The output pixels' rays of the last split frame.
    pub(super) last_rays: Option<RayDirections>,
}

impl Renderer {
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

    /// A perspective frame split into Lacroute's pyramids (`views`, from
    /// [`PerspectiveView::frame`]; `cam` is `camera` with the perspective
    /// zoom, the eye `distance` world units from the volume centre). The
    /// image is cleared, then each pyramid in turn gets its plan (its own
    /// axis, slices and window), is composited by the one per-plan function
    /// every frame uses ([`Renderer::composite_plan`]) and warped into its own
    /// output pixels only ([`warp_owned`]). No pyramid: an empty image.
    pub(super) fn render_pyramids<T: Texel>(
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
}
