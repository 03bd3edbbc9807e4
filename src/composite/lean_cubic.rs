//! The lean cubic iso frame: the binary rotator's iso surface under the
//! cubic reconstruction ([`crate::kernels::reconstruct`]) in the common
//! case, without the generality it does not use.
//!
//! A frame takes this path when its plan translates every slice
//! ([`MapKind::Translate`]), composites every slice with no per-ray limits,
//! focus interval or intermediate samples, the mode is [`Mode::Iso`] and the
//! depth search is the bit scan ([`LeanCubic::applies`]); the renderer
//! decides once per frame, every other cubic frame takes the general ray
//! loop of [`super::raycast`].
//!
//! What makes it lean:
//! - **A per-slice table** ([`SliceEntry`]): in parallel projection every ray of
//!   slice `k` shares the offset of its cell and the bilinear weights, so a
//!   ray locates its sample in a slice by one table entry and one in-volume
//!   test on two integers, instead of the general ray's sample map. With
//!   the cubic in the slice, every ray of a slice also shares its fraction
//!   along the cubic's axis, so the table holds that fraction's
//!   [`Weights`] (Catmull–Rom for the sample, B-spline for the normal),
//!   computed once a slice instead of once a sample.
//! - **A walk of its own** (`Walk`): each word of a depth row is matched
//!   once, when the walk reaches it, and a visit takes one bit scan and one
//!   bit clear (the general [`crate::encode::depth::SetBits`] matches the
//!   remaining codes of the word again at every visit); the walking
//!   direction is a constant of the compiled row.
//! - **In the slice, the axis a constant**: the sample and the gradient are
//!   compiled for the cubic along stack axis 0 and along 1, so their voxel
//!   offsets are fixed strides, read without per-voxel bounds checks (one
//!   check of the range).
//! - **Along the slices, a register of four densities**: a candidate `k`
//!   tests the cubic through the samples of the slices `k − 2 … k + 1` (in
//!   walking order); a ray keeps the four of its last candidate and shifts
//!   them by one slice when the next candidate is the next slice, so a run
//!   of candidates reads one new sample each, and the segment's
//!   [`reconstruct::upper_bound`] rejects it before any solve.
//! - **Prefetched first tests**: in groups of rays, every ray's first
//!   candidate is found and the voxels its first test reads are prefetched
//!   before the group is traced, so the cache misses of a group overlap.
//! - **The next row's voxel row**: every sample prefetches the voxel row
//!   that the ray of the next row of rays reads there and this row's rays do
//!   not (the lean frame's reasoning, [`super::lean`]).
//! - **The expensive parts only at the hit**: the crossing's solve
//!   ([`reconstruct::crossing`]) runs where the bound admits one, and the
//!   normal (the B-spline gradient) once, at the ray's hit.
//!
//! Invariants (what keeps the image the general path's and the brute
//! force's, bit for bit):
//! - the candidate slices are the general walk's ([`crate::encode::depth::SetBits`]
//!   with the same matcher and the bit scan), in the same order;
//! - a sample's cell, weights and density are the general ray's
//!   ([`super::raycast::GridRay`] over the same [`crate::view::plan::SliceMap`]s,
//!   the same in-volume test, `RayContext::sample_cubic_with`'s arithmetic
//!   on the same [`Weights`] of the same fraction);
//! - the four samples of a segment, their fallbacks at the ends of the
//!   volume, the bound, the crossing and the hit are the general path's
//!   (`RayContext::hit_along`, `RayContext::hit_in_slice`,
//!   `RayContext::hit_at_slice`), so every float operation is the same.

use crate::composite::lean::{SliceEntry, slice_table};
use crate::composite::raycast::{At, MISS, RayContext, RayResult, RowOut, render_rows};
use crate::composite::{Intermediate, Mode, Rect};
use crate::data::slices::{bilinear, prefetch_cell};
use crate::encode::depth::{Matcher, Search, Word};
use crate::encode::mask::BinaryMask;
use crate::kernels::reconstruct::{self, Weights};
use crate::view::plan::{FramePlan, MapKind};

/// The per-slice table of the lean cubic frame, kept across frames.
#[derive(Clone, Debug, Default)]
pub struct LeanCubic {
    slices: Vec<SliceEntry>,
    /// In the slice, the [`Weights`] of each slice's fraction along the
    /// cubic's axis.
    weights: Vec<Weights>,
}

/// What the rays of one frame read.
struct Frame<'c, 'a> {
    ctx: &'c RayContext<'a>,
    slices: &'c [SliceEntry],
    weights: &'c [Weights],
    n0: usize,
    cells: [u32; 2],
    /// The cubic's stack axis (2: along the slices).
    za: usize,
    /// The last slice index.
    last: usize,
    /// A row of voxels (`n0`) with prefetches, 0 without: the next row's
    /// voxel row lies this far past a sample's cell times two (three along
    /// stack axis 1 in the slice); without, the hint names the line a
    /// sample reads anyway, so it needs no branch.
    ahead: usize,
    /// Whether a group's first candidates are prefetched before it is traced.
    group: bool,
}

impl LeanCubic {
    /// Whether a cubic iso frame of `plan` in `mode` with depth search
    /// `search` takes the lean path (with a cubic along the slices the
    /// renderer also needs [`super::raycast::cubic_walks`], true for every
    /// translated plan).
    pub fn applies(plan: &FramePlan, mode: Mode, search: Search) -> bool {
        plan.kind == MapKind::Translate
            && mode == Mode::Iso
            && search == Search::Bitscan
            && !plan.limited()
            && plan.focus.is_none()
            && !plan.intermediate()
    }

    /// The tables of the frame of `ctx` with the cubic along stack axis `za`.
    fn fill(&mut self, ctx: &RayContext, za: usize) {
        slice_table(ctx, &mut self.slices);
        self.weights.clear();
        if za < 2 {
            self.weights.extend(self.slices.iter().map(|e| Weights::new(if za == 0 { e.wi } else { e.wj })));
        }
    }

    /// Renders the rays of `rect` of a cubic frame for which
    /// [`LeanCubic::applies`] holds (`ctx` runs the cubic along the stack
    /// axis [`reconstruct::cubic_axis`] gives, [`RayContext::with_cubic`]) through the sheared `mask` of
    /// cubic codes and its matcher `m`, into `out`; marks `rect` valid. The
    /// same image as [`super::raycast::render_binary`] of the same frame,
    /// bit for bit. With `prefetch` every sample prefetches the voxel row the
    /// next row of rays reads there and each group's first tests are
    /// prefetched (module docs); without, no hint names a line the frame has
    /// not just read.
    pub fn render<W: Word>(
        &mut self,
        ctx: &RayContext,
        mask: &BinaryMask<W>,
        m: &Matcher,
        prefetch: bool,
        rect: Option<Rect>,
        out: &mut Intermediate,
    ) {
        assert!(LeanCubic::applies(ctx.plan, ctx.mode, Search::Bitscan), "a frame the lean cubic path does not cover");
        assert_eq!(m.width(), mask.code_width(), "a matcher of another code width");
        let za = reconstruct::cubic_axis(ctx.stack.perm());
        self.fill(ctx, za);
        let f = Frame {
            ctx,
            slices: &self.slices,
            weights: &self.weights,
            n0: ctx.stack.n[0],
            cells: ctx.cell_counts(),
            za,
            last: ctx.stack.n[2] - 1,
            ahead: if prefetch { ctx.stack.n[0] } else { 0 },
            group: prefetch,
        };
        let avx2 = mask.cpu_level().has_avx2();
        if ctx.ascending { rows::<W, true>(&f, mask, m, rect, out, avx2) } else { rows::<W, false>(&f, mask, m, rect, out, avx2) }
    }
}

/// The rows of `rect` of the frame `f`, walking the slices in ascending
/// (`ASC`) or descending order; `avx2`: the mask's CPU level has AVX2.
fn rows<W: Word, const ASC: bool>(f: &Frame, mask: &BinaryMask<W>, m: &Matcher, rect: Option<Rect>, out: &mut Intermediate, avx2: bool) {
    render_rows(rect, out, |row| {
        #[cfg(target_arch = "x86_64")]
        if avx2 {
            // SAFETY: the mask's CPU level has AVX2; a mask's level is
            // capped to at most `kernels::detected()`, which is `Avx2`
            // only when `is_x86_feature_detected!` found lzcnt and bmi1
            // on this CPU at run time, all that `row_lzcnt` requires;
            // its body is the safe `cubic_row`.
            unsafe { row_lzcnt::<W, ASC>(f, mask, m, row) };
            return;
        }
        let _ = avx2;
        cubic_row::<W, ASC>(f, mask, m, row)
    });
}

/// The candidate slices of one depth row in walking order (ascending:
/// `ASC`): the slots whose code the matcher takes, the same slices in the
/// same order as [`crate::encode::depth::SetBits`] with the same matcher and the bit scan. Each
/// word is matched once as it is reached; a visit then takes one bit scan
/// and one bit clear.
struct Walk<'a, W: Word, const ASC: bool> {
    row: &'a [W],
    m: &'a Matcher,
    /// `log₂` of the code width (a slot's bit position to its slot).
    log_nb: u32,
    /// The index of the current word.
    w: usize,
    /// The matching slots of the current word not yet taken (the top bit of each).
    cur: W,
}

impl<'a, W: Word, const ASC: bool> Walk<'a, W, ASC> {
    #[inline(always)]
    fn new(row: &'a [W], m: &'a Matcher) -> Self {
        let w = if ASC { 0 } else { row.len().wrapping_sub(1) };
        let cur = row.get(w).map_or(W::ZERO, |&x| m.hits(x));
        Walk { row, m, log_nb: m.width().trailing_zeros(), w, cur }
    }

    /// Moves past words with no matching slot left; false at the row's end.
    #[inline(always)]
    fn settle(&mut self) -> bool {
        while self.cur == W::ZERO {
            if ASC {
                self.w += 1;
                if self.w >= self.row.len() {
                    return false;
                }
            } else {
                if self.w == 0 {
                    return false;
                }
                self.w -= 1;
            }
            self.cur = self.m.hits(self.row[self.w]);
        }
        true
    }

    /// The bit position (from the MSB) of the next matching slot's top bit
    /// (the walk must be settled).
    #[inline(always)]
    fn pos(&self) -> u32 {
        if ASC { self.cur.lz() } else { W::BITS - 1 - self.cur.tz() }
    }

    /// The slice of the slot at `pos` of the current word.
    #[inline(always)]
    fn slice(&self, pos: u32) -> usize {
        (self.w << (W::BITS.trailing_zeros() - self.log_nb)) + (pos >> self.log_nb) as usize
    }

    /// The slice the next step takes, without taking it.
    #[inline(always)]
    fn peek(&mut self) -> Option<usize> {
        self.settle().then(|| self.slice(self.pos()))
    }
}

impl<W: Word, const ASC: bool> Iterator for Walk<'_, W, ASC> {
    type Item = usize;
    #[inline(always)]
    fn next(&mut self) -> Option<usize> {
        if !self.settle() {
            return None;
        }
        let pos = self.pos();
        self.cur = if ASC { self.cur & !(W::MSB >> pos) } else { self.cur.clear_lowest() };
        Some(self.slice(pos))
    }
}

/// Rays per group: the first candidates of a group are found and their
/// voxels prefetched before the group is traced (the general path's
/// [`super::raycast::PREFETCH_GROUP`]).
const GROUP: usize = super::raycast::PREFETCH_GROUP;

/// One row of the lean cubic frame: each ray walks its (super) column of
/// the mask, stepping from column to column with a counter; in groups of
/// [`GROUP`] rays, first every ray's first candidate is found and the
/// voxels its first test reads are prefetched, then the rays are traced.
#[inline(always)]
fn cubic_row<W: Word, const ASC: bool>(f: &Frame, mask: &BinaryMask<W>, m: &Matcher, row: RowOut) {
    let RowOut { q, p0, rgba, depth } = row;
    let (mut sp, mut left) = mask.column_run(p0);
    let sq = mask.ray_column(p0, q).1;
    let s = mask.cell_size();
    let mut walks: [Option<Walk<W, ASC>>; GROUP] = std::array::from_fn(|_| None);
    for (g, (cg, dg)) in rgba.chunks_mut(GROUP).zip(depth.chunks_mut(GROUP)).enumerate() {
        let pg = p0 + g * GROUP;
        for (dp, w) in walks[..cg.len()].iter_mut().enumerate() {
            let mut walk = Walk::<W, ASC>::new(mask.row(sp, sq), m);
            *w = walk.peek().map(|k0| {
                if f.group {
                    f.prefetch(pg + dp, q, k0);
                }
                walk
            });
            left -= 1;
            if left == 0 {
                sp += 1;
                left = s;
            }
        }
        for (dp, ((c, d), w)) in cg.iter_mut().zip(dg.iter_mut()).zip(walks.iter_mut()).enumerate() {
            let res = match w.take() {
                None => MISS,
                Some(walk) => f.trace(pg + dp, q, walk),
            };
            *c = res.rgba;
            *d = res.depth;
        }
    }
}

/// [`cubic_row`] compiled with `lzcnt`/`tzcnt` (single instructions for
/// the bit scans). Callers must hold a CPU level with AVX2 that is at most
/// [`crate::kernels::detected`] (that level implies lzcnt and bmi1).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "lzcnt,bmi1")]
unsafe fn row_lzcnt<W: Word, const ASC: bool>(f: &Frame, mask: &BinaryMask<W>, m: &Matcher, row: RowOut) {
    cubic_row::<W, ASC>(f, mask, m, row)
}

impl Frame<'_, '_> {
    /// Ray `(p, q)`'s sample in slice `k`: its located cell, if the ray
    /// meets the slice inside the volume, and the cell's first stack index.
    #[inline(always)]
    fn at(&self, p: usize, q: usize, k: usize) -> Option<(At, usize)> {
        let e = &self.slices[k];
        let ci = p as i32 + e.di;
        let cj = q as i32 + e.dj;
        ((ci as u32) < self.cells[0] && (cj as u32) < self.cells[1]).then(|| {
            let b = (p + self.n0 * q).wrapping_add_signed(e.base);
            (At { k, ci: ci as usize, cj: cj as usize, wi: e.wi, wj: e.wj }, b)
        })
    }

    /// The density of ray `(p, q)` in slice `k` along the slices (`None`
    /// outside the volume): `RayContext::sample_cubic`'s.
    #[inline(always)]
    fn density(&self, p: usize, q: usize, k: usize) -> Option<f32> {
        let e = &self.slices[k];
        let ci = p as i32 + e.di;
        let cj = q as i32 + e.dj;
        if (ci as u32) < self.cells[0] && (cj as u32) < self.cells[1] {
            let b = (p + self.n0 * q).wrapping_add_signed(e.base);
            // the row the next row of rays reads here and this one does not
            self.ctx.stack.prefetch_voxel(b.wrapping_add(2 * self.ahead));
            Some(bilinear(self.ctx.stack.cell_at(b), e.wi, e.wj))
        } else {
            None
        }
    }

    /// Hints the cache to fetch what ray `(p, q)`'s test at its first
    /// candidate `k` reads: along the slices its cells in the slices `k − 2 …
    /// k + 1` (walking order), in the slice the four voxel rows around its
    /// cell in slice `k` and the slice before. No effect on results.
    #[inline(always)]
    fn prefetch(&self, p: usize, q: usize, k: usize) {
        let data = self.ctx.stack.data();
        let cell = |k: usize| (p + self.n0 * q).wrapping_add_signed(self.slices[k].base);
        let kp = self.prev(k);
        if self.za == 2 {
            for k in [kp.and_then(|kp| self.prev(kp)), kp, Some(k), self.next(k)].into_iter().flatten() {
                prefetch_cell(data, cell(k), self.n0);
            }
        } else {
            for k in [kp, Some(k)].into_iter().flatten() {
                let b = cell(k).wrapping_sub(1);
                prefetch_cell(data, b.wrapping_sub(self.n0), 2 * self.n0);
                prefetch_cell(data, b, 2 * self.n0);
            }
        }
    }

    /// The slice before `k` in walking order, if any.
    #[inline(always)]
    fn prev(&self, k: usize) -> Option<usize> {
        if self.ctx.ascending { k.checked_sub(1) } else { (k < self.last).then_some(k + 1) }
    }

    /// The slice after `k` in walking order, if any.
    #[inline(always)]
    fn next(&self, k: usize) -> Option<usize> {
        if self.ctx.ascending { (k < self.last).then_some(k + 1) } else { k.checked_sub(1) }
    }

    /// [`Frame::trace`] with the cubic in the slice, along stack axis `ZA`.
    #[inline(always)]
    fn trace_in_slice<const ZA: usize>(&self, p: usize, q: usize, walk: impl Iterator<Item = usize>) -> RayResult {
        let ctx = self.ctx;
        let (iso, rgb) = (ctx.iso, ctx.iso_rgb);
        for k in walk {
            let Some((at, b)) = self.at(p, q, k) else { continue };
            // the row the next row of rays reads here and this one does not:
            // along axis 1 a sample reads the cell's rows and one each side
            self.ctx.stack.prefetch_voxel(b.wrapping_add(if ZA == 1 { 3 } else { 2 } * self.ahead));
            let w = &self.weights[k];
            let d = ctx.sample_in_slice::<ZA>(at, b, &w.cr);
            if d >= iso {
                let prev = self.prev(k).and_then(|kp| self.at(p, q, kp)).map(|(ap, bp)| {
                    let wp = &self.weights[ap.k];
                    (ap, ctx.sample_in_slice::<ZA>(ap, bp, &wp.cr), wp)
                });
                return ctx.hit_in_slice_za::<ZA>((iso, rgb), (at, d, w), prev);
            }
        }
        MISS
    }

    /// Traces ray `(p, q)` over its candidate slices `walk`.
    #[inline(always)]
    fn trace(&self, p: usize, q: usize, walk: impl Iterator<Item = usize>) -> RayResult {
        let ctx = self.ctx;
        let (iso, rgb) = (ctx.iso, ctx.iso_rgb);
        match self.za {
            0 => return self.trace_in_slice::<0>(p, q, walk),
            1 => return self.trace_in_slice::<1>(p, q, walk),
            _ => {}
        }
        // the densities of the slices before the slice before, before, at and
        // after the last candidate (walking order; None: no such slice, or
        // outside the volume), shifted by one slice between consecutive candidates
        let mut last = usize::MAX;
        let mut reg: [Option<f32>; 4] = [None; 4];
        let sample = |k: Option<usize>| k.and_then(|k| self.density(p, q, k));
        for k in walk {
            let (kp, kn) = (self.prev(k), self.next(k));
            reg = if last != usize::MAX && kp == Some(last) {
                [reg[1], reg[2], reg[3], sample(kn)]
            } else {
                [sample(kp.and_then(|kp| self.prev(kp))), sample(kp), sample(Some(k)), sample(kn)]
            };
            last = k;
            let Some(d) = reg[2] else { continue };
            let (Some(kp), Some(dp)) = (kp, reg[1]) else {
                if d >= iso {
                    return ctx.hit_at_slice(rgb, self.at(p, q, k).expect("sampled").0);
                }
                continue;
            };
            // the four samples around the segment from the slice before to k, in walking order
            let before = match reg[0] {
                Some(x) => (self.prev(kp).expect("sampled"), x),
                None => (kp, dp),
            };
            let after = match (kn, reg[3]) {
                (Some(kn), Some(x)) => (kn, x),
                _ => (k, d),
            };
            let four = [before, (kp, dp), (k, d), after];
            let v = four.map(|s| s.1 as f64);
            if reconstruct::upper_bound(v[1].max(v[2]), v[0].min(v[3])) < iso as f64 {
                continue;
            }
            if let Some(t) = reconstruct::crossing(v, iso as f64) {
                let at = |(k, d): (usize, f32)| (self.at(p, q, k).expect("sampled").0, d);
                let four = [at(four[0]), at(four[1]), at(four[2]), at(four[3])];
                return ctx.hit_along(rgb, four, t);
            }
        }
        MISS
    }
}
