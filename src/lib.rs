//! # shearwarp
//!
//! Fast, accurate CPU volume rendering built around the bit-packed binary
//! shear-warp fast rotator (Csébfalvi 1999).

pub mod error;
pub mod phantom;
pub mod volume;

pub use error::{Error, Result};
pub use volume::{Volume, VoxelData, VoxelType};
pub mod classify;
pub mod cli;
pub mod composite;
pub mod depth;
pub mod mask;
pub mod phantom;
pub mod presets;
pub mod raycast;
pub mod render;
pub mod shear;
pub mod slices;
pub mod view;
pub mod warp;
