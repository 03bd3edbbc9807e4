//! Encodings of a classified volume that let a frame skip what it does not need.
//!
//! Owns the two acceleration structures and their per-frame updates:
//! - the bit-packed binary cell mask: cell codes from the classification
//!   ([`cells`]), packed along depth with super cells and the occupied
//!   rectangle ([`mask`]), kept sheared per view by one-bit, fused two-bit or
//!   direct shears ([`crate::view::shear`]: translation arrays and shift vectors; [`shift`]:
//!   the shift kernels, plain and AVX2), and searched along depth for candidate
//!   slices ([`depth`]: byte LUTs and bit scans over 1/2/4-bit codes), and
//!   walked by rays that diverge from the direction it is sheared to
//!   (perspective, another pixel pitch: [`walk`]);
//! - Lacroute's run-length encoding of the pre-classified volume per principal
//!   axis ([`rle`]: classification per voxel, runs, per-view tables; its slice
//!   traversal is [`crate::composite::slices`]).

pub mod cells;
pub mod depth;
pub mod mask;
pub mod rle;
pub mod shift;
pub mod walk;
