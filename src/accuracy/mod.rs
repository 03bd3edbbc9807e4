//! Accuracy: what the fast paths are measured against.
//!
//! Owns the reference renderer ([`reference`](mod@reference): true rays, trilinear, fine
//! steps, f64; and what a fast path's frame shows: its iso hit per pixel and
//! the normal it shades that hit with), the analytic iso-surfaces of the
//! phantoms that have one ([`truth`]: first-hit depth and surface normal per
//! pixel, in both projections, at any sampling spacing), and the image,
//! depth and normal metrics ([`metrics`]: RMSE, PSNR, SSIM, silhouette, depth
//! error in voxels, normal-angle error in degrees).

pub mod metrics;
pub mod reference;
pub mod truth;
