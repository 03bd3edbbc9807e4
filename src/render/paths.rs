//! The per-method frame paths: compositing one frame plan by the settings' [`Method`].

use super::axes::{AnyMask, missing};
use super::{FrameStats, Lattice, Method, Normals, Renderer, Settings};

use std::time::Instant;

use crate::classify::Classifier;
use crate::classify::shade_table::{ShadeTable, headlight_object};
use crate::composite::lean::LeanFrame;
use crate::composite::lean_cubic::LeanCubic;
use crate::composite::raycast::{
    RayContext, cubic_walks, occupied_scaled_rays, render_binary, render_brute, volume_rect, volume_rect_with_mids,
};
use crate::composite::{Intermediate, Mode, Rect};
use crate::data::normals::{NormalStack, StackNormals};
use crate::data::slices::SliceStack;
use crate::encode::depth::{Matcher, binary_matcher};
use crate::encode::mask::ShearWork;
use crate::encode::walk::Drift;
use crate::error::Result;
use crate::kernels::reconstruct::{Reconstruction, cubic_axis};
use crate::view::plan::{FramePlan, MapKind};

impl Renderer {
    /// Composites one frame plan into the intermediate image by the
    /// renderer's method (its axis's structures must exist: see
    /// [`Renderer::ensure_axis`]), then runs `then_warp` on it (in the same
    /// job on the pool), adding the shear, render and warp times and the
    /// rays to `stats`. The one per-plan step of every frame: a parallel or
    /// one-pyramid frame has one plan, a split perspective frame one per
    /// pyramid.
    pub(super) fn composite_plan(
        &mut self,
        plan: &FramePlan,
        stats: &mut FrameStats,
        then_warp: impl FnOnce(&Intermediate) + Send,
    ) -> Result<()> {
        let axis = plan.view.axis;
        let mode = self.settings.mode;
        let focus = self.focus_tissue();
        // the current preset's one-bit mask where it is current (a focus reads two presets' codes)
        let one_bit = self.preset_mask_serves(axis, focus.is_some());
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
        let matcher = if one_bit { binary_matcher() } else { matcher };
        let classes = FrameClasses { cls, iso, focus };
        let (inter, rle) = (&mut self.inter, &mut self.axes.rle);
        let mask = match one_bit {
            true => self.axes.preset[axis].as_mut().map(|t| &mut t.mask),
            false => self.axes.masks[axis].as_mut().map(|m| &mut m.mask),
        };
        let (normals, shade) = (&self.axes.normals, &mut self.shade);
        let (lean, lean_cubic) = (&mut self.lean, &mut self.lean_cubic);
        // the lean binary iso frame, chosen once for the frame from its plan
        let lean_frame = self.lean_on
            && settings.method == Method::Binary
            && (settings.reconstruction == Reconstruction::Linear || settings.cubic_crossing())
            && LeanFrame::applies(plan, mode, settings.normals == Normals::Codes && normals[axis].is_some(), settings.search);
        // its cubic counterpart, likewise
        let lean_cubic_frame =
            self.lean_on && settings.method == Method::Binary && settings.cubic_rays() && LeanCubic::applies(plan, mode, settings.search);
        // one job on the pool per plan: shear and render run inside it
        let result: Result<()> = self.pool.install(|| {
            let t = Instant::now();
            let rect: Option<Rect> = match settings.method {
                Method::Binary => {
                    let mask = mask.ok_or_else(|| missing("the sheared mask", axis))?;
                    let w: ShearWork = match mask {
                        AnyMask::W32(m) => m.shear_to(&plan.shear),
                        AnyMask::W64(m) => m.shear_to(&plan.shear),
                    };
                    if plan.kind == MapKind::ScaleTranslate {
                        // what the diverging rays' walks skip blocks by (rays
                        // that do not drift read the shear's fractions only)
                        let tables = !Drift::for_plan(plan).is_still();
                        match mask {
                            AnyMask::W32(m) => m.update_occupancy(matcher, &plan.shear, tables),
                            AnyMask::W64(m) => m.update_occupancy(matcher, &plan.shear, tables),
                        }
                    }
                    (stats.shear_steps, stats.shear_direct, stats.shear_words) = (w.steps, w.direct, w.words);
                    let scaled = plan.kind == MapKind::ScaleTranslate;
                    let cubic = settings.cubic_rays() && mode == Mode::Iso;
                    let mask: &AnyMask = mask;
                    let rect = match mask {
                        // (a scaled plan's occupied-ray rectangle misses rays the cubic
                        // hits: the cubic casts every ray of the volume there)
                        _ if !settings.occupied_rect || (scaled && cubic) => volume_rect(plan, stack.cells()),
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
                    let ctx = ray_context(stack, plan, classes, settings, normals[axis].as_ref(), shade);
                    // the cubic along the slices when a ray moves farther than its codes
                    // assume (a perspective eye near the volume): every slice, as brute force
                    let walks = !cubic || cubic_axis(stack.perm()) != 2 || cubic_walks(plan);
                    match (mask, lean_frame) {
                        _ if !walks => render_brute(&ctx, volume_rect(plan, stack.cells()), inter),
                        (AnyMask::W32(m), _) if lean_cubic_frame => lean_cubic.render(&ctx, m, matcher, settings.prefetch, rect, inter),
                        (AnyMask::W64(m), _) if lean_cubic_frame => lean_cubic.render(&ctx, m, matcher, settings.prefetch, rect, inter),
                        (AnyMask::W32(m), true) => lean.render(&ctx, m, matcher, settings.prefetch, rect, inter),
                        (AnyMask::W64(m), true) => lean.render(&ctx, m, matcher, settings.prefetch, rect, inter),
                        (AnyMask::W32(m), false) => render_binary(&ctx, m, settings.search, matcher, settings.prefetch, rect, inter),
                        (AnyMask::W64(m), false) => render_binary(&ctx, m, settings.search, matcher, settings.prefetch, rect, inter),
                    }
                    stats.render_ms += t.elapsed().as_secs_f64() * 1e3;
                    stats.lean = (lean_frame || lean_cubic_frame) && walks;
                    stats.preset_mask = one_bit;
                    rect
                }
                Method::Brute => {
                    let rect = volume_rect(plan, stack.cells());
                    stats.shear_ms += t.elapsed().as_secs_f64() * 1e3;
                    let t = Instant::now();
                    inter.prepare(plan.grid.size);
                    let ctx = ray_context(stack, plan, classes, settings, normals[axis].as_ref(), shade);
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
                        (Method::Rle, _) => rle.render(plan, settings.ert, rect, settings.cpu, inter),
                        (_, Some(b)) => rle.render_brute(b, plan, settings.ert, rect, inter),
                        // (the encoding's normal codes: the reconstruction's)
                        (_, None) => rle.render_brute(&StackNormals::new(stack, settings.reconstruction), plan, settings.ert, rect, inter),
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

/// What a frame's samples are classified by: the classifier and iso value
/// of the current tissue (or the one transfer function), and of the focus
/// tissue when there is one.
#[derive(Clone, Copy)]
struct FrameClasses<'a> {
    cls: &'a Classifier,
    iso: f32,
    focus: Option<(&'a Classifier, f32)>,
}

/// The rays' context of a frame of `plan`: the classification, iso value and
/// material, with table shading when the settings ask for it and the normal
/// codes exist (the shade table brought up to date for the view).
fn ray_context<'a>(
    stack: &'a SliceStack,
    plan: &'a FramePlan,
    classes: FrameClasses<'a>,
    settings: Settings,
    normals: Option<&'a NormalStack>,
    shade: &'a mut ShadeTable,
) -> RayContext<'a> {
    let FrameClasses { cls, iso, focus } = classes;
    let mut ctx =
        RayContext::new(stack, cls, plan, settings.mode, iso, settings.shading, settings.ert).with_intermediate(plan.intermediate());
    if let Some((fc, fiso)) = focus {
        ctx = ctx.with_focus(fc, fiso);
    }
    if settings.cubic_rays() {
        // shaded by the cubic's own gradient, never by normal codes
        return ctx.with_cubic(Some(cubic_axis(stack.perm())));
    }
    match (settings.normals, normals) {
        (Normals::Codes, Some(ns)) => {
            shade.update(headlight_object(&plan.view), settings.shading);
            let ctx = ctx.with_normals(ns, shade);
            // hits found by the linear samples, placed by the cubic's crossing
            // (the codes are the cubic's: the axes' build)
            if settings.cubic_crossing() { ctx.with_cubic_crossing(Some(cubic_axis(stack.perm()))) } else { ctx }
        }
        _ => ctx,
    }
}
