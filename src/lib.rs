//! # shearwarp
//!
//! Fast, accurate CPU volume rendering built around the bit-packed binary
//! shear-warp fast rotator (Csébfalvi 1999).
//!
//! The pipeline, one module per stage:
//! volume ([`volume`], [`slices`], [`phantom`]) → classify ([`classify`], [`presets`])
//! → mask ([`mask`], [`shear`], [`depth`]) → factorize view ([`view`])
//! → composite into the intermediate image ([`raycast`], [`composite`]) → warp ([`warp`]).
//! [`render`] runs the pipeline per frame; [`cli`] is the command-line tool.

pub mod classify;
pub mod cli;
pub mod composite;
pub mod depth;
pub mod error;
pub mod io;
pub mod mask;
pub mod phantom;
pub mod presets;
pub mod raycast;
pub mod render;
pub mod shear;
pub mod slices;
pub mod view;
pub mod viewer;
pub mod volume;
pub mod warp;

pub use error::{Error, Result};
pub use volume::{Volume, VoxelData, VoxelType};
