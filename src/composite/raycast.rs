//! The bilinear resampling raycaster over the intermediate image.
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
use crate::classify::shade_table::ShadeTable;
use crate::classify::shading::apply_shade;
use crate::classify::shading::{Shading, headlight_ndl};
use crate::composite::Rect;
use crate::composite::{Intermediate, Mode, composite, correct_alpha, terminated};
use crate::data::normals::{ByteCells, NormalStack, PackedCells};
use crate::data::slices::{SliceStack, bilinear};
use crate::encode::depth::{Matcher, Search, SetBits, Word};
use crate::encode::mask::BinaryMask;
use crate::encode::mask::BlockOccupancy;
use crate::encode::mask::SliceSpan;
use crate::encode::walk::{ColumnWalk, Drift, StillWalk};
use crate::kernels::reconstruct::{self, Weights};
use crate::view::plan::{FramePlan, MapKind, SliceMap, floor_i64};

/// Everything a ray needs, borrowed for one frame.
pub struct RayContext<'a> {
    pub stack: &'a SliceStack,
    pub classifier: &'a Classifier,
    /// The frame's plan.
    pub plan: &'a FramePlan,
    /// The frame's per-slice maps (their translations' split; a
    /// [`MapKind::ScaleTranslate`] plan's rays read [`FramePlan::scaled`]).
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
    /// Shear-Warp Deluxe I ([`RayContext::with_intermediate`]): a sample at
    /// the midpoint between each pair of slices too, every sample at the
    /// half-step opacity.
    half: bool,
    /// Focus+context ([`RayContext::with_focus`]): the classification, iso
    /// value and iso colour of the samples inside the plan's focus intervals
    /// ([`FramePlan::focus_range`]); the context's own without a focus.
    focus_cls: &'a Classifier,
    focus_iso: f32,
    focus_iso_rgb: [f32; 3],
    /// The cubic reconstruction ([`RayContext::with_cubic`]): the stack axis
    /// it runs along.
    cubic: Option<usize>,
    /// The cubic crossing of table-shaded iso hits
    /// ([`RayContext::with_cubic_crossing`]): the stack axis it runs along.
    cubic_crossing: Option<usize>,
}

/// What one ray produced.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayResult {
    pub rgba: [f32; 4],
    /// Fractional slice index of the iso hit (NaN if none).
    pub depth: f32,
}

pub(crate) const MISS: RayResult = RayResult { rgba: [0.0; 4], depth: f32::NAN };

/// A located slice sample: slice `k`, cell `(ci, cj)`, in-cell weights
/// `(wi, wj)`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct At {
    pub k: usize,
    pub ci: usize,
    pub cj: usize,
    pub wi: f32,
    pub wj: f32,
}

/// A located sample of Deluxe I: slice `k`, or (`mid`) the midpoint between
/// slices `k` and `k + 1`, in cell `(ci, cj)` at weights `(wi, wj)`.
#[derive(Clone, Copy, Debug)]
struct Pt {
    k: usize,
    mid: bool,
    ci: usize,
    cj: usize,
    wi: f32,
    wj: f32,
}

impl Pt {
    /// The sample's fractional slice index.
    #[inline(always)]
    fn depth(&self) -> f32 {
        if self.mid { self.k as f32 + 0.5 } else { self.k as f32 }
    }
}

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
    /// The density of voxel `b` (exactly the stack's).
    fn density(&self, b: usize) -> f32;
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
    /// Hints the cache to fetch voxel `b`'s line of densities and codes (no
    /// effect on results): one row of a cell, where a ray of the next row of
    /// rays will read ([`super::lean`]'s visits).
    fn prefetch_voxel(&self, b: usize);
    /// [`bilinear`] of [`Cells::densities`] at `(wi, wj)`, by a copy that
    /// gathers the corners into one SSE vector where the layout allows it:
    /// the same value bit for bit.
    ///
    /// # Safety
    /// The CPU must have SSSE3, and the caller be compiled with it.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn sample_ssse3(&self, b: usize, wi: f32, wj: f32) -> f32 {
        bilinear(self.densities(b), wi, wj)
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
    fn density(&self, b: usize) -> f32 {
        self.stack.data()[b]
    }
    #[inline(always)]
    fn prefetch(&self, b: usize) {
        self.stack.prefetch_cell(b);
        crate::data::slices::prefetch_cell(self.codes, b, self.stack.n[0]);
    }
    #[inline(always)]
    fn prefetch_voxel(&self, b: usize) {
        self.stack.prefetch_voxel(b);
        crate::data::slices::prefetch(self.codes, b);
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
    fn density(&self, b: usize) -> f32 {
        PackedCells::density(self, b)
    }
    #[inline(always)]
    fn prefetch(&self, b: usize) {
        PackedCells::prefetch(self, b)
    }
    #[inline(always)]
    fn prefetch_voxel(&self, b: usize) {
        PackedCells::prefetch_voxel(self, b)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn sample_ssse3(&self, b: usize, wi: f32, wj: f32) -> f32 {
        // SAFETY: the caller guarantees SSSE3 (this method's contract)
        unsafe { PackedCells::sample_ssse3(self, b, wi, wj) }
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
    fn density(&self, b: usize) -> f32 {
        ByteCells::density(self, b)
    }
    #[inline(always)]
    fn prefetch(&self, b: usize) {
        ByteCells::prefetch(self, b)
    }
    #[inline(always)]
    fn prefetch_voxel(&self, b: usize) {
        ByteCells::prefetch_voxel(self, b)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn sample_ssse3(&self, b: usize, wi: f32, wj: f32) -> f32 {
        // SAFETY: the caller guarantees SSSE3 (this method's contract)
        unsafe { ByteCells::sample_ssse3(self, b, wi, wj) }
    }
}

/// Runs `$body` with `$v` bound to the cells of `$ctx` in their layout (one
/// monomorphized copy of the row loop per layout, no branch per access).
macro_rules! with_cells {
    ($ctx:expr, |$v:ident| $body:expr) => {
        match ($ctx.packed(), $ctx.bytes_cells()) {
            (Some($v), _) => $body,
            (None, Some($v)) => $body,
            (None, None) => {
                let $v = $ctx.split();
                $body
            }
        }
    };
}
pub(crate) use with_cells;

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
            half: false,
            focus_cls: classifier,
            focus_iso: iso,
            focus_iso_rgb: [iso_c.r, iso_c.g, iso_c.b],
            cubic: None,
            cubic_crossing: None,
        }
    }

    /// Focus+context (a sampler): a sample inside its ray's focus interval
    /// ([`FramePlan::focus_range`]) is classified by `classifier` (blend) or
    /// tested against `iso` and coloured by `classifier` at `iso` (iso mode);
    /// the others by the context's own. The candidates a binary walk visits
    /// must cover both (the union of the two tissues' codes).
    pub fn with_focus(mut self, classifier: &'a Classifier, iso: f32) -> Self {
        let c = classifier.classify(iso);
        (self.focus_cls, self.focus_iso, self.focus_iso_rgb) = (classifier, iso, [c.r, c.g, c.b]);
        self
    }

    /// The classifier of slice `k`'s sample on a ray with focus interval `foc`.
    #[inline(always)]
    fn cls_at(&self, k: usize, foc: [usize; 2]) -> &'a Classifier {
        if foc[0] <= k && k <= foc[1] { self.focus_cls } else { self.classifier }
    }

    /// Whether the Deluxe I sample `(k, mid)` lies in the focus interval
    /// `foc`: slice `k`'s iff `k` does, the midpoint between slices `k` and
    /// `k + 1` iff both do (so the focus's samples span the same depths
    /// `[f0, f1]` with or without Deluxe I, and a midpoint is never focus
    /// next to a context slice sample it interpolates; the RLE paths take the
    /// same rule, [`FramePlan::in_focus_mid`]).
    #[inline(always)]
    fn in_focus_pt(k: usize, mid: bool, foc: [usize; 2]) -> bool {
        foc[0] <= k && k + mid as usize <= foc[1]
    }

    /// The iso value and iso colour of slice `k`'s sample on a ray with focus interval `foc`.
    #[inline(always)]
    fn iso_at(&self, k: usize, foc: [usize; 2]) -> (f32, [f32; 3]) {
        if foc[0] <= k && k <= foc[1] { (self.focus_iso, self.focus_iso_rgb) } else { (self.iso, self.iso_rgb) }
    }

    /// Shear-Warp Deluxe I (`on`): each ray also samples the intermediate
    /// slice halfway between slices `k` and `k + 1` (index order) where it
    /// meets slice `k` inside the volume, at its own position at depth
    /// `k + ½` ([`Ray::locate_mid`]): the trilinear sample there, the mean of
    /// the two slices' bilinear samples at that in-slice position (shaded by
    /// the mean of their shade entries or gradients). Samples are composited
    /// in depth order (`k`, `k + ½`, `k + 1`, …), every one (slice or
    /// midpoint) with the half-step opacity `α_n = 1 − √(1 − α)`
    /// ([`Ray::half_opacity`]: post-classified straight colour, so no colour
    /// normalization); iso mode takes the first sample of either kind at or
    /// above the iso value and refines the hit against the sample before it.
    /// The binary path needs a mask whose bit `k` also covers the midpoint
    /// after slice `k` ([`crate::encode::cells::CellCodes::build_half`]).
    pub fn with_intermediate(mut self, on: bool) -> Self {
        self.half = on;
        self
    }

    /// The density a Deluxe I ray samples at slice `k` (`mid` false) or at
    /// its midpoint between slices `k` and `k + 1` (`mid`), read from the f32
    /// stack; `None` where the ray meets slice `k` outside the volume (or the
    /// midpoint lies outside). For tests: the trilinear check of the midpoint.
    pub fn half_sample<R: Ray>(&self, ray: R, k: usize, mid: bool) -> Option<f32> {
        let p = self.locate_pt(ray, k, mid)?;
        Some(self.density_pt(&self.split(), p))
    }

    /// True with Deluxe I ([`RayContext::with_intermediate`]).
    pub fn intermediate(&self) -> bool {
        self.half
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

    /// The cubic reconstruction of the iso surface
    /// ([`crate::kernels::reconstruct`], `Some(z_axis)`: the stack axis of
    /// the volume's z, along which it runs; the stack must be resident and
    /// the context shade by gradient). Along the slices (`z_axis` 2) a ray
    /// tests, at each candidate slice `k`, the Catmull–Rom cubic through its
    /// bilinear samples in the four slices around the segment from the slice
    /// before `k` to `k` (a sample outside the ray's slices or the volume
    /// repeats its neighbour), so a crossing between two samples below iso
    /// is found; in the slice (`z_axis` 0 or 1) each sample is Catmull–Rom
    /// across the four voxel rows along z and linear along the other axis,
    /// and the hit is refined linearly against the sample before it. The
    /// normal is the central differences blended by the cubic B-spline's
    /// weights along z and linearly along the other axes (no normal codes).
    /// The binary walk needs a mask of [`crate::encode::cells::CellCodes::build_cubic`]
    /// codes and, along the slices, rays that move at most one voxel a slice
    /// ([`cubic_walks`]).
    pub fn with_cubic(mut self, z_axis: Option<usize>) -> Self {
        self.cubic = z_axis;
        self
    }

    /// The cubic reconstruction's crossing for the iso hits of a
    /// table-shaded context ([`RayContext::with_normals`], whose codes
    /// should be the cubic's: [`crate::data::normals::cubic_voxel_normal`]);
    /// `Some(z_axis)`: the stack axis of the volume's z. A ray finds its hit
    /// as the linear reconstruction does (the first slice whose bilinear
    /// sample reaches iso, the same mask and walk), and the hit is placed in
    /// the segment from the slice before it: along the
    /// slices (`z_axis` 2) at the Catmull–Rom crossing through the four
    /// samples around the segment, which the two bracketing samples
    /// guarantee ([`reconstruct::crossing_near`]); in the slice at the
    /// straight crossing between the two slices' Catmull–Rom samples across
    /// the voxel rows along z. The shade is the blend of both slices' codes at
    /// that fraction, as the linear hit's. A surface that only the cubic's
    /// overshoot between two samples below iso reaches is not drawn: the
    /// preview of [`RayContext::with_cubic`]'s surface at the linear frame's
    /// cost of traversal.
    pub fn with_cubic_crossing(mut self, z_axis: Option<usize>) -> Self {
        self.cubic_crossing = z_axis;
        self
    }

    /// The stack axis of [`RayContext::with_cubic_crossing`], if set.
    pub fn cubic_crossing(&self) -> Option<usize> {
        self.cubic_crossing
    }

    /// The density a ray reads at `at` before a walk: the cubic
    /// reconstruction's sample when it runs in the slice, else the bilinear one.
    #[inline(always)]
    fn first_sample<V: Cells>(&self, v: &V, at: At) -> f32 {
        match self.cubic {
            Some(za) if za < 2 => self.sample_cubic(za, at),
            _ => self.sample(v, at.ci, at.cj, at.k, at.wi, at.wj),
        }
    }

    /// The cubic reconstruction's sample at `at` (`za`: its stack axis):
    /// bilinear along the slices, else [`RayContext::sample_cubic_with`].
    #[inline(always)]
    pub(crate) fn sample_cubic(&self, za: usize, at: At) -> f32 {
        let At { k, ci, cj, wi, wj } = at;
        let st = self.stack;
        if za == 2 {
            return bilinear(st.cell_at(st.index(ci, cj, k)), wi, wj);
        }
        let w_z = if za == 0 { wi } else { wj };
        self.sample_cubic_with(za, at, st.index(ci, cj, k), &Weights::new(w_z).cr)
    }

    /// The cubic reconstruction's sample at `at` in the slice (`za` 0 or
    /// 1), whose cell's first voxel has stack index `b` and whose fraction
    /// along `za` has the Catmull–Rom weights `cr` ([`Weights`]): the
    /// Catmull–Rom cubic (`f32`) across the four voxel lines along `za`
    /// (clamped), each linear along the other axis.
    #[inline(always)]
    pub(crate) fn sample_cubic_with(&self, za: usize, at: At, b: usize, cr: &[f32; 4]) -> f32 {
        if za == 0 { self.sample_in_slice::<0>(at, b, cr) } else { self.sample_in_slice::<1>(at, b, cr) }
    }

    /// [`RayContext::sample_cubic_with`] along stack axis `ZA` (0 or 1).
    #[inline(always)]
    pub(crate) fn sample_in_slice<const ZA: usize>(&self, at: At, b: usize, cr: &[f32; 4]) -> f32 {
        let data = self.stack.data();
        let n0 = self.stack.n[0];
        // the step to the next line along za, and to the other voxel of a line
        let (step, other, c, w_o) = if ZA == 0 { (1, n0, at.ci, at.wj) } else { (n0, 1, at.cj, at.wi) };
        let last = self.cells[ZA] as usize; // the last voxel line along za
        let before = if c > 0 { b - step } else { b };
        let after = if c + 1 < last { b + 2 * step } else { b + step };
        // every voxel read lies in [before, after + other] (step, other ≥ 1,
        // before ≤ b < b + step ≤ after)
        assert!(after + other < data.len(), "a cubic sample outside the stack");
        #[cfg(target_arch = "x86_64")]
        if before + step == b && after == b + 2 * step {
            // SAFETY: the four lines are `before + m·step` (m = 0..4), every
            // voxel read is one of the plain code's, in range (asserted above).
            return unsafe { cubic_sample_sse::<ZA>(data, before, n0, w_o, cr) };
        }
        // SAFETY: every line read is one of [before, b, b + step, after], each
        // with its voxel `other` further, all ≤ after + other (asserted above)
        unsafe { cubic_sample_plain(data, [before, b, b + step, after], other, w_o, cr) }
    }

    /// The cubic reconstruction's gradient at the sample `at` (stack axes,
    /// voxel units) when it runs in the slice (`za` 0 or 1; `w`: the
    /// [`Weights`] of its fraction along `za`), the gradient of the cubic
    /// B-spline smoothing of the four voxel lines along `za` (as the
    /// reference's): along `za` the B-spline's derivative of the lines'
    /// samples, along the other axes the lines' central differences blended
    /// by the B-spline's weights, in `f32`. Each line's sample and central
    /// differences are linear along the other in-slice axis, so away from
    /// the borders they are read as eight voxels a line
    /// ([`RayContext::gradient_cubic_border`] elsewhere: one-sided
    /// differences at a border).
    #[inline(always)]
    fn gradient_cubic<const ZA: usize>(&self, at: At, w: &Weights) -> [f32; 3] {
        let At { k, ci, cj, wi, wj } = at;
        let st = self.stack;
        let n = st.n;
        // the other in-slice axis: its cell and weight
        let (c, oa, co, w_o) = if ZA == 0 { (ci, 1, cj, wj) } else { (cj, 0, ci, wi) };
        if !(co >= 1 && co + 2 < n[oa] && k >= 1 && k + 1 < n[2]) {
            return self.gradient_cubic_border(ZA, at, w);
        }
        let n01 = n[0] * n[1];
        // the steps to the next voxel line along za and along the other axis
        let (s_l, s_o) = if ZA == 0 { (1, n[0]) } else { (n[0], 1) };
        let data = st.data();
        let lines = four(c, n[ZA]);
        // the voxels read lie in [o₀ − n₀n₁ − s_o, o₃ + n₀n₁ + 2s_o] of the
        // first and last line's o (k ≥ 1 and co ≥ 1 above, lines ascending)
        let o_at = |l: usize| l * s_l + co * s_o + k * n01;
        assert!(o_at(lines[0]) >= n01 + s_o && o_at(lines[3]) + n01 + 2 * s_o < data.len(), "a cubic gradient outside the stack");
        // per line: the sample, and twice the central differences along the
        // other axis and along the slices (`l[x][m]`: quantity x of line m)
        let o = lines.map(o_at);
        #[cfg(target_arch = "x86_64")]
        // SAFETY: every index either reads lies in the range asserted above
        // (the same voxels of the same lines)
        let l = unsafe { cubic_lines_sse::<ZA>(data, o, s_o, n01, w_o) };
        #[cfg(not(target_arch = "x86_64"))]
        // SAFETY: every index it reads lies in the range asserted above
        let l = unsafe { cubic_lines_plain(data, o, s_o, n01, w_o) };
        let dot = |w: [f32; 4], x: usize| w[0] * l[x][0] + w[1] * l[x][1] + w[2] * l[x][2] + w[3] * l[x][3];
        let mut g = [0.5 * dot(w.bs, 2); 3];
        g[ZA] = dot(w.dbs, 0);
        g[oa] = 0.5 * dot(w.bs, 1);
        g
    }

    /// [`RayContext::gradient_cubic`] at any sample: each line's gradient
    /// by [`SliceStack::gradient`] (one-sided at the borders).
    #[inline(never)]
    fn gradient_cubic_border(&self, za: usize, at: At, w: &Weights) -> [f32; 3] {
        let At { k, ci, cj, wi, wj } = at;
        let st = self.stack;
        let c = if za == 0 { ci } else { cj };
        let last = self.cells[za] as usize - 1;
        let mut g = [0f32; 3];
        for (m, l) in four(c, last + 2).into_iter().enumerate() {
            // voxel line l: the cell starting there, or the last cell's far side
            let (cell, f) = if l > last { (last, 1.0) } else { (l, 0.0) };
            let (gl, value) = if za == 0 {
                (st.gradient(cell, cj, k, f, wj), st.bilinear(cell, cj, k, f, wj))
            } else {
                (st.gradient(ci, cell, k, wi, f), st.bilinear(ci, cell, k, wi, f))
            };
            for (a, (x, y)) in g.iter_mut().zip(gl).enumerate() {
                *x += if a == za { w.dbs[m] * value } else { w.bs[m] * y };
            }
        }
        g
    }

    /// The slice after `k` in walking order within `[lo, hi]`, if any.
    #[inline(always)]
    fn next_slice(&self, k: usize, lo: usize, hi: usize) -> Option<usize> {
        if self.ascending { (k < hi).then_some(k + 1) } else { (k > lo).then(|| k - 1) }
    }

    /// [`RayContext::trace_iso`] under the cubic reconstruction along stack
    /// axis `za` ([`RayContext::with_cubic`]), with the iso value of each
    /// candidate's slice (focus or context).
    ///
    /// A ray's samples depend only on their slice, so each is computed once
    /// and kept in a window of the last four slices sampled ([`Window`]):
    /// consecutive candidates along the slices share three of their four
    /// samples, and the segment's [`reconstruct::upper_bound`] rejects it
    /// before any solve (the first test of [`reconstruct::crossing`], so the
    /// result is the same). In the slice the sample before a candidate is
    /// read only for its hit's refinement.
    #[inline(always)]
    fn trace_iso_cubic<R: Ray>(
        &self,
        ray: R,
        ks: impl Iterator<Item = usize>,
        za: usize,
        [lo, hi]: [usize; 2],
        foc: [usize; 2],
    ) -> RayResult {
        let locate = |k: usize| -> Option<At> {
            let (ci, cj, wi, wj) = ray.locate(self, k)?;
            Some(At { k, ci, cj, wi, wj })
        };
        if za < 2 {
            // a sample, its weights along za and its density
            let sample = |k: usize| {
                locate(k).map(|at| {
                    let w = Weights::new(if za == 0 { at.wi } else { at.wj });
                    (at, w, self.sample_cubic_with(za, at, self.stack.index(at.ci, at.cj, k), &w.cr))
                })
            };
            for k in ks {
                let Some((at, w, d)) = sample(k) else { continue };
                let (iso, rgb) = self.iso_at(k, foc);
                if d >= iso {
                    let prev = self.prev_slice(k, lo, hi).and_then(sample);
                    return self.hit_in_slice(za, (iso, rgb), (at, d, &w), prev.as_ref().map(|(ap, wp, dp)| (*ap, *dp, wp)));
                }
            }
            return MISS;
        }
        let sample = |k: usize| locate(k).map(|at| (at, self.sample_cubic(za, at)));
        let mut window = Window::default();
        let mut sample = |k: usize| window.get(k, sample);
        for k in ks {
            let Some((at, d)) = sample(k) else { continue };
            let (iso, rgb) = self.iso_at(k, foc);
            let Some((ap, dp)) = self.prev_slice(k, lo, hi).and_then(&mut sample) else {
                if d >= iso {
                    return self.hit_at_slice(rgb, at);
                }
                continue;
            };
            // the four samples around the segment from the slice before to k, in walking order
            let before = self.prev_slice(ap.k, lo, hi).and_then(&mut sample).unwrap_or((ap, dp));
            let after = self.next_slice(k, lo, hi).and_then(&mut sample).unwrap_or((at, d));
            let four = [before, (ap, dp), (at, d), after];
            let p = four.map(|s| s.1 as f64);
            if reconstruct::upper_bound(p[1].max(p[2]), p[0].min(p[3])) < iso as f64 {
                continue;
            }
            if let Some(t) = reconstruct::crossing(p, iso as f64) {
                return self.hit_along(rgb, four, t);
            }
        }
        MISS
    }

    /// The hit `(at, d)` of the cubic in the slice (`za` 0 or 1; `w` the
    /// [`Weights`] of its fraction along `za`) against the iso value and
    /// colour `(iso, rgb)`: refined linearly against the sample before it in
    /// walking order (`prev`, with its weights, when it is below iso), as
    /// the linear reconstruction does, and shaded by the blend of both
    /// samples' [`RayContext::gradient_cubic`].
    #[inline(always)]
    pub(crate) fn hit_in_slice(
        &self,
        za: usize,
        hit: (f32, [f32; 3]),
        at: (At, f32, &Weights),
        prev: Option<(At, f32, &Weights)>,
    ) -> RayResult {
        if za == 0 { self.hit_in_slice_za::<0>(hit, at, prev) } else { self.hit_in_slice_za::<1>(hit, at, prev) }
    }

    /// [`RayContext::hit_in_slice`] along stack axis `ZA` (0 or 1).
    #[inline(never)]
    pub(crate) fn hit_in_slice_za<const ZA: usize>(
        &self,
        (iso, rgb): (f32, [f32; 3]),
        (at, d, w): (At, f32, &Weights),
        prev: Option<(At, f32, &Weights)>,
    ) -> RayResult {
        let k = at.k;
        let before = prev.filter(|&(_, dp, _)| dp < iso).map(|(ap, dp, wp)| (ap, wp, ((iso - dp) / (d - dp)).clamp(0.0, 1.0)));
        let mut g = self.gradient_cubic::<ZA>(at, w);
        let depth = match before {
            None => k as f32,
            Some((ap, wp, t)) => {
                let gp = self.gradient_cubic::<ZA>(ap, wp);
                g = [0, 1, 2].map(|c| gp[c] + (g[c] - gp[c]) * t);
                ap.k as f32 + (k as f32 - ap.k as f32) * t
            }
        };
        self.shade_hit(rgb, g, depth)
    }

    /// An iso hit at slice `at` with no slice before it along the ray,
    /// shaded by the trilinear gradient there.
    #[inline(never)]
    pub(crate) fn hit_at_slice(&self, rgb: [f32; 3], at: At) -> RayResult {
        self.shade_hit(rgb, self.stack.gradient(at.ci, at.cj, at.k, at.wi, at.wj), at.k as f32)
    }

    /// The hit of a crossing at fraction `t` of the segment between the
    /// middle two of the four samples `four` (in walking order) along the
    /// slices, shaded by the gradient of the B-spline smoothing of the four
    /// samples: in the slice their central differences blended by its
    /// weights; along the ray its derivative, less what the in-slice gradient
    /// adds as the ray moves across the slice.
    #[inline(never)]
    pub(crate) fn hit_along(&self, rgb: [f32; 3], four: [(At, f32); 4], t: f64) -> RayResult {
        let (ap, at) = (four[1].0, four[2].0);
        let w = Weights::new(t as f32);
        let (mut g, mut along) = ([0f32; 3], 0f32);
        for ((b, db), (a, d)) in w.bs.into_iter().zip(w.dbs).zip(four) {
            let ga = self.stack.gradient_in_slice(a.ci, a.cj, a.k, a.wi, a.wj);
            g[0] += b * ga[0];
            g[1] += b * ga[1];
            along += db * d;
        }
        // how far the ray moves across the slice from the slice before to k
        let dx = [(at.ci as f32 - ap.ci as f32) + (at.wi - ap.wi), (at.cj as f32 - ap.cj as f32) + (at.wj - ap.wj)];
        let across = g[0] * dx[0] + g[1] * dx[1];
        g[2] = if self.ascending { along - across } else { across - along };
        let depth = ap.k as f32 + (at.k as f32 - ap.k as f32) * t as f32;
        self.shade_hit(rgb, g, depth)
    }

    /// An opaque iso hit at `depth` in `iso_rgb`, shaded by the gradient `g`.
    #[inline(always)]
    pub(crate) fn shade_hit(&self, iso_rgb: [f32; 3], g: [f32; 3], depth: f32) -> RayResult {
        let rgb = self.shading.shade(iso_rgb, headlight_ndl(g, self.grad_m, self.grad_s));
        RayResult { rgba: [rgb[0], rgb[1], rgb[2], 1.0], depth }
    }

    /// The cells of this context kept apart (the f32 stack and the codes).
    pub fn split(&self) -> Split<'a> {
        Split { stack: self.stack, codes: self.normals.map_or(&[][..], |(ns, _)| ns.codes()) }
    }

    /// The 8-bit densities and codes of this context's normal codes, if it
    /// holds them.
    pub fn bytes_cells(&self) -> Option<ByteCells<'a>> {
        self.normals.and_then(|(ns, _)| ns.bytes_cells())
    }

    /// The shade table of table shading (`None`: gradient shading).
    pub fn table(&self) -> Option<&'a ShadeTable> {
        self.normals.map(|(_, t)| t)
    }

    /// Cells per slice along `i` and `j`.
    pub fn cell_counts(&self) -> [u32; 2] {
        self.cells
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

    /// The shaded colour of `rgb` at the sample `at` (either shading model).
    #[inline(always)]
    fn shade_sample<V: Cells>(&self, v: &V, rgb: [f32; 3], at: At) -> [f32; 3] {
        let At { k, ci, cj, wi, wj } = at;
        match self.normals {
            Some((_, table)) => apply_shade(rgb, table.blend(v.codes(self.stack.index(ci, cj, k)), wi, wj)),
            None => {
                let g = self.stack.gradient(ci, cj, k, wi, wj);
                self.shading.shade(rgb, headlight_ndl(g, self.grad_m, self.grad_s))
            }
        }
    }

    /// The ray of intermediate pixel `(p, q)` under a scaled plan
    /// ([`MapKind::ScaleTranslate`]): its sheared point and opacity exponent.
    #[inline(always)]
    pub fn scaled_ray(&self, p: usize, q: usize) -> ScaledRay {
        ScaledRay { at: self.plan.intermediate_to_sheared(p as f64, q as f64), e: self.plan.opacity_exponent(p, q) }
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
    pub fn prefetch<V: Cells, R: Ray>(&self, v: &V, ray: R, k: usize, last: &mut usize) {
        if let Some((ci, cj, _, _)) = ray.locate(self, k) {
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

    /// Traces `ray` over the candidate slices `ks` (front to back), all
    /// within the ray's slice range `[lo, hi]` (index order), which also bounds
    /// an iso hit's refinement.
    #[inline(always)]
    pub fn trace<V: Cells, R: Ray>(
        &self,
        v: &V,
        ray: R,
        ks: impl Iterator<Item = usize>,
        lo: usize,
        hi: usize,
        foc: [usize; 2],
    ) -> RayResult {
        // (a ray without a focus interval runs the loops without the per-sample test)
        match (self.mode, self.half, foc[0] <= foc[1]) {
            (Mode::Iso, false, _) if let Some(za) = self.cubic => self.trace_iso_cubic(ray, ks, za, [lo, hi], foc),
            (Mode::Blend, false, false) => self.trace_blend::<_, _, false>(v, ray, ks, foc),
            (Mode::Blend, false, true) => self.trace_blend::<_, _, true>(v, ray, ks, foc),
            (Mode::Iso, false, false) => self.trace_iso::<_, _, false>(v, ray, ks, lo, hi, foc),
            (Mode::Iso, false, true) => self.trace_iso::<_, _, true>(v, ray, ks, lo, hi, foc),
            (Mode::Blend, true, false) => self.trace_blend_half::<_, _, false>(v, ray, ks, hi, foc),
            (Mode::Blend, true, true) => self.trace_blend_half::<_, _, true>(v, ray, ks, hi, foc),
            (Mode::Iso, true, false) => self.trace_iso_half::<_, _, false>(v, ray, ks, lo, hi, foc),
            (Mode::Iso, true, true) => self.trace_iso_half::<_, _, true>(v, ray, ks, lo, hi, foc),
        }
    }

    /// Deluxe I: the sample of candidate slice `k` (`mid` false) or of the
    /// midpoint between `k` and `k + 1` (`mid`; only where the ray meets slice
    /// `k` inside the volume, the cell its mask bit `k` codes), if inside.
    #[inline(always)]
    fn locate_pt<R: Ray>(&self, ray: R, k: usize, mid: bool) -> Option<Pt> {
        let (ci, cj, wi, wj) = ray.locate(self, k)?;
        if !mid {
            return Some(Pt { k, mid, ci, cj, wi, wj });
        }
        let (ci, cj, wi, wj) = ray.locate_mid(self, k)?;
        Some(Pt { k, mid, ci, cj, wi, wj })
    }

    /// The density of a Deluxe I sample (trilinear at a midpoint: the mean of
    /// the two slices' bilinear samples).
    #[inline(always)]
    fn density_pt<V: Cells>(&self, v: &V, p: Pt) -> f32 {
        let d = self.sample(v, p.ci, p.cj, p.k, p.wi, p.wj);
        if p.mid { 0.5 * (d + self.sample(v, p.ci, p.cj, p.k + 1, p.wi, p.wj)) } else { d }
    }

    /// The shade entry of a Deluxe I sample (table shading; a midpoint's is
    /// the mean of the two slices').
    #[inline(always)]
    fn entry_pt<V: Cells>(&self, v: &V, table: &ShadeTable, p: Pt) -> [f32; 2] {
        let e = table.blend(v.codes(self.stack.index(p.ci, p.cj, p.k)), p.wi, p.wj);
        if !p.mid {
            return e;
        }
        let e1 = table.blend(v.codes(self.stack.index(p.ci, p.cj, p.k + 1)), p.wi, p.wj);
        [0.5 * (e[0] + e1[0]), 0.5 * (e[1] + e1[1])]
    }

    /// The gradient of a Deluxe I sample (gradient shading; a midpoint's is
    /// the mean of the two slices').
    #[inline(always)]
    fn gradient_pt(&self, p: Pt) -> [f32; 3] {
        let g = self.stack.gradient(p.ci, p.cj, p.k, p.wi, p.wj);
        if !p.mid {
            return g;
        }
        let g1 = self.stack.gradient(p.ci, p.cj, p.k + 1, p.wi, p.wj);
        [0, 1, 2].map(|c| 0.5 * (g[c] + g1[c]))
    }

    /// Composites the Deluxe I sample `(k, mid)` of `ray` into `acc` at the
    /// half-step opacity, classified by `cls`.
    #[inline(always)]
    fn blend_pt<V: Cells, R: Ray>(&self, v: &V, ray: R, k: usize, mid: bool, cls: &Classifier, acc: &mut [f32; 4]) {
        let Some(p) = self.locate_pt(ray, k, mid) else { return };
        let d = self.density_pt(v, p);
        let alpha = cls.alpha(d);
        if alpha <= 0.0 {
            return;
        }
        let alpha = ray.half_opacity(alpha);
        let c = cls.classify(d);
        let rgb = [c.r, c.g, c.b];
        let rgb = match self.normals {
            Some((_, table)) => apply_shade(rgb, self.entry_pt(v, table, p)),
            None => self.shading.shade(rgb, headlight_ndl(self.gradient_pt(p), self.grad_m, self.grad_s)),
        };
        composite(acc, rgb, alpha);
    }

    /// [`RayContext::trace_blend`] with Deluxe I: each candidate slice `k`
    /// brings its own sample and the midpoint after it in index order (when
    /// `k + 1 ≤ hi`), composited in walking order; (`F`) a sample in the
    /// focus ([`RayContext::in_focus_pt`]) by the focus's classification.
    #[inline(always)]
    fn trace_blend_half<V: Cells, R: Ray, const F: bool>(
        &self,
        v: &V,
        ray: R,
        ks: impl Iterator<Item = usize>,
        hi: usize,
        foc: [usize; 2],
    ) -> RayResult {
        let mut acc = [0f32; 4];
        'ray: for k in ks {
            let order = if self.ascending { [(k, false), (k, true)] } else { [(k, true), (k, false)] };
            for (k, mid) in order {
                if mid && k >= hi {
                    continue;
                }
                if terminated(acc[3], self.ert) {
                    break 'ray;
                }
                let cls = if F && Self::in_focus_pt(k, mid, foc) { self.focus_cls } else { self.classifier };
                self.blend_pt(v, ray, k, mid, cls, &mut acc);
            }
        }
        RayResult { rgba: acc, depth: f32::NAN }
    }

    /// [`RayContext::trace_iso`] with Deluxe I: the first sample, slice or
    /// midpoint, at or above the iso value where it lies (focus or context, `F`).
    #[inline(always)]
    fn trace_iso_half<V: Cells, R: Ray, const F: bool>(
        &self,
        v: &V,
        ray: R,
        ks: impl Iterator<Item = usize>,
        lo: usize,
        hi: usize,
        foc: [usize; 2],
    ) -> RayResult {
        for k in ks {
            let order = if self.ascending { [(k, false), (k, true)] } else { [(k, true), (k, false)] };
            for (k, mid) in order {
                if mid && k >= hi {
                    continue;
                }
                let Some(p) = self.locate_pt(ray, k, mid) else { continue };
                let d = self.density_pt(v, p);
                let at = if F && Self::in_focus_pt(k, mid, foc) { (self.focus_iso, self.focus_iso_rgb) } else { (self.iso, self.iso_rgb) };
                if d >= at.0 {
                    return self.iso_hit_half(v, ray, p, d, [lo, hi], at);
                }
            }
        }
        MISS
    }

    /// The Deluxe I sample before `(k, mid)` in walking order within `[lo, hi]`.
    #[inline(always)]
    fn prev_pt(&self, k: usize, mid: bool, lo: usize, hi: usize) -> Option<(usize, bool)> {
        match (self.ascending, mid) {
            (true, false) => (k > lo).then(|| (k - 1, true)),
            (true, true) => Some((k, false)),
            (false, false) => (k < hi).then_some((k, true)),
            (false, true) => Some((k + 1, false)),
        }
    }

    /// [`RayContext::iso_hit`] with Deluxe I: the hit refined against the
    /// sample before it (a slice or a midpoint, half a slice away), against
    /// the hit's iso value and in its iso colour (`(iso, iso_rgb)`).
    #[inline(never)]
    fn iso_hit_half<V: Cells, R: Ray>(
        &self,
        v: &V,
        ray: R,
        p: Pt,
        d: f32,
        [lo, hi]: [usize; 2],
        (iso, iso_rgb): (f32, [f32; 3]),
    ) -> RayResult {
        let before = self.prev_pt(p.k, p.mid, lo, hi).and_then(|(kp, mp)| {
            let pp = self.locate_pt(ray, kp, mp)?;
            let dp = self.density_pt(v, pp);
            (dp < iso).then(|| (pp, ((iso - dp) / (d - dp)).clamp(0.0, 1.0)))
        });
        let depth = before.map_or(p.depth(), |(pp, t)| pp.depth() + (p.depth() - pp.depth()) * t);
        let rgb = match self.normals {
            Some((_, table)) => {
                let mut e = self.entry_pt(v, table, p);
                if let Some((pp, t)) = before {
                    let ep = self.entry_pt(v, table, pp);
                    e = [0, 1].map(|a| ep[a] + (e[a] - ep[a]) * t);
                }
                apply_shade(iso_rgb, e)
            }
            None => {
                let mut g = self.gradient_pt(p);
                if let Some((pp, t)) = before {
                    let gp = self.gradient_pt(pp);
                    g = [0, 1, 2].map(|c| gp[c] + (g[c] - gp[c]) * t);
                }
                self.shading.shade(iso_rgb, headlight_ndl(g, self.grad_m, self.grad_s))
            }
        };
        RayResult { rgba: [rgb[0], rgb[1], rgb[2], 1.0], depth }
    }

    #[inline(always)]
    fn trace_blend<V: Cells, R: Ray, const F: bool>(&self, v: &V, ray: R, ks: impl Iterator<Item = usize>, foc: [usize; 2]) -> RayResult {
        let mut acc = [0f32; 4];
        for k in ks {
            if terminated(acc[3], self.ert) {
                break;
            }
            let Some((ci, cj, wi, wj)) = ray.locate(self, k) else {
                continue;
            };
            let d = self.sample(v, ci, cj, k, wi, wj);
            let cls = if F { self.cls_at(k, foc) } else { self.classifier };
            let alpha = cls.alpha(d);
            if alpha <= 0.0 {
                continue;
            }
            let alpha = ray.opacity(alpha);
            let c = cls.classify(d);
            composite(&mut acc, self.shade_sample(v, [c.r, c.g, c.b], At { k, ci, cj, wi, wj }), alpha);
        }
        RayResult { rgba: acc, depth: f32::NAN }
    }

    #[inline(always)]
    fn trace_iso<V: Cells, R: Ray, const F: bool>(
        &self,
        v: &V,
        ray: R,
        ks: impl Iterator<Item = usize>,
        lo: usize,
        hi: usize,
        foc: [usize; 2],
    ) -> RayResult {
        for k in ks {
            let Some((ci, cj, wi, wj)) = ray.locate(self, k) else {
                continue;
            };
            let d = self.sample(v, ci, cj, k, wi, wj);
            // the iso value that applies where the sample is (focus or context)
            let iso = if F { self.iso_at(k, foc).0 } else { self.iso };
            if d >= iso {
                let at = if F { self.iso_at(k, foc) } else { (self.iso, self.iso_rgb) };
                return self.iso_hit(v, ray, At { k, ci, cj, wi, wj }, d, [lo, hi], at);
            }
        }
        MISS
    }

    /// The slice before `k` in walking order within `[lo, hi]`, if any.
    #[inline(always)]
    fn prev_slice(&self, k: usize, lo: usize, hi: usize) -> Option<usize> {
        if self.ascending { (k > lo).then(|| k - 1) } else { (k < hi).then_some(k + 1) }
    }

    /// Refines a hit `at` (of density `d`) against the previous slice in
    /// walking order within the ray's slices `[lo, hi]` and shades it, by the
    /// iso value and colour `(iso, iso_rgb)`.
    #[inline(never)]
    fn iso_hit<V: Cells, R: Ray>(&self, v: &V, ray: R, at: At, d: f32, [lo, hi]: [usize; 2], (iso, iso_rgb): (f32, [f32; 3])) -> RayResult {
        let At { k, ci, cj, wi, wj } = at;
        // the sample before the hit, when it is below the hit's iso value: the
        // surface crosses between the two slices at fraction t
        let before = self.prev_slice(k, lo, hi).and_then(|kp| {
            let (pi, pj, pwi, pwj) = ray.locate(self, kp)?;
            let dp = self.sample(v, pi, pj, kp, pwi, pwj);
            (dp < iso).then(|| {
                let linear = ((iso - dp) / (d - dp)).clamp(0.0, 1.0);
                let t = match self.cubic_crossing {
                    None => linear,
                    Some(2) => {
                        // the samples before the segment and after it (repeating its ends)
                        let outer = |k: Option<usize>, end: f32| {
                            k.and_then(|k| ray.locate(self, k).map(|(ci, cj, wi, wj)| self.sample(v, ci, cj, k, wi, wj))).unwrap_or(end)
                        };
                        let four = [outer(self.prev_slice(kp, lo, hi), dp), dp, d, outer(self.next_slice(k, lo, hi), d)];
                        reconstruct::crossing_near(four, iso, linear)
                    }
                    Some(za) => {
                        let (n, last) = (self.stack.n, self.cells[za] as usize);
                        let ap = At { k: kp, ci: pi, cj: pj, wi: pwi, wj: pwj };
                        let cp = cubic_in_slice(v, n[0], za, last, ap, self.stack.index(pi, pj, kp));
                        let c = cubic_in_slice(v, n[0], za, last, at, self.stack.index(ci, cj, k));
                        in_slice_fraction(cp, c, iso, linear)
                    }
                };
                (kp, t, (pi, pj, pwi, pwj))
            })
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
                apply_shade(iso_rgb, e)
            }
            None => {
                let mut g = self.stack.gradient(ci, cj, k, wi, wj);
                if let Some((kp, t, (pi, pj, pwi, pwj))) = before {
                    let gp = self.stack.gradient(pi, pj, kp, pwi, pwj);
                    g = [0, 1, 2].map(|c| gp[c] + (g[c] - gp[c]) * t);
                }
                self.shading.shade(iso_rgb, headlight_ndl(g, self.grad_m, self.grad_s))
            }
        };
        RayResult { rgba: [rgb[0], rgb[1], rgb[2], 1.0], depth }
    }
}

/// The fraction of a cubic crossing in the slice
/// ([`RayContext::with_cubic_crossing`]): where the straight line from the
/// slice before's cubic sample `cp` to the hit slice's `c` meets iso,
/// clamped to the segment; `linear` (the bilinear samples' crossing) where
/// the cubic samples do not rise along it.
#[inline]
pub(crate) fn in_slice_fraction(cp: f32, c: f32, iso: f32, linear: f32) -> f32 {
    if c > cp { ((iso - cp) / (c - cp)).clamp(0.0, 1.0) } else { linear }
}

/// The Catmull–Rom sample at `at` (stack index `b` of its cell) across the
/// four voxel lines along stack axis `za` (0 or 1; `last`, the cells along
/// it: a line beyond the volume repeats its neighbour), each linear along
/// the other in-slice axis, read from the cells `v` of a stack with rows of
/// `n0` voxels. The weights are [`reconstruct::catmull_rom_f32`] of the
/// sample's fraction along `za`. The sample of [`RayContext::with_cubic_crossing`] in the
/// slice, by one function for every path.
#[inline(always)]
pub(crate) fn cubic_in_slice<V: Cells>(v: &V, n0: usize, za: usize, last: usize, at: At, b: usize) -> f32 {
    let (step, other, c, w_z, w_o) = if za == 0 { (1, n0, at.ci, at.wi, at.wj) } else { (n0, 1, at.cj, at.wj, at.wi) };
    // each line's two voxels (the first, and the one `other` further)
    let pairs: [[f32; 2]; 4] = if c > 0 && c + 1 < last {
        // inside: the lines are the cells at `b − step` and `b + step`
        // (corners [v, v + 1, v + n₀, v + n₀ + 1]), two reads
        let (lo, hi) = (v.densities(b - step), v.densities(b + step));
        if za == 0 {
            [[lo[0], lo[2]], [lo[1], lo[3]], [hi[0], hi[2]], [hi[1], hi[3]]]
        } else {
            [[lo[0], lo[1]], [lo[2], lo[3]], [hi[0], hi[1]], [hi[2], hi[3]]]
        }
    } else {
        // at a border a line beyond the volume repeats its neighbour
        let lines = [if c > 0 { b - step } else { b }, b, b + step, if c + 1 < last { b + 2 * step } else { b + step }];
        lines.map(|x| [v.density(x), v.density(x + other)])
    };
    let cr = reconstruct::catmull_rom_f32(w_z);
    let line = |[a, b]: [f32; 2]| a + (b - a) * w_o;
    cr[0] * line(pairs[0]) + cr[1] * line(pairs[1]) + cr[2] * line(pairs[2]) + cr[3] * line(pairs[3])
}

/// The samples of one ray in the last four slices it sampled along the
/// slices, by slice index modulo 4 (a ray's sample depends only on its
/// slice, so a kept sample is the one a new computation would give).
#[derive(Default)]
struct Window {
    slots: [Option<(usize, Sample)>; 4],
}

/// A located sample and its density (`None`: outside the volume).
type Sample = Option<(At, f32)>;

impl Window {
    /// The sample of slice `k`: kept, or computed by `f` and kept.
    #[inline(always)]
    fn get(&mut self, k: usize, f: impl FnOnce(usize) -> Sample) -> Sample {
        let slot = &mut self.slots[k & 3];
        match *slot {
            Some((kk, s)) if kk == k => s,
            _ => {
                let s = f(k);
                *slot = Some((k, s));
                s
            }
        }
    }
}

/// The cubic through the four lines `o` of `data` at weights `cr`, each line
/// the lerp at `w_o` of its voxel and the one `other` further.
///
/// # Safety
/// Every `o[m]` and `o[m] + other` must lie in `data`.
#[inline(always)]
unsafe fn cubic_sample_plain(data: &[f32], o: [usize; 4], other: usize, w_o: f32, cr: &[f32; 4]) -> f32 {
    let line = |o: usize| {
        // SAFETY: the caller's contract
        let (a, z) = unsafe { (*data.get_unchecked(o), *data.get_unchecked(o + other)) };
        a + (z - a) * w_o
    };
    cr[0] * line(o[0]) + cr[1] * line(o[1]) + cr[2] * line(o[2]) + cr[3] * line(o[3])
}

/// Per voxel line `o[m]` of `data` (the four lines of a cubic in the slice,
/// `s_o` the step along the other in-slice axis, `n01` the slice's):
/// `[lerp(v₀, v₁), lerp(v₁ − v₋₁, v₂ − v₀), lerp(p₀ − m₀, p₁ − m₁)]` at weight
/// `w_o` (`vᵢ` the line's voxels along the other axis, `p`/`m` those of the
/// slices after and before), quantity by quantity: `out[x][m]`.
///
/// # Safety
/// Every index `o[m] − n01 … o[m] + n01 + 2·s_o` it reads must lie in `data`.
#[inline(always)]
unsafe fn cubic_lines_plain(data: &[f32], o: [usize; 4], s_o: usize, n01: usize, w_o: f32) -> [[f32; 4]; 3] {
    // SAFETY: the caller's contract
    let v = |o: usize| unsafe { *data.get_unchecked(o) };
    let lerp = |a: f32, c: f32| a + (c - a) * w_o;
    let mut out = [[0f32; 4]; 3];
    for (m, &o) in o.iter().enumerate() {
        let (vm, v0, v1, v2) = (v(o - s_o), v(o), v(o + s_o), v(o + 2 * s_o));
        let (p0, p1, m0, m1) = (v(o + n01), v(o + n01 + s_o), v(o - n01), v(o - n01 + s_o));
        out[0][m] = lerp(v0, v1);
        out[1][m] = lerp(v1 - vm, v2 - v0);
        out[2][m] = lerp(p0 - m0, p1 - m1);
    }
    out
}

/// [`cubic_lines_plain`] with the four lines in the lanes of SSE vectors,
/// the same float operations lane for lane (tested equal bit for bit), for
/// a cubic along stack axis `ZA`: along 0 the other axis is 1 (`s_o = n₀`)
/// and four consecutive lines (`o[m] = o[0] + m`) load as one vector per
/// voxel (lines repeated at a border take the plain code); along 1 the other
/// axis is 0 (`s_o = 1`), a line's voxels along it load as one vector and
/// are transposed into lanes.
///
/// # Safety
/// [`cubic_lines_plain`]'s, with `s_o` as above.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn cubic_lines_sse<const ZA: usize>(data: &[f32], o: [usize; 4], s_o: usize, n01: usize, w_o: f32) -> [[f32; 4]; 3] {
    use std::arch::x86_64::*;
    debug_assert!(ZA == 0 || s_o == 1);
    if ZA == 0 && !(o[1] == o[0] + 1 && o[2] == o[0] + 2 && o[3] == o[0] + 3) {
        // SAFETY: the caller's contract (this function's is the same)
        return unsafe { cubic_lines_plain(data, o, s_o, n01, w_o) };
    }
    let p = data.as_ptr();
    // SAFETY: SSE and SSE2 are the x86-64 baseline. Along 0 each load takes
    // the four lines' voxel at one offset (`o[0] + m + r` for m = 0..4, each a
    // voxel the plain code reads); along 1 a line's `o − 1 … o + 2` and its
    // pairs at `o ± n01`, each a voxel the plain code reads. All in `data`
    // by the caller's contract.
    unsafe {
        let (vm, v0, v1, v2, p0, p1, m0, m1);
        if ZA == 0 {
            let ld = |r: usize| _mm_loadu_ps(p.add(r));
            let b = o[0];
            (vm, v0, v1, v2) = (ld(b - s_o), ld(b), ld(b + s_o), ld(b + 2 * s_o));
            (p0, p1, m0, m1) = (ld(b + n01), ld(b + n01 + s_o), ld(b - n01), ld(b - n01 + s_o));
        } else {
            // rows: line m's [v₋₁, v₀, v₁, v₂] and [p₀, p₁, m₀, m₁]
            let a = o.map(|o| _mm_loadu_ps(p.add(o - 1)));
            let c = o.map(|o| _mm_castpd_ps(_mm_loadh_pd(_mm_load_sd(p.add(o + n01).cast::<f64>()), p.add(o - n01).cast::<f64>())));
            (vm, v0, v1, v2) = transpose(a);
            (p0, p1, m0, m1) = transpose(c);
        }
        let w = _mm_set1_ps(w_o);
        let lerp = |a: __m128, c: __m128| _mm_add_ps(a, _mm_mul_ps(_mm_sub_ps(c, a), w));
        let x = [lerp(v0, v1), lerp(_mm_sub_ps(v1, vm), _mm_sub_ps(v2, v0)), lerp(_mm_sub_ps(p0, m0), _mm_sub_ps(p1, m1))];
        x.map(|x| {
            let mut out = [0f32; 4];
            _mm_storeu_ps(out.as_mut_ptr(), x);
            out
        })
    }
}

/// The columns of four rows of four lanes.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn transpose(
    r: [std::arch::x86_64::__m128; 4],
) -> (std::arch::x86_64::__m128, std::arch::x86_64::__m128, std::arch::x86_64::__m128, std::arch::x86_64::__m128) {
    use std::arch::x86_64::*;
    // SAFETY: SSE is the x86-64 baseline; no memory is touched
    unsafe {
        let (t0, t1) = (_mm_unpacklo_ps(r[0], r[1]), _mm_unpacklo_ps(r[2], r[3]));
        let (t2, t3) = (_mm_unpackhi_ps(r[0], r[1]), _mm_unpackhi_ps(r[2], r[3]));
        (_mm_movelh_ps(t0, t1), _mm_movehl_ps(t1, t0), _mm_movelh_ps(t2, t3), _mm_movehl_ps(t3, t2))
    }
}

/// [`RayContext::sample_in_slice`] away from the borders, the four lines in
/// the lanes of one SSE vector: the same float operations lane for lane and
/// the same order of the sum (tested equal bit for bit). Line `m` starts at
/// `before + m·step` (`step` 1 along 0, `n0` along 1), its other voxel one
/// step along the other axis.
///
/// # Safety
/// Every voxel the plain code reads (`before + m·step` and the next along
/// the other axis, m = 0..4) must lie in `data`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn cubic_sample_sse<const ZA: usize>(data: &[f32], before: usize, n0: usize, w_o: f32, cr: &[f32; 4]) -> f32 {
    use std::arch::x86_64::*;
    let p = data.as_ptr();
    // SAFETY: SSE and SSE2 are the x86-64 baseline; every lane read is a
    // voxel of the contract
    unsafe {
        let (a, z) = if ZA == 0 {
            (_mm_loadu_ps(p.add(before)), _mm_loadu_ps(p.add(before + n0)))
        } else {
            let pair = |m: usize| _mm_castpd_ps(_mm_load_sd(p.add(before + m * n0).cast::<f64>()));
            let (x, y) = (_mm_movelh_ps(pair(0), pair(1)), _mm_movelh_ps(pair(2), pair(3)));
            (_mm_shuffle_ps::<0b10_00_10_00>(x, y), _mm_shuffle_ps::<0b11_01_11_01>(x, y))
        };
        let line = _mm_add_ps(a, _mm_mul_ps(_mm_sub_ps(z, a), _mm_set1_ps(w_o)));
        let t = _mm_mul_ps(_mm_loadu_ps(cr.as_ptr()), line);
        // ((t₀ + t₁) + t₂) + t₃, the plain code's order
        let s = _mm_add_ss(t, _mm_shuffle_ps::<1>(t, t));
        let s = _mm_add_ss(s, _mm_movehl_ps(t, t));
        _mm_cvtss_f32(_mm_add_ss(s, _mm_shuffle_ps::<3>(t, t)))
    }
}

/// The four voxel lines `c − 1 … c + 2` around cell `c` of `n` voxels,
/// clamped to the volume (a border repeats its line).
#[inline(always)]
fn four(c: usize, n: usize) -> [usize; 4] {
    [c.saturating_sub(1), c, c + 1, (c + 2).min(n - 1)]
}

/// Whether the binary walk serves the cubic reconstruction along the slices
/// under `plan` ([`RayContext::with_cubic`]): every ray moves at most one
/// voxel a slice along each in-slice axis, as the cubic codes assume
/// ([`crate::encode::cells::CellCodes::build_cubic`]). True for every
/// parallel plan (the factorization shears by at most a voxel a slice); a
/// perspective plan with the eye near may move farther.
pub fn cubic_walks(plan: &FramePlan) -> bool {
    let n = plan.slices();
    match plan.kind {
        MapKind::Translate => (0..2).all(|a| plan.shear.trans[a].windows(2).all(|w| (w[1] - w[0]).abs() <= 1.0)),
        MapKind::ScaleTranslate => {
            let g = plan.grid.size;
            let corners = [[0.0, 0.0], [g[0] as f64, g[1] as f64]].map(|[p, q]| plan.intermediate_to_sheared(p, q));
            (1..n).all(|k| {
                let (m0, m1) = (&plan.scaled[k - 1], &plan.scaled[k]);
                (0..2).all(|a| corners.iter().all(|c| ((m1.scale - m0.scale) * c[a] + (m1.trans[a] - m0.trans[a])).abs() <= 1.0))
            })
        }
    }
}

/// Where a ray samples: the cell and in-cell weights of its sample in slice `k`
/// (`None` outside the volume), read from the plan's sample map, and the
/// correction of a sample's opacity to the ray's own spacing. One trace loop
/// serves every kind of map: [`GridRay`] for translated slices
/// ([`MapKind::Translate`]), [`ScaledRay`] for scaled ones
/// ([`MapKind::ScaleTranslate`]: perspective, or another pixel pitch).
pub trait Ray: Copy {
    fn locate(&self, ctx: &RayContext, k: usize) -> Option<(usize, usize, f32, f32)>;
    /// The cell and weights of the ray's point at depth `k + ½` (Deluxe I),
    /// halfway between its samples in slices `k` and `k + 1` (`k + 1` must
    /// be a slice): the mean of the two positions, since the maps are affine
    /// in `k`. Its cell is within one of the slice-`k` sample's along each
    /// axis while the ray moves at most two voxels a slice.
    fn locate_mid(&self, ctx: &RayContext, k: usize) -> Option<(usize, usize, f32, f32)>;
    /// The opacity `alpha` (corrected to the plan's uniform spacing) corrected
    /// to this ray's spacing.
    fn opacity(&self, alpha: f32) -> f32;
    /// The opacity `alpha` (corrected to the plan's uniform spacing) corrected
    /// to half this ray's spacing (Deluxe I): `1 − (1 − α)^(e/2)`.
    fn half_opacity(&self, alpha: f32) -> f32;
}

/// `α` at half its sample spacing, `1 − √(1 − α)` (Deluxe I, eq. 6).
#[inline(always)]
pub fn half_step_alpha(alpha: f32) -> f32 {
    1.0 - (1.0 - alpha).sqrt()
}

/// The cell (in `[0, cells)`) and weight of in-slice positions `(x, y)`.
#[inline(always)]
fn cell_at(ctx: &RayContext, x: f64, y: f64) -> Option<(usize, usize, f32, f32)> {
    let (ci, cj) = (floor_i64(x), floor_i64(y));
    if (ci as u64) < ctx.cells[0] as u64 && (cj as u64) < ctx.cells[1] as u64 {
        Some((ci as usize, cj as usize, (x - ci as f64) as f32, (y - cj as f64) as f32))
    } else {
        None
    }
}

/// The ray of intermediate pixel `(p, q)` of a translated plan: its sample in
/// slice `k` is in cell `(p, q) − pad + floor(trans[k])`, at the slice's weights.
#[derive(Clone, Copy, Debug)]
pub struct GridRay {
    pub p: i32,
    pub q: i32,
}

impl Ray for GridRay {
    #[inline(always)]
    fn locate(&self, ctx: &RayContext, k: usize) -> Option<(usize, usize, f32, f32)> {
        let s = ctx.maps[k];
        let ci = self.p - ctx.pad + s.floor[0];
        let cj = self.q - ctx.pad + s.floor[1];
        if (ci as u32) < ctx.cells[0] && (cj as u32) < ctx.cells[1] {
            Some((ci as usize, cj as usize, s.weight[0], s.weight[1]))
        } else {
            None
        }
    }
    #[inline(always)]
    fn locate_mid(&self, ctx: &RayContext, k: usize) -> Option<(usize, usize, f32, f32)> {
        let t = &ctx.plan.shear.trans;
        let (a, b) = ((self.p - ctx.pad) as f64, (self.q - ctx.pad) as f64);
        cell_at(ctx, a + 0.5 * (t[0][k] + t[0][k + 1]), b + 0.5 * (t[1][k] + t[1][k + 1]))
    }
    #[inline(always)]
    fn opacity(&self, alpha: f32) -> f32 {
        alpha
    }
    #[inline(always)]
    fn half_opacity(&self, alpha: f32) -> f32 {
        half_step_alpha(alpha)
    }
}

/// The ray through sheared point `at` of a scaled plan: its sample in slice `k`
/// is at `σ_k · at + τ_k` ([`FramePlan::scaled`], the same numbers as
/// [`FramePlan::cell_of`]); `e` is its opacity exponent
/// ([`FramePlan::opacity_exponent`]).
#[derive(Clone, Copy, Debug)]
pub struct ScaledRay {
    pub at: [f64; 2],
    pub e: f32,
}

impl Ray for ScaledRay {
    #[inline(always)]
    fn locate(&self, ctx: &RayContext, k: usize) -> Option<(usize, usize, f32, f32)> {
        let m = &ctx.plan.scaled[k];
        let (x, y) = (m.scale * self.at[0] + m.trans[0], m.scale * self.at[1] + m.trans[1]);
        let (ci, cj) = (floor_i64(x), floor_i64(y));
        if (ci as u64) < ctx.cells[0] as u64 && (cj as u64) < ctx.cells[1] as u64 {
            Some((ci as usize, cj as usize, (x - ci as f64) as f32, (y - cj as f64) as f32))
        } else {
            None
        }
    }
    #[inline(always)]
    fn locate_mid(&self, ctx: &RayContext, k: usize) -> Option<(usize, usize, f32, f32)> {
        let (m0, m1) = (&ctx.plan.scaled[k], &ctx.plan.scaled[k + 1]);
        let at = |m: &crate::view::plan::ScaledMap, a: usize| m.scale * self.at[a] + m.trans[a];
        cell_at(ctx, 0.5 * (at(m0, 0) + at(m1, 0)), 0.5 * (at(m0, 1) + at(m1, 1)))
    }
    #[inline(always)]
    fn opacity(&self, alpha: f32) -> f32 {
        correct_alpha(alpha, self.e)
    }
    #[inline(always)]
    fn half_opacity(&self, alpha: f32) -> f32 {
        if self.e == 1.0 { half_step_alpha(alpha) } else { correct_alpha(alpha, 0.5 * self.e) }
    }
}

/// A ray less its hole `[h0, h1]` ([`FramePlan::ray_hole`]): its samples in
/// the hole's slices, and the Deluxe I midpoints next to them, are outside
/// the volume to the trace (skipped when blending, never an iso hit nor the
/// sample an iso hit is refined against), so every traversal that traces
/// rays honours the hole with the one trace loop.
#[derive(Clone, Copy, Debug)]
pub struct HoledRay<R> {
    pub ray: R,
    pub hole: [usize; 2],
}

impl<R: Ray> HoledRay<R> {
    #[inline(always)]
    fn in_hole(&self, k: usize) -> bool {
        self.hole[0] <= k && k <= self.hole[1]
    }
}

impl<R: Ray> Ray for HoledRay<R> {
    #[inline(always)]
    fn locate(&self, ctx: &RayContext, k: usize) -> Option<(usize, usize, f32, f32)> {
        if self.in_hole(k) { None } else { self.ray.locate(ctx, k) }
    }
    #[inline(always)]
    fn locate_mid(&self, ctx: &RayContext, k: usize) -> Option<(usize, usize, f32, f32)> {
        if self.in_hole(k) || self.in_hole(k + 1) { None } else { self.ray.locate_mid(ctx, k) }
    }
    #[inline(always)]
    fn opacity(&self, alpha: f32) -> f32 {
        self.ray.opacity(alpha)
    }
    #[inline(always)]
    fn half_opacity(&self, alpha: f32) -> f32 {
        self.ray.half_opacity(alpha)
    }
}

/// The candidates of `it` outside the hole `[h0, h1]` (a walk's candidates in
/// the hole are never hits: the walk goes on past them).
struct SkipHole<I> {
    it: I,
    hole: [usize; 2],
}

impl<I: Iterator<Item = usize>> Iterator for SkipHole<I> {
    type Item = usize;
    #[inline(always)]
    fn next(&mut self) -> Option<usize> {
        loop {
            let k = self.it.next()?;
            if k < self.hole[0] || k > self.hole[1] {
                return Some(k);
            }
        }
    }
}

/// Rays of `rect` of the intermediate image through the sheared mask (for a
/// scaled plan, with its block occupancy up to date for `m`:
/// [`BinaryMask::update_occupancy`]): each ray
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
pub fn render_binary<W: Word>(
    ctx: &RayContext,
    mask: &BinaryMask<W>,
    search: Search,
    m: &Matcher,
    prefetch: bool,
    rect: Option<Rect>,
    out: &mut Intermediate,
) {
    let walker = Walker { search, m, prefetch };
    with_cells!(ctx, |v| match ctx.plan.limited() {
        false => binary_rows::<W, _, false>(ctx, &v, mask, walker, rect, out),
        true => binary_rows::<W, _, true>(ctx, &v, mask, walker, rect, out),
    })
}

/// How the rows of [`render_binary`] find their rays' candidates: the depth
/// search, the matcher of the codes the walks visit, and whether each group's
/// first candidates are prefetched.
#[derive(Clone, Copy)]
struct Walker<'m> {
    search: Search,
    m: &'m Matcher,
    prefetch: bool,
}

/// One row of the intermediate image as a row loop writes it: row `q`, and
/// its pixels `p0, p0 + 1, …` of the colour and depth planes.
pub(crate) struct RowOut<'r> {
    pub q: usize,
    pub p0: usize,
    pub rgba: &'r mut [[f32; 4]],
    pub depth: &'r mut [f32],
}

/// [`render_binary`] for one cell layout, with (`LIMITED`) or without ray limits.
fn binary_rows<W: Word, V: Cells, const LIMITED: bool>(
    ctx: &RayContext,
    v: &V,
    mask: &BinaryMask<W>,
    walker: Walker,
    rect: Option<Rect>,
    out: &mut Intermediate,
) {
    let Walker { search, m, .. } = walker;
    match ctx.plan.kind {
        MapKind::Translate => render_rows(rect, out, |row| {
            let mut src = Columns::new(ctx, mask, search, m, row.q, row.p0);
            binary_row_dispatch::<W, V, LIMITED, _>(ctx, v, mask, walker, &mut src, row)
        }),
        MapKind::ScaleTranslate => {
            let drift = Drift::for_plan(ctx.plan);
            if drift.is_still() {
                // a parallel plan at another pixel pitch: no ray drifts
                return render_rows(rect, out, |row| {
                    let mut src = Still { ctx, mask, occ: mask.occupancy(), search, m, q: row.q, drift };
                    binary_row_dispatch::<W, V, LIMITED, _>(ctx, v, mask, walker, &mut src, row)
                });
            }
            render_rows(rect, out, |row| {
                let mut src = Diverging { ctx, mask, occ: mask.occupancy(), search, m, q: row.q, drift, blocks: None };
                binary_row_dispatch::<W, V, LIMITED, _>(ctx, v, mask, walker, &mut src, row)
            })
        }
    }
}

/// One row of [`render_binary`], by the copy compiled for the CPU level.
#[inline(always)]
fn binary_row_dispatch<W: Word, V: Cells, const LIMITED: bool, S: RaySource>(
    ctx: &RayContext,
    v: &V,
    mask: &BinaryMask<W>,
    walker: Walker,
    src: &mut S,
    row: RowOut,
) {
    let prefetch = walker.prefetch;
    #[cfg(target_arch = "x86_64")]
    if walker.search == Search::Bitscan && mask.cpu_level().has_avx2() {
        // SAFETY: the mask's CPU level has AVX2 here; a mask's level is always
        // capped to at most `kernels::detected()`, which is `Avx2` only when
        // `is_x86_feature_detected!` found lzcnt and bmi1 on this CPU at run
        // time, which is all `binary_row_lzcnt` requires; its body is the safe
        // `binary_row`.
        unsafe { binary_row_lzcnt::<V, LIMITED, S>(ctx, v, src, prefetch, row) };
        return;
    }
    let _ = mask;
    binary_row::<V, LIMITED, S>(ctx, v, src, prefetch, row);
}

/// Where a row of [`render_binary`] gets its rays, each with the walk over its
/// candidate slices: the one place the two kinds of sample map differ.
trait RaySource {
    type Ray: Ray;
    type Walk: Iterator<Item = usize>;
    /// The ray of pixel `p` of the row (called for `p0, p0 + 1, …` in order)
    /// and, unless it has no candidate, its walk and its first candidate (which
    /// the walk will return first); `v` is the frame's cells (what a source may
    /// sample before walking).
    fn ray<V: Cells>(&mut self, v: &V, p: usize) -> (Self::Ray, Option<(Self::Walk, usize)>);
    /// Called before the rays of pixels `p0 .. p0 + n` (a group of
    /// [`binary_row`]) are asked for: where a source finds what a group of rays
    /// shares.
    #[inline(always)]
    fn group(&mut self, p0: usize, n: usize) {
        let _ = (p0, n);
    }
    /// The ray of pixel `p` again (cheap: kept out of the walks between a
    /// group's two phases, which would only move it around).
    fn ray_of(&self, p: usize) -> Self::Ray;
}

/// The rays of a translated plan: each reads one (super) column of the mask,
/// stepping from column to column with a counter (no division per ray).
struct Columns<'a, W: Word> {
    ctx: &'a RayContext<'a>,
    mask: &'a BinaryMask<W>,
    search: Search,
    m: &'a Matcher,
    q: usize,
    s: usize,
    sp: usize,
    left: usize,
    sq: usize,
}

impl<'a, W: Word> Columns<'a, W> {
    #[inline(always)]
    fn new(ctx: &'a RayContext<'a>, mask: &'a BinaryMask<W>, search: Search, m: &'a Matcher, q: usize, p0: usize) -> Self {
        let (sp, left) = mask.column_run(p0);
        let sq = mask.ray_column(p0, q).1;
        Columns { ctx, mask, search, m, q, s: mask.cell_size(), sp, left, sq }
    }
}

impl<'a, W: Word> RaySource for Columns<'a, W> {
    type Ray = GridRay;
    type Walk = SetBits<'a, W>;
    #[inline(always)]
    fn ray<V: Cells>(&mut self, _: &V, p: usize) -> (GridRay, Option<(SetBits<'a, W>, usize)>) {
        let mut it = SetBits::with_matcher(self.mask.row(self.sp, self.sq), self.ctx.ascending, self.search, self.m);
        let walk = it.peek().map(|k0| (it, k0));
        self.left -= 1;
        if self.left == 0 {
            self.sp += 1;
            self.left = self.s;
        }
        (GridRay { p: p as i32, q: self.q as i32 }, walk)
    }
    #[inline(always)]
    fn ray_of(&self, p: usize) -> GridRay {
        GridRay { p: p as i32, q: self.q as i32 }
    }
}

/// The rays of a scaled plan: each walks across the mask's columns as it
/// diverges from the direction the mask is sheared to ([`ColumnWalk`]), over
/// its own slice range, from the first block in which its group may have a
/// candidate ([`BlockOccupancy::first_block`]).
struct Diverging<'a, W: Word> {
    ctx: &'a RayContext<'a>,
    mask: &'a BinaryMask<W>,
    occ: &'a BlockOccupancy,
    search: Search,
    m: &'a Matcher,
    q: usize,
    /// The plan's drift across the mask.
    drift: Drift,
    /// The group's first and last blocks with a possible candidate, in
    /// walking order (`None`: no ray of the group has one).
    blocks: Option<(usize, usize)>,
}

impl<'a, W: Word> RaySource for Diverging<'a, W> {
    type Ray = ScaledRay;
    type Walk = ColumnWalk<'a, W>;
    #[inline(always)]
    fn ray<V: Cells>(&mut self, v: &V, p: usize) -> (ScaledRay, Option<(ColumnWalk<'a, W>, usize)>) {
        let ctx = self.ctx;
        let ray = ctx.scaled_ray(p, self.q);
        let Some((b, e)) = self.blocks else { return (ray, None) };
        let plan = ctx.plan;
        let [mut lo, mut hi] = plan.ray_range(p, self.q);
        let len = self.occ.block_len();
        // the eye in tissue: when the group may have a candidate in the ray's
        // first block and the ray's first sample is an iso hit, that sample is
        // the ray's result, as the walk (which holds it: the mask is
        // conservative) and brute force (its first sample) would find it
        let first = if ctx.ascending { lo } else { hi };
        if ctx.mode == Mode::Iso
            && lo <= hi
            && first / len == b
            && plan.ray_hole(p, self.q).is_none_or(|[h0, h1]| first < h0 || first > h1)
            && let Some((ci, cj, wi, wj)) = ray.locate(ctx, first)
            && ctx.first_sample(v, At { k: first, ci, cj, wi, wj }) >= ctx.iso_at(first, plan.focus_range(p, self.q)).0
        {
            return (ray, Some((ColumnWalk::only(self.mask, self.occ, self.m, self.search, first), first)));
        }
        // (the blocks outside the group's hold no candidate of this ray)
        let (first, last) = if ctx.ascending { (b, e) } else { (e, b) };
        (lo, hi) = (lo.max(first * len), hi.min(last * len + len - 1));
        let span = SliceSpan { lo, hi, ascending: ctx.ascending };
        let mut it = ColumnWalk::new(self.mask, self.occ, &self.drift, ray.at, span, self.search, self.m);
        let walk = it.peek().map(|k0| (it, k0));
        (ray, walk)
    }
    #[inline(always)]
    fn ray_of(&self, p: usize) -> ScaledRay {
        self.ctx.scaled_ray(p, self.q)
    }
    #[inline(always)]
    fn group(&mut self, p0: usize, n: usize) {
        let plan = self.ctx.plan;
        let (a0, a1) =
            (plan.intermediate_to_sheared(p0 as f64, self.q as f64), plan.intermediate_to_sheared((p0 + n - 1) as f64, self.q as f64));
        let at = [[a0[0].min(a1[0]), a0[0].max(a1[0])], [a0[1].min(a1[1]), a0[1].max(a1[1])]];
        // the plan's slices hold every ray's own range
        let [lo, hi] = plan.k_range;
        let first = |lo, hi, ascending| self.occ.first_block(self.mask, &plan.shear, &plan.scaled, at, SliceSpan { lo, hi, ascending });
        let asc = self.ctx.ascending;
        self.blocks = first(lo, hi, asc).map(|b| {
            // the last, from the back up to the first
            let len = self.occ.block_len();
            let (lo, hi) = if asc { (lo.max(b * len), hi) } else { (lo, hi.min(b * len + len - 1)) };
            (b, first(lo, hi, !asc).unwrap_or(b))
        });
    }
}

/// The rays of a scaled plan none of whose rays drifts across the mask
/// ([`Drift::is_still`]: a parallel plan at another pixel pitch, `--quality`
/// or Deluxe M): each reads the one or two columns per axis its cells sit in
/// ([`StillWalk`]), as a translated ray reads its one column.
struct Still<'a, W: Word> {
    ctx: &'a RayContext<'a>,
    mask: &'a BinaryMask<W>,
    occ: &'a BlockOccupancy,
    search: Search,
    m: &'a Matcher,
    q: usize,
    drift: Drift,
}

impl<'a, W: Word> RaySource for Still<'a, W> {
    type Ray = ScaledRay;
    type Walk = StillWalk<'a, W>;
    #[inline(always)]
    fn ray<V: Cells>(&mut self, _: &V, p: usize) -> (ScaledRay, Option<(StillWalk<'a, W>, usize)>) {
        let ctx = self.ctx;
        let ray = ctx.scaled_ray(p, self.q);
        let [lo, hi] = ctx.plan.ray_range(p, self.q);
        let span = SliceSpan { lo, hi, ascending: ctx.ascending };
        let mut it = StillWalk::new(self.mask, self.occ, &self.drift, ray.at, span, self.search, self.m);
        let first = it.peek();
        (ray, first.map(|k0| (it, k0)))
    }
    #[inline(always)]
    fn ray_of(&self, p: usize) -> ScaledRay {
        self.ctx.scaled_ray(p, self.q)
    }
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

/// Traces `ray` (of pixel `(p, q)`) over candidates `ks`: the whole stack, or
/// (`LIMITED`) clipped to the plan's range for the ray.
#[inline(always)]
fn trace_ray<V: Cells, R: Ray, const LIMITED: bool>(
    ctx: &RayContext,
    v: &V,
    ray: R,
    p: usize,
    q: usize,
    ks: impl Iterator<Item = usize>,
) -> RayResult {
    let foc = ctx.plan.focus_range(p, q);
    if LIMITED {
        let [lo, hi] = ctx.plan.ray_range(p, q);
        if lo > hi {
            return MISS;
        }
        let ks = Clip { it: ks, lo, hi, ascending: ctx.ascending };
        match ctx.plan.ray_hole(p, q) {
            None => ctx.trace(v, ray, ks, lo, hi, foc),
            Some(hole) => ctx.trace(v, HoledRay { ray, hole }, SkipHole { it: ks, hole }, lo, hi, foc),
        }
    } else {
        ctx.trace(v, ray, ks, 0, ctx.stack.n[2] - 1, foc)
    }
}

/// One row of [`render_binary`] (inlined into both compiled copies): in groups
/// of [`PREFETCH_GROUP`] rays, first every ray's first candidate (prefetched),
/// then the walks.
#[inline(always)]
fn binary_row<V: Cells, const LIMITED: bool, S: RaySource>(ctx: &RayContext, v: &V, src: &mut S, prefetch: bool, row: RowOut) {
    let RowOut { q, p0, rgba: crow, depth: drow } = row;
    // each ray's walk, positioned at its first candidate between the phases
    let mut walks: [Option<S::Walk>; PREFETCH_GROUP] = std::array::from_fn(|_| None);
    let mut last_line = usize::MAX;
    for (g, (cg, dg)) in crow.chunks_mut(PREFETCH_GROUP).zip(drow.chunks_mut(PREFETCH_GROUP)).enumerate() {
        let pg = p0 + g * PREFETCH_GROUP;
        src.group(pg, cg.len());
        // phase 1: the first candidate slice of every ray of the group (none for
        // an empty column), prefetched
        for (dp, walk) in walks[..cg.len()].iter_mut().enumerate() {
            // (a match, not a closure: the walk's bit scans must stay inside
            // this function, compiled for the CPU level of its caller)
            let (ray, w) = src.ray(v, pg + dp);
            *walk = match w {
                Some((it, k0)) => {
                    if prefetch {
                        ctx.prefetch(v, ray, k0, &mut last_line);
                    }
                    Some(it)
                }
                None => None,
            };
        }
        // phase 2: the walks, from the first candidate on
        for (dp, ((c, d), walk)) in cg.iter_mut().zip(dg.iter_mut()).zip(walks.iter_mut()).enumerate() {
            let res = match walk.take() {
                None => MISS,
                Some(walk) => trace_ray::<V, _, LIMITED>(ctx, v, src.ray_of(pg + dp), pg + dp, q, walk),
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
#[target_feature(enable = "lzcnt,bmi1")]
unsafe fn binary_row_lzcnt<V: Cells, const LIMITED: bool, S: RaySource>(ctx: &RayContext, v: &V, src: &mut S, prefetch: bool, row: RowOut) {
    binary_row::<V, LIMITED, S>(ctx, v, src, prefetch, row)
}

/// The brute-force reference: every slice of every ray of `rect` (within the
/// plan's slice range and ray limits), no mask, with the same rays as
/// [`render_binary`] (the plan's sample maps, either kind).
pub fn render_brute(ctx: &RayContext, rect: Option<Rect>, out: &mut Intermediate) {
    with_cells!(ctx, |v| match ctx.plan.kind {
        MapKind::Translate => brute_rows(ctx, &v, rect, out, |p, q| GridRay { p: p as i32, q: q as i32 }),
        MapKind::ScaleTranslate => brute_rows(ctx, &v, rect, out, |p, q| ctx.scaled_ray(p, q)),
    })
}

/// [`render_brute`] for one cell layout and kind of ray.
fn brute_rows<V: Cells, R: Ray>(
    ctx: &RayContext,
    v: &V,
    rect: Option<Rect>,
    out: &mut Intermediate,
    ray: impl Fn(usize, usize) -> R + Sync,
) {
    render_rows(rect, out, |row| {
        let RowOut { q, p0, rgba, depth } = row;
        for (dp, (c, d)) in rgba.iter_mut().zip(depth.iter_mut()).enumerate() {
            let p = p0 + dp;
            let [lo, hi] = ctx.plan.ray_range(p, q);
            let r = ray(p, q);
            let foc = ctx.plan.focus_range(p, q);
            let res = match (lo <= hi, ctx.ascending, ctx.plan.ray_hole(p, q)) {
                (false, ..) => MISS,
                (true, true, None) => ctx.trace(v, r, lo..=hi, lo, hi, foc),
                (true, false, None) => ctx.trace(v, r, (lo..=hi).rev(), lo, hi, foc),
                // every slice of the ray, the hole's too: its ray skips them
                (true, true, Some(hole)) => ctx.trace(v, HoledRay { ray: r, hole }, lo..=hi, lo, hi, foc),
                (true, false, Some(hole)) => ctx.trace(v, HoledRay { ray: r, hole }, (lo..=hi).rev(), lo, hi, foc),
            };
            *c = res.rgba;
            *d = res.depth;
        }
    });
}

/// Runs `row` for every row `q` of `rect` in parallel, with the row's pixels
/// `p0..=p1` of the colour and depth planes; seals `rect`.
pub(crate) fn render_rows(rect: Option<Rect>, out: &mut Intermediate, row: impl Fn(RowOut) + Sync) {
    out.seal(rect);
    let Some(r) = rect else { return };
    let w = out.size[0];
    let (rgba, depth) = (&mut out.rgba, &mut out.depth);
    // slice the rows first: rayon's parallel `skip` would heap-allocate a job per frame
    let rows = r.q0 * w..(r.q1 + 1) * w;
    rgba[rows.clone()].par_chunks_mut(w).zip(depth[rows].par_chunks_mut(w)).enumerate().for_each(|(dq, (crow, drow))| {
        row(RowOut { q: r.q0 + dq, p0: r.p0, rgba: &mut crow[r.p0..=r.p1], depth: &mut drow[r.p0..=r.p1] });
    });
}

/// The rectangle of the intermediate grid that rays through the volume can reach
/// under `plan`'s slice maps (geometry only, no mask): used by brute force.
pub fn volume_rect(plan: &FramePlan, cells: [usize; 2]) -> Option<Rect> {
    maps_rect(plan, cells, false)
}

/// [`volume_rect`] with the pixels of the plan's intermediate samples
/// (Deluxe I) as well: a midpoint's position is the mean of its two slices'
/// positions, so where consecutive slices' positions differ by more than a
/// cell (a perspective ray at a wide angle, the eye near) a pixel can sample
/// the volume at the midpoint and outside it at both slices. The RLE brute
/// force's rectangle ([`RleVolume::rect`](crate::encode::rle::runs::RleVolume::rect)
/// takes the same maps over the slices' boxes).
pub fn volume_rect_with_mids(plan: &FramePlan, cells: [usize; 2]) -> Option<Rect> {
    maps_rect(plan, cells, plan.intermediate())
}

/// The pixels whose samples fall in the cells of the slices composited
/// (and, with `mids`, of the intermediate samples between them).
fn maps_rect(plan: &FramePlan, cells: [usize; 2], mids: bool) -> Option<Rect> {
    let grid = plan.grid.size;
    if cells[0] == 0 || cells[1] == 0 || plan.maps.is_empty() {
        return None;
    }
    plan.front_to_back().next()?;
    // (a slice whose cells no pixel of the grid samples adds none; a plan
    // whose slices all fall off its grid — a pyramid of a split perspective
    // frame can — has no rect)
    let [k0, k1] = plan.k_range;
    let mid_ks = if mids { k0..k1.min(plan.slices().saturating_sub(1)) } else { 0..0 };
    let span = |a: usize| {
        let last = cells[a] as i64 - 1;
        let xs = || {
            plan.front_to_back()
                .map(move |k| plan.pixels_of_cells(k, a, 0, last))
                .chain(mid_ks.clone().map(move |k| plan.mid_map(k, a).pixels_of_cells(0, last)))
                .map(|[x0, x1]| [x0.max(0), x1.min(grid[a] as i64 - 1)])
                .filter(|[x0, x1]| x0 <= x1)
        };
        let lo = xs().map(|x| x[0]).min()?;
        let hi = xs().map(|x| x[1]).max()?;
        Some((lo as usize, hi as usize))
    };
    let (p0, p1) = span(0)?;
    let (q0, q1) = span(1)?;
    Some(Rect { p0, p1, q0, q1 })
}

/// The rays of a scaled plan ([`MapKind::ScaleTranslate`]) that can meet an
/// occupied cell of `mask` (of a volume of `cells` cells per slice): the
/// pixels whose samples fall in some composited slice's box of non-zero codes
/// ([`BinaryMask::slice_cells`]). The scaled counterpart of
/// [`BinaryMask::occupied_rays`]; every other ray's walk would find nothing.
pub fn occupied_scaled_rays<W: Word>(plan: &FramePlan, mask: &BinaryMask<W>, cells: [usize; 2]) -> Option<Rect> {
    let grid = plan.grid.size;
    if cells[0] == 0 || cells[1] == 0 || grid[0] == 0 || grid[1] == 0 {
        return None;
    }
    let (mut lo, mut hi) = ([i64::MAX; 2], [i64::MIN; 2]);
    'slices: for k in plan.front_to_back() {
        let Some([i0, i1, j0, j1]) = mask.slice_cells(k) else { continue };
        let c = [[i0.max(0), i1.min(cells[0] as i64 - 1)], [j0.max(0), j1.min(cells[1] as i64 - 1)]];
        let mut x = [[0i64; 2]; 2];
        for a in 0..2 {
            x[a] = plan.pixels_of_cells(k, a, c[a][0], c[a][1]);
            if c[a][0] > c[a][1] || x[a][0] > x[a][1] {
                continue 'slices;
            }
        }
        for a in 0..2 {
            lo[a] = lo[a].min(x[a][0]);
            hi[a] = hi[a].max(x[a][1]);
        }
    }
    if lo[0] > hi[0] || lo[1] > hi[1] {
        return None;
    }
    // one pixel more each side: a ray locates its samples through the plan's
    // f64 maps ([`ScaledRay`]), which may put a sample that lies exactly on a
    // voxel line in the cell after the one the fixed-point axis map gives
    let (p0, q0) = ((lo[0] - 1).max(0), (lo[1] - 1).max(0));
    let (p1, q1) = ((hi[0] + 1).min(grid[0] as i64 - 1), (hi[1] + 1).min(grid[1] as i64 - 1));
    if p0 > p1 || q0 > q1 {
        return None;
    }
    Some(Rect { p0: p0 as usize, p1: p1 as usize, q0: q0 as usize, q1: q1 as usize })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every parallel plan moves its rays by at most one voxel a slice, so the
    /// cubic's binary walk serves it: views at every whole degree about each
    /// eye axis from each named view, 45° and 135° included (where the
    /// principal axis is a tie).
    #[test]
    fn the_cubic_walks_every_parallel_plan() {
        use crate::view::{Camera, Factorization, NamedView, rotate_eye};
        for (dims, sp) in
            [([40, 36, 30], [1.0f32; 3]), ([21, 19, 23], [1.0; 3]), ([256, 256, 256], [1.0; 3]), ([33, 20, 17], [0.6, 0.6, 5.0])]
        {
            for view in NamedView::ALL {
                for axis in 0..3 {
                    for deg in 0..360 {
                        let cam = Camera::new(rotate_eye(view.rotation(), axis, deg as f64), [64, 64]);
                        let plan = FramePlan::parallel(&Factorization::new(&cam, dims, sp).unwrap(), sp);
                        assert!(cubic_walks(&plan), "{view:?} turned {deg}° about eye axis {axis}, {dims:?}");
                    }
                }
            }
        }
    }

    /// The SSE cubic kernels of the slice (the four lines' quantities of the
    /// gradient, the sample) equal the plain ones bit for bit, along both
    /// in-slice axes, at borders (repeated lines) and inside.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn cubic_kernels_in_the_slice_equal_the_plain_ones() {
        let mut next = crate::testing::xorshift(0x51ce_c0de_2545_f491);
        let mut unit = move || (next() >> 40) as f32 / (1u64 << 24) as f32;
        let (n0, n1, nk) = (9usize, 7usize, 5usize);
        let n01 = n0 * n1;
        let data: Vec<f32> = (0..n01 * nk).map(|_| unit() * 300.0 - 40.0).collect();
        for _ in 0..4000 {
            let w_o = [0.0, 1.0, 0.5, unit()][(unit() * 4.0) as usize % 4];
            let cr = [unit() - 0.5, unit(), unit(), unit() - 0.5];
            let k = 1 + (unit() * (nk - 2) as f32) as usize % (nk - 2);
            // along 0: lines along i (step 1), the other axis j (n0)
            let c = (unit() * (n0 - 1) as f32) as usize % (n0 - 1);
            let co = 1 + (unit() * (n1 - 3) as f32) as usize % (n1 - 3);
            let lines = four(c, n0);
            let o = lines.map(|l| l + co * n0 + k * n01);
            // SAFETY: k, co away from the borders: every read lies in data
            let (a, b) = unsafe { (cubic_lines_sse::<0>(&data, o, n0, n01, w_o), cubic_lines_plain(&data, o, n0, n01, w_o)) };
            assert_eq!(a.map(|x| x.map(f32::to_bits)), b.map(|x| x.map(f32::to_bits)), "along 0 at {o:?}");
            // along 1: lines along j (step n0), the other axis i (1)
            let c = (unit() * (n1 - 1) as f32) as usize % (n1 - 1);
            let co = 1 + (unit() * (n0 - 3) as f32) as usize % (n0 - 3);
            let o = four(c, n1).map(|l| co + l * n0 + k * n01);
            // SAFETY: as above
            let (a, b) = unsafe { (cubic_lines_sse::<1>(&data, o, 1, n01, w_o), cubic_lines_plain(&data, o, 1, n01, w_o)) };
            assert_eq!(a.map(|x| x.map(f32::to_bits)), b.map(|x| x.map(f32::to_bits)), "along 1 at {o:?}");
            // the sample inside: four consecutive lines from `before`
            let before = k * n01 + (unit() * (n01 - 4 * n0 - 2) as f32) as usize % (n01 - 4 * n0 - 2);
            for (za, step, other) in [(0, 1, n0), (1, n0, 1)] {
                let o = [0, 1, 2, 3].map(|m| before + m * step);
                // SAFETY: every read lies within three rows and a voxel of `before`, in data
                let (a, b) = unsafe {
                    let a = if za == 0 {
                        cubic_sample_sse::<0>(&data, before, n0, w_o, &cr)
                    } else {
                        cubic_sample_sse::<1>(&data, before, n0, w_o, &cr)
                    };
                    (a, cubic_sample_plain(&data, o, other, w_o, &cr))
                };
                assert_eq!(a.to_bits(), b.to_bits(), "sample along {za} from {before}");
            }
        }
    }
    use crate::classify::TransferFunction;
    use crate::data::volume::Volume;
    use crate::encode::depth::binary_matcher;
    use crate::encode::mask::CellCodes;
    use crate::view::plan::ScaledMap;
    use crate::view::{Camera, Factorization};
    use glam::DMat3;

    /// A parallel plan turned into a scaled one at another pixel pitch (the
    /// adaptive intermediate image size, or matched sampling's pitch per
    /// axis): `pitch` voxels per pixel, slice `k` sampled at
    /// `sigma · (a, b) + trans[k]`.
    fn rescaled(mut plan: FramePlan, pitch: [f64; 2], sigma: f64) -> FramePlan {
        let g = plan.grid;
        let f = pitch.map(|p| 1.0 / (p * sigma));
        plan.grid.pitch = pitch;
        plan.grid.pad = (g.pad as f64 * f[0].max(f[1])).ceil() as usize;
        plan.grid.size = [0, 1].map(|a| (g.size[a] as f64 * f[0].max(f[1])).ceil() as usize + 2);
        plan.kind = MapKind::ScaleTranslate;
        plan.scaled =
            (0..plan.slices()).map(|k| ScaledMap { scale: sigma, trans: [plan.shear.trans[0][k], plan.shear.trans[1][k]] }).collect();
        plan
    }

    /// The binary walk reads any scaled plan: a parallel view at 2 pixels per
    /// voxel, at 0.75, at 1 and 3 (a pitch per axis), and with a uniform
    /// slice scale, renders the brute force's image bit for bit (blend and
    /// iso, cell sizes 1 and 2, u32 and u64).
    #[test]
    fn uniform_scale_parallel_plan_binary_equals_brute_force() {
        let dims = [19, 17, 41];
        let vol = Volume::from_fn(dims, [1.0; 3], |x, y, z| {
            let d = ((x as f32 - 9.0).powi(2) + (y as f32 - 8.0).powi(2) + (z as f32 - 20.0).powi(2)).sqrt();
            (200.0 * (1.0 - d / 9.0)).max(0.0) + if (x * 7 + y * 3 + z * 5) % 23 == 0 { 90.0 } else { 0.0 }
        })
        .unwrap();
        let tf = TransferFunction::ramp(40.0, 160.0, 0.5, [0.9, 0.7, 0.5]);
        let (lo, hi) = vol.value_range();
        let cls = Classifier::new(&tf, lo, hi);
        let mut checked = 0;
        for (i, r) in [DMat3::from_euler(glam::EulerRot::XYZ, 0.3, -0.4, 0.2), DMat3::from_euler(glam::EulerRot::XYZ, 1.9, 0.5, -0.3)]
            .into_iter()
            .enumerate()
        {
            let f = Factorization::new(&Camera::new(r, [64, 64]), dims, [1.0; 3]).unwrap();
            let stack = SliceStack::new(&vol, f.axis);
            let base = FramePlan::parallel(&f, [1.0; 3]);
            for (pitch, sigma) in [([0.5; 2], 1.0), ([1.0 / 0.75; 2], 1.0), ([1.0; 2], 0.8), ([1.0, 1.0 / 3.0], 1.0)] {
                let plan = rescaled(base.clone(), pitch, sigma);
                for mode in [Mode::Blend, Mode::Iso] {
                    let iso = 100.0;
                    let ctx = RayContext::new(&stack, &cls, &plan, mode, iso, Shading::default(), 0.95);
                    let visible = |_: f32, h: f32| if mode == Mode::Iso { h >= iso } else { h > 39.0 };
                    let codes = CellCodes::binary(&stack, visible);
                    let rect = volume_rect(&plan, stack.cells());
                    let mut want = Intermediate::default();
                    want.prepare(plan.grid.size);
                    render_brute(&ctx, rect, &mut want);
                    for s in [1, 2] {
                        let mut got = Intermediate::default();
                        got.prepare(plan.grid.size);
                        if (i + s) % 2 == 0 {
                            let mut mask = BinaryMask::<u64>::from_codes(&codes, s);
                            mask.shear_to(&plan.shear);
                            mask.update_occupancy(binary_matcher(), &plan.shear, true);
                            render_binary(&ctx, &mask, Search::Bitscan, binary_matcher(), true, rect, &mut got);
                        } else {
                            let mut mask = BinaryMask::<u32>::from_codes(&codes, s);
                            mask.shear_to(&plan.shear);
                            mask.update_occupancy(binary_matcher(), &plan.shear, true);
                            render_binary(&ctx, &mask, Search::Bitscan, binary_matcher(), true, rect, &mut got);
                        }
                        let bits = |x: &Intermediate| {
                            x.rgba.iter().flatten().map(|v| v.to_bits()).chain(x.depth.iter().map(|v| v.to_bits())).collect::<Vec<u32>>()
                        };
                        assert_eq!(bits(&got), bits(&want), "view {i} pitch {pitch:?} sigma {sigma} {mode:?} cell {s}");
                        assert!(want.rgba.iter().any(|p| p[3] > 0.0));
                        checked += 1;
                    }
                }
            }
        }
        assert_eq!(checked, 32);
    }
}
