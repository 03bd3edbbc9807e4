//! The per-axis structures a renderer builds lazily, the first time a view
//! along an axis needs them (slice stacks, BCC slices, normal codes, cell
//! codes, sheared masks, run-length encodings), how long each took, and the
//! memory budget they are built under; [`estimate_axis`] predicts their
//! bytes before anything is built.
//! The [`super::Renderer`] methods that build them ([`super::Renderer::prepare_axis`]
//! and the frame's own build), keep them within the budget, and let go of
//! the volume's voxels (park, unpark) live here too.

use super::settings::{Lattice, Normals, Settings, WordSize};
use super::stats::BuildTimes;
use super::{MAX_INTERMEDIATE_PIXELS, MAX_MASK_BYTES, Renderer};
use crate::kernels::reconstruct::{Reconstruction, cubic_axis};

use std::time::Instant;

use crate::classify::Classifier;
use crate::composite::Mode;
use crate::data::bcc::{BccLattice, BccStack};
use crate::data::normals::{CellSource, NormalStack, StackNormals};
use crate::data::slices::{Densities, SliceStack};
use crate::data::volume::Volume;
use crate::encode::mask::{BinaryMask, CellCodes, PackedCodes};
use crate::encode::rle::{ClassKey, RleCache};
use crate::error::{Error, Result};
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
    /// Per axis, the current tissue preset's one-bit mask, packed from
    /// [`Axes::masks`]' threshold codes ([`PresetMask`]).
    pub(super) preset: [Option<PresetMask>; 3],
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
    /// Bytes held beyond shared cell codes ([`BinaryMask::held_bytes`]).
    pub(super) fn held_bytes(&self) -> usize {
        match self {
            AnyMask::W32(m) => m.held_bytes(),
            AnyMask::W64(m) => m.held_bytes(),
        }
    }
    /// Bytes of the words and the super-cell codes, shared or not.
    fn own_bytes(&self) -> usize {
        match self {
            AnyMask::W32(m) => m.bytes() + m.code_bytes(),
            AnyMask::W64(m) => m.bytes() + m.code_bytes(),
        }
    }
    /// The one-bit mask of codes at least `c` ([`BinaryMask::at_least`]).
    fn at_least(&self, c: u8) -> AnyMask {
        match self {
            AnyMask::W32(m) => AnyMask::W32(m.at_least(c)),
            AnyMask::W64(m) => AnyMask::W64(m.at_least(c)),
        }
    }
}

/// One tissue preset's one-bit mask: the super cells whose threshold code
/// is at least the preset's (`code`, its index + 1), packed from the code
/// mask of `key`. A frame of that preset reads it instead of the code mask
/// when it is current (no focus region, which needs two presets' codes):
/// the same candidates, so the same image, from a code width's fraction of
/// the words to shear and walk. A tissue switch leaves it stale and keeps
/// O(1): the frames read the code mask until [`super::Renderer::prefetch_axis`]
/// (an idle moment) builds the new preset's, and the code mask is not
/// sheared while this one serves.
#[derive(Debug)]
pub(super) struct PresetMask {
    pub(super) key: MaskKey,
    pub(super) code: u8,
    pub(super) mask: AnyMask,
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
    /// The cubic reconstruction's iso surface: each bit covers what the
    /// cubic can reach from its cell ([`CellCodes::build_cubic`]).
    pub(super) cubic: bool,
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
        let (code, preset) = mask_parts(cells, n[2], nb, settings);
        m.masks[a] = code + preset;
    }
    m
}

/// The bytes of the code mask of `cells` cells and `nk` slices of `nb`-bit
/// codes, and of its [`PresetMask`] (none for one-bit codes).
fn mask_parts(cells: [usize; 2], nk: usize, nb: u32, settings: &Settings) -> (u64, u64) {
    (code_mask_bytes(cells, nk, nb, settings), if nb > 1 { preset_mask_bytes(cells, nk, settings) } else { 0 })
}

/// The bytes of a mask of `nb`-bit codes ([`BinaryMask::bytes_for`]).
fn code_mask_bytes(cells: [usize; 2], nk: usize, nb: u32, settings: &Settings) -> u64 {
    match settings.word {
        WordSize::U32 => BinaryMask::<u32>::bytes_for(cells, nk, nb, settings.cell),
        WordSize::U64 => BinaryMask::<u64>::bytes_for(cells, nk, nb, settings.cell),
    }
}

/// The bytes of a [`PresetMask`]: a one-bit mask, and its own super-cell codes
/// at every cell size.
fn preset_mask_bytes(cells: [usize; 2], nk: usize, settings: &Settings) -> u64 {
    let s = settings.cell.clamp(1, crate::encode::mask::MAX_CELL);
    let sc = crate::encode::cells::super_cells(cells, s);
    let codes = PackedCodes::bytes_for(1, sc[0], sc[1] * nk);
    code_mask_bytes(cells, nk, 1, settings) + if s == 1 { codes } else { 0 }
}

/// A pipeline's artefact that `ensure_axis` should have built is missing: an
/// error, never a silent fall-back to another path.
pub(super) fn missing(what: &str, axis: usize) -> Error {
    Error::Other(format!("internal: {what} of axis {} was not built for this frame", ["x", "y", "z"][axis]))
}

impl Renderer {
    /// The voxels of a parked volume, from any packed cells that hold them.
    pub(super) fn parked_voxels(&self) -> Result<std::sync::Arc<crate::data::volume::VoxelData>> {
        let lost = || Error::Other("internal: the volume's voxels were let go with no packed cells holding them".into());
        let ns = self.axes.normals.iter().flatten().find(|n| n.holds_voxels()).ok_or_else(lost)?;
        Ok(std::sync::Arc::new(ns.voxels_in_volume_order()?.ok_or_else(lost)?))
    }

    /// Gives the volume its voxels back if this renderer let go of them.
    pub(super) fn unpark(&mut self) -> Result<()> {
        if self.volume.is_parked() {
            let data = self.pool.install(|| self.parked_voxels())?;
            self.volume.unpark(data);
        }
        Ok(())
    }

    /// Lets go of the volume's voxels when packed cells of this renderer hold
    /// them (or a build of them is under way: `building`) and nothing outside
    /// it shares them: the binary path of an integer scan then holds the
    /// voxels once, in its cells, instead of twice ([`Renderer::volume`] and
    /// the builds of other paths get them back from the cells).
    pub(super) fn park(&mut self, building: bool) {
        let held = building || self.axes.normals.iter().flatten().any(NormalStack::holds_voxels);
        if held && self.can_let_go() {
            self.volume.park();
        }
    }

    /// True when the volume's voxels are resident and only this renderer holds them.
    pub(super) fn can_let_go(&self) -> bool {
        !self.volume.is_parked() && self.volume.data_handles() == 1
    }

    /// Bytes of the packed masks' words that exist now (the presets' code
    /// masks and the current preset's one-bit masks).
    pub fn mask_bytes(&self) -> usize {
        let preset: usize = self.axes.preset.iter().flatten().map(|t| t.mask.bytes()).sum();
        self.axes.masks.iter().flatten().map(|m| m.mask.bytes()).sum::<usize>() + preset
    }

    /// Bytes of the run-length encodings that exist now, per axis.
    pub fn rle_axis_bytes(&self) -> [usize; 3] {
        self.axes.rle.bytes()
    }

    /// Bytes of the run-length encodings that exist now.
    pub fn rle_bytes(&self) -> usize {
        self.axes.rle.bytes().iter().sum()
    }

    /// The pre-classified state (classification and encodings) of the RLE paths.
    pub fn rle_cache(&self) -> &RleCache {
        &self.axes.rle
    }

    /// How long the last build of each structure took, per axis.
    pub fn build_times(&self) -> BuildTimes {
        self.axes.build_times
    }

    /// Bytes held now, per structure and axis.
    pub fn memory(&self) -> Memory {
        let per = |f: &dyn Fn(usize) -> usize| [0, 1, 2].map(|a| f(a) as u64);
        Memory {
            volume: self.volume.bytes(),
            stacks: per(&|a| {
                self.axes.stacks[a].as_ref().map_or(0, SliceStack::bytes) + self.axes.bcc[a].as_ref().map_or(0, BccStack::bytes)
            }),
            normals: per(&|a| self.axes.normals[a].as_ref().map_or(0, NormalStack::bytes)),
            cell_codes: per(&|a| self.axes.codes[a].as_ref().map_or(0, |c| c.1.bytes())),
            masks: per(&|a| {
                self.axes.masks[a].as_ref().map_or(0, |m| m.mask.held_bytes())
                    + self.axes.preset[a].as_ref().map_or(0, |t| t.mask.own_bytes())
            }),
            rle: self.axes.rle.bytes().map(|b| b as u64),
            intermediate: self.inter.bytes() as u64,
        }
    }

    /// Limits what the renderer may hold ([`Renderer::memory`]'s total): before
    /// it builds the structures a view needs, it predicts their size
    /// ([`estimate_axis`]); when they would not fit it first frees the other
    /// axes' structures (rebuilt when a view needs them again), and when they
    /// still would not fit the frame fails with [`Error::Memory`], before
    /// anything is allocated. `None` (the default) sets no limit.
    pub fn set_memory_budget(&mut self, budget: Option<u64>) {
        self.axes.budget = budget;
    }

    /// The memory budget, if any.
    pub fn memory_budget(&self) -> Option<u64> {
        self.axes.budget
    }

    /// The bytes `ensure_axis(axis)` would allocate now (structures that exist
    /// and are current count 0), and the intermediate image's growth.
    pub(super) fn missing_bytes(&self, axis: usize) -> Memory {
        let mut m = estimate_axis(&self.volume, &self.settings, self.code_bits(), axis);
        if self.axes.stacks[axis].as_ref().is_some_and(|s| s.is_resident() && s.perm() == self.axis_perm(axis))
            && self.settings.lattice == Lattice::Cartesian
        {
            m.stacks[axis] = 0;
        }
        if self.axes.bcc[axis].is_some() && self.settings.lattice == Lattice::Bcc {
            m.stacks[axis] = 0;
        }
        if self.axes.normals[axis].is_some() {
            m.normals[axis] = 0;
        }
        if self.settings.method.uses_mask() {
            let dims = self.volume.dims();
            let p = crate::view::permutation(axis);
            let cells = [dims[p[0]].saturating_sub(1), dims[p[1]].saturating_sub(1)];
            let (code, preset) = mask_parts(cells, dims[p[2]], self.code_bits(), &self.settings);
            let key = Some(self.mask_key());
            if self.axes.masks[axis].as_ref().map(|m| m.key) == key {
                m.masks[axis] -= code;
                m.cell_codes[axis] = 0;
            }
            // (a stale preset's mask is replaced by one of the same size; none
            // is built with the knob off)
            if self.preset_code().is_none() || self.axes.preset[axis].as_ref().map(|t| t.key) == key {
                m.masks[axis] -= preset;
            }
        }
        m.volume = 0;
        m.intermediate = m.intermediate.saturating_sub(self.inter.bytes() as u64);
        m
    }

    /// Frees every structure of principal axis `axis` (first giving the volume
    /// its voxels back if they were let go).
    pub(super) fn drop_axis(&mut self, axis: usize) -> Result<()> {
        if self.axes.normals[axis].is_some() {
            self.unpark()?;
        }
        self.axes.stacks[axis] = None;
        self.axes.bcc[axis] = None;
        self.axes.normals[axis] = None;
        self.axes.codes[axis] = None;
        self.axes.masks[axis] = None;
        self.axes.preset[axis] = None;
        self.axes.rle.drop_axis(axis);
        Ok(())
    }

    /// True when building `axis` now fits the budget beside everything held
    /// (less the volume, when the build lets go of it). The build allocates
    /// the cell array while the volume is still held, but touches only its
    /// last third (one byte a voxel of an 8-bit scan) before the volume goes,
    /// so what is resident stays below the total counted here; under a
    /// virtual-memory limit (`ulimit -v`) the allocation itself may be refused,
    /// which is [`Error::Memory`], never an abort.
    pub(super) fn fits_budget(&self, axis: usize) -> bool {
        let needed = self.missing_bytes(axis).total();
        needed == 0 || self.axes.budget.is_none_or(|b| (self.memory().total() + needed).saturating_sub(self.releasable(axis)) <= b)
    }

    /// The bytes of volume that building `axis` lets go of: all of it when the
    /// compact binary path builds packed cells while the volume is resident
    /// and nothing outside this renderer shares the voxels.
    pub(super) fn releasable(&self, axis: usize) -> u64 {
        let building = compact_binary(&self.volume, &self.settings) && self.axes.normals[axis].is_none();
        if building && self.can_let_go() { self.volume.bytes() } else { 0 }
    }

    /// Checks the budget for building `axis` now; frees the other axes first
    /// if that makes it fit.
    pub(super) fn fit_budget(&mut self, axis: usize) -> Result<()> {
        let Some(budget) = self.axes.budget else { return Ok(()) };
        if self.fits_budget(axis) {
            return Ok(());
        }
        for a in (0..3).filter(|&a| a != axis) {
            self.drop_axis(a)?;
        }
        if !self.fits_budget(axis) {
            let (needed, held) = (self.missing_bytes(axis).total(), self.memory().total());
            let d = self.volume.dims();
            return Err(Error::Memory {
                what: format!(
                    "rendering the {}×{}×{} volume along {} ({})",
                    d[0],
                    d[1],
                    d[2],
                    ["x", "y", "z"][axis],
                    self.settings.method.name()
                ),
                needed,
                held,
                budget,
            });
        }
        Ok(())
    }

    /// The object axes `(i, j, k)` of principal axis `axis` this renderer's
    /// frames use: the cyclic [`crate::view::permutation`], or with
    /// [`Settings::rle_reuse`] on an RLE path under a parallel projection
    /// [`crate::view::reuse_permutation`] (z mirrored to share x's scanlines).
    pub(super) fn axis_perm(&self, axis: usize) -> [usize; 3] {
        let rle = self.settings.method.is_rle();
        if self.settings.rle_reuse && rle && !self.frame.projection.is_perspective() {
            crate::view::reuse_permutation(axis)
        } else {
            crate::view::permutation(axis)
        }
    }

    /// What the pre-classified state depends on: classification generation,
    /// tissue, mode and the sampler (pre- or post-classified, Deluxe P).
    pub(super) fn rle_key(&self) -> ClassKey {
        let tissue = self.classes.tissues.as_ref().map_or(0, |t| t.current as u64 + 1);
        // (a pre-classified encoding holds the voxels the focus tissue shows too)
        let focus = self.focus_tissue().map_or(0, |f| f as u64 + 1);
        self.rle_enc_key() | (tissue << 2) | (focus << 12)
    }

    /// What a post-classified encoding depends on (the key without the
    /// tissue: it keeps the cells every tissue preset may show), the lattice,
    /// and the reconstruction whose normal codes the voxels carry
    /// ([`StackNormals`]).
    pub(super) fn rle_enc_key(&self) -> ClassKey {
        let bcc = (self.settings.lattice == Lattice::Bcc) as u64;
        let cubic = (self.settings.reconstruction == Reconstruction::Cubic) as u64;
        (self.classes.generation << 20)
            | (cubic << 10)
            | (bcc << 9)
            | ((self.settings.deluxe.post as u64) << 1)
            | (self.settings.mode == Mode::Blend) as u64
    }

    pub(super) fn mask_key(&self) -> MaskKey {
        MaskKey {
            mode: if self.classes.tissues.is_some() { None } else { Some(self.settings.mode) },
            word: self.settings.word,
            cell: self.settings.cell,
            generation: self.classes.generation,
            half: self.settings.deluxe.intermediate,
            cubic: self.settings.cubic_rays(),
        }
    }

    /// Fails when the intermediate image or (binary path) the sheared mask of
    /// principal axis `axis` would exceed [`MAX_INTERMEDIATE_PIXELS`] or
    /// [`MAX_MASK_BYTES`] — very elongated volumes (e.g. 16384×4×4 seen along its
    /// long axis), whose padding for shears up to 45° dwarfs the data. Without
    /// this the allocation fails and aborts the process.
    pub(super) fn check_axis_size(&self, axis: usize) -> Result<()> {
        let dims = self.volume.dims();
        let p = crate::view::permutation(axis);
        let n = [dims[p[0]], dims[p[1]], dims[p[2]]];
        let cells = [n[0].saturating_sub(1), n[1].saturating_sub(1)];
        let Grid { size: grid, .. } = Grid::parallel(cells, n[2]);
        let too_big = |what: String| {
            Err(Error::value(
                "volume shape",
                format!(
                    "{}×{}×{} seen along {}: {what}; the volume is too elongated for shear-warp along this axis",
                    dims[0],
                    dims[1],
                    dims[2],
                    ["x", "y", "z"][axis]
                ),
            ))
        };
        let px = grid[0] as u64 * grid[1] as u64;
        if px > MAX_INTERMEDIATE_PIXELS {
            return too_big(format!("the intermediate image would need {}×{} pixels (limit {MAX_INTERMEDIATE_PIXELS})", grid[0], grid[1]));
        }
        if self.settings.method.uses_mask() {
            // an upper bound of what BinaryMask::from_codes allocates
            let bytes = estimate_axis(&self.volume, &self.settings, self.code_bits(), axis).masks[axis];
            if bytes > MAX_MASK_BYTES {
                return too_big(format!("its sheared mask would need {bytes} bytes (limit {MAX_MASK_BYTES})"));
            }
        }
        Ok(())
    }

    /// Makes sure the slice stack (and, for the binary path, the mask) of `axis`
    /// exist and are current. Returns the milliseconds spent building.
    pub(super) fn ensure_axis(&mut self, axis: usize) -> Result<f64> {
        self.check_axis_size(axis)?;
        self.fit_budget(axis)?;
        let t = Instant::now();
        let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
        if self.settings.lattice == Lattice::Bcc {
            // the RLE paths on the BCC grid (check_deluxe allows no other):
            // the interleaved slices, their classification and encoding
            if self.axes.bcc[axis].is_none() {
                let t = Instant::now();
                self.unpark()?;
                let vol = &self.volume;
                self.axes.bcc[axis] = Some(self.pool.install(|| BccStack::try_new(vol, axis))?);
                self.axes.build_times.stacks[axis] = ms(t);
            }
            self.ensure_rle(axis, true);
            return Ok(t.elapsed().as_secs_f64() * 1e3);
        }
        if self.axes.bcc.iter().any(Option::is_some) {
            self.axes.bcc = [None, None, None];
        }
        let compact = compact_binary(&self.volume, &self.settings);
        let raycast = self.settings.method.is_raycast();
        if compact && self.axes.normals[axis].is_none() {
            // the densities and codes packed in 3 (8-bit) or 4 bytes a voxel,
            // no f32 stack, and the volume let go once the cells hold its voxels
            let t = Instant::now();
            let threads = self.pool.current_num_threads();
            let vol = &self.volume;
            let src = match self.axes.normals.iter().flatten().find(|n| n.holds_voxels()) {
                // the volume was let go: re-lay another axis's cells
                Some(ns) if vol.is_parked() => CellSource::Cells(ns),
                _ => CellSource::Volume(vol),
            };
            let build =
                self.pool.install(|| NormalStack::try_cells(src, axis, threads))?.ok_or_else(|| missing("the packed cells", axis))?;
            if self.axes.stacks[axis].is_none() {
                self.axes.stacks[axis] = Some(SliceStack::shell(vol, axis));
            }
            // the build holds the voxels now: the volume can go before the codes are computed
            self.park(true);
            let spacing = self.volume.spacing();
            self.axes.normals[axis] = Some(self.pool.install(|| build.finish(spacing, self.settings.reconstruction)));
            self.axes.build_times.normals[axis] = ms(t);
        }
        let perm = self.axis_perm(axis);
        if !compact && self.axes.stacks[axis].as_ref().is_none_or(|s| !s.is_resident() || s.perm() != perm) {
            let t = Instant::now();
            self.unpark()?;
            let vol = &self.volume;
            self.axes.stacks[axis] = Some(self.pool.install(|| SliceStack::try_permuted(vol, perm))?);
            self.axes.build_times.stacks[axis] = ms(t);
        }
        if raycast && self.settings.normals == Normals::Codes && self.axes.normals[axis].is_none() {
            let t = Instant::now();
            let (stack, spacing, pack, recon) = (
                self.axes.stacks[axis].as_ref().expect("stack built above"),
                self.volume.spacing(),
                self.settings.pack,
                self.settings.reconstruction,
            );
            self.axes.normals[axis] = Some(self.pool.install(|| NormalStack::try_with_codes(stack, spacing, pack, recon))?);
            self.axes.build_times.normals[axis] = ms(t);
        }
        if self.settings.method.uses_mask() {
            let key = self.mask_key();
            if self.axes.masks[axis].as_ref().map(|m| m.key) != Some(key) {
                // the densities come from the resident stack, or from the packed cells
                let stack: &dyn Densities = match (&self.axes.stacks[axis], &self.axes.normals[axis]) {
                    (Some(s), _) if s.is_resident() => s,
                    (_, Some(ns)) => ns,
                    _ => return Err(missing("the densities", axis)),
                };
                // cell codes depend only on the classification (and Deluxe I's
                // dilation); cell size and word size reuse them
                let codes_key =
                    key.generation * 8 + key.cubic as u64 * 4 + key.mode.map_or(0, |m| (m == Mode::Blend) as u64) * 2 + key.half as u64;
                if self.axes.codes[axis].as_ref().map(|c| c.0) != Some(codes_key) {
                    let t = Instant::now();
                    let half = key.half;
                    // the cubic's stack axis: the volume's z
                    let z_axis = key.cubic.then(|| cubic_axis(perm));
                    let codes = self.pool.install(|| match (&self.classes.tissues, self.settings.mode) {
                        (Some(ts), _) if let Some(za) = z_axis => {
                            CellCodes::thresholds_cubic(stack, za, &ts.thresholds).expect("thresholds validated in with_tissues")
                        }
                        (None, Mode::Iso) if let Some(za) = z_axis => {
                            let iso = self.classes.iso;
                            CellCodes::binary_cubic(stack, za, |_, hi| hi >= iso)
                        }
                        (Some(ts), _) if half => {
                            CellCodes::thresholds_half(stack, &ts.thresholds).expect("thresholds validated in with_tissues")
                        }
                        (Some(ts), _) => CellCodes::thresholds(stack, &ts.thresholds).expect("thresholds validated in with_tissues"),
                        (None, Mode::Iso) => {
                            let iso = self.classes.iso;
                            if half {
                                CellCodes::binary_half(stack, |_, hi| hi >= iso)
                            } else {
                                CellCodes::binary(stack, |_, hi| hi >= iso)
                            }
                        }
                        (None, Mode::Blend) => {
                            let cls = &self.classes.classifier;
                            let visible = |lo, hi| cls.may_be_visible(lo, hi);
                            if half { CellCodes::binary_half(stack, visible) } else { CellCodes::binary(stack, visible) }
                        }
                    });
                    self.axes.codes[axis] = Some((codes_key, codes));
                    self.axes.build_times.cell_codes[axis] = ms(t);
                }
                let t = Instant::now();
                let codes = &self.axes.codes[axis].as_ref().expect("built above").1;
                let mask = self.pool.install(|| match key.word {
                    WordSize::U32 => AnyMask::W32(BinaryMask::from_codes(codes, key.cell)),
                    WordSize::U64 => AnyMask::W64(BinaryMask::from_codes(codes, key.cell)),
                });
                self.axes.masks[axis] = Some(AxisMask { key, mask });
                // the current preset's own mask with it: this frame pays for a build anyway
                self.build_preset_mask(axis);
                self.axes.build_times.masks[axis] = ms(t);
            }
            // the mask carries the settings' CPU level to its shear kernels and to
            // the ray loop's bit scan (`render_binary`); a mask outlives a settings change
            if let Some(m) = self.axes.masks[axis].as_mut() {
                m.mask.set_cpu_level(self.settings.cpu);
            }
            if let Some(m) = self.axes.preset[axis].as_mut() {
                m.mask.set_cpu_level(self.settings.cpu);
            }
        }
        if self.settings.method.is_rle() {
            self.ensure_rle(axis, false);
        }
        Ok(t.elapsed().as_secs_f64() * 1e3)
    }

    /// The threshold code of the current tissue preset when the masks hold
    /// codes of more than one bit (a [`PresetMask`] then pays).
    pub(super) fn preset_code(&self) -> Option<u8> {
        let ts = self.classes.tissues.as_ref()?;
        (self.preset_masks && self.code_bits() > 1).then_some(ts.current as u8 + 1)
    }

    /// True when `axis` has the current preset's [`PresetMask`] for the
    /// current code mask.
    pub(super) fn preset_mask_current(&self, axis: usize) -> bool {
        let (Some(code), Some(t), Some(m)) = (self.preset_code(), &self.axes.preset[axis], &self.axes.masks[axis]) else { return false };
        t.code == code && t.key == m.key && m.key == self.mask_key()
    }

    /// Whether a frame along `axis` reads the current preset's
    /// [`PresetMask`] (it is current, and the frame has no focus region,
    /// which needs two presets' codes) rather than the code mask. Another
    /// preset's mask goes: stale until rebuilt for this one, and, left
    /// unsheared while the code mask serves, a long shear to catch up if its
    /// preset came back.
    pub(super) fn preset_mask_serves(&mut self, axis: usize, focus: bool) -> bool {
        if self.axes.preset[axis].as_ref().is_some_and(|t| Some(t.code) != self.preset_code()) {
            self.axes.preset[axis] = None;
        }
        !focus && self.preset_mask_current(axis)
    }

    /// Builds the current preset's [`PresetMask`] of `axis` from its code
    /// mask, if that is current and the preset's is not (the old preset's
    /// mask goes first, so the two never coexist).
    pub(super) fn build_preset_mask(&mut self, axis: usize) {
        let Some(code) = self.preset_code() else {
            self.axes.preset[axis] = None;
            return;
        };
        let key = self.mask_key();
        let Some(m) = self.axes.masks[axis].as_ref().filter(|m| m.key == key) else { return };
        if self.preset_mask_current(axis) {
            return;
        }
        self.axes.preset[axis] = None;
        let mask = self.pool.install(|| m.mask.at_least(code));
        self.axes.preset[axis] = Some(PresetMask { key, code, mask });
    }

    /// The pre-classified state of `axis`: the classification, and (for
    /// [`Method::Rle`]) the encoding of the axis's slices — the cartesian
    /// stack, or the interleaved BCC slices when `bcc` (the classification
    /// key tells the two apart).
    pub(super) fn ensure_rle(&mut self, axis: usize, bcc: bool) {
        let key = self.rle_key();
        if !self.axes.rle.is_for(key) {
            let cls = self.preclass_classifier().into_owned();
            if self.settings.deluxe.post {
                // the encoding keeps the cells any tissue preset of the mode may show
                let visible: Vec<&Classifier> = match (&self.classes.tissues, self.settings.mode) {
                    (Some(ts), Mode::Iso) => ts.iso_cls.iter().collect(),
                    (Some(ts), Mode::Blend) => ts.blend_cls.iter().collect(),
                    (None, _) => vec![&cls],
                };
                self.axes.rle.reset_post(key, self.rle_enc_key(), &cls, &visible, self.volume.spacing());
            } else {
                self.axes.rle.reset(key, &cls, self.volume.spacing());
            }
            // focus+context: the focus tissue's classification of the mode
            let focus = match (&self.classes.tissues, self.focus_tissue(), self.settings.mode) {
                (Some(ts), Some(f), Mode::Iso) => Some(&ts.iso_cls[f]),
                (Some(ts), Some(f), Mode::Blend) => Some(&ts.blend_cls[f]),
                _ => None,
            };
            self.axes.rle.set_focus(focus, self.volume.spacing());
        }
        if self.settings.method.encodes_runs() {
            // (an encoding, or a pointer table over another axis's: see RleCache::ensure_axis)
            let t = Instant::now();
            let rle = &mut self.axes.rle;
            // (asked first: a frame whose encoding is current sends no job to the pool)
            let built = if bcc {
                let src = self.axes.bcc[axis].as_ref().expect("BCC slices built above");
                !rle.is_current(src) && self.pool.install(|| rle.ensure_axis(src))
            } else {
                // the voxels' normal codes: the reconstruction's (the key above tells them apart)
                let stack = self.axes.stacks[axis].as_ref().expect("stack built above");
                let src = StackNormals::new(stack, self.settings.reconstruction);
                !rle.is_current(&src) && self.pool.install(|| rle.ensure_axis(&src))
            };
            if built {
                self.axes.build_times.rle[axis] = t.elapsed().as_secs_f64() * 1e3;
            }
        }
    }

    /// Builds the stack and mask of every axis now (so frames measure only shear,
    /// render and warp). Returns the milliseconds spent. An axis beyond the
    /// memory limits is skipped; a frame that needs it returns the error.
    pub fn prepare_all_axes(&mut self) -> f64 {
        (0..3).map(|a| self.ensure_axis(a).unwrap_or(0.0)).sum()
    }

    /// Builds the stack and mask of principal axis `axis` (0..3) now if they are
    /// missing or stale, so a later view along it does not pay for it. Returns the
    /// milliseconds spent (0 when current), or the error when the axis is beyond
    /// the memory limits.
    pub fn prepare_axis(&mut self, axis: usize) -> Result<f64> {
        self.ensure_axis(axis.min(2))
    }

    /// Builds principal axis `axis` ahead of need, but only if it fits the
    /// memory budget beside everything held now: unlike [`Renderer::prepare_axis`]
    /// it never frees another axis to make room (a prefetch that evicted the
    /// axis on screen would make the next frame rebuild it). Returns whether
    /// the axis is built now. It also builds the current tissue preset's
    /// one-bit mask, which a tissue switch (O(1): it builds nothing, and
    /// neither does [`Renderer::prepare_axis`]) leaves stale: the frames read
    /// the threshold-coded mask until then.
    pub fn prefetch_axis(&mut self, axis: usize) -> Result<bool> {
        let axis = axis.min(2);
        if !self.fits_budget(axis) {
            return Ok(false);
        }
        self.ensure_axis(axis)?;
        self.build_preset_mask(axis);
        Ok(true)
    }

    /// True when the frames along principal axis `axis` read the code mask
    /// for want of the current tissue preset's own one-bit mask (after a
    /// tissue switch): [`Renderer::prefetch_axis`] builds it.
    pub fn preset_mask_pending(&self, axis: usize) -> bool {
        let axis = axis.min(2);
        let code_mask = self.axes.masks[axis].as_ref().is_some_and(|m| m.key == self.mask_key());
        self.settings.method.uses_mask() && self.preset_code().is_some() && code_mask && !self.preset_mask_current(axis)
    }
}
