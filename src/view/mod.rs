//! The view: camera, factorization, and the frame plan every traversal reads.
//!
//! Owns the camera and its standard views ([`camera`]), Lacroute's
//! factorization of the viewing transform into a shear of the slices and a
//! warp of the intermediate image (`factor`, re-exported here), and the
//! per-frame plan every traversal reads ([`plan`]). A factorization takes
//! the object axes of each principal axis it is given
//! ([`Factorization::with_permutations`]): the cyclic [`permutation`] by
//! default, or [`reuse_permutation`] (z mirrored to (y, x, z)) when the RLE
//! paths share one encoding between x and z. [`perspective`] holds the
//! perspective projection and factorization, whose plans
//! [`FramePlan::set_perspective`] makes. [`clip`] holds clipping planes: the
//! half-spaces kept, as per-pixel ray limits of any plan.

pub mod camera;
pub mod clip;
mod factor;
pub mod opacity;
pub mod perspective;
pub mod plan;
pub mod shear;

pub use camera::*;
pub use factor::*;
pub use perspective::{PerspectiveView, Projection};
pub use plan::FramePlan;
