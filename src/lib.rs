//! # shearwarp
//!
//! Fast, accurate CPU volume rendering built around the bit-packed binary
//! shear-warp fast rotator (Csébfalvi 1999).

pub mod error;
pub mod io;
pub mod volume;

pub use error::{Error, Result};
pub use volume::{Volume, VoxelData, VoxelType};
