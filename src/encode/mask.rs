//! The bit-packed cell mask of one principal axis, and its shear.
//!
//! Owns [`BinaryMask`]: the cell codes of [`crate::encode::cells`], `nb` bits per slice, packed along depth into words
//! of type `W` (u32 or u64, one implementation) and kept *sheared*.
//!
//! **Super cells.** With cell size `s`, slice `k` sits at super offset
//! `F[k] = ceil(f[k] / s)`, `f[k] = floor(trans[k])`, and a ray at intermediate
//! column `p` reads super column `P = floor((p − pad)/s) + PAD`. Writing
//! `a = p − pad = s·A + α` and `f = s·F − φ` (`0 ≤ α, φ < s`), the ray's cell at
//! slice `k` is `ci = a + f = s·(A + F) + α − φ`, within `s − 1` of `s·SI` for the
//! super cell `SI = A + F` found at `P` in slice `k`. So super cell `SI` holds the
//! highest code of the cells `[s·SI − (s − 1), s·SI + (s − 1)]` (its own and its
//! neighbours' halves, along both axes), and every ray's row is conservative: the
//! image is the same for every `s`, while the mask shrinks by about `s²` and each
//! shear step moves slices by `s` voxels. With `s = 1` nothing is dilated.
//!
//! Layout: `words[(q · width + p) · nw + w]` — the `nw` words of one depth row
//! (one super column) are contiguous. The grid is padded by `PAD` super cells on
//! every side, enough for any shear up to 45° about the centre slice, so no bit
//! is ever shifted out.
//!
//! Shearing: [`BinaryMask::shear_to`] moves the mask to a target [`ShearState`],
//! by incremental one-bit steps (per-bit shift vectors: each slice moves −1, 0
//! or +1, the split between directions may fall anywhere inside a word) when the
//! target is at most a few bits away, else by a staged shear (per bit of the
//! distance and direction, the slices whose distance has that bit move by it in
//! one pass). The direct shear (clear and re-scatter from the unsheared cell
//! bits, [`BinaryMask::shear_direct`]) is the reference both equal word for
//! word. Two incremental steps are fused into one pass
//! over the words where the target is two or more bits away (each slice moves
//! −2..=+2, five shift vectors): the same words, half the memory traffic.
//! A move of [`MIN_ONE_PASS_BITS`] or more along an axis, of depth rows
//! longer than the fused kernels take, runs in a single pass: every word is
//! OR-ed from the old columns (rows) at the distances its slots move by (at
//! most four), read from a copy of its grid row (from a ring of the old rows
//! above it, per band of columns). Either way only the occupied rectangle of
//! the grid is touched.

use rayon::prelude::*;

use crate::data::slices::SliceStack;
use crate::encode::cells::group_flags;
pub use crate::encode::cells::{CellCodes, PackedCodes};
use crate::encode::depth::{Matcher, Word, slot_shift};
use crate::encode::shift::*;
use crate::kernels::{self, CpuLevel};
use crate::view::plan::{Rect, ScaledMap, floor_i64};
use crate::view::shear::ShearState;

/// Steps above this count are done as one staged shear instead (about
/// `2·log2(steps)` passes over the occupied words, fewer when every slice moves
/// one way). The threshold was set against the direct shear, which clears the
/// occupied region and scatters every non-zero code; a step passes once over
/// the occupied words. Measured with `rotate --json` at
/// several `--step-deg` (2 threads, 2026-11-24): on the 512×512×413 chest CT's
/// 2-bit tissue mask a step costs about 1.5 ms and a direct shear 75 ms; on the
/// 256³ head phantom's 0.3 ms and 7 ms: a direct shear is worth 20–50 steps.
/// At 6 (the value before) a 1° drag on the chest (7–9 steps a frame) took the
/// direct path on 28 of 120 frames in the viewer, at 86 ms each.
pub const MAX_INCREMENTAL_STEPS: u32 = 16;

/// A move along i or j this many bits away or more, of depth rows longer than
/// [`MAX_FUSED_COLUMN`] words, runs in one pass (when every word's slots move
/// by at most four distances) rather than as single steps, each a pass over
/// the whole occupied mask: on a large scan's mask under the tissue presets
/// (a 512×512×413 CT's is a quarter of a gigabyte, 16 words a depth row) the
/// steps are bound by memory. Shorter rows keep the fused two-step kernels,
/// which run fewer instructions there.
pub const MIN_ONE_PASS_BITS: u32 = 3;

/// Distances a slice may move by in one incremental shear, −m..=m.
const SPAN: usize = 2 * MAX_INCREMENTAL_STEPS as usize + 1;

/// Most distances the slots of one word may move by for the one-pass move
/// along i (the slices' moves grow linearly with depth, so a word's slots
/// usually share one or two; the pass runs with as many terms a word as the
/// busiest word needs).
const MOVE_TERMS: usize = 4;

/// Longest column (words per depth row) with shift kernels compiled for its
/// length; longer columns run the general kernels, one step per pass.
pub const MAX_FIXED_COLUMN: usize = 16;

/// Longest column (words per depth row) whose incremental steps are fused two
/// to a pass. Measured (`cargo bench --bench skips -- shear_two_steps`): two
/// steps of the 256×256×225 head's mask take 242 µs fused against 330 µs
/// single at 4 words (1-bit codes), but 2.6 ms against 1.3 ms at 15 words
/// (4-bit codes), where the five-column window no longer fits in registers.
pub const MAX_FUSED_COLUMN: usize = 4;
// the fused kernels are compiled for the lengths [1 2 3 4] (`shift_columns2`, `shift_rows2`)
const _: () = assert!(MAX_FUSED_COLUMN == 4);

/// Largest super-cell size.
pub const MAX_CELL: usize = 8;

/// The bytes of mask a ray's depth row may hold before super cells pay for a
/// rotation: one cache line. Every frame of a rotation moves every word of
/// the mask (each depth row shifts by the change of its slices' shear), while
/// a ray reads only the one or two words around its first candidates; once a
/// depth row is longer than a cache line, the shear's memory traffic per ray
/// exceeds the render's, and super cells of size `S` divide it by `S²` (the
/// render pays for the dilation with more false candidates).
pub const AUTO_CELL_ROW_BYTES: usize = 64;

/// The cell size a rotation takes by default: the smallest `S` in
/// `1..=`[`MAX_CELL`] at which a depth row of `nk` slices of `nb`-bit codes in
/// words of `word_bits` bits, shared by the `S²` rays of a super cell, is at
/// most [`AUTO_CELL_ROW_BYTES`] per ray. (A 256-slice one-bit mask: 32 bytes,
/// `S = 1`; 512 slices of two-bit tissue codes in u64 words: 128 bytes, `S = 2`.)
pub fn auto_cell(nk: usize, nb: u32, word_bits: u32) -> usize {
    let per_word = (word_bits / nb.max(1)).max(1) as usize;
    let row_bytes = nk.div_ceil(per_word).max(1) * (word_bits / 8) as usize;
    (1..=MAX_CELL).find(|s| row_bytes <= AUTO_CELL_ROW_BYTES * s * s).unwrap_or(MAX_CELL)
}

/// How much a shear did (for the "limit of the shear step" report).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ShearWork {
    /// Incremental one-step shears performed.
    pub steps: u32,
    /// Direct shears performed.
    pub direct: u32,
    /// Words read-modify-written.
    pub words: u64,
}

/// The sheared, bit-packed cell mask of one principal axis.
#[derive(Clone, Debug)]
pub struct BinaryMask<W: Word> {
    /// Super-cell size.
    s: usize,
    /// Bits per slice code.
    nb: u32,
    /// Super cells along i and j.
    cells: [usize; 2],
    /// Slices.
    nk: usize,
    /// Padding of the intermediate image (voxel units).
    vpad: usize,
    /// Padding on each side (super cells).
    pad: usize,
    /// Grid size `[width, height]` in super columns.
    grid: [usize; 2],
    /// Words per depth row.
    nw: usize,
    words: Vec<W>,
    /// Unsheared super-cell codes, slice-major (at cell size 1, the
    /// [`CellCodes`]' own array, shared).
    codes: std::sync::Arc<PackedCodes>,
    /// Per-slice bounding box of non-zero super cells `[si0, si1, sj0, sj1]`.
    bbox: Vec<Option<[usize; 4]>>,
    /// Current grid offset of each slice along i and j: `PAD − F[k]`.
    off: [Vec<i32>; 2],
    /// Scratch for shifts (no allocation per frame).
    up: Vec<W>,
    down: Vec<W>,
    keep: Vec<W>,
    target: [Vec<i32>; 2],
    prev_off: [Vec<i32>; 2],
    /// Which shift kernels run: at [`CpuLevel::Avx2`] the copies compiled for
    /// AVX2, at [`CpuLevel::Scalar`] the plain build's (the reference, see
    /// [`BinaryMask::set_cpu_level`]). Always at most [`kernels::detected`].
    cpu: CpuLevel,
    /// Fuse two incremental steps into one pass where possible ([`BinaryMask::set_fused`]).
    fused: bool,
    /// Scratch of a fused step: the shift vectors of the moves +2, +1, 0, −1, −2.
    moves: [Vec<W>; 5],
    /// Scratch of a one-pass move ([`BinaryMask::word_terms`]): per word of a
    /// depth row, [`MOVE_TERMS`] terms (where the old word is: along i its
    /// offset in a row buffer with zero margins, along j its distance plus
    /// [`MAX_INCREMENTAL_STEPS`]; and the slots moving by that distance).
    terms: Vec<(usize, W)>,
    /// How many terms each word uses.
    term_used: Vec<usize>,
    /// The buffers of the bands a pass runs in (the one-pass moves' rows, the
    /// old rows around [`BinaryMask::row_bands`]' bands), kept: steady frames
    /// allocate nothing.
    move_bufs: Vec<Vec<W>>,
    /// Scratch of a one-pass move along j ([`BinaryMask::move_rows`]): per
    /// distance, the slots of each word that move by it.
    dist_masks: Vec<W>,
    /// The block occupancy of the last scaled frame ([`BinaryMask::update_occupancy`]),
    /// its tables reused across frames.
    occupancy: BlockOccupancy,
}

/// Runs `$fixed` with the constant `$n` bound to the column length `$nw` when it
/// is 1 to [`MAX_FIXED_COLUMN`] words (a kernel compiled for that length), else
/// `$any`. Sixteen u64 words hold 1024 one-bit slices, or 256 slices of the
/// tissue presets' 4-bit codes.
macro_rules! by_column_length {
    ($nw:expr, $n:ident => $fixed:expr, _ => $any:expr) => {
        by_column_length!(@arms $nw, $n, $fixed, $any, [1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16])
    };
    (@arms $nw:expr, $n:ident, $fixed:expr, $any:expr, [$($len:literal)*]) => {
        match $nw {
            $($len => {
                const $n: usize = $len;
                $fixed
            })*
            _ => $any,
        }
    };
}

/// Runs `$body` with the constant `$c` set to [`column_chunk`]`($nw)`: the
/// chunk in which the `_chunks` kernels build columns longer than
/// [`by_column_length!`]'s.
macro_rules! by_column_chunk {
    ($nw:expr, $c:ident => $body:expr) => {
        by_column_length!(@arms column_chunk($nw), $c, $body, unreachable!("a chunk of 16, 8, 4, 2 or 1 words"), [16 8 4 2 1])
    };
}

impl<W: Word> BinaryMask<W> {
    /// Builds the 1-bit mask of `stack` (cell size 1): cell `(ci, cj, k)` is set
    /// when `visible(lo, hi)` for the range `[lo, hi]` of its four corner densities.
    /// The mask starts unsheared.
    pub fn build(stack: &SliceStack, visible: impl Fn(f32, f32) -> bool + Sync) -> Self {
        Self::from_codes(&CellCodes::binary(stack, visible), 1)
    }

    /// The layout of the mask of `cells` cells and `nk` slices with `nb`-bit
    /// codes at super-cell size `s`: the view grid's padding, the padding in
    /// super cells, the grid in super columns and the words per depth row.
    fn layout(cells: [usize; 2], nk: usize, nb: u32, s: usize) -> (usize, usize, [usize; 2], usize) {
        let vpad = crate::view::plan::Grid::parallel(cells, nk).pad;
        let sc = crate::encode::cells::super_cells(cells, s);
        let pad = vpad.div_ceil(s) + 1;
        let nw = nk.div_ceil((W::BITS / nb) as usize).max(1);
        (vpad, pad, [sc[0] + 2 * pad, sc[1] + 2 * pad], nw)
    }

    /// The bytes [`BinaryMask::from_codes`] allocates for `cells` cells and
    /// `nk` slices of `nb`-bit codes at super-cell size `s`: the words, plus
    /// the packed super-cell codes when `s` is above 1 (at 1 the mask shares
    /// the cell codes).
    pub fn bytes_for(cells: [usize; 2], nk: usize, nb: u32, s: usize) -> u64 {
        let s = s.clamp(1, MAX_CELL);
        let (_, _, grid, nw) = Self::layout(cells, nk, nb, s);
        let sc = crate::encode::cells::super_cells(cells, s);
        let words = (grid[0] * grid[1] * nw) as u64 * (W::BITS / 8) as u64;
        words + if s > 1 { PackedCodes::bytes_for(nb, sc[0], sc[1] * nk) } else { 0 }
    }

    /// Packs `codes` with super-cell size `s` (1..=[`MAX_CELL`]), unsheared.
    pub fn from_codes(codes: &CellCodes, s: usize) -> Self {
        let s = s.clamp(1, MAX_CELL);
        let layout = Self::layout(codes.cells, codes.nk, codes.nb, s);
        let (cells, sc, bbox) = codes.supercells(s);
        let mut m = Self::with_codes(s, codes.nb, cells, codes.nk, layout, sc, bbox);
        m.scatter();
        m
    }

    /// The one-bit mask of the super cells whose code is at least `c`
    /// (`1 ≤ c < 2^nb`), at the same cell size, layout *and shear*: each
    /// depth row's slots compared at once, a word at a time, the unsheared
    /// codes likewise ([`PackedCodes::at_least`]). It equals the mask
    /// [`BinaryMask::from_codes`] packs from one-bit codes "code ≥ c" sheared
    /// to the same state, since a super cell's code is the highest of its
    /// cells'. With threshold codes, one tissue preset's mask: the same rays'
    /// candidates as this mask with that preset's [`Matcher`], from a code
    /// width's fraction of the words, and no shear to catch up.
    pub fn at_least(&self, c: u8) -> Self {
        assert!(c >= 1 && (c as u32) < (1 << self.nb), "code {c} of {} bits", self.nb);
        if self.nb == 1 {
            return self.clone();
        }
        let codes = std::sync::Arc::new(self.codes.at_least(c));
        let bbox = crate::encode::cells::slice_boxes(&codes, self.cells, self.nk);
        let nw = self.nk.div_ceil(W::BITS as usize).max(1);
        let mut m = Self::with_codes(self.s, 1, self.cells, self.nk, (self.vpad, self.pad, self.grid, nw), codes, bbox);
        m.off.clone_from(&self.off);
        m.cpu = self.cpu;
        m.fused = self.fused;
        let (nb, cnw) = (self.nb, self.nw);
        // (slot 0 is the most significant bits: a group's first word fills the top)
        let per = W::BITS / nb;
        m.words.par_chunks_mut(nw * self.grid[0]).zip(self.words.par_chunks(cnw * self.grid[0])).for_each(|(out, src)| {
            for (o, row) in out.chunks_mut(nw).zip(src.chunks(cnw)) {
                if row.iter().all(|w| *w == W::ZERO) {
                    continue;
                }
                for (ow, ws) in o.iter_mut().zip(row.chunks(nb as usize)) {
                    *ow = W::from_u64(group_flags(ws.iter().map(|w| w.as_u64()), nb, c, per, true));
                }
            }
        });
        m
    }

    /// A mask of super-cell codes `codes` (`cells` super cells along i and
    /// j, `nk` slices of `nb` bits) and their slices' boxes, laid out as
    /// [`BinaryMask::layout`] gives it, with every word zero.
    fn with_codes(
        s: usize,
        nb: u32,
        cells: [usize; 2],
        nk: usize,
        (vpad, pad, grid, nw): (usize, usize, [usize; 2], usize),
        sc: std::sync::Arc<PackedCodes>,
        bbox: Vec<Option<[usize; 4]>>,
    ) -> Self {
        BinaryMask {
            s,
            nb,
            cells,
            nk,
            vpad,
            pad,
            grid,
            nw,
            words: vec![W::ZERO; grid[0] * grid[1] * nw],
            codes: sc,
            bbox,
            off: [vec![pad as i32; nk], vec![pad as i32; nk]],
            up: vec![W::ZERO; nw],
            down: vec![W::ZERO; nw],
            keep: vec![W::ZERO; nw],
            target: [vec![0; nk], vec![0; nk]],
            prev_off: [vec![0; nk], vec![0; nk]],
            cpu: kernels::level(),
            fused: true,
            moves: std::array::from_fn(|_| vec![W::ZERO; nw]),
            terms: vec![(0, W::ZERO); nw * MOVE_TERMS],
            term_used: vec![0; nw],
            move_bufs: Vec::new(),
            dist_masks: Vec::new(),
            occupancy: Default::default(),
        }
    }

    /// Super-cell size.
    pub fn cell_size(&self) -> usize {
        self.s
    }
    /// Chooses the shift kernels by CPU level, capped by what the CPU has
    /// ([`kernels::detected`]): [`CpuLevel::Avx2`] runs them compiled for
    /// AVX2, [`CpuLevel::Scalar`] the plain build's. Every level gives the same
    /// words; the default is [`kernels::level`] (the renderer sets
    /// [`crate::render::Settings::cpu`]), lower levels exist so tests and
    /// benches can compare the kernels.
    pub fn set_cpu_level(&mut self, cpu: CpuLevel) {
        self.cpu = cpu.capped();
    }

    /// The CPU level the shift kernels run at (after capping).
    pub fn cpu_level(&self) -> CpuLevel {
        self.cpu
    }

    /// `true` (the default) fuses two incremental steps into one pass over the
    /// words wherever the target is two or more bits away; `false` makes every
    /// step a pass of its own. The same words either way (tests compare them).
    pub fn set_fused(&mut self, on: bool) {
        self.fused = on;
    }

    /// Bits per code.
    pub fn code_width(&self) -> u32 {
        self.nb
    }
    /// Grid size `[width, height]` in super columns.
    pub fn grid(&self) -> [usize; 2] {
        self.grid
    }
    /// Padding on each side, in super cells.
    pub fn pad(&self) -> usize {
        self.pad
    }
    /// Words per depth row.
    pub fn words_per_row(&self) -> usize {
        self.nw
    }
    /// Slices.
    pub fn slices(&self) -> usize {
        self.nk
    }
    /// Super cells along i and j.
    pub fn cells(&self) -> [usize; 2] {
        self.cells
    }
    /// The depth row of grid column `(p, q)`.
    #[inline(always)]
    pub fn row(&self, p: usize, q: usize) -> &[W] {
        let s = self.row_start(p, q);
        &self.words[s..s + self.nw]
    }
    /// Where the depth row of grid column `(p, q)` starts in [`BinaryMask::words`].
    #[inline(always)]
    pub fn row_start(&self, p: usize, q: usize) -> usize {
        (q * self.grid[0] + p) * self.nw
    }
    /// The depth row that ray `(p, q)` of the intermediate image reads.
    #[inline(always)]
    pub fn ray_row(&self, p: usize, q: usize) -> &[W] {
        let (sp, sq) = self.ray_column(p, q);
        self.row(sp, sq)
    }
    /// The super column `sp` of ray `p` and how many rays `p, p + 1, …` in a row
    /// read it before the next column starts (1..=s): lets a row of rays step
    /// from column to column without a division per ray.
    #[inline]
    pub fn column_run(&self, p: usize) -> (usize, usize) {
        let s = self.s as i64;
        let x = p as i64 - self.vpad as i64;
        ((x.div_euclid(s) + self.pad as i64) as usize, (s - x.rem_euclid(s)) as usize)
    }
    /// The super column of ray `(p, q)`: `floor((p − pad)/s) + PAD`.
    #[inline(always)]
    pub fn ray_column(&self, p: usize, q: usize) -> (usize, usize) {
        let s = self.s as i64;
        let a = (p as i64 - self.vpad as i64).div_euclid(s) + self.pad as i64;
        let b = (q as i64 - self.vpad as i64).div_euclid(s) + self.pad as i64;
        (a as usize, b as usize)
    }
    /// All words (for comparisons in tests).
    pub fn words(&self) -> &[W] {
        &self.words
    }
    /// Bytes of the packed, sheared array.
    pub fn bytes(&self) -> usize {
        self.words.len() * W::BITS as usize / 8
    }
    /// Bytes this mask holds beyond the cell codes it shares: the words, plus
    /// its own super-cell codes when the cell size is above 1.
    pub fn held_bytes(&self) -> usize {
        self.bytes() + if self.s > 1 { self.codes.bytes() } else { 0 }
    }
    /// Bytes of the super-cell codes it reads (shared with the cell codes at
    /// cell size 1).
    pub fn code_bytes(&self) -> usize {
        self.codes.bytes()
    }
    /// The unsheared code of super cell `(si, sj, k)`.
    pub fn code(&self, si: usize, sj: usize, k: usize) -> u8 {
        self.codes.get(k * self.cells[1] + sj, si)
    }
    /// True when the unsheared super cell has a non-zero code.
    pub fn cell(&self, si: usize, sj: usize, k: usize) -> bool {
        self.code(si, sj, k) != 0
    }
    /// The cells `[ci0, ci1, cj0, cj1]` of slice `k` that may have a non-zero
    /// code (a super cell's span, so possibly reaching past the volume's
    /// cells), or `None` when the slice has none.
    pub fn slice_cells(&self, k: usize) -> Option<[i64; 4]> {
        let s = self.s as i64;
        self.bbox[k]
            .map(|[i0, i1, j0, j1]| [s * i0 as i64 - (s - 1), s * i1 as i64 + s - 1, s * j0 as i64 - (s - 1), s * j1 as i64 + s - 1])
    }
    /// Current super offsets `F[k]` of each slice along i and j.
    pub fn floors(&self) -> [Vec<i32>; 2] {
        [0, 1].map(|a| self.off[a].iter().map(|o| self.pad as i32 - o).collect())
    }

    /// The occupied rectangle of the grid for the given offsets, if any code is set.
    fn occupied(&self, off: &[Vec<i32>; 2]) -> Option<Rect> {
        let mut r: Option<Rect> = None;
        for (k, bb) in self.bbox.iter().enumerate() {
            if let Some([i0, i1, j0, j1]) = *bb {
                let (oi, oj) = (off[0][k], off[1][k]);
                let s = Rect {
                    p0: (i0 as i32 + oi) as usize,
                    p1: (i1 as i32 + oi) as usize,
                    q0: (j0 as i32 + oj) as usize,
                    q1: (j1 as i32 + oj) as usize,
                };
                r = Rect::union(r, Some(s));
            }
        }
        r
    }

    /// The occupied rectangle in the current state, in super columns.
    pub fn occupied_rect(&self) -> Option<Rect> {
        self.occupied(&self.off)
    }

    /// The rays of the intermediate image whose super column is occupied.
    pub fn occupied_rays(&self, inter: [usize; 2]) -> Option<Rect> {
        let r = self.occupied_rect()?;
        let s = self.s as i64;
        // P = floor((p − vpad)/s) + PAD  ⇔  p ∈ [(P − PAD)·s + vpad, (P − PAD)·s + vpad + s − 1]
        let lo = |pp: usize| (pp as i64 - self.pad as i64) * s + self.vpad as i64;
        let p0 = lo(r.p0).max(0) as usize;
        let q0 = lo(r.q0).max(0) as usize;
        let p1 = (lo(r.p1) + s - 1).min(inter[0] as i64 - 1);
        let q1 = (lo(r.q1) + s - 1).min(inter[1] as i64 - 1);
        if p1 < p0 as i64 || q1 < q0 as i64 {
            return None;
        }
        Some(Rect { p0, p1: p1 as usize, q0, q1: q1 as usize })
    }

    /// Target offsets of a state; panics only if the state is not for this mask.
    #[allow(clippy::needless_range_loop)] // the index picks one axis of several arrays
    fn offsets_for(&self, state: &ShearState, out: &mut [Vec<i32>; 2]) {
        assert_eq!(state.slices(), self.nk, "shear state for a different slice count");
        for a in 0..2 {
            for (o, &f) in out[a].iter_mut().zip(&state.floor[a]) {
                // F = ceil(f / s)
                let v = self.pad as i32 + (-f).div_euclid(self.s as i32);
                // pad covers |floor| ≤ ceil((nk-1)/2)+1: a principal-axis view never exceeds it
                assert!(v >= 0 && v as usize + self.cells[a] <= self.grid[a], "shear beyond 45° for this mask");
                *o = v;
            }
        }
    }

    /// Moves the mask to `state`: incrementally when every slice is at most
    /// [`MAX_INCREMENTAL_STEPS`] super cells away, else by a direct shear.
    pub fn shear_to(&mut self, state: &ShearState) -> ShearWork {
        let mut target = std::mem::take(&mut self.target);
        self.offsets_for(state, &mut target);
        let dist = (0..2).flat_map(|a| self.off[a].iter().zip(&target[a]).map(|(x, y)| (x - y).unsigned_abs())).max().unwrap_or(0);
        let work = if dist == 0 {
            ShearWork::default()
        } else if dist <= MAX_INCREMENTAL_STEPS {
            let mut w = ShearWork::default();
            let (nw, m) = (self.nw, MAX_INCREMENTAL_STEPS as i32);
            let along = |o: &[i32], t: &[i32]| o.iter().zip(t).map(|(x, y)| (x - y).unsigned_abs()).max().unwrap_or(0);
            let along_i = along(&self.off[0], &target[0]);
            // the old word of column p − d sits at (p − ps + m − d)·nw + w in
            // the row buffer (zero margins of m columns on both sides)
            if self.fused
                && nw > MAX_FUSED_COLUMN
                && along_i >= MIN_ONE_PASS_BITS
                && let Some(t) = self.word_terms(0, &target[0], |d, w| (m - d) as usize * nw + w)
            {
                w.words += match t {
                    0 | 1 => self.move_columns::<1>(&target[0]),
                    2 => self.move_columns::<2>(&target[0]),
                    3 => self.move_columns::<3>(&target[0]),
                    _ => self.move_columns::<MOVE_TERMS>(&target[0]),
                };
                w.steps += along_i;
            }
            let along_j = along(&self.off[1], &target[1]);
            // along j a term names its distance: d + m
            if self.fused
                && nw > MAX_FUSED_COLUMN
                && along_j >= MIN_ONE_PASS_BITS
                && self.word_terms(1, &target[1], |d, _| (d + m) as usize).is_some()
            {
                w.words += self.move_rows(&target[1]);
                w.steps += along_j;
            }
            let mut left = (0..2).flat_map(|a| self.off[a].iter().zip(&target[a]).map(|(x, y)| (x - y).unsigned_abs())).max().unwrap_or(0);
            while left > 0 {
                let by = if self.fused && left >= 2 && self.nw <= MAX_FUSED_COLUMN { 2 } else { 1 };
                w.words += self.step_towards(&target, by as i32);
                w.steps += by;
                left -= by;
            }
            w
        } else {
            self.staged(&target)
        };
        self.target = target;
        work
    }

    /// Moves the mask to `state` by a direct shear (the reset): clear the occupied
    /// region, then scatter every code to its target position.
    pub fn shear_direct(&mut self, state: &ShearState) -> ShearWork {
        let mut target = std::mem::take(&mut self.target);
        self.offsets_for(state, &mut target);
        let w = self.direct(&target);
        self.target = target;
        w
    }

    /// Moves the mask to `target` in stages of powers of two: per axis, per
    /// bit of the largest distance and per direction, the slices whose
    /// distance has that bit move by it in one in-place pass over the occupied
    /// rectangle ([`move_columns`], [`move_rows`]). A slice moves only towards
    /// its target, so its bits stay between where they were and where they go
    /// (inside the grid), and slices never share a slot: the result is the
    /// direct shear's, word for word (tested against [`BinaryMask::shear_direct`]).
    /// About `2·log2(distance)` passes over the rectangle instead of a scatter
    /// of every code.
    #[allow(clippy::needless_range_loop)] // the index picks one axis of several arrays
    fn staged(&mut self, target: &[Vec<i32>; 2]) -> ShearWork {
        let (nb, nw) = (self.nb, self.nw);
        let mut w = ShearWork { steps: 0, direct: 1, words: 0 };
        let mut mv = std::mem::take(&mut self.up);
        for a in 0..2 {
            let dist = self.off[a].iter().zip(&target[a]).map(|(o, t)| (t - o).unsigned_abs()).max().unwrap_or(0);
            let mut t = 1u32;
            while t <= dist {
                for dir in [1i32, -1] {
                    mv.fill(W::ZERO);
                    let before = self.occupied_rect();
                    let mut any = false;
                    for (k, (o, &g)) in self.off[a].iter_mut().zip(&target[a]).enumerate() {
                        let d = g - *o;
                        if d.signum() == dir && d.unsigned_abs() & t != 0 {
                            mv[k / (W::BITS / nb) as usize] |= crate::encode::depth::slot_mask::<W>(nb, k);
                            *o += dir * t as i32;
                            any = true;
                        }
                    }
                    let Some(r) = Rect::union(before, self.occupied_rect()).filter(|_| any) else { continue };
                    let gw = self.grid[0];
                    let (ps, pe) = (r.p0, r.p1.min(gw - 1));
                    let rows = &mut self.words[r.q0 * gw * nw..(r.q1 + 1) * gw * nw];
                    if a == 0 {
                        let (t, up, mv, avx2) = (t as usize, dir > 0, &mv[..], self.cpu.has_avx2());
                        let tasks = rows.par_chunks_mut(gw * nw);
                        by_column_length!(@arms nw, N, tasks.for_each(|row| {
                                #[cfg(target_arch = "x86_64")]
                                if avx2 {
                                    // SAFETY: `self.cpu` is always capped to at most
                                    // `kernels::detected()`, which is `Avx2` only when AVX2
                                    // was detected on this CPU at run time, all the kernel
                                    // requires; its body is the safe `move_columns_n`.
                                    unsafe { move_columns_n_avx2::<W, N>(row, ps, pe, t, mv, up) };
                                    return;
                                }
                                let _ = avx2;
                                move_columns_n::<W, N>(row, ps, pe, t, mv, up)
                            }),
                            tasks.for_each(|row| move_columns(row, nw, ps, pe, t, mv, up)), [1 2 3 4]);
                    } else {
                        let m = RowMove { row_len: gw * nw, span: [ps * nw, (pe + 1) * nw], qs: [r.q0, r.q1], t: t as usize, up: dir > 0 };
                        let avx2 = self.cpu.has_avx2();
                        let words = &mut self.words;
                        by_column_length!(@arms nw, N, {
                                #[cfg(target_arch = "x86_64")]
                                if avx2 {
                                    // SAFETY: `self.cpu` is always capped to at most
                                    // `kernels::detected()`, which is `Avx2` only when AVX2
                                    // was detected on this CPU at run time, all the kernel
                                    // requires; its body is the safe `move_rows_n`.
                                    unsafe { move_rows_n_avx2::<W, N>(words, m, &mv) };
                                } else {
                                    move_rows_n::<W, N>(words, m, &mv);
                                }
                                #[cfg(not(target_arch = "x86_64"))]
                                {
                                    let _ = avx2;
                                    move_rows_n::<W, N>(words, m, &mv);
                                }
                            },
                            move_rows(words, m, &mv), [1 2 3 4]);
                    }
                    w.words += ((r.q1 - r.q0 + 1) * (pe - ps + 1) * nw) as u64;
                }
                t <<= 1;
            }
        }
        debug_assert!(self.off == *target);
        self.up = mv;
        w
    }

    #[allow(clippy::needless_range_loop)] // the index picks one axis of several arrays
    fn direct(&mut self, target: &[Vec<i32>; 2]) -> ShearWork {
        let mut words = 0;
        if let Some(r) = self.occupied_rect() {
            let nw = self.nw;
            for q in r.q0..=r.q1 {
                let s = (q * self.grid[0] + r.p0) * nw;
                let e = (q * self.grid[0] + r.p1 + 1) * nw;
                self.words[s..e].fill(W::ZERO);
                words += (e - s) as u64;
            }
        }
        for a in 0..2 {
            self.off[a].copy_from_slice(&target[a]);
        }
        self.scatter();
        ShearWork { steps: 0, direct: 1, words }
    }

    /// Writes every code at its current offset (the grid must be clear there).
    fn scatter(&mut self) {
        let [_, cj_n] = self.cells;
        let (gw, nw, nk, nb) = (self.grid[0], self.nw, self.nk, self.nb);
        let slots = (W::BITS / nb) as usize;
        let (codes, off, bbox) = (&self.codes, &self.off, &self.bbox);
        // parallel over grid rows q: each row's words are written by one task
        self.words.par_chunks_mut(gw * nw).enumerate().for_each(|(q, row)| {
            for k in 0..nk {
                let Some([i0, i1, j0, j1]) = bbox[k] else { continue };
                let cj = q as i32 - off[1][k];
                if cj < j0 as i32 || cj > j1 as i32 {
                    continue;
                }
                let cj = cj as usize;
                debug_assert!(cj < cj_n);
                let shift = slot_shift::<W>(nb, (k % slots) as u32);
                let w = k / slots;
                let o = off[0][k];
                codes.for_each_nonzero(k * cj_n + cj, i0, i1, |ci, c| {
                    let p = (ci as i32 + o) as usize;
                    row[p * nw + w] |= W::from_u64(c as u64) << shift;
                });
            }
        });
    }

    /// One incremental step (`by` = 1), or two fused into one pass (`by` = 2):
    /// every slice moves at most `by` super columns along i and `by` super rows
    /// along j towards `target`. Returns the words touched.
    fn step_towards(&mut self, target: &[Vec<i32>; 2], by: i32) -> u64 {
        let before = self.occupied_rect();
        let mut next = std::mem::take(&mut self.off);
        let mut prev = std::mem::take(&mut self.prev_off);
        for a in 0..2 {
            prev[a].copy_from_slice(&next[a]);
        }
        for a in 0..2 {
            for (o, &t) in next[a].iter_mut().zip(&target[a]) {
                *o += (t - *o).clamp(-by, by);
            }
        }
        let after = self.occupied(&next);
        let Some(r) = Rect::union(before, after) else {
            self.off = next;
            self.prev_off = prev;
            return 0;
        };
        let mut touched = 0;
        if by == 2 {
            for a in 0..2 {
                if shift_vectors2(self.nb, &prev[a], &next[a], &mut self.moves) > 0 {
                    touched += if a == 0 { self.shift_columns2(r) } else { self.shift_rows2(r) };
                }
            }
            self.off = next;
            self.prev_off = prev;
            return touched;
        }
        // along i (columns p)
        if shift_vectors(self.nb, &prev[0], &next[0], &mut self.up, &mut self.down) > 0 {
            self.set_keep();
            touched += self.shift_columns(r);
        }
        // along j (rows q)
        if shift_vectors(self.nb, &prev[1], &next[1], &mut self.up, &mut self.down) > 0 {
            self.set_keep();
            touched += self.shift_rows(r);
        }
        self.off = next;
        self.prev_off = prev;
        touched
    }

    fn set_keep(&mut self) {
        for ((k, u), d) in self.keep.iter_mut().zip(&self.up).zip(&self.down) {
            *k = !(*u | *d);
        }
    }

    /// `new[p] = old[p] & keep | old[p−1] & up | old[p+1] & down` over the rect,
    /// one grid row per task. Columns of 1 to 16 words (depths up to 1024
    /// slices in u64, 256 of 4-bit codes) run a kernel with the column length
    /// fixed at compile time ([`shift_columns_n`]): no inner loop to mispredict, the words of a column
    /// combined in registers. Longer columns run [`shift_columns_any`].
    fn shift_columns(&mut self, r: Rect) -> u64 {
        let nw = self.nw;
        let gw = self.grid[0];
        let (up, down, keep) = (&self.up[..], &self.down[..], &self.keep[..]);
        let (ps, pe) = (r.p0, r.p1.min(gw - 1));
        let rows = &mut self.words[r.q0 * gw * nw..(r.q1 + 1) * gw * nw];
        let tasks = rows.par_chunks_mut(gw * nw);
        let avx2 = self.cpu.has_avx2();
        by_column_length!(nw, N => tasks.for_each(|row| {
                #[cfg(target_arch = "x86_64")]
                if avx2 {
                    // SAFETY: `self.cpu` is always capped (`set_cpu_level`,
                    // `kernels::level`) to at most `kernels::detected()`, which
                    // is `Avx2` only when AVX2 was detected on this CPU at run
                    // time, all the kernel requires; its body is the safe
                    // `shift_columns_n`.
                    unsafe { shift_columns_n_avx2::<W, N>(row, ps, pe, up, down, keep) };
                    return;
                }
                let _ = avx2;
                shift_columns_n::<W, N>(row, ps, pe, up, down, keep)
            }),
            _ => tasks.for_each(|row| shift_columns_any(row, nw, ps, pe, up, down, keep)));
        ((r.q1 - r.q0 + 1) * (pe - ps + 1) * nw) as u64
    }

    /// `new[q] = old[q] & keep | old[q−1] & up | old[q+1] & down` over the rect
    /// ([`BinaryMask::row_bands`]); columns of 1 to 16 words run with the
    /// column length fixed at compile time, longer ones a chunk of words at a
    /// time ([`shift_row_chunks`]).
    fn shift_rows(&mut self, r: Rect) -> u64 {
        let nw = self.nw;
        let (up, down, keep) = (std::mem::take(&mut self.up), std::mem::take(&mut self.down), std::mem::take(&mut self.keep));
        let avx2 = self.cpu.has_avx2();
        let words = by_column_length!(nw, N => self.row_bands::<1>(r, |row, [next, _], [prev, _]| {
            #[cfg(target_arch = "x86_64")]
            if avx2 {
                // SAFETY: as in `shift_columns`: `self.cpu <= kernels::detected()`,
                // so AVX2 was detected at run time.
                unsafe { shift_row_n_avx2::<W, N>(row, next, prev, &up, &down, &keep) };
                return;
            }
            let _ = avx2;
            shift_row_n::<W, N>(row, next, prev, &up, &down, &keep)
        }),
        _ => by_column_chunk!(nw, C => self.row_bands::<1>(r, |row, [next, _], [prev, _]| {
            #[cfg(target_arch = "x86_64")]
            if avx2 {
                // SAFETY: as in `shift_columns`: `self.cpu <= kernels::detected()`,
                // so AVX2 was detected at run time.
                unsafe { shift_row_chunks_avx2::<W, C>(row, next, prev, nw, [&up, &down, &keep]) };
                return;
            }
            shift_row_chunks::<W, C>(row, next, prev, nw, [&up, &down, &keep])
        })));
        (self.up, self.down, self.keep) = (up, down, keep);
        words
    }

    /// Splits `nrows` grid rows into bands, one a thread of the current pool
    /// (the render's split of its rows): the rows a band and the bands, with
    /// a buffer each in `move_bufs` (grown once, then reused).
    fn thread_bands(&mut self, nrows: usize) -> (usize, usize) {
        let band = nrows.div_ceil(rayon::current_num_threads().clamp(1, nrows.max(1)));
        let bands = nrows.div_ceil(band);
        if self.move_bufs.len() < bands {
            self.move_bufs.resize_with(bands, Vec::new);
        }
        (band, bands)
    }

    /// Runs `kernel` over grid rows `r.q0..=r.q1` of the mask (the words of
    /// columns `r.p0..=r.p1` of each), in place from the top, where a row's new
    /// words depend on the old words of the `D` (1 or 2) rows before and after
    /// it: the kernel gets the row, the old rows after it (`[q + 1, q + 2]`;
    /// zeros past the grid) and before it (`[q − 1, q − 2]`, zeros before the
    /// grid), which it must rotate (the row's old words into `prev[0]`, the
    /// old `prev[0]` into `prev[1]`). The rows run in bands, one task each, as
    /// the render splits its rows (so a band's words stay in the cache of the
    /// thread that reads them next); the old rows around each band are copied
    /// before any band moves. Returns the words touched.
    fn row_bands<const D: usize>(&mut self, r: Rect, kernel: impl Fn(&mut [W], [&[W]; 2], [&mut [W]; 2]) + Sync) -> u64 {
        let (nw, gw, gh) = (self.nw, self.grid[0], self.grid[1]);
        let (ps, pe) = (r.p0 * nw, (r.p1 + 1).min(gw) * nw);
        let (len, row_len) = (pe - ps, gw * nw);
        let nrows = r.q1 - r.q0 + 1;
        let (band, bands) = self.thread_bands(nrows);
        // per band: old rows qa − 1, qa − 2, qe, qe + 1 (its first row qa, one
        // past its last qe), zeros outside the grid
        for (b, buf) in self.move_bufs[..bands].iter_mut().enumerate() {
            let (qa, qe) = (r.q0 + b * band, (r.q0 + (b + 1) * band).min(r.q1 + 1));
            buf.clear();
            for q in [qa.checked_sub(1), qa.checked_sub(2), Some(qe), Some(qe + 1)] {
                match q.filter(|&q| q < gh) {
                    Some(q) => buf.extend_from_slice(&self.words[q * row_len + ps..q * row_len + pe]),
                    None => buf.resize(buf.len() + len, W::ZERO),
                }
            }
        }
        let rows = &mut self.words[r.q0 * row_len..(r.q1 + 1) * row_len];
        rows.par_chunks_mut(band * row_len).zip(self.move_bufs[..bands].par_iter_mut()).for_each(|(rows, buf)| {
            let n = rows.len() / row_len;
            let (prev, after) = buf.split_at_mut(2 * len);
            let (p1, p2) = prev.split_at_mut(len);
            let (p2, after) = (&mut p2[..len], &after[..2 * len]);
            for t in 0..n {
                let (head, tail) = rows.split_at_mut((t + 1) * row_len);
                let row = &mut head[t * row_len + ps..t * row_len + pe];
                // old row t + 1 + x: in the band (not yet moved) or after it
                let next = |x: usize| {
                    if t + 1 + x < n { &tail[x * row_len + ps..x * row_len + pe] } else { &after[(t + 1 + x - n) * len..][..len] }
                };
                let next2 = if D == 2 { next(1) } else { &after[..0] };
                kernel(row, [next(0), next2], [&mut *p1, &mut *p2]);
            }
        });
        (nrows * len) as u64
    }

    /// Fills `terms` for a move of every slice along `axis` from its offset
    /// to `target`, each term as `(at(d, w), slots)` for the slots of word `w`
    /// moving by `d`; the most terms a word needs, or `None` when some word's
    /// slots move by more than [`MOVE_TERMS`] distances. A term of no slots
    /// (`at(0, w)`, nothing kept) pads the rest.
    fn word_terms(&mut self, axis: usize, target: &[i32], at: impl Fn(i32, usize) -> usize) -> Option<usize> {
        let (nw, nb) = (self.nw, self.nb);
        let slots = (W::BITS / nb) as usize;
        for w in 0..nw {
            self.terms[w * MOVE_TERMS..(w + 1) * MOVE_TERMS].fill((at(0, w), W::ZERO));
        }
        let used = &mut self.term_used;
        used.fill(0);
        for (k, (&o, &t)) in self.off[axis].iter().zip(target).enumerate() {
            let (d, w) = (t - o, k / slots);
            debug_assert!(d.unsigned_abs() <= MAX_INCREMENTAL_STEPS);
            let at = at(d, w);
            let terms = &mut self.terms[w * MOVE_TERMS..(w + 1) * MOVE_TERMS];
            let slot = crate::encode::depth::slot_mask::<W>(nb, k);
            match terms[..used[w]].iter_mut().find(|t| t.0 == at) {
                Some(t) => t.1 |= slot,
                None if used[w] < MOVE_TERMS => {
                    terms[used[w]] = (at, slot);
                    used[w] += 1;
                }
                None => return None,
            }
        }
        used.iter().copied().max()
    }

    /// The rectangle a move of every slice along `axis` to `target` touches:
    /// the occupied rectangles before and after it, joined (`None`: the mask
    /// is empty).
    fn move_rect(&mut self, axis: usize, target: &[i32]) -> Option<Rect> {
        let before = self.occupied_rect();
        // (`prev_off` is scratch between steps)
        let mut next = std::mem::take(&mut self.prev_off);
        for (a, n) in next.iter_mut().enumerate() {
            n.copy_from_slice(if a == axis { target } else { &self.off[a] });
        }
        let after = self.occupied(&next);
        self.prev_off = next;
        Rect::union(before, after)
    }

    /// Moves every slice along i to `target` in one pass over the occupied
    /// rectangle, one grid row per task: word `w` of column `p` becomes
    /// `OR_d old[p − d][w] & slots_d[w]` over the (at most [`MOVE_TERMS`])
    /// distances its slots move by ([`BinaryMask::word_terms`] filled
    /// them; `T` of them, the busiest word's), read from a copy of the row's
    /// old columns between zero margins. The steps' words, and the direct
    /// shear's (tested against both).
    fn move_columns<const T: usize>(&mut self, target: &[i32]) -> u64 {
        let Some(r) = self.move_rect(0, target) else {
            self.off[0].copy_from_slice(target);
            return 0;
        };
        let (nw, gw, m) = (self.nw, self.grid[0], MAX_INCREMENTAL_STEPS as usize);
        let (ps, pe) = (r.p0, r.p1.min(gw - 1));
        let cols = pe - ps + 1;
        let terms = &self.terms[..];
        // bands of grid rows, a row buffer each (grown once, then reused)
        let nrows = r.q1 - r.q0 + 1;
        let bands = (rayon::current_num_threads() * 4).min(nrows);
        let band = nrows.div_ceil(bands);
        if self.move_bufs.len() < bands {
            self.move_bufs.resize_with(bands, Vec::new);
        }
        let rows = &mut self.words[r.q0 * gw * nw..(r.q1 + 1) * gw * nw];
        rows.par_chunks_mut(band * gw * nw).zip(self.move_bufs.par_iter_mut()).for_each(|(rows, old)| {
            for row in rows.chunks_exact_mut(gw * nw) {
                // columns outside [ps, pe] hold nothing before the move
                old.clear();
                old.resize(m * nw, W::ZERO);
                old.extend_from_slice(&row[ps * nw..(pe + 1) * nw]);
                old.resize((cols + 2 * m) * nw, W::ZERO);
                for (p, out) in row[ps * nw..(pe + 1) * nw].chunks_exact_mut(nw).enumerate() {
                    let old = &old[p * nw..];
                    for (o, t) in out.iter_mut().zip(terms.chunks_exact(MOVE_TERMS)) {
                        // (offsets are below (2m + 1)·nw: inside `old` from column p on)
                        *o = t[..T].iter().fold(W::ZERO, |acc, &(at, slots)| acc | (old[at] & slots));
                    }
                }
            }
        });
        self.off[0].copy_from_slice(target);
        (r.q1 - r.q0 + 1) as u64 * (cols * nw) as u64
    }

    /// Moves every slice along j to `target` in one pass over the occupied
    /// rectangle: word `w` of row `q` becomes `OR_d old[q − d][w] & slots_d[w]`
    /// over its terms ([`BinaryMask::word_terms`]). The rectangle's
    /// rows are split into bands, one task each, as the render splits its
    /// rows (so a band's words stay in the cache of the thread that reads them
    /// next), that go down their rows: a row's old words are kept in the
    /// band's ring (as deep as the largest forward move) before they are
    /// overwritten, the rows below are still old, the old rows just before
    /// and after the band are copied before any band moves, and rows outside
    /// the rectangle read as zero. A row looks up once where the old row of
    /// each distance its slots move by is, then builds each column in
    /// registers from those rows ([`move_row_n`]; a column longer than 16
    /// words a chunk at a time, [`move_row_chunks`]) and writes it once. The
    /// steps' words, and the direct shear's (tested against both).
    fn move_rows(&mut self, target: &[i32]) -> u64 {
        let Some(r) = self.move_rect(1, target) else {
            self.off[1].copy_from_slice(target);
            return 0;
        };
        let (nw, gw, m) = (self.nw, self.grid[0], MAX_INCREMENTAL_STEPS as usize);
        let (ps, pe) = (r.p0, r.p1.min(gw - 1));
        let (q0, q1, width, row_len) = (r.q0, r.q1, (pe - ps + 1) * nw, gw * nw);
        // per distance index i (d = i − m): the slots of each word moving by
        // d, and whether any slot does
        let masks = &mut self.dist_masks;
        masks.clear();
        masks.resize(SPAN * nw, W::ZERO);
        let mut any = [false; SPAN];
        for (x, &(i, slots)) in self.terms.iter().enumerate() {
            if slots != W::ZERO {
                masks[i * nw + x / MOVE_TERMS] |= slots;
                any[i] = true;
            }
        }
        // the farthest rows a distance reads: above (moving down, d > 0) and below
        let used = || (0..SPAN).filter(|&i| any[i]);
        let forward = used().map(|i| i.saturating_sub(m)).max().unwrap_or(0);
        let backward = used().map(|i| m.saturating_sub(i)).max().unwrap_or(0);
        let depth = forward + 1;
        let (band, bands) = self.thread_bands(q1 - q0 + 1);
        // per band (rows qa..qe): its ring, holding the old rows qa − forward
        // .. qa − 1 at their slots; the old rows qe .. qe + backward − 1
        for (b, buf) in self.move_bufs[..bands].iter_mut().enumerate() {
            let (qa, qe) = (q0 + b * band, (q0 + (b + 1) * band).min(q1 + 1));
            buf.clear();
            buf.resize((depth + backward) * width, W::ZERO);
            for q in qa.saturating_sub(forward).max(q0)..qa {
                buf[(q % depth) * width..][..width].copy_from_slice(&self.words[q * row_len + ps * nw..][..width]);
            }
            for (x, q) in (qe..(qe + backward).min(q1 + 1)).enumerate() {
                buf[(depth + x) * width..][..width].copy_from_slice(&self.words[q * row_len + ps * nw..][..width]);
            }
        }
        let masks = &self.dist_masks[..];
        let rows = &mut self.words[q0 * row_len..(q1 + 1) * row_len];
        let avx2 = self.cpu.has_avx2();
        rows.par_chunks_mut(band * row_len).zip(self.move_bufs[..bands].par_iter_mut()).enumerate().for_each(|(b, (rows, buf))| {
            let (qa, n) = (q0 + b * band, rows.len() / row_len);
            let base = rows.as_mut_ptr();
            let bufp = buf.as_mut_ptr();
            let (ring, after) = (bufp, bufp.wrapping_add(depth * width));
            for t in 0..n {
                let q = qa + t;
                // SAFETY: every pointer below stays in its allocation: `base`
                // is this task's rows (`n` whole grid rows, of which columns
                // ps..=pe are the `width` words from `ps·nw`), `bufp` its buffer
                // of `depth + backward` rows of `width` words. Row `t` is
                // copied into the ring before it is written; the rows after
                // it in the band are only read, and written later; the ring's
                // and the after-rows' words are this task's own. A distance's
                // old row is read only where it lies in the rectangle and
                // within `forward` rows above or `backward` below (which the
                // ring and the copies hold). No reference into the rows or
                // the buffer is alive while they are read and written through
                // these raw pointers. Exercised by
                // `one_pass_moves_equal_the_steps_and_the_direct_shear` and
                // `row_bands_equal_the_direct_shear_for_any_thread_count`.
                let row = unsafe {
                    let row = base.add(t * row_len + ps * nw);
                    std::ptr::copy_nonoverlapping(row, ring.add((q % depth) * width), width);
                    std::slice::from_raw_parts_mut(row, width)
                };
                // distance d = i − m reads old row q − d: outside the
                // rectangle nothing; this row or above (moved already) in the
                // ring; in the band, the mask; after it, the copy
                let source = |i: usize| -> Option<&[W]> {
                    let sq = (q + m).wrapping_sub(i);
                    if sq < q0 || sq > q1 {
                        return None;
                    }
                    let at = if sq <= q {
                        ring.wrapping_add((sq % depth) * width)
                    } else if sq < qa + n {
                        base.wrapping_add((sq - qa) * row_len + ps * nw)
                    } else {
                        after.wrapping_add((sq - qa - n) * width)
                    };
                    // SAFETY: (as above) a row of `width` words in this task's
                    // rows or buffer, other than row q's words in the mask,
                    // read only while `row` is written
                    Some(unsafe { std::slice::from_raw_parts(at.cast_const(), width) })
                };
                // the row's sources: each old row a distance reads, with the
                // slots of each word that move from it
                let mut any: [MoveSourceAny<W>; SPAN] = [(&[], &[]); SPAN];
                let mut used_n = 0;
                for i in used() {
                    if let Some(src) = source(i) {
                        any[used_n] = (src, &masks[i * nw..][..nw]);
                        used_n += 1;
                    }
                }
                let any = &any[..used_n];
                by_column_length!(nw, N => {
                    let mut srcs: [MoveSource<W, N>; SPAN] = [(&[], fixed(&masks[..N])); SPAN];
                    for (to, &(src, slots)) in srcs.iter_mut().zip(any) {
                        *to = (src.as_chunks::<N>().0, fixed(slots));
                    }
                    let (row, _) = row.as_chunks_mut::<N>();
                    let srcs = &srcs[..any.len()];
                    #[cfg(target_arch = "x86_64")]
                    if avx2 {
                        // SAFETY: as in `shift_columns`: `self.cpu <= kernels::detected()`,
                        // so AVX2 was detected at run time.
                        unsafe { move_row_n_avx2::<W, N>(row, srcs) };
                        continue;
                    }
                    move_row_n::<W, N>(row, srcs)
                },
                // longer columns: built a chunk of words at a time
                _ => by_column_chunk!(nw, C => {
                    #[cfg(target_arch = "x86_64")]
                    if avx2 {
                        // SAFETY: as in `shift_columns`: `self.cpu <= kernels::detected()`,
                        // so AVX2 was detected at run time.
                        unsafe { move_row_chunks_avx2::<W, C>(row, nw, any) };
                        continue;
                    }
                    move_row_chunks::<W, C>(row, nw, any)
                }));
            }
        });
        self.off[1].copy_from_slice(target);
        (q1 - q0 + 1) as u64 * width as u64
    }

    /// Two steps along i in one pass: `new[p] = OR_d old[p − d] & moves[2 − d]`
    /// for d = +2..=−2 over the rect, one grid row per task; columns of 1 to
    /// [`MAX_FUSED_COLUMN`] words only (longer ones take two single steps: see `shear_to`).
    fn shift_columns2(&mut self, r: Rect) -> u64 {
        let nw = self.nw;
        let gw = self.grid[0];
        let (ps, pe) = (r.p0, r.p1.min(gw - 1));
        let moves = &self.moves;
        let rows = &mut self.words[r.q0 * gw * nw..(r.q1 + 1) * gw * nw];
        let tasks = rows.par_chunks_mut(gw * nw);
        let avx2 = self.cpu.has_avx2();
        by_column_length!(@arms nw, N, tasks.for_each(|row| {
                let m = moves.each_ref().map(|v| fixed::<W, N>(v));
                #[cfg(target_arch = "x86_64")]
                if avx2 {
                    // SAFETY: `self.cpu` is always capped to at most
                    // `kernels::detected()`, which is `Avx2` only when AVX2 was
                    // detected on this CPU at run time, all the kernel
                    // requires; its body is the safe `shift_columns2_n`.
                    unsafe { shift_columns2_n_avx2::<W, N>(row, ps, pe, m) };
                    return;
                }
                let _ = avx2;
                shift_columns2_n::<W, N>(row, ps, pe, m)
            }),
            unreachable!("fused steps only for columns of 1 to 4 words"), [1 2 3 4]);
        ((r.q1 - r.q0 + 1) * (pe - ps + 1) * nw) as u64
    }

    /// Two steps along j in one pass: `new[q] = OR_d old[q − d] & moves[2 − d]`
    /// ([`BinaryMask::row_bands`]).
    fn shift_rows2(&mut self, r: Rect) -> u64 {
        let moves = std::mem::take(&mut self.moves);
        let avx2 = self.cpu.has_avx2();
        let words = by_column_length!(@arms self.nw, N, self.row_bands::<2>(r, |row, [next1, next2], [prev1, prev2]| {
                let m = moves.each_ref().map(|v| fixed::<W, N>(v));
                #[cfg(target_arch = "x86_64")]
                if avx2 {
                    // SAFETY: as in `shift_columns`: `self.cpu <= kernels::detected()`,
                    // so AVX2 was detected at run time.
                    unsafe { shift_row2_n_avx2::<W, N>(row, next1, next2, prev1, prev2, m) };
                    return;
                }
                let _ = avx2;
                shift_row2_n::<W, N>(row, next1, next2, prev1, prev2, m)
            }),
            unreachable!("fused steps only for columns of 1 to 4 words"), [1 2 3 4]);
        self.moves = moves;
        words
    }

    /// Rebuilds the block occupancy of the mask, sheared to `state`, for
    /// matcher `m` (what the walks of a scaled plan's rays read: see
    /// [`crate::encode::walk`]), reusing its tables; without `tables` only the
    /// shear's fractions and the occupied slices (all a
    /// [`crate::encode::walk::StillWalk`] reads).
    pub fn update_occupancy(&mut self, m: &crate::encode::depth::Matcher, state: &ShearState, tables: bool) {
        let mut occ = std::mem::take(&mut self.occupancy);
        occ.build(self, m, state, tables);
        self.occupancy = occ;
    }

    /// The block occupancy last built by [`BinaryMask::update_occupancy`].
    pub fn occupancy(&self) -> &BlockOccupancy {
        &self.occupancy
    }

    /// One paper-style rotation step of `state` (see [`ShearState::rotated`]):
    /// the end slices move by `s` voxels (one super cell), applied incrementally.
    /// Returns the new state.
    pub fn rotate_step(&mut self, state: &ShearState, along: usize, dir: i32) -> ShearState {
        let next = state.rotated(along, dir * self.s as i32);
        self.shear_to(&next);
        next
    }
}

/// Rounding margin on the drift `u` (voxels): the maps are computed per slice
/// in f64, affine in `k` to far below this.
pub(crate) const MARGIN: f64 = 1e-7;

/// Blocks of slices per word of [`BlockOccupancy`]: a quarter word (16 slices
/// of a u64 1-bit mask) spans a narrower rectangle of columns than a word.
pub const BLOCKS_PER_WORD: usize = 4;

/// Per block of slices (a quarter of a word: [`BLOCKS_PER_WORD`]), a
/// summed-area table of the mask columns with a code the matcher accepts in
/// the block, over the occupied rectangle of the mask (see the module docs).
/// Built per frame, after the shear.
#[derive(Clone, Debug, Default)]
pub struct BlockOccupancy {
    /// The occupied rectangle, in super columns (None: nothing occupied).
    pub(crate) rect: Option<Rect>,
    /// Table row length: rectangle width + 1.
    pub(crate) stride: usize,
    /// Blocks (tables), interleaved: entry `(y, x)` of block `b` is
    /// `sums[(y · stride + x) · blocks + (b ^ 3)]`, so the blocks a ray tests one
    /// after the other at nearby columns share cache lines.
    pub(crate) blocks: usize,
    /// Slices per block (a power of two) and its log2.
    pub(crate) len: usize,
    pub(crate) log_len: u32,
    /// The slices with a non-zero code `[k0, k1]` (`k0 > k1`: none).
    pub(crate) slices: [usize; 2],
    /// Per block, the range of the fractional parts of its slices' shear
    /// translations, `[min_i, max_i, min_j, max_j]`: a sample's cell sits
    /// `floor(u + frac(trans))` columns from the ray's base (see [`ColumnWalk`](crate::encode::walk::ColumnWalk)).
    pub(crate) frac: Vec<[f64; 4]>,
    /// The union of the blocks' ranges, for [`StillWalk`](crate::encode::walk::StillWalk).
    pub(crate) all_frac: [f64; 4],
    /// The counts modulo 2^16 (a rectangle of fewer than 2^16 columns is
    /// exact; [`BlockOccupancy::any`] answers a larger one with a
    /// conservative "maybe"), each word's four blocks in reverse order (block
    /// `b` at `b ^ 3`: the order a little-endian store of the per-quarter
    /// counter lanes leaves them in).
    pub(crate) sums: Vec<u16>,
}

impl BlockOccupancy {
    /// Rebuilds the tables for `mask` in its current shear and matcher `m`,
    /// reusing the allocation; without `tables`, only the fractions and the
    /// occupied slices ([`StillWalk`](crate::encode::walk::StillWalk) reads no block table).
    pub fn build<W: Word>(&mut self, mask: &BinaryMask<W>, m: &Matcher, shear: &ShearState, tables: bool) {
        // (without tables no rectangle: `any` then reads none)
        self.rect = if tables { mask.occupied_rect() } else { None };
        let nk = mask.slices();
        let slots = (W::BITS / m.width()) as usize;
        self.len = slots.div_ceil(BLOCKS_PER_WORD);
        assert!(self.len.is_power_of_two(), "slots per word are a power of two");
        self.log_len = self.len.trailing_zeros();
        self.frac.clear();
        self.frac.extend((0..nk.div_ceil(self.len)).map(|b| {
            let mut f = [f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY];
            for k in b * self.len..((b + 1) * self.len).min(nk) {
                for ax in [0, 1] {
                    let t = shear.trans[ax][k];
                    let x = t - t.floor();
                    f[2 * ax] = f[2 * ax].min(x);
                    f[2 * ax + 1] = f[2 * ax + 1].max(x);
                }
            }
            f
        }));
        self.all_frac = self.frac.iter().fold([f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY], |a, f| {
            [a[0].min(f[0]), a[1].max(f[1]), a[2].min(f[2]), a[3].max(f[3])]
        });
        let first = (0..nk).find(|&k| mask.slice_cells(k).is_some());
        let last = (0..nk).rev().find(|&k| mask.slice_cells(k).is_some());
        self.slices = match (first, last) {
            (Some(a), Some(b)) => [a, b],
            _ => [1, 0],
        };
        let Some(r) = self.rect else { return };
        let (w, h) = (r.p1 - r.p0 + 1, r.q1 - r.q0 + 1);
        self.stride = w + 1;
        let nw = mask.words_per_row();
        let per_word = slots / self.len;
        // (slots per word are 8, 16, 32 or 64: always four blocks a word)
        assert_eq!(per_word, BLOCKS_PER_WORD, "four blocks per word");
        let nbk = nw * per_word;
        self.blocks = nbk;
        let row_len = (w + 1) * nbk;
        // every entry is written below but the first row's (zero): no clearing pass
        let size = (h + 1) * row_len;
        if self.sums.len() < size {
            self.sums.resize(size, 0);
        }
        self.sums[..row_len].fill(0);
        // block i of a word holds its slots [i·len, (i + 1)·len) from the most
        // significant bit: the word's i-th quarter from the top, and the
        // (3 − i)-th from the bottom, which lane 3 − i of a row's running
        // counts (four u16 in a u64: a row is narrower than 2^16 columns, so
        // no lane carries into the next) counts
        assert!(w < 1 << 16, "a mask row of {w} columns");
        // each row's running counts along p, in parallel over rows: a column's
        // counts are the column before's plus its own flags
        self.sums[row_len..size].par_chunks_mut(row_len).enumerate().for_each(|(q, t)| {
            t[..nbk].fill(0);
            for p in 0..w {
                let (before, out) = t.split_at_mut((p + 1) * nbk);
                let (prev, out) = (&before[p * nbk..], &mut out[..nbk]);
                let words = mask.row(r.p0 + p, r.q0 + q);
                let blocks = out.chunks_exact_mut(BLOCKS_PER_WORD).zip(prev.chunks_exact(BLOCKS_PER_WORD));
                for (&word, (o, pr)) in words.iter().zip(blocks) {
                    let run = pr.iter().rev().fold(0u64, |c, &x| (c << 16) | x as u64);
                    let c = run + quarter_flags::<W>(m.hits(word).as_u64());
                    o.copy_from_slice(&[c as u16, (c >> 16) as u16, (c >> 32) as u16, (c >> 48) as u16]);
                }
            }
        });
        // then down the rows
        for q in 1..=h {
            let (above, row) = self.sums[..size].split_at_mut(q * row_len);
            for (x, a) in row[..row_len].iter_mut().zip(&above[(q - 1) * row_len..]) {
                *x = x.wrapping_add(*a);
            }
        }
    }

    /// Slices per block.
    pub fn block_len(&self) -> usize {
        self.len
    }

    /// The first block, in walking order, over the slices of `span` in which a ray of a group may meet a matching column: every ray
    /// through a sheared point of `[at[0][0], at[0][1]] × [at[1][0], at[1][1]]`
    /// (min, max per axis) under the slices' `scaled` maps, against `mask` in
    /// `shear` (the mask and shear this table was built for). `None`: no ray
    /// of the group has a candidate. The group's drift over a block spans the
    /// extremes of its corner rays at the block's end slices (affine in the
    /// point and in `k`), so its rectangle holds every member's columns and a
    /// block it skips has no candidate for any of them: a group of rays pays
    /// for the empty blocks in front of its surface once instead of once per
    /// ray.
    pub fn first_block<W: Word>(
        &self,
        mask: &BinaryMask<W>,
        shear: &ShearState,
        scaled: &[ScaledMap],
        at: [[f64; 2]; 2],
        span: SliceSpan,
    ) -> Option<usize> {
        let SliceSpan { lo, hi, ascending } = span;
        let (lo, hi) = (lo.max(self.slices[0]), hi.min(self.slices[1]));
        if lo > hi || self.rect.is_none() {
            return None;
        }
        let len = self.len.max(1);
        let (bl, bh) = (lo / len, hi / len);
        let drift = |ax: usize, k: usize| {
            let (s, t) = (&scaled[k], shear.trans[ax][k]);
            let (x0, x1) = (s.scale * at[ax][0] + s.trans[ax] - t, s.scale * at[ax][1] + s.trans[ax] - t);
            (x0.min(x1), x0.max(x1))
        };
        for i in 0..=bh - bl {
            let b = if ascending { bl + i } else { bh - i };
            let (ka, kb) = (lo.max(b * len), hi.min(b * len + len - 1));
            let cols = |ax: usize| {
                let ((a0, a1), (b0, b1)) = (drift(ax, ka), drift(ax, kb));
                columns(mask, &self.frac[b], ax, a0.min(b0), a1.max(b1))
            };
            if let (Some((p0, p1)), Some((q0, q1))) = (cols(0), cols(1))
                && self.any(b, p0, p1, q0, q1)
            {
                return Some(b);
            }
        }
        None
    }

    /// True when some column of `[p0, p1] × [q0, q1]` (super columns) has a
    /// match in block `w`.
    #[inline(always)]
    pub(crate) fn any(&self, w: usize, p0: usize, p1: usize, q0: usize, q1: usize) -> bool {
        let Some(r) = self.rect else { return false };
        let (a0, a1, b0, b1) = (p0.max(r.p0), p1.min(r.p1), q0.max(r.q0), q1.min(r.q1));
        if a0 > a1 || b0 > b1 {
            return false;
        }
        let (x0, x1, y0, y1) = (a0 - r.p0, a1 - r.p0 + 1, b0 - r.q0, b1 - r.q0 + 1);
        // (counts modulo 2^16: exact below 2^16 columns)
        if (x1 - x0) * (y1 - y0) >= 1 << 16 {
            return true;
        }
        let t = &self.sums[w ^ 3..];
        let (s, n) = (self.stride, self.blocks);
        t[(y1 * s + x1) * n].wrapping_add(t[(y0 * s + x0) * n]) != t[(y0 * s + x1) * n].wrapping_add(t[(y1 * s + x0) * n])
    }
}

/// One in lane `j` (bit `16·j`) of the result for each non-zero quarter `j`
/// (from the least significant end) of a `W` word `x`: four quarters, four
/// u16 lanes. The top bit of each quarter's low bits plus all-ones-but-top
/// carries into the quarter's top bit iff those bits are non-zero (no carry
/// leaves the quarter).
#[inline(always)]
pub(crate) fn quarter_flags<W: Word>(x: u64) -> u64 {
    if W::BITS == 64 {
        const LOW: u64 = 0x7FFF_7FFF_7FFF_7FFF;
        ((((x & LOW) + LOW) | x) & !LOW) >> 15
    } else {
        const LOW: u64 = 0x7F7F_7F7F;
        let f = ((((x & LOW) + LOW) | x) & 0x8080_8080) >> 7;
        (f & 1) | ((f & 0x100) << 8) | ((f & 0x1_0000) << 16) | ((f & 0x100_0000) << 24)
    }
}

/// The mask columns `[c0, c1]` along axis `ax` that hold the cells of samples
/// whose drift lies in `[u0, u1]`, in slices of one block (whose fractions of
/// the shear translations are `frac`: [`BlockOccupancy`]), clipped to the grid
/// (`None`: off the grid). See the module docs.
#[inline(always)]
pub(crate) fn columns<W: Word>(mask: &BinaryMask<W>, frac: &[f64; 4], ax: usize, u0: f64, u1: f64) -> Option<(usize, usize)> {
    // the cell's offset from the slice's, floor(x) − floor(t) = floor(u + frac(t)),
    // over the slices' fractions in the block
    let h0 = floor_i64(u0 + frac[2 * ax] - MARGIN);
    let h1 = floor_i64(u1 + frac[2 * ax + 1] + MARGIN);
    let s = mask.cell_size() as i64;
    let pad = mask.pad() as i64;
    // (no division at cell size 1, the usual case)
    let (c0, c1) = if s == 1 { (h0 + pad, h1 + pad) } else { ((h0 - s + 1).div_euclid(s) + pad, h1.div_euclid(s) + pad) };
    let (c0, c1) = (c0.max(0), c1.min(mask.grid()[ax] as i64 - 1));
    (c0 <= c1).then_some((c0 as usize, c1 as usize))
}

/// The slices a walk covers: `[lo, hi]` in index order (none when
/// `lo > hi`), walked from `lo` up (`ascending`) or from `hi` down.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SliceSpan {
    pub lo: usize,
    pub hi: usize,
    pub ascending: bool,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::volume::Volume;

    fn blob(n: [usize; 3], seed: u64) -> Volume {
        Volume::from_fn(n, [1.0; 3], |x, y, z| {
            let mut s = seed ^ (x as u64 * 0x9E37_79B9 + y as u64 * 0x85EB_CA6B + z as u64 * 0xC2B2_AE35);
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s = s.wrapping_mul(0x2545F4914F6CDD1D);
            if (s >> 40).is_multiple_of(7) { 100.0 } else { 0.0 }
        })
        .unwrap()
    }

    /// The mask recomputed from scratch with a bit vector per code plane: code
    /// (p, q, k) is the unsheared code at (p − off_i, q − off_j).
    #[allow(clippy::needless_range_loop)] // the index picks one slice of several arrays
    fn naive<W: Word>(m: &BinaryMask<W>) -> Vec<W> {
        use bitvec::prelude::*;
        let slots = (W::BITS / m.nb) as usize;
        let mut planes = vec![bitvec![0; m.grid[0] * m.grid[1] * m.nk]; m.nb as usize];
        let fl = m.floors();
        for k in 0..m.nk {
            for cj in 0..m.cells[1] {
                for ci in 0..m.cells[0] {
                    let c = m.code(ci, cj, k);
                    let p = (ci as i32 + m.pad as i32 - fl[0][k]) as usize;
                    let q = (cj as i32 + m.pad as i32 - fl[1][k]) as usize;
                    for (b, plane) in planes.iter_mut().enumerate() {
                        plane.set((q * m.grid[0] + p) * m.nk + k, (c >> b) & 1 == 1);
                    }
                }
            }
        }
        let mut out = vec![W::ZERO; m.words.len()];
        for col in 0..m.grid[0] * m.grid[1] {
            for k in 0..m.nk {
                let c: u64 = (0..m.nb as usize).map(|b| (planes[b][col * m.nk + k] as u64) << b).sum();
                out[col * m.nw + k / slots] |= W::from_u64(c) << slot_shift::<W>(m.nb, (k % slots) as u32);
            }
        }
        out
    }

    fn check_incremental<W: Word>(n: [usize; 3]) {
        let v = blob(n, 99);
        let st = SliceStack::new(&v, 2);
        let mut m = BinaryMask::<W>::build(&st, |_, hi| hi > 50.0);
        assert_eq!(m.words, naive(&m));
        let mut s = ShearState::identity(n[2]);
        let mut seed = 3u64;
        let lim = (n[2] as i64 - 1) / 2;
        let mut net = [0i64; 2];
        for step in 0..400 {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let along = (seed >> 35) as usize & 1;
            let dir = if (seed >> 45) & 1 == 0 { 1 } else { -1 };
            if (net[along] + dir as i64).abs() > lim {
                continue;
            }
            net[along] += dir as i64;
            s = m.rotate_step(&s, along, dir);
            if step % 37 == 0 {
                assert_eq!(m.words, naive(&m), "after step {step}");
            }
        }
        let mut direct = BinaryMask::<W>::build(&st, |_, hi| hi > 50.0);
        direct.shear_direct(&s);
        assert_eq!(m.words, direct.words);
        assert_eq!(m.words, naive(&m));
    }

    /// Far moves (more than [`MAX_INCREMENTAL_STEPS`] super cells) take the
    /// staged shear: it ends in the scatter's words for both word sizes, 1-
    /// and 2-bit codes, super cells and long stacks, jumping between random
    /// shears of both signs about both axes.
    fn check_far_jumps<W: Word>(n: [usize; 3], nb: u32, s: usize) {
        let v = blob(n, 7);
        let st = SliceStack::new(&v, 2);
        let codes = CellCodes::build(&st, nb, |_, hi| (hi / 40.0).min(((1u32 << nb) - 1) as f32) as u8);
        let mut m = BinaryMask::<W>::from_codes(&codes, s);
        let lim = ((n[2] - 1) / 2) as f64;
        let mut seed = 11u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 33) % 2001) as f64 / 1000.0 - 1.0
        };
        let mut far = 0;
        for jump in 0..12 {
            // along i from one side to the other (always far), along j anywhere
            let side = if jump % 2 == 0 { 1.0 } else { -1.0 };
            let e = [side * (0.6 + 0.4 * rnd().abs()), rnd()].map(|x| (x * lim).round());
            let state = ShearState::from_ends(n[2], [0, 1].map(|a| [-e[a], e[a]]));
            far += m.shear_to(&state).direct;
            let mut d = BinaryMask::<W>::from_codes(&codes, s);
            d.shear_direct(&state);
            assert_eq!(m.words, d.words, "jump {jump} to {e:?}");
        }
        assert!(far >= 11, "only {far} of 12 jumps were far");
    }

    /// The default cell size keeps a ray's share of its depth row within a
    /// cache line, and is the smallest size that does.
    #[test]
    fn auto_cell_keeps_a_rays_depth_row_within_a_cache_line() {
        assert_eq!(auto_cell(256, 1, 64), 1);
        assert_eq!(auto_cell(512, 1, 64), 1);
        assert_eq!(auto_cell(513, 1, 64), 2);
        assert_eq!(auto_cell(256, 2, 64), 1);
        assert_eq!(auto_cell(413, 2, 64), 2);
        assert_eq!(auto_cell(512, 2, 32), 2);
        assert_eq!(auto_cell(1, 4, 32), 1);
        assert_eq!(auto_cell(usize::MAX / 4, 4, 64), MAX_CELL);
        for nb in [1u32, 2, 4] {
            for bits in [32u32, 64] {
                for nk in (1usize..3000).step_by(7) {
                    let row = nk.div_ceil((bits / nb) as usize) * (bits / 8) as usize;
                    let s = auto_cell(nk, nb, bits);
                    assert!(row <= AUTO_CELL_ROW_BYTES * s * s || s == MAX_CELL, "{nk} {nb} {bits}");
                    assert!(s == 1 || row > AUTO_CELL_ROW_BYTES * (s - 1) * (s - 1), "{nk} {nb} {bits}");
                }
            }
        }
    }

    #[test]
    fn far_jumps_equal_the_direct_shear() {
        check_far_jumps::<u64>([21, 17, 130], 1, 1);
        check_far_jumps::<u32>([21, 17, 130], 1, 1);
        check_far_jumps::<u64>([19, 23, 90], 2, 1);
        check_far_jumps::<u64>([24, 20, 140], 1, 2);
        check_far_jumps::<u32>([17, 16, 75], 2, 3);
        // depth rows of one, two and four words (the fixed-length moves)
        check_far_jumps::<u64>([15, 13, 60], 1, 1);
        check_far_jumps::<u64>([15, 13, 100], 1, 1);
        check_far_jumps::<u64>([15, 13, 250], 1, 1);
    }

    /// Moves of [`MIN_ONE_PASS_BITS`] to [`MAX_INCREMENTAL_STEPS`] super cells
    /// along i of depth rows longer than [`MAX_FUSED_COLUMN`] words take the
    /// one-pass move ([`BinaryMask::move_columns`]), each
    /// slice by its own distance, in both directions, with moves along j
    /// beside them, for 1-, 2- and 4-bit codes, both word sizes and super
    /// cells: the words of the steps and of the scatter.
    fn check_one_pass<W: Word>(n: [usize; 3], nb: u32, s: usize) -> u32 {
        let v = blob(n, 5);
        let st = SliceStack::new(&v, 2);
        let codes = CellCodes::build(&st, nb, |_, hi| (hi / 40.0).min(((1u32 << nb) - 1) as f32) as u8);
        let mut m = BinaryMask::<W>::from_codes(&codes, s);
        let mut steps = m.clone();
        steps.set_fused(false);
        let lim = ((n[2] - 1) / 2) as f64;
        let mut seed = 5u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 33) % 2001) as f64 / 1000.0 - 1.0
        };
        let mut ends = [0.0f64; 2];
        let mut one_pass = 0;
        for jump in 0..40 {
            // up to 4 bits at the stack's ends (8 apart), along i,
            // j or both; now and then every slice shifted alike as well
            let reach = 4.0;
            for (a, e) in ends.iter_mut().enumerate() {
                if jump % 3 != a {
                    *e = (*e + (rnd() * reach).round()).clamp(-lim, lim);
                }
            }
            let shift = if jump % 5 == 4 { 2.0 } else { 0.0 };
            let state = ShearState::from_ends(n[2], [0, 1].map(|a| [shift - ends[a], shift + ends[a]]));
            let before = m.off.clone();
            let w = m.shear_to(&state);
            let moved = |a: usize| before[a].iter().zip(&m.off[a]).map(|(x, y)| (x - y).unsigned_abs()).max().unwrap_or(0);
            one_pass += (w.direct == 0 && moved(0) >= MIN_ONE_PASS_BITS) as u32 + (w.direct == 0 && moved(1) >= MIN_ONE_PASS_BITS) as u32;
            steps.shear_to(&state);
            let mut d = BinaryMask::<W>::from_codes(&codes, s);
            d.shear_direct(&state);
            assert_eq!(m.words, d.words, "jump {jump} to {ends:?}: one pass and scatter");
            assert_eq!(steps.words, d.words, "jump {jump} to {ends:?}: steps and scatter");
        }
        one_pass
    }

    #[test]
    fn one_pass_moves_equal_the_steps_and_the_direct_shear() {
        // (depth rows of 5 to 8 words; a word of 64 one-bit slots can span
        // more distances than the pass takes: those moves take the steps)
        let n = [
            check_one_pass::<u64>([13, 11, 330], 1, 1),
            check_one_pass::<u32>([13, 11, 170], 1, 1),
            check_one_pass::<u64>([11, 13, 200], 2, 1),
            check_one_pass::<u64>([11, 9, 70], 4, 1),
            check_one_pass::<u64>([16, 14, 300], 1, 2),
            check_one_pass::<u32>([17, 16, 75], 2, 3),
        ];
        assert!(n[2] >= 10 && n[3] >= 10 && n.iter().sum::<u32>() >= 40, "jumps along i in one pass: {n:?}");
    }

    /// Depth rows longer than the fixed column lengths (17 to 66 words)
    /// move and step a chunk of words at a time ([`column_chunk`]): at every
    /// chunk size, in one pass and in single steps, in bands on two
    /// threads, the words end as the scatter's.
    #[test]
    fn long_depth_rows_equal_the_direct_shear() {
        // (slices, code width, word bits, the chunk its rows take)
        let cases: [(usize, u32, u32, usize); 5] = [(1024, 2, 64, 16), (384, 4, 64, 8), (320, 2, 32, 4), (1100, 1, 64, 2), (520, 4, 64, 1)];
        for (nk, nb, bits, chunk) in cases {
            let nw = nk.div_ceil((bits / nb) as usize);
            assert!(nw > 16 && column_chunk(nw) == chunk, "{nk} slices of {nb} bits: {nw} words");
            let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
            pool.install(|| match bits {
                32 => check_one_pass::<u32>([7, 6, nk], nb, 1),
                _ => check_one_pass::<u64>([6, 7, nk], nb, 1),
            });
        }
    }

    /// A tissue preset's one-bit mask ([`BinaryMask::at_least`]) of a code
    /// mask sheared anywhere equals, word for word, the mask of the one-bit
    /// codes "code ≥ c" sheared to the same state, and keeps equal to it
    /// through further shears: for 1-, 2- and 4-bit codes, every code `c`, u32
    /// and u64 words, depth rows of one word and of several (partial groups
    /// of code words included), and super cells.
    #[test]
    fn a_presets_mask_equals_the_mask_of_its_one_bit_codes() {
        fn check<W: Word>(n: [usize; 3], nb: u32, s: usize) {
            let st = SliceStack::new(&blob(n, 29), 2);
            let top = ((1u32 << nb) - 1) as f32;
            let codes = CellCodes::build(&st, nb, |_, hi| (hi / 25.0).min(top) as u8);
            let lim = ((n[2] - 1) / 2) as i64;
            let at = |e: [i64; 2]| ShearState::from_ends(n[2], [0, 1].map(|a| [-e[a] as f64, e[a] as f64]));
            for c in 1..(1u8 << nb) {
                let ones = CellCodes::build(&st, 1, |_, hi| ((hi / 25.0).min(top) as u8 >= c) as u8);
                let mut coded = BinaryMask::<W>::from_codes(&codes, s);
                coded.shear_to(&at([lim / 2, -lim / 3]));
                let mut one = coded.at_least(c);
                assert_eq!((one.nb, one.nw, one.s), (1, n[2].div_ceil(W::BITS as usize), s));
                let mut direct = BinaryMask::<W>::from_codes(&ones, s);
                direct.shear_direct(&at([lim / 2, -lim / 3]));
                assert_eq!(one.words, direct.words, "{n:?} {nb}-bit codes, cell {s}, code {c}: as built");
                assert_eq!(one.codes, direct.codes);
                assert_eq!(one.bbox, direct.bbox);
                for e in [[lim / 2 + 1, -lim / 3 + 2], [-lim, lim], [0, 0]] {
                    one.shear_to(&at(e));
                    direct.shear_direct(&at(e));
                    assert_eq!(one.words, direct.words, "{n:?} {nb}-bit codes, cell {s}, code {c}: sheared to {e:?}");
                }
            }
        }
        check::<u64>([9, 8, 40], 1, 2);
        check::<u64>([9, 8, 40], 2, 1);
        check::<u64>([10, 7, 300], 4, 1);
        check::<u32>([8, 9, 70], 4, 1);
        check::<u32>([7, 10, 50], 2, 2);
        check::<u64>([12, 11, 90], 4, 3);
    }

    /// The moves along j run in bands of grid rows, one a thread
    /// ([`BinaryMask::row_bands`]): with 1 to 7 threads (bands of one row and
    /// more, and fewer rows than threads), single and fused steps end in the
    /// scatter's words, for short and long depth rows, 1- and 2-bit codes and
    /// super cells.
    #[test]
    fn row_bands_equal_the_direct_shear_for_any_thread_count() {
        fn check<W: Word>(n: [usize; 3], nb: u32, s: usize, fused: bool) {
            let st = SliceStack::new(&blob(n, 13), 2);
            let codes = CellCodes::build(&st, nb, |_, hi| (hi / 40.0).min(((1u32 << nb) - 1) as f32) as u8);
            let lim = ((n[2] - 1) / 2) as i64;
            for threads in [1, 2, 3, 5, 7] {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                let mut m = BinaryMask::<W>::from_codes(&codes, s);
                m.set_fused(fused);
                let mut seed = 17u64 + threads as u64;
                let mut ends = [0i64; 2];
                for jump in 0..30 {
                    seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                    // 1 to 3 steps along j (and now and then along i)
                    let d = (seed >> 40) as i64 % 7 - 3;
                    ends[1] = (ends[1] + d).clamp(-lim, lim);
                    if jump % 4 == 0 {
                        ends[0] = (ends[0] + d.signum()).clamp(-lim, lim);
                    }
                    let state = ShearState::from_ends(n[2], [0, 1].map(|a| [-ends[a] as f64, ends[a] as f64]));
                    pool.install(|| m.shear_to(&state));
                    let mut direct = BinaryMask::<W>::from_codes(&codes, s);
                    direct.shear_direct(&state);
                    assert_eq!(m.words, direct.words, "{threads} threads, jump {jump} to {ends:?}");
                }
            }
        }
        for fused in [true, false] {
            check::<u64>([9, 5, 40], 1, 1, fused);
            check::<u32>([7, 11, 100], 1, 1, fused);
            check::<u64>([8, 13, 90], 2, 1, fused);
            check::<u64>([12, 10, 330], 1, 1, fused);
            check::<u32>([10, 14, 60], 2, 2, fused);
        }
    }

    #[test]
    fn incremental_equals_direct_u32_and_u64() {
        check_incremental::<u32>([13, 11, 45]);
        check_incremental::<u64>([13, 11, 45]);
        check_incremental::<u32>([9, 7, 70]);
        check_incremental::<u64>([9, 7, 130]);
        check_incremental::<u32>([5, 6, 2]);
    }

    #[test]
    fn build_is_exactly_the_corner_rule() {
        let v = blob([9, 8, 7], 5);
        let st = SliceStack::new(&v, 2);
        let m = BinaryMask::<u32>::build(&st, |_, hi| hi > 50.0);
        for k in 0..7 {
            for cj in 0..7 {
                for ci in 0..8 {
                    let any = [(0, 0), (1, 0), (0, 1), (1, 1)].iter().any(|&(a, b)| st.at(ci + a, cj + b, k) > 50.0);
                    assert_eq!(m.cell(ci, cj, k), any);
                }
            }
        }
    }
}
