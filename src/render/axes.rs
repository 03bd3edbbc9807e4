//! The per-axis structures a renderer builds lazily, the first time a view
//! along an axis needs them (slice stacks, BCC slices, normal codes, cell
//! codes, sheared masks, run-length encodings), how long each took, and the
//! memory budget they are built under; [`estimate_axis`] predicts their
//! bytes before anything is built.

use super::settings::{Lattice, Normals, Settings, WordSize};
use super::stats::BuildTimes;
use crate::composite::Mode;
use crate::data::bcc::{BccLattice, BccStack};
use crate::data::normals::NormalStack;
use crate::data::slices::SliceStack;
use crate::data::volume::Volume;
use crate::encode::mask::{BinaryMask, CellCodes, PackedCodes};
use crate::encode::rle::RleCache;
use crate::error::Error;
use crate::memory::Memory;
use crate::view::plan::Grid;

/// The per-axis structures of a renderer and the budget they are built under.
#[derive(Default)]
pub(super) struct Axes {
    pub(super) stacks: [Option<SliceStack>; 3],
    /// Per axis, the interleaved slices of the BCC grid ([`Lattice::Bcc`]; the
    /// RLE paths read them instead of [`Axes::stacks`]).
    pub(super) bcc: [Option<BccStack>; 3],
    /// Per axis, every voxel's normal code (raycast paths with [`Normals::Codes`]).
    pub(super) normals: [Option<NormalStack>; 3],
    pub(super) codes: [Option<(u64, CellCodes)>; 3],
    pub(super) masks: [Option<AxisMask>; 3],
    /// Classification, encodings and tables of the pre-classified paths.
    pub(super) rle: RleCache,
    /// Largest total of [`super::Renderer::memory`] a new structure may bring about.
    pub(super) budget: Option<u64>,
    /// How long each structure took to build.
    pub(super) build_times: BuildTimes,
}

#[derive(Clone, Debug)]
pub(super) enum AnyMask {
    W32(BinaryMask<u32>),
    W64(BinaryMask<u64>),
}

impl AnyMask {
    pub(super) fn bytes(&self) -> usize {
        match self {
            AnyMask::W32(m) => m.bytes(),
            AnyMask::W64(m) => m.bytes(),
        }
    }
    pub(super) fn set_cpu_level(&mut self, cpu: crate::kernels::CpuLevel) {
        match self {
            AnyMask::W32(m) => m.set_cpu_level(cpu),
            AnyMask::W64(m) => m.set_cpu_level(cpu),
        }
    }
}

/// What a cached mask was built for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct MaskKey {
    /// Predicate masks depend on the mode; code masks do not.
    pub(super) mode: Option<Mode>,
    pub(super) word: WordSize,
    pub(super) cell: usize,
    pub(super) generation: u64,
    /// Deluxe I: each bit also covers the midpoint after its slice
    /// ([`CellCodes::build_half`]).
    pub(super) half: bool,
}

#[derive(Debug)]
pub(super) struct AxisMask {
    pub(super) key: MaskKey,
    pub(super) mask: AnyMask,
}

/// True when the binary path keeps no f32 stack for `volume`: table shading
/// with packed cells, whose 8- or 16-bit densities are all its rays read (8-
/// and 16-bit scans). Every other path samples a resident [`SliceStack`].
pub(super) fn compact_binary(volume: &Volume, settings: &Settings) -> bool {
    settings.method.uses_mask()
        && settings.normals == Normals::Codes
        && settings.pack
        && volume.data().voxel_type() != crate::data::volume::VoxelType::F32
}

/// The bytes a renderer with `settings` holds for principal axis `axis` of
/// `volume` once a frame along it is rendered (with a mask of `code_bits`-bit
/// codes: 1 for one transfer function, 2 for up to three tissue presets, 4 for
/// up to fifteen), before anything is built: the volume (none on the binary
/// path of an 8/16-bit scan, which lets go of it once its packed cells hold
/// the voxels — if the renderer holds the only handle of them), the slice
/// stack (none on that path either), the normal codes (there: 2 bytes a voxel
/// packed with the densities in their own type; otherwise 4 bytes when packed with
/// the densities of an f32 stack, an upper bound, else 2), the cell codes and
/// the mask's words (binary path; the words are allocated, the pages touched
/// are fewer) and the intermediate image. The run-length encoding (RLE
/// paths) depends on the data and is not predicted (0).
pub fn estimate_axis(volume: &Volume, settings: &Settings, code_bits: u32, axis: usize) -> Memory {
    let dims = volume.dims();
    let p = crate::view::permutation(axis.min(2));
    let n = [dims[p[0]], dims[p[1]], dims[p[2]]];
    let voxels = (n[0] * n[1] * n[2]) as u64;
    let cells = [n[0].saturating_sub(1), n[1].saturating_sub(1)];
    let grid = Grid::parallel(cells, n[2]);
    let compact = compact_binary(volume, settings);
    let mut m = Memory {
        // the compact path lets go of the volume once its packed cells hold the voxels
        volume: if compact { 0 } else { volume.bytes() },
        intermediate: grid.size[0] as u64 * grid.size[1] as u64 * 20,
        ..Default::default()
    };
    let a = axis.min(2);
    m.stacks[a] = match settings.lattice {
        _ if compact => 0,
        Lattice::Cartesian => voxels * 4,
        // the interleaved BCC slices (f32)
        Lattice::Bcc => BccLattice::new(dims).map_or(0, |l| l.samples() as u64 * 4),
    };
    let raycast = settings.method.is_raycast();
    if raycast && settings.normals == Normals::Codes {
        m.normals[a] = if compact {
            // the densities in their own type packed with 2-byte codes
            voxels * (2 + volume.data().voxel_type().size() as u64)
        } else {
            // an f32 stack's codes are packed with its densities when they are
            // integers spanning at most 65 535, which depends on the values,
            // so 4 is an upper bound
            voxels * if settings.pack { 4 } else { 2 }
        };
    }
    if settings.method.uses_mask() {
        let nb = code_bits.max(1);
        m.cell_codes[a] = PackedCodes::bytes_for(nb, cells[0], cells[1] * n[2]);
        m.masks[a] = match settings.word {
            WordSize::U32 => BinaryMask::<u32>::bytes_for(cells, n[2], nb, settings.cell),
            WordSize::U64 => BinaryMask::<u64>::bytes_for(cells, n[2], nb, settings.cell),
        };
    }
    m
}

/// A pipeline's artefact that `ensure_axis` should have built is missing: an
/// error, never a silent fall-back to another path.
pub(super) fn missing(what: &str, axis: usize) -> Error {
    Error::Other(format!("internal: {what} of axis {} was not built for this frame", ["x", "y", "z"][axis]))
}
