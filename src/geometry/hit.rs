//! The volume's iso hit under an output pixel of the last frame: what the
//! depth test of geometry in the volume
//! ([`super::composite_iso_over_geometry`]) and the viewer's lens (centred on
//! the first visible surface under the mouse) both read, for every frame —
//! one plan, or a perspective frame split into pyramids, each pyramid's
//! intermediate depth kept ([`Renderer::set_keep_depths`]) and read through
//! the plan that owns the pixel ([`Renderer::last_owner`]).

use glam::DVec3;

use super::inverse_warp::sample_voxel;
use crate::render::Renderer;

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
    let (nk, [gw, gh]) = (plan.slices(), plan.grid.size);
    if nk == 0 {
        return None;
    }
    let [p, q] = plan.output_to_intermediate(u, v)?;
    let (x0, y0) = (p.floor(), q.floor());
    let (fx, fy) = (p - x0, q - y0);
    let (mut wsum, mut at) = (0.0, DVec3::ZERO);
    for (dx, dy, wt) in [(0.0, 0.0, (1.0 - fx) * (1.0 - fy)), (1.0, 0.0, fx * (1.0 - fy)), (0.0, 1.0, (1.0 - fx) * fy), (1.0, 1.0, fx * fy)]
    {
        let (x, y) = (x0 + dx, y0 + dy);
        if x < 0.0 || y < 0.0 || x >= gw as f64 || y >= gh as f64 || wt <= 0.0 {
            continue;
        }
        let k = renderer.last_depth_at(i, x as usize, y as usize) as f64;
        if !k.is_finite() {
            continue;
        }
        // the sample positions are affine in k: between the slices around k
        let k0 = (k.floor() as usize).min(nk - 1);
        let k1 = (k0 + 1).min(nk - 1);
        let (a, b) = (sample_voxel(plan, k0, x as usize, y as usize), sample_voxel(plan, k1, x as usize, y as usize));
        wsum += wt;
        at += wt * (a + (b - a) * (k - k0 as f64));
    }
    (wsum >= 0.5).then(|| at / wsum)
}
