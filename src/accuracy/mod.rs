//! Accuracy: what the fast paths are measured against.
//!
//! Owns the reference renderer ([`reference`](mod@reference): true rays, trilinear, fine
//! steps, f64), the analytic iso-surfaces of the sphere and Marschner–Lobb
//! phantoms ([`truth`]), and the image and depth metrics ([`metrics`]: RMSE,
//! PSNR, SSIM, silhouette and depth error).

pub mod metrics;
pub mod reference;
pub mod truth;
