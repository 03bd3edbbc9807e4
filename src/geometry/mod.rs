//! Geometry in the volume (Bruckner's InverseWarp hybrid).
//!
//! Owns the surfaces placed in a volume and their picture at the output
//! resolution:
//! - [`mesh`]: triangle meshes in voxel-index coordinates (with a transform)
//!   and the analytic primitives for quick use and for tests: sphere, box,
//!   cylinder ("needle") and plane;
//! - [`io`]: meshes from OBJ, STL and PLY files;
//! - [`raster`]: the CPU rasterizer that draws meshes into a colour and depth
//!   buffer at the output resolution, in the renderer's own image coordinates
//!   and for both projections (near-plane clipping, the top-left fill rule,
//!   back-face modes, Lambert/Blinn-Phong under the headlight);
//! - [`inverse_warp`]: that depth buffer as the frame plan's per-pixel ray
//!   limits ([`GeometryLimits`], a [`crate::view::plan::Limiter`]: every
//!   path stops at the geometry), and the final image of the volume over the
//!   geometry's colour;
//! - [`clip_mesh`]: a closed convex mesh as a clip region, its inside or
//!   outside kept ([`MeshClip`], a [`crate::view::plan::Limiter`]: its front
//!   and back faces' depth buffers through the inverse warp's gather);
//! - [`hit`]: the volume's iso hit under an output pixel of the last frame,
//!   plain or split into pyramids ([`volume_hit`]: the depth test of the
//!   final image and the viewer's lens).
//!
//! The depth buffer is in the reference renderer's depth units (world units
//! along the view from the plane through the volume centre), so a pixel's
//! geometry and volume depths compare directly.

pub mod clip_mesh;
pub mod hit;
pub mod inverse_warp;
pub mod io;
pub mod mesh;
pub mod raster;
pub mod sampling;

pub use clip_mesh::{ConvexMesh, MeshClip};
pub use hit::volume_hit;
pub use inverse_warp::{GeometryLimits, composite_iso_over_geometry, composite_over_geometry};
pub use io::{load_mesh, load_mesh_within};
pub use mesh::Mesh;
pub use raster::{Cull, GeometryImage, Material, Projector, rasterize};

/// A small xorshift generator for the geometry tests' random cases: uniform
/// numbers in `[lo, hi)` from `seed` (deterministic, no dependency).
#[cfg(test)]
pub(crate) fn test_rng(mut seed: u64) -> impl FnMut(f64, f64) -> f64 {
    move |lo: f64, hi: f64| {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        lo + (hi - lo) * (seed >> 11) as f64 / (1u64 << 53) as f64
    }
}
