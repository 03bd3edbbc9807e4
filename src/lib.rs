//! # shearwarp
//!
//! Fast, accurate CPU volume rendering built around the bit-packed binary
//! shear-warp fast rotator (Csébfalvi 1999).
//!
//! The pipeline, one module per stage:
//! volume ([`volume`], [`io`], [`orientation`], [`slices`], [`phantom`]) → classify ([`classify`], [`presets`])
//! → mask ([`mask`], [`shear`], [`depth`]) → factorize view ([`view`])
//! → composite into the intermediate image ([`raycast`], [`composite`], shaded by
//! [`normals`]) → warp ([`warp`]).
//! [`render`] runs the pipeline per frame; [`cli`] is the command-line tool.
//! Accuracy: [`reference`] (true rays, trilinear, fine steps) and [`truth`]
//! (analytic iso-surfaces) are what [`metrics`] measures the fast paths
//! against; [`bench`] runs the speed/accuracy matrix (`shearwarp bench`).

pub mod bench;
pub mod checks;
pub mod classify;
pub mod cli;
pub mod composite;
pub mod depth;
pub mod error;
pub mod io;
pub mod mask;
pub mod metrics;
pub mod normals;
pub mod orientation;
pub mod phantom;
pub mod presets;
pub mod raycast;
pub mod reference;
pub mod render;
pub mod rle;
pub mod shear;
pub mod slices;
pub mod truth;
pub mod view;
pub mod viewer;
pub mod volume;
pub mod warp;

pub use error::{Error, Result};
pub use volume::{Volume, VoxelData, VoxelType};
