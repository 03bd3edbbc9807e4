//! Stage 3 — encodings of a classified volume that let a frame skip what it does not need.
//!
//! Owns the two acceleration structures and their per-frame updates:
//! - the bit-packed binary cell mask ([`mask`]: cell codes, packing, super
//!   cells, the occupied rectangle), kept sheared per view by one-bit,
//!   fused two-bit or direct shears ([`shear`]: translation arrays and shift
//!   vectors), and searched along depth for candidate slices ([`depth`]: byte
//!   LUTs and bit scans over 1/2/4-bit codes);
//! - Lacroute's run-length encoding of the pre-classified volume per principal
//!   axis ([`rle`]: classification per voxel, runs, per-view tables; its slice
//!   traversal is [`crate::composite::slices`]).

pub mod depth;
pub mod mask;
pub mod rle;
pub mod shear;
