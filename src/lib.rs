//! # shearwarp
//!
//! Fast, accurate CPU volume rendering built around the bit-packed binary
//! shear-warp fast rotator (Csébfalvi 1999), with Lacroute's run-length-encoded
//! shear-warp beside it.
//!
//! The library is the renderer; the command-line tool, the bench runner and the
//! viewer live in the binary (feature `cli`).
//!
//! # Layers
//!
//! The folders are the stages of a frame, in one dependency order: each
//! imports only what stands below it in this tree, never what stands above.
//!
//! ```text
//! geometry/   surfaces in the volume, their rasterizer and the inverse warp
//! accuracy/   the reference renderer, analytic truth, metrics
//! bricks/     one volume as bricks, rendered apart and composited sort-last
//! render/     the Renderer: one frame through every stage below; checks
//! warp.rs     the intermediate image to the final one
//! composite/  ray and slice traversals into the intermediate image
//! encode/     cell mask, shift kernels, depth search, walks, RLE encoding
//! classify/   transfer functions, presets, shading, the shade table by code
//! data/       volume, orientation, loaders, phantoms, slice stacks, normal codes
//! view/       camera, factorization, shear state, opacity tables, frame plan, clips
//! kernels/ memory.rs error.rs fmt.rs output.rs   the ground: CPU level, allocation, errors,
//!             numbers, atomic file output
//! ```
//!
//! So a frame reads bottom up: the [`view`] plans it (camera, the factorization
//! into shear and warp, the per-frame plan every traversal reads), [`data`]
//! holds what it samples, [`classify`] turns densities into colour and
//! opacity, [`encode`] builds what lets a traversal skip empty space,
//! [`composite`] traverses into the intermediate image and [`warp`] resamples
//! it to the output. [`render`] owns the per-frame state and runs the stages;
//! [`bricks`] splits a volume into bricks rendered apart (one per MPI rank
//! in a distributed run) and composites their partial images;
//! [`accuracy`] measures the fast paths against a reference renderer, and
//! [`geometry`] places meshes and clip regions in the frame as per-pixel ray
//! limits. [`kernels`] holds the one CPU level every SIMD kernel is chosen by,
//! [`memory`] what each structure holds and the fallible allocation of the
//! large ones, [`error`] the error type, [`fmt`] the numbers of messages and
//! [`output`] the atomic writing of every file (a temporary renamed into place,
//! every error checked).
//!
//! The everyday API is re-exported here: load or build a [`Volume`], make a
//! [`Renderer`] with [`Settings`], and render a [`Camera`] into an [`Image`].

pub mod accuracy;
pub mod bricks;
pub mod classify;
pub mod composite;
pub mod data;
pub mod encode;
pub mod error;
pub mod fmt;
pub mod geometry;
pub mod kernels;
pub mod memory;
pub mod output;
pub mod render;
#[cfg(test)]
mod testing;
pub mod view;
pub mod warp;

pub use composite::Mode;
pub use data::volume::{Volume, VoxelData, VoxelType};
pub use error::{Error, Result};
pub use memory::Memory;
pub use render::{Deluxe, FrameStats, Lattice, Method, Renderer, Settings};
pub use view::{Camera, NamedView};
pub use warp::{Image, Image8};
