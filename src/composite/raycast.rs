//! Stage 5c — the bilinear resampling raycaster over the intermediate image.
//!
//! Owns the per-ray loop shared by the binary path and its brute-force reference:
//! each ray of the intermediate image visits candidate slices in front-to-back
//! order; at each it computes the exact in-slice sample position from the real
//! (not floored) slice translation, interpolates the density bilinearly from the
//! four voxels, classifies it, shades it (Blinn-Phong headlight: by default the
//! bilinear blend of its cell's four shade-table entries, looked up by the
//! voxels' normal codes of [`crate::data::normals`]; with [`crate::render::Normals::Gradient`]
//! the exact central-difference gradient at the sample) and composites it. A
//! ray reads its cells through [`Cells`]: from the f32 stack and the code array,
//! or, for 16-bit integer scans, from the one array that packs both
//! ([`crate::data::normals::NormalStack`]), with the same numbers either way. The *only* difference between the paths is the
//! candidate list: the binary path jumps from set bit to set bit of its sheared
//! mask ([`crate::encode::depth::SetBits`]), brute force visits every slice. Because the
//! mask is conservative, both produce the same image sample for sample.
//!
//! Modes: [`Mode::Iso`] stops at the first sample whose density reaches the iso
//! value, refines the hit linearly between it and the previous slice's sample, and
//! shades it opaque; [`Mode::Blend`] alpha-blends every visible sample with
//! opacity corrected for the view's sample spacing, until the accumulated opacity
//! reaches the early-termination threshold.

use rayon::prelude::*;

use crate::classify::Classifier;
use crate::classify::shading::{Shading, headlight_ndl};
use crate::composite::Rect;
use crate::composite::{Intermediate, Mode, composite, terminated};
use crate::data::normals::{ByteCells, NormalStack, PackedCells, ShadeTable, apply_shade};
use crate::data::slices::{SliceStack, bilinear};
use crate::encode::depth::{Matcher, Search, SetBits, Word};
use crate::encode::mask::BinaryMask;
use crate::view::plan::{FramePlan, MapKind, SliceMap};

/// Everything a ray needs, borrowed for one frame.
pub struct RayContext<'a> {
    pub stack: &'a SliceStack,
    pub classifier: &'a Classifier,
    /// The frame's plan.
    pub plan: &'a FramePlan,
    /// The frame's per-slice maps (translations: [`MapKind::Translate`]).
    pub maps: &'a [SliceMap],
    pub shading: Shading,
    pub mode: Mode,
    /// Iso value (iso mode).
    pub iso: f32,
    /// Unshaded colour of the iso surface.
    pub iso_rgb: [f32; 3],
    /// Early ray termination threshold on accumulated opacity (blend mode; see
    /// [`crate::composite::terminated`]).
    pub ert: f32,
    pub ascending: bool,
    /// Padding of the intermediate grid (mask column p ↔ sheared a = p − pad).
    pub pad: i32,
    cells: [u32; 2],
    grad_m: [f32; 3],
    grad_s: [f32; 3],
    /// Table shading ([`RayContext::with_normals`]): every voxel's normal code
    /// and the view's shade table. `None` shades from the exact gradient.
    normals: Option<(&'a NormalStack, &'a ShadeTable)>,
}

/// What one ray produced.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayResult {
    pub rgba: [f32; 4],
    /// Fractional slice index of the iso hit (NaN if none).
    pub depth: f32,
}

const MISS: RayResult = RayResult { rgba: [0.0; 4], depth: f32::NAN };

/// How a ray reads one cell of slice memory at stack index `b`: its four corner
/// densities, its four corner normal codes (table shading) and the cache hint
/// for both. Three layouts: [`Split`] (the f32 stack and the u16 code array: two
/// lines of each per cell), [`PackedCells`] (16-bit densities and codes in
/// one array: two lines) and [`ByteCells`] (8-bit densities and codes in
/// three bytes: two lines, now and then three). The row loops are compiled
/// once per layout, with no branch per access.
pub trait Cells: Sync {
    /// The corner densities `[v00, v10, v01, v11]` (exactly the stack's).
    fn densities(&self, b: usize) -> [f32; 4];
    /// The corner normal codes, same order (table shading only).
    fn codes(&self, b: usize) -> [u16; 4];
    /// Hints the cache to fetch both rows of the cell, densities and codes (no
    /// effect on results).
    fn prefetch(&self, b: usize);
    /// Hints the cache to fetch the cell's density rows (where only a sample
    /// is likely: the slice after a candidate). The same as
    /// [`Cells::prefetch`] where densities and codes share their lines.
    #[inline(always)]
    fn prefetch_densities(&self, b: usize) {
        self.prefetch(b)
    }
}

/// The stack's densities and the codes kept apart (no codes: gradient shading).
pub struct Split<'a> {
    stack: &'a SliceStack,
    codes: &'a [u16],
}

impl Cells for Split<'_> {
    #[inline(always)]
    fn densities(&self, b: usize) -> [f32; 4] {
        self.stack.cell_at(b)
    }
    #[inline(always)]
    fn codes(&self, b: usize) -> [u16; 4] {
        crate::data::slices::cell_corners(self.codes, b, self.stack.n[0])
    }
    #[inline(always)]
    fn prefetch(&self, b: usize) {
        self.stack.prefetch_cell(b);
        crate::data::slices::prefetch_cell(self.codes, b, self.stack.n[0]);
    }
}

impl Cells for PackedCells<'_> {
    #[inline(always)]
    fn densities(&self, b: usize) -> [f32; 4] {
        PackedCells::densities(self, b)
    }
    #[inline(always)]
    fn codes(&self, b: usize) -> [u16; 4] {
        PackedCells::codes(self, b)
    }
    #[inline(always)]
    fn prefetch(&self, b: usize) {
        PackedCells::prefetch(self, b)
    }
}

impl Cells for ByteCells<'_> {
    #[inline(always)]
    fn densities(&self, b: usize) -> [f32; 4] {
        ByteCells::densities(self, b)
    }
    #[inline(always)]
    fn codes(&self, b: usize) -> [u16; 4] {
        ByteCells::codes(self, b)
    }
    #[inline(always)]
    fn prefetch(&self, b: usize) {
        ByteCells::prefetch(self, b)
    }
}

/// Runs `$body` with `$v` bound to the cells of `$ctx` in their layout (one
/// monomorphized copy of the row loop per layout, no branch per access).
macro_rules! with_cells {
    ($ctx:expr, |$v:ident| $body:expr) => {
        match ($ctx.packed(), $ctx.normals.and_then(|(ns, _)| ns.bytes_cells())) {
            (Some($v), _) => $body,
            (None, Some($v)) => $body,
            (None, None) => {
                let $v = $ctx.split();
                $body
            }
        }
    };
}

impl<'a> RayContext<'a> {
    /// Sets up the rays of one frame of `plan` (whose slices must be `stack`'s).
    pub fn new(
        stack: &'a SliceStack,
        classifier: &'a Classifier,
        plan: &'a FramePlan,
        mode: Mode,
        iso: f32,
        shading: Shading,
        ert: f32,
    ) -> Self {
        assert_eq!(plan.kind, MapKind::Translate, "the ray traversal samples translated slices");
        assert_eq!(plan.maps.len(), stack.n[2], "a plan for another stack");
        let c = stack.cells();
        let iso_c = classifier.classify(iso);
        let f = &plan.view;
        RayContext {
            stack,
            classifier,
            plan,
            maps: &plan.maps,
            shading,
            mode,
            iso,
            iso_rgb: [iso_c.r, iso_c.g, iso_c.b],
            ert,
            ascending: f.ascending,
            pad: plan.grid.pad as i32,
            cells: [c[0] as u32, c[1] as u32],
            grad_m: f.grad_to_eye_z.map(|x| x as f32),
            grad_s: f.grad_scale.map(|x| x as f32),
            normals: None,
        }
    }

    /// Shades by table instead of by gradient: a sample's shade is the bilinear
    /// blend of its cell's four corner entries of `table` (looked up by the
    /// codes of `normals`, which must be built from this context's stack), an
    /// iso hit's the blend at the two slices of its refinement, interpolated
    /// like its depth.
    pub fn with_normals(mut self, normals: &'a NormalStack, table: &'a ShadeTable) -> Self {
        assert_eq!(normals.n, self.stack.n, "normal codes of another stack");
        self.normals = Some((normals, table));
        self
    }

    /// The cells of this context kept apart (the f32 stack and the codes).
    pub fn split(&self) -> Split<'a> {
        Split { stack: self.stack, codes: self.normals.map_or(&[][..], |(ns, _)| ns.codes()) }
    }

    /// The packed cells of this context's normal codes, if they are packed.
    pub fn packed(&self) -> Option<PackedCells<'a>> {
        self.normals.and_then(|(ns, _)| ns.packed())
    }

    /// Bilinear density of a located sample.
    #[inline(always)]
    fn sample<V: Cells>(&self, v: &V, ci: usize, cj: usize, k: usize, wi: f32, wj: f32) -> f32 {
        bilinear(v.densities(self.stack.index(ci, cj, k)), wi, wj)
    }

    /// The shaded colour of `rgb` at a sample (either shading model).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn shade_sample<V: Cells>(&self, v: &V, rgb: [f32; 3], ci: usize, cj: usize, k: usize, wi: f32, wj: f32) -> [f32; 3] {
        match self.normals {
            Some((_, table)) => apply_shade(rgb, table.blend(v.codes(self.stack.index(ci, cj, k)), wi, wj)),
            None => {
                let g = self.stack.gradient(ci, cj, k, wi, wj);
                self.shading.shade(rgb, headlight_ndl(g, self.grad_m, self.grad_s))
            }
        }
    }

    /// The cell and weights of ray `(p, q)` at slice `k`, or `None` outside the volume.
    #[inline(always)]
    fn locate(&self, p: i32, q: i32, k: usize) -> Option<(usize, usize, f32, f32)> {
        let s = self.maps[k];
        let ci = p - self.pad + s.floor[0];
        let cj = q - self.pad + s.floor[1];
        if (ci as u32) < self.cells[0] && (cj as u32) < self.cells[1] {
            Some((ci as usize, cj as usize, s.weight[0], s.weight[1]))
        } else {
            None
        }
    }

    /// Hints the cache to fetch what ray `(p, q)` reads from its first
    /// candidate slice `k` on, unless its voxel shares the 16-voxel line `last`
    /// of the ray before (whose prefetch covered it); updates `last`. With table
    /// shading: the cell's densities and codes at `k`, at the slice before it
    /// (a hit's refinement) and at the slice after it (the walk's next sample
    /// when `k` misses; the same cell, which the shear moves by at most one
    /// voxel). Adding the slice after was 5–8 % of the render at 512² on the
    /// 256-voxel volumes (interleaved A/B).
    /// With gradient shading: the neighbourhood a hit's gradients read.
    #[inline(always)]
    pub fn prefetch<V: Cells>(&self, v: &V, p: i32, q: i32, k: usize, last: &mut usize) {
        if let Some((ci, cj, _, _)) = self.locate(p, q, k) {
            let b = self.stack.index(ci, cj, k);
            if b >> 4 != *last {
                *last = b >> 4;
                match self.normals {
                    Some(_) => {
                        let n01 = self.stack.n[0] * self.stack.n[1];
                        // the slices before and after k in walking order (an index
                        // past either end wraps or overruns: the prefetch skips it)
                        let (before, after) = if self.ascending { (b.wrapping_sub(n01), b + n01) } else { (b + n01, b.wrapping_sub(n01)) };
                        v.prefetch(b);
                        v.prefetch(before);
                        v.prefetch_densities(after);
                    }
                    None => self.stack.prefetch_hit(ci, cj, k, self.ascending),
                }
            }
        }
    }

    /// Traces ray `(p, q)` over the candidate slices `ks` (front to back), all
    /// within the ray's slice range `[lo, hi]` (index order), which also bounds
    /// an iso hit's refinement.
    #[inline(always)]
    pub fn trace<V: Cells>(&self, v: &V, p: i32, q: i32, ks: impl Iterator<Item = usize>, lo: usize, hi: usize) -> RayResult {
        match self.mode {
            Mode::Blend => self.trace_blend(v, p, q, ks),
            Mode::Iso => self.trace_iso(v, p, q, ks, lo, hi),
        }
    }

    #[inline(always)]
    fn trace_blend<V: Cells>(&self, v: &V, p: i32, q: i32, ks: impl Iterator<Item = usize>) -> RayResult {
        let mut acc = [0f32; 4];
        for k in ks {
            if terminated(acc[3], self.ert) {
                break;
            }
            let Some((ci, cj, wi, wj)) = self.locate(p, q, k) else {
                continue;
            };
            let d = self.sample(v, ci, cj, k, wi, wj);
            let alpha = self.classifier.alpha(d);
            if alpha <= 0.0 {
                continue;
            }
            let c = self.classifier.classify(d);
            composite(&mut acc, self.shade_sample(v, [c.r, c.g, c.b], ci, cj, k, wi, wj), alpha);
        }
        RayResult { rgba: acc, depth: f32::NAN }
    }

    #[inline(always)]
    fn trace_iso<V: Cells>(&self, v: &V, p: i32, q: i32, ks: impl Iterator<Item = usize>, lo: usize, hi: usize) -> RayResult {
        for k in ks {
            let Some((ci, cj, wi, wj)) = self.locate(p, q, k) else {
                continue;
            };
            let d = self.sample(v, ci, cj, k, wi, wj);
            if d >= self.iso {
                return self.iso_hit(v, p, q, k, ci, cj, wi, wj, d, lo, hi);
            }
        }
        MISS
    }

    /// The slice before `k` in walking order within `[lo, hi]`, if any.
    #[inline(always)]
    fn prev_slice(&self, k: usize, lo: usize, hi: usize) -> Option<usize> {
        if self.ascending { (k > lo).then(|| k - 1) } else { (k < hi).then_some(k + 1) }
    }

    /// Refines a hit at slice `k` against the previous slice in walking order and
    /// shades it.
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    fn iso_hit<V: Cells>(
        &self,
        v: &V,
        p: i32,
        q: i32,
        k: usize,
        ci: usize,
        cj: usize,
        wi: f32,
        wj: f32,
        d: f32,
        lo: usize,
        hi: usize,
    ) -> RayResult {
        // the sample before the hit, when it is below the iso value: the surface
        // crosses between the two slices at fraction t
        let before = self.prev_slice(k, lo, hi).and_then(|kp| {
            let (pi, pj, pwi, pwj) = self.locate(p, q, kp)?;
            let dp = self.sample(v, pi, pj, kp, pwi, pwj);
            (dp < self.iso).then(|| (kp, ((self.iso - dp) / (d - dp)).clamp(0.0, 1.0), (pi, pj, pwi, pwj)))
        });
        let depth = before.map_or(k as f32, |(kp, t, _)| kp as f32 + (k as f32 - kp as f32) * t);
        let rgb = match self.normals {
            Some((_, table)) => {
                let entry = |ci, cj, k, wi, wj| table.blend(v.codes(self.stack.index(ci, cj, k)), wi, wj);
                let mut e = entry(ci, cj, k, wi, wj);
                if let Some((kp, t, (pi, pj, pwi, pwj))) = before {
                    let ep = entry(pi, pj, kp, pwi, pwj);
                    e = [0, 1].map(|a| ep[a] + (e[a] - ep[a]) * t);
                }
                apply_shade(self.iso_rgb, e)
            }
            None => {
                let mut g = self.stack.gradient(ci, cj, k, wi, wj);
                if let Some((kp, t, (pi, pj, pwi, pwj))) = before {
                    let gp = self.stack.gradient(pi, pj, kp, pwi, pwj);
                    g = [0, 1, 2].map(|c| gp[c] + (g[c] - gp[c]) * t);
                }
                self.shading.shade(self.iso_rgb, headlight_ndl(g, self.grad_m, self.grad_s))
            }
        };
        RayResult { rgba: [rgb[0], rgb[1], rgb[2], 1.0], depth }
    }
}

/// Rays of `rect` of the intermediate image through the sheared mask: each ray
/// reads its (super) column and visits only the slices whose code `m` matches,
/// in parallel over rows; marks `rect` valid. A row steps from super column to
/// super column with a counter (no division per ray) and answers a ray whose
/// column is empty without starting a walk. A row runs in groups of
/// [`PREFETCH_GROUP`] rays: first every ray's depth search (and, with
/// `prefetch`, a prefetch of the voxel rows its first candidate slice reads),
/// then the walks, so the cache misses of a group overlap instead of stalling
/// one ray after the other. With
/// [`Search::Bitscan`] at the mask's CPU level ([`BinaryMask::cpu_level`], the
/// renderer's [`crate::render::Settings::cpu`]) `Avx2` the row loop runs a copy
/// compiled for `lzcnt`/`tzcnt`; at `Scalar` the plain build's (the same image).
#[allow(clippy::too_many_arguments)]
pub fn render_binary<W: Word>(
    ctx: &RayContext,
    mask: &BinaryMask<W>,
    search: Search,
    m: &Matcher,
    prefetch: bool,
    rect: Option<Rect>,
    out: &mut Intermediate,
) {
    with_cells!(ctx, |v| match ctx.plan.limited() {
        false => binary_rows::<W, _, false>(ctx, &v, mask, search, m, prefetch, rect, out),
        true => binary_rows::<W, _, true>(ctx, &v, mask, search, m, prefetch, rect, out),
    })
}

/// [`render_binary`] for one cell layout, with (`LIMITED`) or without ray limits.
#[allow(clippy::too_many_arguments)]
fn binary_rows<W: Word, V: Cells, const LIMITED: bool>(
    ctx: &RayContext,
    v: &V,
    mask: &BinaryMask<W>,
    search: Search,
    m: &Matcher,
    prefetch: bool,
    rect: Option<Rect>,
    out: &mut Intermediate,
) {
    let hw = search == Search::Bitscan && mask.cpu_level().has_avx2();
    render_rows(rect, out, |q, p0, crow, drow| {
        #[cfg(target_arch = "x86_64")]
        if hw {
            // SAFETY: `hw` is true only when the mask's CPU level has AVX2; a
            // mask's level is always capped to at most `kernels::detected()`,
            // which is `Avx2` only when `is_x86_feature_detected!` found lzcnt and
            // bmi1 on this CPU at run time, which is all `binary_row_lzcnt`
            // requires; its body is the safe `binary_row`.
            unsafe { binary_row_lzcnt::<W, V, LIMITED>(ctx, v, mask, search, m, prefetch, q, p0, crow, drow) };
            return;
        }
        let _ = hw;
        binary_row::<W, V, LIMITED>(ctx, v, mask, search, m, prefetch, q, p0, crow, drow);
    });
}

/// Rays per prefetch group of [`render_binary`]: enough misses in flight to
/// cover a memory latency, few enough lines (about 12 per ray) to stay in L1/L2.
pub const PREFETCH_GROUP: usize = 16;

/// The candidate slices of `it` (front to back) that lie in `[lo, hi]`: those
/// before the range are skipped, the walk ends past it.
struct Clip<I> {
    it: I,
    lo: usize,
    hi: usize,
    ascending: bool,
}

impl<I: Iterator<Item = usize>> Iterator for Clip<I> {
    type Item = usize;
    #[inline(always)]
    fn next(&mut self) -> Option<usize> {
        loop {
            let k = self.it.next()?;
            let (before, past) = if self.ascending { (k < self.lo, k > self.hi) } else { (k > self.hi, k < self.lo) };
            if past {
                return None;
            }
            if !before {
                return Some(k);
            }
        }
    }
}

/// Traces ray `(p, q)` over candidates `ks`: the whole stack, or (`LIMITED`)
/// clipped to the plan's range for the ray.
#[inline(always)]
fn trace_ray<V: Cells, const LIMITED: bool>(ctx: &RayContext, v: &V, p: usize, q: usize, ks: impl Iterator<Item = usize>) -> RayResult {
    if LIMITED {
        let [lo, hi] = ctx.plan.ray_range(p, q);
        if lo > hi {
            return MISS;
        }
        ctx.trace(v, p as i32, q as i32, Clip { it: ks, lo, hi, ascending: ctx.ascending }, lo, hi)
    } else {
        ctx.trace(v, p as i32, q as i32, ks, 0, ctx.stack.n[2] - 1)
    }
}

/// One row of [`render_binary`] (inlined into both compiled copies).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn binary_row<W: Word, V: Cells, const LIMITED: bool>(
    ctx: &RayContext,
    v: &V,
    mask: &BinaryMask<W>,
    search: Search,
    m: &Matcher,
    prefetch: bool,
    q: usize,
    p0: usize,
    crow: &mut [[f32; 4]],
    drow: &mut [f32],
) {
    let s = mask.cell_size();
    let (mut sp, mut left) = mask.column_run(p0);
    let sq = mask.ray_column(p0, q).1;
    // each ray's walk, positioned at its first candidate between the phases
    let mut walks: [Option<SetBits<W>>; PREFETCH_GROUP] = std::array::from_fn(|_| None);
    let mut last_line = usize::MAX;
    for (g, (cg, dg)) in crow.chunks_mut(PREFETCH_GROUP).zip(drow.chunks_mut(PREFETCH_GROUP)).enumerate() {
        let pg = p0 + g * PREFETCH_GROUP;
        // phase 1: the first candidate slice of every ray of the group (none for
        // an empty column), prefetched
        for (dp, walk) in walks[..cg.len()].iter_mut().enumerate() {
            let mut it = SetBits::with_matcher(mask.row(sp, sq), ctx.ascending, search, m);
            *walk = it.peek().map(|k0| {
                if prefetch {
                    ctx.prefetch(v, (pg + dp) as i32, q as i32, k0, &mut last_line);
                }
                it
            });
            left -= 1;
            if left == 0 {
                sp += 1;
                left = s;
            }
        }
        // phase 2: the walks, from the first candidate on
        for (dp, ((c, d), walk)) in cg.iter_mut().zip(dg.iter_mut()).zip(walks.iter_mut()).enumerate() {
            let res = match walk.take() {
                None => MISS,
                Some(walk) => trace_ray::<V, LIMITED>(ctx, v, pg + dp, q, walk),
            };
            *c = res.rgba;
            *d = res.depth;
        }
    }
}

/// [`binary_row`] compiled with `lzcnt`/`tzcnt`: `leading_zeros` and
/// `trailing_zeros` of the depth search become single instructions instead of
/// `bsr`/`bsf` plus a zero test. Callers must hold a CPU level with AVX2 that is
/// at most [`crate::kernels::detected`] (that level implies lzcnt and bmi1).
#[cfg(target_arch = "x86_64")]
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "lzcnt,bmi1")]
unsafe fn binary_row_lzcnt<W: Word, V: Cells, const LIMITED: bool>(
    ctx: &RayContext,
    v: &V,
    mask: &BinaryMask<W>,
    search: Search,
    m: &Matcher,
    prefetch: bool,
    q: usize,
    p0: usize,
    crow: &mut [[f32; 4]],
    drow: &mut [f32],
) {
    binary_row::<W, V, LIMITED>(ctx, v, mask, search, m, prefetch, q, p0, crow, drow)
}

/// The brute-force reference: every slice of every ray of `rect` (within the
/// plan's slice range and ray limits), no mask.
pub fn render_brute(ctx: &RayContext, rect: Option<Rect>, out: &mut Intermediate) {
    with_cells!(ctx, |v| brute_rows(ctx, &v, rect, out))
}

/// [`render_brute`] for one cell layout.
fn brute_rows<V: Cells>(ctx: &RayContext, v: &V, rect: Option<Rect>, out: &mut Intermediate) {
    render_rows(rect, out, |q, p0, crow, drow| {
        for (dp, (c, d)) in crow.iter_mut().zip(drow.iter_mut()).enumerate() {
            let p = p0 + dp;
            let [lo, hi] = ctx.plan.ray_range(p, q);
            let res = match (lo <= hi, ctx.ascending) {
                (false, _) => MISS,
                (true, true) => ctx.trace(v, p as i32, q as i32, lo..=hi, lo, hi),
                (true, false) => ctx.trace(v, p as i32, q as i32, (lo..=hi).rev(), lo, hi),
            };
            *c = res.rgba;
            *d = res.depth;
        }
    });
}

/// Runs `row(q, p0, rgba, depth)` for every row `q` of `rect` in parallel, with
/// the row's pixels `p0..=p1` of the colour and depth planes; seals `rect`.
fn render_rows(rect: Option<Rect>, out: &mut Intermediate, row: impl Fn(usize, usize, &mut [[f32; 4]], &mut [f32]) + Sync) {
    out.seal(rect);
    let Some(r) = rect else { return };
    let w = out.size[0];
    let (rgba, depth) = (&mut out.rgba, &mut out.depth);
    // slice the rows first: rayon's parallel `skip` would heap-allocate a job per frame
    let rows = r.q0 * w..(r.q1 + 1) * w;
    rgba[rows.clone()].par_chunks_mut(w).zip(depth[rows].par_chunks_mut(w)).enumerate().for_each(|(dq, (crow, drow))| {
        row(r.q0 + dq, r.p0, &mut crow[r.p0..=r.p1], &mut drow[r.p0..=r.p1]);
    });
}

/// The rectangle of the intermediate grid that rays through the volume can reach
/// under `plan`'s slice maps (geometry only, no mask): used by brute force.
pub fn volume_rect(plan: &FramePlan, cells: [usize; 2]) -> Option<Rect> {
    let grid = plan.grid.size;
    if cells[0] == 0 || cells[1] == 0 || plan.maps.is_empty() {
        return None;
    }
    plan.front_to_back().next()?;
    // the pixels whose samples fall in the cells of the slices composited
    let span = |a: usize| {
        let xs = || plan.front_to_back().map(move |k| plan.pixels_of_cells(k, a, 0, cells[a] as i64 - 1));
        let lo = xs().map(|x| x[0]).min().unwrap_or(0).max(0) as usize;
        let hi = xs().map(|x| x[1]).max().unwrap_or(0).max(0) as usize;
        (lo, hi.min(grid[a] - 1))
    };
    let (p0, p1) = span(0);
    let (q0, q1) = span(1);
    Some(Rect { p0, p1, q0, q1 })
}
