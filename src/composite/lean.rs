//! The lean binary iso frame: the common case of the binary rotator
//! (parallel projection, iso mode, normal-code shading) without the
//! generality it does not use.
//!
//! A frame takes this path when its plan translates every slice
//! ([`MapKind::Translate`]), composites every slice with no per-ray limits,
//! focus interval or intermediate samples, the mode is [`Mode::Iso`], the
//! rays shade by normal codes and the depth search is the bit scan
//! ([`LeanFrame::applies`]). The renderer decides once per frame; every other
//! frame takes the general ray loop of [`super::raycast`]. The cubic
//! reconstruction's preview ([`RayContext::with_cubic_crossing`]: the linear
//! samples' hit placed at the cubic's crossing) takes this frame too, with
//! rows compiled for it (`CUBIC`), so the linear rows carry none of its code.
//!
//! What makes it lean:
//! - **A per-slice table** ([`SliceEntry`]): in parallel projection every ray
//!   of slice `k` shares the integer offset of its cell and the bilinear
//!   weights, so the table holds per slice the stack-index offset of ray
//!   `(0, 0)`'s cell, the cell shift along both in-slice axes (for the
//!   in-volume test) and the weights. A ray keeps its own base index
//!   `p + n₀·q`; a visit is one bit scan, one table entry, one in-volume test
//!   on two integers and the cell's four densities.
//! - **A walk with no direction branch**: the walk over a depth row is
//!   compiled once per direction (`ASC`), and a word's matching slots are
//!   found once when the word is loaded ([`Matcher::hits`]: the top bit of
//!   every slot whose code matches), so one-bit masks and threshold codes
//!   walk alike: a bit scan, the slot (the bit position over the code width)
//!   and one bit cleared.
//! - **No test per visit at cell size 1**: a ray's depth row is then its
//!   own cells' column (no dilation, [`crate::encode::mask`]), so a matching
//!   bit is a cell of the volume; with super cells a visit tests its cell
//!   against the slice's extent (two integer compares), as does every
//!   refinement's previous-slice read.
//! - **A compact state per ray**: a ray's walk keeps a word index, the
//!   remaining matching bits and the slice of the word's first slot.
//! - **Each visit prefetches what the next row of rays reads**: the rays of a
//!   row are traced one after the other, and every visit prefetches the voxel
//!   row that the ray of the next row of rays will read there. The cell of
//!   ray `(p, q)` in slice `k` spans voxel rows `j` and `j + 1`; ray
//!   `(p, q + 1)` meets the slice in rows `j + 1` and `j + 2`, and on a
//!   surface neighbouring rays visit neighbouring slices, so row `j + 2` is
//!   the line a visit of the next row would otherwise wait for (this row has
//!   just read row `j + 1`). A row of rays takes microseconds, far longer
//!   than a fetch from memory, and its lines (tens of kilobytes) stay in the
//!   per-core cache until the next row reads them. This covers a ray's first
//!   candidate as well as the visits after it, with one hint a visit and no
//!   state carried between rays (a pass that finds and prefetches a group of
//!   rays' first candidates before tracing them is what the general path
//!   does, [`super::raycast::PREFETCH_GROUP`]).
//! - **One vector per sample**: where the CPU level has SSSE3, a visit gathers
//!   its cell's four densities into one SSE vector and interpolates them
//!   there ([`Cells::sample_ssse3`]): the same float operations, the same
//!   value bit for bit (8-bit cells leave out the clamp to the corners'
//!   range, which cannot bind for whole numbers:
//!   `data::slices::bilinear_sse_bytes`).
//!
//! Invariants (what keeps the image the general path's, bit for bit):
//! - the candidate slices are the general walk's ([`crate::encode::depth::SetBits`]
//!   with the same matcher), in the same order;
//! - a sample's cell and weights are [`super::raycast::GridRay`]'s (the same
//!   [`crate::view::plan::SliceMap`]; the same `(ci, cj) ∈ cells` test);
//! - the density, the refinement against the previous slice in walking order,
//!   the depth and the shade are computed by the same functions in the same
//!   order ([`bilinear`], [`ShadeTable::blend`], [`apply_shade`]), so every
//!   float operation is the general path's.

use crate::classify::shade_table::ShadeTable;
use crate::classify::shading::ShadeEntry;
use crate::classify::shading::apply_shade;
use crate::composite::raycast::{At, Cells, MISS, RayContext, RowOut, cubic_in_slice, in_slice_fraction, render_rows};
use crate::composite::{Intermediate, Mode, Rect};
use crate::data::slices::bilinear;
use crate::encode::depth::{Matcher, Search, Word};
use crate::encode::mask::BinaryMask;
use crate::kernels::reconstruct;
use crate::view::plan::{FramePlan, Grid, MapKind};

/// One slice of the per-slice table of a frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SliceEntry {
    /// Stack index of the first voxel of ray `(0, 0)`'s cell in this slice
    /// (`di + n₀·dj + n₀n₁·k`, possibly negative): ray `(p, q)`'s is this plus
    /// `p + n₀·q`.
    pub base: isize,
    /// The cell of ray `(p, q)` is `(p + di, q + dj)`.
    pub di: i32,
    pub dj: i32,
    /// The bilinear weights every ray of the slice shares.
    pub wi: f32,
    pub wj: f32,
}

/// The per-slice table of the lean frame, kept across frames (refilled per
/// frame without allocating once it has grown to the longest axis).
#[derive(Clone, Debug, Default)]
pub struct LeanFrame {
    slices: Vec<SliceEntry>,
}

/// What a row of the lean frame reads, borrowed for one frame.
struct Frame<'a, W: Word> {
    /// The per-slice table, at least as long as a depth row has slots.
    slices: &'a [SliceEntry],
    /// Slices of the stack.
    nk: usize,
    words: &'a [W],
    m: &'a Matcher,
    table: &'a ShadeTable,
    iso: f32,
    iso_rgb: [f32; 3],
    /// Cells per slice along `i` and `j`.
    cells: [u32; 2],
    /// Voxels per row of the stack.
    n0: usize,
    /// Slices per word and `log2` of the code width.
    slots: usize,
    log_nb: u32,
    /// How far past a visited cell's first voxel the voxel row the next
    /// row of rays reads starts (two rows); 0 without prefetches, where a
    /// visit's hint names the line it reads anyway, so it needs no branch.
    ahead: usize,
    /// The cubic crossing's stack axis ([`RayContext::with_cubic_crossing`]).
    cubic: Option<usize>,
}

/// Ray `(p, q)` of the intermediate image and its base stack index
/// `rb = p + n₀·q` (its cell in slice entry `e` starts at `rb + e.base`).
#[derive(Clone, Copy, Debug)]
struct LeanRay {
    p: usize,
    q: usize,
    rb: usize,
}

/// A ray's walk over its depth row: the word being consumed, its remaining
/// matching slots (top bits, [`Matcher::hits`]; none left: the ray has no
/// candidate), the slice of its first slot and how many words are left after
/// it in walking order.
#[derive(Clone, Copy, Debug)]
struct Walk<W: Word> {
    w: usize,
    cur: W,
    kbase: usize,
    left: usize,
}

impl<W: Word> Walk<W> {
    /// Moves on by `n` of the words left, in walking order (`slots` slices
    /// a word); the current word's slots are the caller's to set.
    #[inline(always)]
    fn pass<const ASC: bool>(&mut self, n: usize, slots: usize) {
        self.left -= n;
        if ASC {
            self.w += n;
            self.kbase += n * slots;
        } else {
            self.w -= n;
            self.kbase -= n * slots;
        }
    }
}

impl LeanFrame {
    /// Whether a frame of `plan` in `mode`, shaded by normal codes (`codes`),
    /// with depth search `search`, takes the lean path.
    pub fn applies(plan: &FramePlan, mode: Mode, codes: bool, search: Search) -> bool {
        plan.kind == MapKind::Translate
            && mode == Mode::Iso
            && codes
            && search == Search::Bitscan
            && !plan.limited()
            && plan.focus.is_none()
            && !plan.intermediate()
    }

    /// The table of the frame of `ctx`, padded to `len` entries (the slots of
    /// a depth row) with entries whose cell is outside every volume.
    fn fill(&mut self, ctx: &RayContext, len: usize) {
        slice_table(ctx, &mut self.slices);
        // (a padding slot is never a candidate of a correct mask; were it one,
        // its cell fails the in-volume test and its index every bounds check)
        let outside = SliceEntry { base: isize::MIN / 2, di: i32::MIN / 2, dj: i32::MIN / 2, wi: 0.0, wj: 0.0 };
        self.slices.resize(len.max(self.slices.len()), outside);
    }

    /// The table of the last frame rendered (one entry per slice, then the
    /// padding up to the slots of a depth row).
    pub fn slices(&self) -> &[SliceEntry] {
        &self.slices
    }

    /// Renders the rays of `rect` of a frame for which [`LeanFrame::applies`]
    /// holds (`ctx` shades by normal codes) through the sheared `mask` and
    /// its matcher `m`, into `out`; marks `rect` valid. The same image as
    /// [`super::raycast::render_binary`] of the same frame, bit for bit.
    /// With `prefetch` every visit prefetches the voxel row the next row of
    /// rays reads there (module docs); without, no hint names a line the
    /// frame has not just read.
    pub fn render<W: Word>(
        &mut self,
        ctx: &RayContext,
        mask: &BinaryMask<W>,
        m: &Matcher,
        prefetch: bool,
        rect: Option<Rect>,
        out: &mut Intermediate,
    ) {
        assert!(
            LeanFrame::applies(ctx.plan, ctx.mode, ctx.table().is_some(), Search::Bitscan) && !ctx.intermediate(),
            "a frame the lean path does not cover"
        );
        assert_eq!(m.width(), mask.code_width(), "a matcher of another code width");
        let Some(table) = ctx.table() else { return };
        let slots = (W::BITS >> m.width().trailing_zeros()) as usize;
        self.fill(ctx, mask.words_per_row() * slots);
        let n = ctx.stack.n;
        assert!(self.slices.len() >= mask.words_per_row() * slots && ctx.maps.len() <= self.slices.len());
        let f = Frame {
            slices: &self.slices,
            nk: ctx.maps.len(),
            words: mask.words(),
            m,
            table,
            iso: ctx.iso,
            iso_rgb: ctx.iso_rgb,
            cells: ctx.cell_counts(),
            n0: n[0],
            slots,
            log_nb: m.width().trailing_zeros(),
            ahead: if prefetch { 2 * n[0] } else { 0 },
            cubic: ctx.cubic_crossing(),
        };
        let avx2 = mask.cpu_level().has_avx2();
        // at cell size 1 a ray's column is its own cells' (no dilation): a
        // matching bit at slice k is a cell of the volume, so its visit needs
        // no in-volume test (the grid's margin is the mask's, module docs)
        let exact = mask.cell_size() == 1 && ctx.plan.grid.pad == Grid::parallel(ctx.stack.cells(), n[2]).pad;
        let one = m.width() == 1;
        let cubic = f.cubic.is_some();
        super::raycast::with_cells!(ctx, |v| {
            render_rows(rect, out, |out| {
                let row = RowStart::new(mask, out.q, out.p0);
                match (ctx.ascending, exact, one, cubic) {
                    (true, true, true, false) => lean_row_at::<W, _, true, false, true, false>(&f, &v, avx2, row, out),
                    (false, true, true, false) => lean_row_at::<W, _, false, false, true, false>(&f, &v, avx2, row, out),
                    (true, false, true, false) => lean_row_at::<W, _, true, true, true, false>(&f, &v, avx2, row, out),
                    (false, false, true, false) => lean_row_at::<W, _, false, true, true, false>(&f, &v, avx2, row, out),
                    (true, true, false, false) => lean_row_at::<W, _, true, false, false, false>(&f, &v, avx2, row, out),
                    (false, true, false, false) => lean_row_at::<W, _, false, false, false, false>(&f, &v, avx2, row, out),
                    (true, false, false, false) => lean_row_at::<W, _, true, true, false, false>(&f, &v, avx2, row, out),
                    (false, false, false, false) => lean_row_at::<W, _, false, true, false, false>(&f, &v, avx2, row, out),
                    (true, true, true, true) => lean_row_at::<W, _, true, false, true, true>(&f, &v, avx2, row, out),
                    (false, true, true, true) => lean_row_at::<W, _, false, false, true, true>(&f, &v, avx2, row, out),
                    (true, false, true, true) => lean_row_at::<W, _, true, true, true, true>(&f, &v, avx2, row, out),
                    (false, false, true, true) => lean_row_at::<W, _, false, true, true, true>(&f, &v, avx2, row, out),
                    (true, true, false, true) => lean_row_at::<W, _, true, false, false, true>(&f, &v, avx2, row, out),
                    (false, true, false, true) => lean_row_at::<W, _, false, false, false, true>(&f, &v, avx2, row, out),
                    (true, false, false, true) => lean_row_at::<W, _, true, true, false, true>(&f, &v, avx2, row, out),
                    (false, false, false, true) => lean_row_at::<W, _, false, true, false, true>(&f, &v, avx2, row, out),
                }
            })
        });
    }
}

/// The per-slice table of the frame of `ctx` into `out` (one entry per
/// slice, refilled without allocating once `out` has grown).
pub(crate) fn slice_table(ctx: &RayContext, out: &mut Vec<SliceEntry>) {
    let n = ctx.stack.n;
    let (n0, n01) = (n[0] as isize, (n[0] * n[1]) as isize);
    let pad = ctx.pad;
    out.clear();
    out.extend(ctx.maps.iter().enumerate().map(|(k, s)| {
        let (di, dj) = (s.floor[0] - pad, s.floor[1] - pad);
        SliceEntry { base: di as isize + n0 * dj as isize + n01 * k as isize, di, dj, wi: s.weight[0], wj: s.weight[1] }
    }));
}

/// Where the depth rows of one row of rays start: the first ray's column
/// (`start`, the index of its first word), the words per row, the super-cell
/// size and how many rays read the first column.
#[derive(Clone, Copy, Debug)]
struct RowStart {
    start: usize,
    nw: usize,
    s: usize,
    left: usize,
}

impl RowStart {
    /// Moves to the next ray's column (`CHECKED`: super cells, where rays share
    /// a column; otherwise every ray has its own).
    #[inline(always)]
    fn advance<const CHECKED: bool>(&mut self) {
        if CHECKED {
            self.left -= 1;
            if self.left == 0 {
                self.start += self.nw;
                self.left = self.s;
            }
        } else {
            // (cell size 1: every ray has its own column)
            debug_assert_eq!(self.s, 1);
            self.start += self.nw;
        }
    }

    fn new<W: Word>(mask: &BinaryMask<W>, q: usize, p0: usize) -> Self {
        let (sp, left) = mask.column_run(p0);
        let sq = mask.ray_column(p0, q).1;
        RowStart { start: mask.row_start(sp, sq), nw: mask.words_per_row(), s: mask.cell_size(), left }
    }
}

impl<W: Word> Frame<'_, W> {
    /// The walk of the depth row starting at word `start`, at its first
    /// matching slot (no slot left: no candidate).
    #[inline(always)]
    fn first<S: Sampler, const ASC: bool, const ONE: bool>(&self, s: S, start: usize, nw: usize) -> Walk<W> {
        let (w, kbase) = if ASC { (start, 0) } else { (start + nw - 1, (nw - 1) * self.slots::<ONE>()) };
        let cur = self.hits::<ONE>(self.word(w));
        let mut walk = Walk { w, cur, kbase, left: nw - 1 };
        // a first word with no match: it and the words after it, four at a
        // time where the level can
        if cur == W::ZERO && s.seek::<W, ASC, ONE>(self, &mut walk, 0) {
            return walk;
        }
        self.settle::<S, ASC, ONE>(s, &mut walk);
        walk
    }

    /// Moves `walk` past words with no matching slot; false at the row's end.
    /// Where the CPU level can ([`Sampler::seek`]), the words after the
    /// current one are tested four at a time, and the walk moves straight to
    /// the first with a match; the last fewer than four are stepped one at a
    /// time.
    #[inline(always)]
    fn settle<S: Sampler, const ASC: bool, const ONE: bool>(&self, s: S, walk: &mut Walk<W>) -> bool {
        if walk.cur != W::ZERO {
            return true;
        }
        if s.seek::<W, ASC, ONE>(self, walk, 1) {
            return walk.cur != W::ZERO;
        }
        loop {
            if walk.left == 0 {
                return false;
            }
            walk.pass::<ASC>(1, self.slots::<ONE>());
            walk.cur = self.hits::<ONE>(self.word(walk.w));
            if walk.cur != W::ZERO {
                return true;
            }
        }
    }

    /// Word `w` of the mask, which must lie in a depth row of the row of
    /// rays being rendered.
    #[inline(always)]
    fn word(&self, w: usize) -> W {
        debug_assert!(w < self.words.len());
        // SAFETY: a walk reads only the words of its ray's depth row, `[start,
        // start + nw)` (`first` starts at either end, `settle` moves at most
        // `nw − 1` words inwards); `lean_row` asserted that the depth rows of
        // every ray of its row lie in `words`. Exercised by every lean frame
        // (tests/it/lean_frame.rs).
        unsafe { *self.words.get_unchecked(w) }
    }

    /// Slices per word (`ONE`: one-bit codes, a slice a bit, known at compile
    /// time).
    #[inline(always)]
    fn slots<const ONE: bool>(&self) -> usize {
        debug_assert!(!ONE || self.slots == W::BITS as usize);
        if ONE { W::BITS as usize } else { self.slots }
    }

    /// The matching slots of word `w` ([`Matcher::hits`]; `ONE`: the codes
    /// are one bit wide, so every set bit matches).
    #[inline(always)]
    fn hits<const ONE: bool>(&self, w: W) -> W {
        debug_assert!(!ONE || self.log_nb == 0);
        if ONE { w } else { self.m.hits(w) }
    }

    /// The table entry of slice `k`, which must be a slot of a depth row
    /// (every slice a walk takes is: `kbase` counts whole words before the
    /// slot) or a slice of the stack (the refinement's slice before).
    #[inline(always)]
    fn slice(&self, k: usize) -> &SliceEntry {
        debug_assert!(k < self.slices.len());
        // SAFETY: `k` is a walk's slot, `kbase + (pos >> log_nb)` with `kbase`
        // at most `(nw − 1)·slots` and `pos < W::BITS = slots << log_nb`, so
        // `k < nw·slots`, or a slice of the stack, `k < nk`; `render` asserted
        // the table at least `nw·slots` and `nk` long (`fill` pads it).
        // Exercised by every lean frame (tests/it/lean_frame.rs).
        unsafe { self.slices.get_unchecked(k) }
    }

    /// The slice of the walk's next candidate (the walk must be settled).
    #[inline(always)]
    fn peek<const ASC: bool, const ONE: bool>(&self, walk: &Walk<W>) -> usize {
        let pos = if ASC { walk.cur.lz() } else { W::BITS - 1 - walk.cur.tz() };
        walk.kbase + (pos >> if ONE { 0 } else { self.log_nb }) as usize
    }

    /// Takes the walk's next candidate (the walk must be settled).
    #[inline(always)]
    fn take<const ASC: bool, const ONE: bool>(&self, walk: &mut Walk<W>) -> usize {
        let k = self.peek::<ASC, ONE>(walk);
        walk.cur = if ASC { walk.cur & !(W::MSB >> walk.cur.lz()) } else { walk.cur.clear_lowest() };
        k
    }

    /// The stack index of `ray`'s cell in slice entry `e`, if the ray meets
    /// the slice inside the volume.
    #[inline(always)]
    fn cell(&self, e: &SliceEntry, ray: LeanRay) -> Option<usize> {
        let ci = ray.p as i32 + e.di;
        let cj = ray.q as i32 + e.dj;
        ((ci as u32) < self.cells[0] && (cj as u32) < self.cells[1]).then(|| ray.rb.wrapping_add_signed(e.base))
    }

    /// The stack index of `ray`'s cell in slice entry `e`, or `usize::MAX`
    /// outside the volume (tested only with `CHECKED`).
    #[inline(always)]
    fn cell_at<const CHECKED: bool>(&self, e: &SliceEntry, ray: LeanRay) -> usize {
        debug_assert!(CHECKED || self.cell(e, ray).is_some(), "a candidate outside the volume at cell size 1");
        if CHECKED { self.cell(e, ray).unwrap_or(usize::MAX) } else { ray.rb.wrapping_add_signed(e.base) }
    }

    /// Traces `ray` into its pixel from its first candidate (slice `k`,
    /// stack index `b`: `usize::MAX` when its cell is outside the volume)
    /// and the rest of its `walk`: the first
    /// candidate whose sample reaches the iso value, refined and shaded; the
    /// pixel is left as it is (a miss) if there is none.
    #[inline(always)]
    fn trace<V: Cells, S: Sampler, const ASC: bool, const CHECKED: bool, const ONE: bool, const CUBIC: bool>(
        &self,
        v: &V,
        s: S,
        ray: LeanRay,
        (mut walk, mut k, mut b): (Walk<W>, usize, usize),
        px: Pixel,
    ) {
        // the last sample below the iso value: its slice and density
        let mut below = Below { k: usize::MAX, d: 0.0 };
        loop {
            if !CHECKED || b != usize::MAX {
                // the row of the cell that the ray of the next row reads here
                // and no ray of this row reads (module docs)
                v.prefetch_voxel(b.wrapping_add(self.ahead));
                let e = self.slice(k);
                let d = s.sample(v, b, e);
                if d >= self.iso {
                    return self.hit::<V, S, ASC, CUBIC>(v, s, ray, Visit { k, b, d }, below, px);
                }
                below = Below { k, d };
            }
            if !self.settle::<S, ASC, ONE>(s, &mut walk) {
                return;
            }
            k = self.take::<ASC, ONE>(&mut walk);
            b = self.cell_at::<CHECKED>(self.slice(k), ray);
        }
    }

    /// The fraction of the cubic crossing ([`RayContext::with_cubic_crossing`]
    /// along stack axis `za`) between the slice before `(kp, bp, dp)` and
    /// the hit `(k, b, d)` (slice, stack index of the cell, density), the
    /// general hit's: the same samples by the same functions.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn cubic_fraction<V: Cells, S: Sampler, const ASC: bool>(
        &self,
        v: &V,
        s: S,
        ray: LeanRay,
        za: usize,
        (k, b, d): (usize, usize, f32),
        (kp, bp, dp): (usize, usize, f32),
        linear: f32,
    ) -> f32 {
        if za == 2 {
            // the samples before the segment and after it (repeating its ends)
            let outer = |k: Option<usize>, end: f32| {
                k.and_then(|k| {
                    let e = self.slice(k);
                    self.cell(e, ray).map(|b| s.sample(v, b, e))
                })
                .unwrap_or(end)
            };
            let before = if ASC { kp.checked_sub(1) } else { Some(kp + 1).filter(|&x| x < self.nk) };
            let after = if ASC { Some(k + 1).filter(|&x| x < self.nk) } else { k.checked_sub(1) };
            return reconstruct::crossing_near([outer(before, dp), dp, d, outer(after, d)], self.iso, linear);
        }
        let at = |k: usize| {
            let e = self.slice(k);
            let (ci, cj) = ((ray.p as i32 + e.di) as usize, (ray.q as i32 + e.dj) as usize);
            At { k, ci, cj, wi: e.wi, wj: e.wj }
        };
        let last = self.cells[za] as usize;
        let cp = cubic_in_slice(v, self.n0, za, last, at(kp), bp);
        let c = cubic_in_slice(v, self.n0, za, last, at(k), b);
        in_slice_fraction(cp, c, self.iso, linear)
    }

    /// The iso hit `at` (slice, stack index, density) into its pixel:
    /// refined against the slice before it in walking order and shaded by the
    /// blend of both slices' shade entries, as [`RayContext`]'s general hit.
    /// `below` is the ray's last sample below the iso value: when it is the
    /// slice before, its density is the one the refinement needs (the same
    /// cell, weights and arithmetic) and is not sampled again.
    /// With the cubic crossing (`CUBIC`: [`RayContext::with_cubic_crossing`],
    /// a row compiled for it, so the linear frame's walk is the same code
    /// without it) the hit is placed at the cubic's fraction instead
    /// ([`Frame::cubic_fraction`]).
    #[inline(always)]
    fn hit<V: Cells, S: Sampler, const ASC: bool, const CUBIC: bool>(&self, v: &V, s: S, ray: LeanRay, at: Visit, below: Below, px: Pixel) {
        let (iso, Visit { k, b, d }) = (self.iso, at);
        let e = self.slice(k);
        let kp = if ASC { k.checked_sub(1) } else { Some(k + 1).filter(|&kp| kp < self.nk) };
        // the slice before in walking order, when its sample is below iso:
        // its slice, the refinement's fraction, its cell and its entry
        let mut before = None;
        if let Some(kp) = kp {
            let ep = self.slice(kp);
            let prev = if below.k == kp {
                // (a visited cell: inside the volume)
                Some((ray.rb.wrapping_add_signed(ep.base), below.d))
            } else {
                self.cell(ep, ray).map(|bp| (bp, s.sample(v, bp, ep)))
            };
            if let Some((bp, dp)) = prev
                && dp < iso
            {
                let linear = ((iso - dp) / (d - dp)).clamp(0.0, 1.0);
                let t = match self.cubic {
                    Some(za) if CUBIC => self.cubic_fraction::<V, S, ASC>(v, s, ray, za, (k, b, d), (kp, bp, dp), linear),
                    _ => linear,
                };
                before = Some((kp, t, bp, ep));
            }
        }
        // (slice indices are below 2^24: exact as f32 through u32, as through
        // usize; `k − kp` is ±1 in walking order, so the general path's
        // `kp + (k − kp)·t` is `kp ± t`, the same float)
        let depth = match before {
            None => k as u32 as f32,
            Some((kp, t, _, _)) => kp as u32 as f32 + if ASC { t } else { -t },
        };
        let s = match before {
            None => self.table.blend(v.codes(b), e.wi, e.wj),
            Some((_, t, bp, ep)) => {
                // both slices' blends in one 4-lane vector: [s, sp]
                let s = blend_pair(self.table, v.codes(b), [e.wi, e.wj], v.codes(bp), [ep.wi, ep.wj]);
                [0, 1].map(|a| s[2 + a] + (s[a] - s[2 + a]) * t)
            }
        };
        let rgb = apply_shade(self.iso_rgb, s);
        *px.rgba = [rgb[0], rgb[1], rgb[2], 1.0];
        *px.depth = depth;
    }
}

/// A sample of a ray at a candidate: slice, stack index of its cell, density.
#[derive(Clone, Copy, Debug)]
struct Visit {
    k: usize,
    b: usize,
    d: f32,
}

/// A ray's last sample below the iso value: its slice and density.
#[derive(Clone, Copy, Debug)]
struct Below {
    k: usize,
    d: f32,
}

/// The colour and depth of one pixel of the intermediate image.
struct Pixel<'a> {
    rgba: &'a mut [f32; 4],
    depth: &'a mut f32,
}

/// [`ShadeTable::blend`] of two cells at once, lane for lane the same float
/// operations: lanes 0–1 the entry of `codes` at weights `w`, lanes 2–3 that of
/// `codes_p` at `wp`. On x86-64 each corner's two entries are loaded straight
/// into the halves of one SSE vector ([`blend_pair_plain`] elsewhere; tested
/// equal bit for bit).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn blend_pair(table: &ShadeTable, codes: [u16; 4], w: [f32; 2], codes_p: [u16; 4], wp: [f32; 2]) -> [f32; 4] {
    use std::arch::x86_64::*;
    // SAFETY: SSE and SSE2 are the x86-64 baseline; each read takes the 8
    // bytes of one `ShadeEntry` (`[f32; 2]`) through a reference to it,
    // unaligned, as the bits of its two floats. Exercised by every lean frame (tests/it/lean_frame.rs)
    // and by `blend_pair_is_the_plain_blend`.
    unsafe {
        let e = |i: usize| {
            let bits = |c: u16| (table.entry(c) as *const ShadeEntry).cast::<i64>().read_unaligned();
            _mm_castsi128_ps(_mm_set_epi64x(bits(codes_p[i]), bits(codes[i])))
        };
        let (e00, e10, e01, e11) = (e(0), e(1), e(2), e(3));
        let (wi, wj) = (_mm_setr_ps(w[0], w[0], wp[0], wp[0]), _mm_setr_ps(w[1], w[1], wp[1], wp[1]));
        let top = _mm_add_ps(e00, _mm_mul_ps(_mm_sub_ps(e10, e00), wi));
        let bot = _mm_add_ps(e01, _mm_mul_ps(_mm_sub_ps(e11, e01), wi));
        let mut out = [0f32; 4];
        _mm_storeu_ps(out.as_mut_ptr(), _mm_add_ps(top, _mm_mul_ps(_mm_sub_ps(bot, top), wj)));
        out
    }
}

#[cfg(not(target_arch = "x86_64"))]
use blend_pair_plain as blend_pair;

/// [`blend_pair`] lane by lane in plain code.
#[cfg_attr(target_arch = "x86_64", allow(dead_code))]
#[inline(always)]
fn blend_pair_plain(table: &ShadeTable, codes: [u16; 4], w: [f32; 2], codes_p: [u16; 4], wp: [f32; 2]) -> [f32; 4] {
    let e = |i: usize| {
        let (a, b) = (table.get(codes[i]), table.get(codes_p[i]));
        [a[0], a[1], b[0], b[1]]
    };
    let (e00, e10, e01, e11) = (e(0), e(1), e(2), e(3));
    let (wi, wj) = ([w[0], w[0], wp[0], wp[0]], [w[1], w[1], wp[1], wp[1]]);
    let mut out = [0f32; 4];
    for l in 0..4 {
        let top = e00[l] + (e10[l] - e00[l]) * wi[l];
        let bot = e01[l] + (e11[l] - e01[l]) * wi[l];
        out[l] = top + (bot - top) * wj[l];
    }
    out
}

/// One row of the lean frame by the copy compiled for the CPU level (`avx2`:
/// the mask's level, [`BinaryMask::cpu_level`], has AVX2).
#[inline(always)]
fn lean_row_at<W: Word, V: Cells, const ASC: bool, const CHECKED: bool, const ONE: bool, const CUBIC: bool>(
    f: &Frame<W>,
    v: &V,
    avx2: bool,
    row: RowStart,
    out: RowOut,
) {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: the mask's CPU level has AVX2; a mask's level is capped to
        // at most `kernels::detected()`, which is `Avx2` only when
        // `is_x86_feature_detected!` found lzcnt and bmi1 on this CPU at run
        // time, all that `lean_row_lzcnt` requires; its body is the safe
        // `lean_row`.
        unsafe { lean_row_lzcnt::<W, V, ASC, CHECKED, ONE, CUBIC>(f, v, row, out) };
        return;
    }
    let _ = avx2;
    lean_row::<W, V, Plain, ASC, CHECKED, ONE, CUBIC>(f, v, Plain, row, out)
}

/// One row of the lean frame: the row cleared to misses, then ray by ray
/// its first candidate and its trace. A ray's base index is the row's plus
/// its offset along the row.
#[inline(always)]
fn lean_row<W: Word, V: Cells, S: Sampler, const ASC: bool, const CHECKED: bool, const ONE: bool, const CUBIC: bool>(
    f: &Frame<W>,
    v: &V,
    s: S,
    mut row: RowStart,
    out: RowOut,
) {
    let RowOut { q, p0, rgba: crow, depth: drow } = out;
    crow.fill(MISS.rgba);
    drow.fill(MISS.depth);
    // the depth rows of all rays lie in the mask (what `Frame::word` relies
    // on): the last ray's column is the row's last
    let n = crow.len();
    let columns = if !CHECKED || n == 0 {
        n
    } else if n <= row.left {
        1
    } else {
        (n - 1 - row.left) / row.s + 2
    };
    assert!(row.start + columns * row.nw <= f.words.len(), "a row of rays past the mask");
    // ray (p0 + dp, q)'s base index is the row's plus dp
    let rb0 = p0 + f.n0 * q;
    // with super cells the rays of a super cell read one column: its first
    // matching slot is found once, for the first of them
    let mut shared: Option<(usize, Walk<W>)> = None;
    for (dp, (rgba, depth)) in crow.iter_mut().zip(drow.iter_mut()).enumerate() {
        let mut walk = match shared {
            Some((start, walk)) if CHECKED && start == row.start => walk,
            _ => {
                let walk = f.first::<S, ASC, ONE>(s, row.start, row.nw);
                shared = CHECKED.then_some((row.start, walk));
                walk
            }
        };
        if walk.cur != W::ZERO {
            let ray = LeanRay { p: p0 + dp, q, rb: rb0 + dp };
            let k = f.take::<ASC, ONE>(&mut walk);
            let b = f.cell_at::<CHECKED>(f.slice(k), ray);
            f.trace::<V, S, ASC, CHECKED, ONE, CUBIC>(v, s, ray, (walk, k, b), Pixel { rgba, depth });
        }
        row.advance::<CHECKED>();
    }
}

/// [`lean_row`] compiled with `lzcnt`/`tzcnt` (single instructions for the
/// bit scans), SSSE3 (the visits' gathers) and AVX2 (the walk's four-word
/// seeks; both [`Avx2`]). Callers must hold a CPU level with AVX2 that is at
/// most [`crate::kernels::detected`] (that level implies lzcnt, bmi1 and
/// SSSE3).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "lzcnt,bmi1,sse3,ssse3,avx,avx2")]
unsafe fn lean_row_lzcnt<W: Word, V: Cells, const ASC: bool, const CHECKED: bool, const ONE: bool, const CUBIC: bool>(
    f: &Frame<W>,
    v: &V,
    row: RowStart,
    out: RowOut,
) {
    // SAFETY: the caller holds a CPU level that has AVX2, so SSSE3 (this
    // function's contract)
    let s = unsafe { Avx2::new() };
    lean_row::<W, V, Avx2, ASC, CHECKED, ONE, CUBIC>(f, v, s, row, out)
}

/// What the CPU level changes in a row of the lean frame: how a visit
/// samples its cell, and whether the walk passes words four at a time
/// ([`Plain`] or [`Avx2`]; the same values and walk, bit for bit).
trait Sampler: Copy {
    /// The density of `v`'s cell at stack index `b` at the weights of slice entry `e`.
    fn sample<V: Cells>(self, v: &V, b: usize, e: &SliceEntry) -> f32;

    /// Moves `walk` to the first word with a matching slot, testing whole
    /// groups of four words; the first group starts `after` words past the
    /// current one in walking order, and the words before it must have no
    /// matching slot left. True when the walk is settled: at that word, its
    /// matching slots loaded, or at the row's end with none (the groups
    /// reached it); false, nothing found, when fewer than four words are
    /// left untested (the walk then stands at the last word tested, with
    /// none). Always false where the level has no vector for it.
    #[inline(always)]
    fn seek<W: Word, const ASC: bool, const ONE: bool>(self, f: &Frame<W>, walk: &mut Walk<W>, after: usize) -> bool {
        let _ = (f, walk, after);
        false
    }
}

/// [`bilinear`] of the four corner densities; words one at a time.
#[derive(Clone, Copy, Debug)]
struct Plain;

impl Sampler for Plain {
    #[inline(always)]
    fn sample<V: Cells>(self, v: &V, b: usize, e: &SliceEntry) -> f32 {
        bilinear(v.densities(b), e.wi, e.wj)
    }
}

/// The layout's SSSE3 gather and [`crate::data::slices::bilinear_sse`]
/// ([`Cells::sample_ssse3`]), and the matcher's four-word test
/// ([`Matcher::hit_words4`]) on u64 words; a value of it proves the CPU has
/// AVX2 (and so SSSE3).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
struct Avx2 {
    _proof: (),
}

#[cfg(target_arch = "x86_64")]
impl Avx2 {
    /// # Safety
    /// The CPU must have AVX2 (and so SSSE3 and SSE3).
    #[inline(always)]
    unsafe fn new() -> Self {
        Avx2 { _proof: () }
    }
}

#[cfg(target_arch = "x86_64")]
impl Sampler for Avx2 {
    #[inline(always)]
    fn sample<V: Cells>(self, v: &V, b: usize, e: &SliceEntry) -> f32 {
        // SAFETY: an `Avx2` exists only where the CPU has AVX2 and so SSSE3
        // (`Avx2::new`'s contract); it is made in `lean_row_lzcnt`, whose
        // code has the features, so the gathers inline. Exercised by every lean
        // frame at the AVX2 level (tests/it/lean_frame.rs compares it with the
        // scalar level and the brute force).
        unsafe { v.sample_ssse3(b, e.wi, e.wj) }
    }

    #[inline(always)]
    fn seek<W: Word, const ASC: bool, const ONE: bool>(self, f: &Frame<W>, walk: &mut Walk<W>, mut after: usize) -> bool {
        if W::BITS != 64 {
            return false;
        }
        let words = f.words.as_ptr().cast::<u64>();
        while walk.left >= after + 3 {
            // the four words from `after` past the current one in walking
            // order, in memory order
            let at = if ASC { walk.w + after } else { walk.w - after - 3 };
            debug_assert!(at + 4 <= f.words.len());
            // SAFETY: `W` is 64 bits wide (checked above; `Word` is u32 or
            // u64), so the words are u64s. `left ≥ after + 3` words of the
            // ray's depth row follow word `w` in walking order, so `[at, at +
            // 4)` lies in the row, which lies in `words` (`Frame::word`). The
            // CPU has AVX2 (a value of `Avx2` proves it). Exercised by the lean
            // frames of depth rows of four words and longer at the AVX2 level
            // (tests/it/lean_frame.rs).
            let hit = unsafe { if ONE { crate::encode::depth::nonzero_words4(words.add(at)) } else { f.m.hit_words4(words.add(at)) } };
            if hit != 0 {
                // the first in walking order: ascending the lowest word,
                // descending the highest
                let i = if ASC { hit.trailing_zeros() } else { hit.leading_zeros() - 28 };
                walk.pass::<ASC>(after + i as usize, f.slots::<ONE>());
                walk.cur = f.hits::<ONE>(f.word(walk.w));
                return true;
            }
            walk.pass::<ASC>(after + 3, f.slots::<ONE>());
            after = 1;
        }
        walk.left == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classify::shading::Shading;

    #[test]
    fn blend_pair_is_the_plain_blend() {
        let mut table = ShadeTable::default();
        table.update([0.3, -0.5, 0.81], Shading::default());
        let mut x = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        for _ in 0..20_000 {
            // (normal codes, as the cells hold)
            let code = |r: u64| (r % crate::data::normals::NORMAL_CODES as u64) as u16;
            let codes = [0; 4].map(|_: u16| code(next()));
            let codes_p = [0; 4].map(|_: u16| code(next()));
            let w = |r: u64| [0.0, 1.0, 0.5, (r >> 40) as f32 / (1u64 << 24) as f32][(r & 3) as usize];
            let (wa, wb) = ([w(next()), w(next())], [w(next()), w(next())]);
            let (a, b) = (blend_pair(&table, codes, wa, codes_p, wb), blend_pair_plain(&table, codes, wa, codes_p, wb));
            assert_eq!(a.map(f32::to_bits), b.map(f32::to_bits), "{codes:?} {codes_p:?} {wa:?} {wb:?}");
        }
    }
}
