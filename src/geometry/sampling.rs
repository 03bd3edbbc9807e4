//! Where a frame's samples lie: the voxel position of an intermediate
//! pixel's sample in a slice, and a slice's eye depth as an affine function
//! of the pixel. The inverse warp's gather and the surface hits read both.

use glam::DVec3;

use super::raster::Projector;
use crate::view::plan::FramePlan;
use crate::view::unpermute;

/// The voxel position of pixel `(p, q)`'s sample in slice `k` (fractional `k`
/// on the ray's line).
pub(crate) fn sample_voxel(plan: &FramePlan, k: usize, p: usize, q: usize) -> DVec3 {
    unpermute(plan.view.perm, DVec3::new(plan.sample_at(k, 0, p), plan.sample_at(k, 1, q), k as f64))
}

/// The eye depth (`−z` in `proj`'s eye space) of slice `k`'s samples as an
/// affine function `c + c_p·p + c_q·q` of the intermediate pixel `(p, q)`
/// (a sample's voxel position is affine in the pixel for a fixed slice in
/// both projections, and the depth affine in the position).
pub(crate) fn slice_depth(plan: &FramePlan, proj: &Projector, k: usize) -> [f64; 3] {
    let depth = |p: usize, q: usize| -proj.eye_space(sample_voxel(plan, k, p, q)).z;
    let c = depth(0, 0);
    [c, depth(1, 0) - c, depth(0, 1) - c]
}
