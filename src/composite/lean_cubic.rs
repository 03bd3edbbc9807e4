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
//!   test on two integers, instead of the general ray's sample map.
//! - **Along the slices, a register of four densities**: a candidate `k`
//!   tests the cubic through the samples of the slices `k − 2 … k + 1` (in
//!   walking order); a ray keeps the four of its last candidate and shifts
//!   them by one slice when the next candidate is the next slice, so a run
//!   of candidates reads one new sample each, and the segment's
//!   [`reconstruct::upper_bound`] rejects it before any solve.
//! - **Prefetched first tests**: in groups of rays, every ray's first
//!   candidate is found and the voxels its first test reads are prefetched
//!   before the group is traced, so the cache misses of a group overlap.
//! - **The expensive parts only at the hit**: the crossing's solve
//!   ([`reconstruct::crossing`]) runs where the bound admits one, and the
//!   normal (the B-spline gradient) once, at the ray's hit.
//!
//! Invariants (what keeps the image the general path's and the brute
//! force's, bit for bit):
//! - the candidate slices are the general walk's ([`SetBits`] with the same
//!   matcher and search), in the same order;
//! - a sample's cell, weights and density are the general ray's
//!   ([`super::raycast::GridRay`] over the same [`crate::view::plan::SliceMap`]s,
//!   the same in-volume test, `RayContext::sample_cubic`'s arithmetic);
//! - the four samples of a segment, their fallbacks at the ends of the
//!   volume, the bound, the crossing and the hit are the general path's
//!   (`RayContext::hit_along`, `RayContext::hit_in_slice`,
//!   `RayContext::hit_at_slice`), so every float operation is the same.

use crate::composite::lean::{SliceEntry, slice_table};
use crate::composite::raycast::{At, MISS, RayContext, RayResult, RowOut, render_rows};
use crate::composite::{Intermediate, Mode, Rect};
use crate::data::slices::{bilinear, prefetch_cell};
use crate::encode::depth::{Matcher, Search, SetBits, Word};
use crate::encode::mask::BinaryMask;
use crate::kernels::reconstruct;
use crate::view::plan::{FramePlan, MapKind};

/// The per-slice table of the lean cubic frame, kept across frames.
#[derive(Clone, Debug, Default)]
pub struct LeanCubic {
    slices: Vec<SliceEntry>,
}

/// What the rays of one frame read.
struct Frame<'c, 'a> {
    ctx: &'c RayContext<'a>,
    slices: &'c [SliceEntry],
    n0: usize,
    cells: [u32; 2],
    /// The cubic's stack axis (2: along the slices).
    za: usize,
    /// The last slice index.
    last: usize,
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

    /// The table of the frame of `ctx`.
    fn fill(&mut self, ctx: &RayContext) {
        slice_table(ctx, &mut self.slices);
    }

    /// Renders the rays of `rect` of a cubic frame for which
    /// [`LeanCubic::applies`] holds (`ctx` runs the cubic along its stack
    /// axis `za`, [`RayContext::with_cubic`]) through the sheared `mask` of
    /// cubic codes and its matcher `m`, into `out`; marks `rect` valid. The
    /// same image as [`super::raycast::render_binary`] of the same frame,
    /// bit for bit.
    pub fn render<W: Word>(
        &mut self,
        ctx: &RayContext,
        za: usize,
        mask: &BinaryMask<W>,
        m: &Matcher,
        rect: Option<Rect>,
        out: &mut Intermediate,
    ) {
        assert!(LeanCubic::applies(ctx.plan, ctx.mode, Search::Bitscan), "a frame the lean cubic path does not cover");
        assert_eq!(m.width(), mask.code_width(), "a matcher of another code width");
        self.fill(ctx);
        let f = Frame { ctx, slices: &self.slices, n0: ctx.stack.n[0], cells: ctx.cell_counts(), za, last: ctx.stack.n[2] - 1 };
        let avx2 = mask.cpu_level().has_avx2();
        render_rows(rect, out, |row| {
            #[cfg(target_arch = "x86_64")]
            if avx2 {
                // SAFETY: the mask's CPU level has AVX2; a mask's level is
                // capped to at most `kernels::detected()`, which is `Avx2`
                // only when `is_x86_feature_detected!` found lzcnt and bmi1
                // on this CPU at run time, all that `row_lzcnt` requires;
                // its body is the safe `cubic_row`.
                unsafe { row_lzcnt(&f, mask, m, row) };
                return;
            }
            let _ = avx2;
            cubic_row(&f, mask, m, row)
        });
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
fn cubic_row<W: Word>(f: &Frame, mask: &BinaryMask<W>, m: &Matcher, row: RowOut) {
    let RowOut { q, p0, rgba, depth } = row;
    let (mut sp, mut left) = mask.column_run(p0);
    let sq = mask.ray_column(p0, q).1;
    let s = mask.cell_size();
    let asc = f.ctx.ascending;
    let mut walks: [Option<SetBits<W>>; GROUP] = std::array::from_fn(|_| None);
    for (g, (cg, dg)) in rgba.chunks_mut(GROUP).zip(depth.chunks_mut(GROUP)).enumerate() {
        let pg = p0 + g * GROUP;
        for (dp, w) in walks[..cg.len()].iter_mut().enumerate() {
            let mut walk = SetBits::with_matcher(mask.row(sp, sq), asc, Search::Bitscan, m);
            *w = walk.peek().map(|k0| {
                f.prefetch(pg + dp, q, k0);
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
unsafe fn row_lzcnt<W: Word>(f: &Frame, mask: &BinaryMask<W>, m: &Matcher, row: RowOut) {
    cubic_row(f, mask, m, row)
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

    /// Traces ray `(p, q)` over its candidate slices `walk`.
    #[inline(always)]
    fn trace<W: Word>(&self, p: usize, q: usize, walk: SetBits<W>) -> RayResult {
        let ctx = self.ctx;
        let (iso, rgb) = (ctx.iso, ctx.iso_rgb);
        if self.za < 2 {
            for k in walk {
                let Some((at, _)) = self.at(p, q, k) else { continue };
                let d = ctx.sample_cubic(self.za, at);
                if d >= iso {
                    let prev = self.prev(k).and_then(|kp| self.at(p, q, kp)).map(|(ap, _)| (ap, ctx.sample_cubic(self.za, ap)));
                    return ctx.hit_in_slice(self.za, (iso, rgb), (at, d), prev);
                }
            }
            return MISS;
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
                let four = four.map(|(k, d)| (self.at(p, q, k).expect("sampled").0, d));
                return ctx.hit_along(rgb, four, t);
            }
        }
        MISS
    }
}
