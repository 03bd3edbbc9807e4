//! The volume's iso hit under an output pixel of the last frame: what the
//! depth test of geometry in the volume
//! ([`super::composite_iso_over_geometry`]) and the viewer's lens (centred on
//! the first visible surface under the mouse) both read, for every frame —
//! one plan, or a perspective frame split into pyramids, each pyramid's
//! intermediate depth kept ([`Renderer::set_keep_depths`]) and read through
//! the plan that owns the pixel ([`Renderer::last_owner`]).

use glam::DVec3;

use super::sampling::sample_voxel;
use crate::composite::Intermediate;
use crate::render::Renderer;
use crate::view::perspective::RayDirections;
use crate::view::plan::FramePlan;

/// The volume's iso hit (voxel indices) under output pixel `(u, v)` of the
/// renderer's last frame (iso mode): the mean position of the neighbouring
/// intermediate pixels' hits, each where its own ray meets its fractional
/// slice, by the warp's bilinear weights over the pixels that hit (the same
/// 0.5 coverage rule as [`crate::accuracy::reference::fast_path_depth`]);
/// `None` where they carry less than half the weight, where no plan owns
/// the pixel, or where the depth of a split frame's pyramid was not kept.
pub fn volume_hit(renderer: &Renderer, u: f64, v: f64) -> Option<DVec3> {
    let i = renderer.last_owner(u, v)?;
    let plan = &renderer.last_plans()[i];
    hit_in(plan, |p, q| renderer.last_depth_at(i, p, q), u, v, |x, y, k| position_at(plan, x, y, k))
}

/// The voxel position where intermediate pixel `(x, y)`'s ray meets its
/// fractional slice `k` (the sample positions are affine in k: between the
/// slices around k).
fn position_at(plan: &FramePlan, x: usize, y: usize, k: f64) -> DVec3 {
    let nk = plan.slices();
    let k0 = (k.floor() as usize).min(nk - 1);
    let k1 = (k0 + 1).min(nk - 1);
    let (a, b) = (sample_voxel(plan, k0, x, y), sample_voxel(plan, k1, x, y));
    a + (b - a) * (k - k0 as f64)
}

/// One plan's depth lookup: the plan, its kept depth image, the first and
/// last slice's depth functions, and the last slice.
type PlanDepths<'r> = (&'r FramePlan, Option<&'r Intermediate>, [f64; 3], [f64; 3], usize);

/// [`volume_hit`]'s eye depth (`−z` in a projector's eye space) for a run of
/// output pixels of one frame: each plan's first and last slice depths set
/// up once ([`super::sampling::slice_depth`]), and a pixel's hit depth
/// the same weighted mean of its neighbours' hits (the depth is affine in
/// the position: the depth of the mean position, up to rounding) with no
/// sample position per pixel.
pub(crate) struct HitDepths<'r> {
    renderer: &'r Renderer,
    /// Per plan: the plan, its depth plane (None: not kept, or not of the
    /// plan's grid: no hit), the first and last slice's depth functions and
    /// the last slice — looked up once per frame, not per pixel.
    plans: Vec<PlanDepths<'r>>,
}

impl<'r> HitDepths<'r> {
    pub(crate) fn new(renderer: &'r Renderer, proj: &super::Projector) -> Self {
        let plans = renderer
            .last_plans()
            .iter()
            .enumerate()
            .map(|(i, plan)| {
                let last = plan.slices().saturating_sub(1);
                // (as Renderer::last_depth_at reads it)
                let d = renderer.last_depth_image(i).filter(|d| d.holds_depths_of(plan.grid.size));
                (plan, d, super::sampling::slice_depth(plan, proj, 0), super::sampling::slice_depth(plan, proj, last), last)
            })
            .collect();
        HitDepths { renderer, plans }
    }

    /// The eye depth of [`volume_hit`] at output pixel `(u, v)` of the
    /// renderer's last frame (the frame these depths were set up for).
    pub(crate) fn at(&self, u: f64, v: f64) -> Option<f64> {
        let i = self.renderer.last_owner(u, v)?;
        let (plan, d, f, l, last) = self.plans[i];
        let d = d?;
        let depth = |x: usize, y: usize, k: f64| {
            let (xf, yf) = (x as f64, y as f64);
            let d0 = f[0] + f[1] * xf + f[2] * yf;
            if last == 0 {
                return d0;
            }
            // (past the last slice, the last slice's sample, as position_at)
            let k = k.min(last as f64);
            d0 + (l[0] + l[1] * xf + l[2] * yf - d0) * (k / last as f64)
        };
        hit_in(plan, |p, q| d.depth_at(p, q), u, v, depth)
    }
}

/// [`volume_hit`] in plan `plan`, whose intermediate iso depth `depth_at`
/// reads: the weighted mean of `value(x, y, k)` (a position, or a depth)
/// over the neighbouring pixels' hits.
fn hit_in<T>(plan: &FramePlan, depth_at: impl Fn(usize, usize) -> f32, u: f64, v: f64, value: impl Fn(usize, usize, f64) -> T) -> Option<T>
where
    T: Copy + Default + std::ops::Add<Output = T> + std::ops::Mul<f64, Output = T> + std::ops::Div<f64, Output = T>,
{
    let (nk, [gw, gh]) = (plan.slices(), plan.grid.size);
    if nk == 0 {
        return None;
    }
    let [p, q] = plan.output_to_intermediate(u, v)?;
    let (x0, y0) = (p.floor(), q.floor());
    let (fx, fy) = (p - x0, q - y0);
    let (mut wsum, mut at) = (0.0, T::default());
    for (dx, dy, wt) in [(0.0, 0.0, (1.0 - fx) * (1.0 - fy)), (1.0, 0.0, fx * (1.0 - fy)), (0.0, 1.0, (1.0 - fx) * fy), (1.0, 1.0, fx * fy)]
    {
        let (x, y) = (x0 + dx, y0 + dy);
        if x < 0.0 || y < 0.0 || x >= gw as f64 || y >= gh as f64 || wt <= 0.0 {
            continue;
        }
        let k = depth_at(x as usize, y as usize) as f64;
        if !k.is_finite() {
            continue;
        }
        wsum += wt;
        at = at + value(x as usize, y as usize, k) * wt;
    }
    (wsum >= 0.5).then(|| at / wsum)
}

/// The iso hits of one frame kept past the renderer's later frames: its
/// plans (without their ray limits and focus intervals) and intermediate
/// iso depths, and a split frame's rays, copied from the renderer after the
/// frame ([`KeptHits::of`]). [`KeptHits::at`] is [`volume_hit`] of that
/// frame, bit for bit, computed when asked (the viewer's lens: the one pixel
/// under the mouse, for every move over the same view).
#[derive(Clone, Debug, Default)]
pub struct KeptHits {
    plans: Vec<FramePlan>,
    /// Per plan, the depth plane (`size`, `valid` and `depth` only).
    depths: Vec<Intermediate>,
    /// The output pixels' rays of a split frame (which pyramid owns a pixel).
    rays: Option<RayDirections>,
}

impl KeptHits {
    /// The hits of `renderer`'s last frame (iso mode; a split perspective
    /// frame's pyramids only where [`Renderer::set_keep_depths`] was on).
    pub fn of(renderer: &Renderer) -> Self {
        let plans: Vec<FramePlan> = renderer
            .last_plans()
            .iter()
            .map(|p| {
                let mut p = p.clone();
                p.limits = None;
                p.focus = None;
                p
            })
            .collect();
        let depths = (0..plans.len())
            .map(|i| match renderer.last_depth_image(i) {
                Some(d) => Intermediate { size: d.size, valid: d.valid, depth: d.depth.clone(), ..Default::default() },
                None => Intermediate::default(),
            })
            .collect();
        KeptHits { plans, depths, rays: renderer.last_rays() }
    }

    /// The iso hit (voxel indices) under output pixel `(u, v)` of the kept
    /// frame, as [`volume_hit`] gave it right after that frame.
    pub fn at(&self, u: f64, v: f64) -> Option<DVec3> {
        let i = match self.rays {
            Some(rays) => {
                let owner = rays.owner(u, v);
                self.plans.iter().position(|p| (p.view.axis, p.view.ascending) == owner)?
            }
            None => (!self.plans.is_empty()).then_some(0)?,
        };
        let (plan, d) = (&self.plans[i], &self.depths[i]);
        let matches = d.holds_depths_of(plan.grid.size);
        hit_in(plan, |p, q| if matches { d.depth_at(p, q) } else { f32::NAN }, u, v, |x, y, k| position_at(plan, x, y, k))
    }
}
