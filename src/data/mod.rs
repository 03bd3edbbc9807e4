//! Data: what a frame samples, before any classification.
//!
//! Owns the volume ([`volume`]: voxels of their own type, spacing, size limits,
//! and where its index axes lie in the patient: [`orientation`]),
//! its value statistics ([`stats`]: range and histograms, read once),
//! the file loaders ([`io`]: NRRD, NIfTI, DICOM, .den, raw), the built-in
//! phantoms ([`phantom`]; those with an analytic surface sampled at any
//! spacing: [`shapes`]), the per-axis slice stacks ([`slices`]: densities laid
//! out along one principal axis, with the shared bilinear sample and gradient)
//! and the per-axis normal codes ([`normals`]: VolPack's 14-bit quantized
//! gradients, alone or packed with the densities; [`packing`] builds the
//! packed cells of an integer scan in place, without the volume beside them)
//! and the volume resampled to a body-centred cubic grid ([`bcc`]: two
//! interleaved sub-grids, slices alternating between them).

pub mod bcc;
pub mod io;
pub mod normals;
pub mod orientation;
pub mod packing;
pub mod phantom;
pub mod shapes;
pub mod slices;
pub mod stats;
pub mod volume;
pub mod voxels;
