//! # shearwarp
//!
//! Fast, accurate CPU volume rendering built around the bit-packed binary
//! shear-warp fast rotator (Csébfalvi 1999), with Lacroute's run-length-encoded
//! shear-warp beside it.
//!
//! The library is the renderer; the command-line tool, the bench runner and the
//! viewer live in the binary (feature `cli`). The folders follow one frame:
//!
//! data ([`data`]: volume, patient orientation, loaders, phantoms, slice stacks, normal codes)
//! → classify ([`classify`]: transfer functions, presets, shading)
//! → encode ([`encode`]: cell mask, shear, depth search, RLE)
//! → view ([`view`]: camera, factorization, frame plan)
//! → composite ([`composite`]: ray and slice traversals into the intermediate image)
//! → warp ([`warp`]: the intermediate image to the final one).
//! [`geometry`] holds surfaces placed in the volume (meshes, primitives) and
//! their rasterizer at the output resolution, for geometry and clip regions
//! that enter the frame plan as per-pixel ray limits.
//! [`render`] runs that pipeline per frame; [`kernels`] holds the one CPU
//! level every SIMD kernel is chosen by; [`memory`] what each structure holds
//! and the fallible allocation of the large ones. [`accuracy`] (reference renderer,
//! analytic truth, metrics) is what the fast paths are measured against;
//! [`checks`] holds the sanity checks and warnings every front end shares;
//! [`output`] writes every file atomically (a temporary renamed into place),
//! every error checked.
//!
//! The everyday API is re-exported here: load or build a [`Volume`], make a
//! [`Renderer`] with [`Settings`], and render a [`Camera`] into an [`Image`].

pub mod accuracy;
pub mod checks;
pub mod classify;
pub mod composite;
pub mod data;
pub mod encode;
pub mod error;
pub mod geometry;
pub mod kernels;
pub mod memory;
pub mod output;
pub mod render;
pub mod view;
pub mod warp;

pub use composite::Mode;
pub use data::volume::{Volume, VoxelData, VoxelType};
pub use error::{Error, Result};
pub use memory::Memory;
pub use render::{Deluxe, FrameStats, Lattice, Method, Renderer, Settings};
pub use view::{Camera, NamedView};
pub use warp::{Image, Image8};

/// Helpers shared by the unit tests.
#[cfg(test)]
pub(crate) mod testing {
    /// Deterministic pseudo-random u64s (xorshift64) from a non-zero `seed`.
    pub fn xorshift(mut s: u64) -> impl FnMut() -> u64 {
        move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        }
    }
}
