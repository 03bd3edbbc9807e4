//! Classification: densities to colour and opacity, and how a sample is shaded.
//!
//! Owns the transfer functions and the [`Classifier`] every path evaluates
//! (`tf`, re-exported here), the tissue presets ([`presets`]), and the one
//! shading model ([`shading`]: a Blinn-Phong headlight) that every path — ray
//! casting, RLE slices, the references — uses.

pub mod presets;
pub mod shade_table;
pub mod shading;
mod tf;

pub use tf::*;
