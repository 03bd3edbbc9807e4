//! Stage 5d — the run-length-encoded, pre-classified volume (Lacroute's shear-warp).
//!
//! Owns the second acceleration structure of the crate, the one VolPack uses:
//!
//! - [`Preclass`]: the per-voxel classification both pre-classified paths share.
//!   A voxel's density is quantized to the nearest node of the [`Classifier`]'s
//!   table; that node ([`RleVoxel::class`], u16) indexes the voxel's raw opacity
//!   (before the per-view sample-spacing correction) *and* its colour, so one
//!   index stores both. A voxel whose node has zero opacity is transparent. Its
//!   shading index ([`RleVoxel::normal`]) is the 14-bit hemi-octahedral code
//!   ([`encode_normal`]) of the central-difference gradient
//!   ([`SliceStack::gradient_at`]) mapped to object (world) space with the voxel
//!   spacing, up to sign because the headlight shading is two-sided; code
//!   [`ZERO_NORMAL`] is a zero gradient, which faces the viewer like
//!   [`crate::classify::shading::headlight_ndl`]'s.
//! - [`RleVolume`]: one principal axis's encoding. Every scanline (row `j` of
//!   slice `k`, along `i`) is a list of `(transparent, non-transparent)` run-length
//!   pairs (u16; the transparent run after the last pair is implicit), and only
//!   the voxels of the non-transparent runs are stored. A gap of at most
//!   [`BRIDGE`] transparent voxels between two runs is bridged: stored as
//!   zero-opacity voxels, which shade to exact zeros, so the runs are longer and
//!   the compositing loop changes run less often. Built from a [`SliceStack`]
//!   when a view first needs the axis; a new transfer function or tissue
//!   re-encodes.
//! - [`ViewTables`]: the per-view lookup tables: the opacity-corrected,
//!   premultiplied colour of every class node (`α' = 1 − (1 − α)^ratio`, rebuilt
//!   when the ratio changes — VolPack's opacity-correction table) and the shade
//!   table `[ambient + diffuse·|n·l|, specular·|n·l|^shininess]` of every normal
//!   code for the headlight (rebuilt when the view direction or the material
//!   changes). A voxel's shaded, premultiplied colour is
//!   `[α'r·d + α'·s, α'g·d + α'·s, α'b·d + α'·s, α']`.
//! - The compositing ([`render_rle`]): slice by slice, front to back, into the
//!   shared intermediate image. Per slice the bilinear weights are computed once;
//!   the two voxel scanlines under an intermediate row are traversed together so
//!   transparent voxels are skipped run by run; opaque intermediate pixels are
//!   skipped through per-pixel skip links with path compression (Lacroute's
//!   opaque-pixel links); between the skips, a span of pixels is composited in
//!   segments over which both scanlines stay in the same kind of run, each a
//!   plain loop over voxel slices; a row pair whose pixels over its scanlines'
//!   non-transparent extent are all opaque is rejected without walking runs, and
//!   the scanline the next row brings in is prefetched at this row's edges (the
//!   only `unsafe`: a cache hint); a pixel is finished once its opacity reaches
//!   [`crate::render::Settings::ert`]. Parallel over bands of intermediate rows
//!   (each band walks all slices front to back), so the image is the same for any
//!   thread count.
//! - Its reference ([`render_brute_preclassified`]): the same samples at the same
//!   positions, classifying every voxel of every slice from the densities, with no
//!   runs and no links. Skipping (and bridging) adds nothing but exact zeros
//!   (for non-negative shading coefficients), so the two images are equal bit
//!   for bit; the tests assert that with early termination off and allow 1e-5
//!   otherwise.
//!
//! The sample geometry is the crate's (see [`crate::composite::raycast::SliceParams`]):
//! intermediate pixel `(p, q)` samples cell `(p − pad + floor_i[k], q − pad +
//! floor_j[k])` of slice `k` with in-cell weights `(weight_i[k], weight_j[k])`.
//! The sample is the bilinear blend of the four voxels' premultiplied colours,
//! composited "over" ([`composite_premultiplied`]).

// Negated float comparisons (`!(a > b)`) are deliberate here: NaN takes the
// "no" branch (a NaN gradient is a zero one, a NaN threshold terminates nothing).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use std::sync::atomic::{AtomicU64, Ordering};

use rayon::prelude::*;

use crate::classify::shading::Shading;
use crate::classify::{Classifier, TABLE_NODES};
use crate::composite::raycast::SliceParams;
use crate::composite::{Intermediate, composite_premultiplied};
pub use crate::data::normals::{NORMAL_CODES, NORMAL_SIDE, ZERO_NORMAL, decode_normal, encode_normal, headlight_object};
use crate::data::normals::{ShadeTable, boxed, voxel_normal};
use crate::data::slices::{SliceStack, prefetch};
use crate::encode::mask::Rect;
use crate::view::Factorization;

/// Gaps of at most this many transparent voxels between two non-transparent
/// runs of a scanline are stored as explicit transparent voxels ("bridged"):
/// they shade to exact zeros, exactly what skipping them would give, and the
/// longer runs mean fewer run changes in the compositing loop. Measured on
/// brainsmall (VolPack's ramp, 512², one thread): compositing 1.65 ms without
/// bridging, 1.44 / 1.33 / 1.30 ms with gaps up to 3 / 6 / 10, slower again at 32;
/// the encoding grows by about a fifth at 8.
pub const BRIDGE: usize = 8;

/// The normal code that marks a bridged transparent voxel (real codes are below
/// [`NORMAL_CODES`]; masked, it indexes a real shade entry, multiplied by zero).
pub const BRIDGE_NORMAL: u16 = u16::MAX;

/// Intermediate rows per parallel band.
const BAND: usize = 16;

/// End of a scanline for the run cursors.
const INF: u32 = u32::MAX;

/// One stored voxel of the encoding (non-transparent, or a bridged transparent one).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[repr(C)]
pub struct RleVoxel {
    /// Classifier table node of the voxel's density: indexes its raw opacity and colour.
    pub class: u16,
    /// Hemi-octahedral code of its object-space gradient direction ([`ZERO_NORMAL`] if none).
    pub normal: u16,
}

/// Source of [`Preclass`] ids (tables remember which classification they were built for).
static PRECLASS_IDS: AtomicU64 = AtomicU64::new(1);

/// The per-voxel classification shared by the RLE path and its brute-force reference.
#[derive(Clone, Debug)]
pub struct Preclass {
    id: u64,
    cls: Classifier,
    /// Raw opacity of each table node (before the per-view correction).
    alpha: Vec<f32>,
    /// `ln(1 − α)` of each node (−∞ for α = 1), for the per-view correction.
    ln_clear: Vec<f32>,
    /// Colour of each node.
    rgb: Vec<[f32; 3]>,
    /// `1 / spacing` per object axis (voxel-space gradient → object space).
    inv_spacing: [f32; 3],
}

impl Preclass {
    /// The classification of `cls` for a volume with voxel `spacing`.
    pub fn new(cls: &Classifier, spacing: [f32; 3]) -> Self {
        let nodes: Vec<_> = (0..TABLE_NODES).map(|i| cls.raw_node(i)).collect();
        Preclass {
            id: PRECLASS_IDS.fetch_add(1, Ordering::Relaxed),
            cls: cls.clone(),
            alpha: nodes.iter().map(|n| n.a).collect(),
            ln_clear: nodes.iter().map(|n| (1.0 - n.a).ln()).collect(),
            rgb: nodes.iter().map(|n| [n.r, n.g, n.b]).collect(),
            inv_spacing: spacing.map(|s| 1.0 / s),
        }
    }

    /// The classifier this classification quantizes to.
    pub fn classifier(&self) -> &Classifier {
        &self.cls
    }

    /// Voxel `(i, j, k)` of `stack`, or `None` when it is transparent.
    #[inline]
    pub fn classify_voxel(&self, stack: &SliceStack, i: usize, j: usize, k: usize) -> Option<RleVoxel> {
        let node = self.cls.nearest_node(stack.at(i, j, k));
        if !(self.alpha[node] > 0.0) {
            return None;
        }
        Some(RleVoxel { class: node as u16, normal: voxel_normal(stack, i, j, k, self.inv_spacing) })
    }

    /// The stored form of transparent voxel `(i, j, k)` inside a bridged gap:
    /// its own (zero-opacity) class, so it shades to exact zeros, and the
    /// [`BRIDGE_NORMAL`] code.
    #[inline]
    fn bridge_voxel(&self, stack: &SliceStack, i: usize, j: usize, k: usize) -> RleVoxel {
        RleVoxel { class: self.cls.nearest_node(stack.at(i, j, k)) as u16, normal: BRIDGE_NORMAL }
    }

    /// Raw opacity of a voxel (before the per-view correction).
    pub fn opacity(&self, v: RleVoxel) -> f32 {
        self.alpha[v.class as usize]
    }

    /// Unshaded colour of a voxel.
    pub fn color(&self, v: RleVoxel) -> [f32; 3] {
        self.rgb[v.class as usize]
    }
}

/// One principal axis of the volume, run-length encoded.
#[derive(Clone, Debug)]
pub struct RleVolume {
    /// Principal axis (0 = x, 1 = y, 2 = z).
    pub axis: usize,
    /// Sizes along `(i, j, k)`.
    pub n: [usize; 3],
    /// Run lengths: per scanline `(transparent, non-transparent)` pairs.
    runs: Vec<u16>,
    /// Scanline `s = j + nj·k` owns `runs[scan_runs[s]..scan_runs[s + 1]]`.
    scan_runs: Vec<u32>,
    /// ... and `voxels[scan_voxels[s]..scan_voxels[s + 1]]`.
    scan_voxels: Vec<u32>,
    /// The non-transparent voxels, scanline by scanline, in `i` order.
    voxels: Vec<RleVoxel>,
    /// Per scanline, the first and last column of its non-transparent voxels
    /// (`[u16::MAX, 0]` when it has none): lets a row pair that has nothing to do
    /// be rejected without walking its runs.
    extent: Vec<[u16; 2]>,
    /// Per slice, the bounding box `[i0, i1, j0, j1]` (inclusive) of its
    /// non-transparent voxels; `i0 > i1` when the slice is empty.
    bbox: Vec<[u32; 4]>,
}

/// One slice's part of an encoding (built in parallel, then concatenated).
struct SliceRuns {
    runs: Vec<u16>,
    voxels: Vec<RleVoxel>,
    /// Per scanline: end of its runs and voxels (relative to the slice).
    ends: Vec<(u32, u32)>,
    extent: Vec<[u16; 2]>,
    bbox: [u32; 4],
}

impl RleVolume {
    /// Encodes `stack` (one principal axis) under classification `pre`, in
    /// parallel over slices (on the current rayon pool).
    pub fn encode(stack: &SliceStack, pre: &Preclass) -> Self {
        let [ni, nj, nk] = stack.n;
        let slices: Vec<SliceRuns> = (0..nk)
            .into_par_iter()
            .map(|k| {
                let mut s = SliceRuns {
                    runs: Vec::new(),
                    voxels: Vec::new(),
                    ends: Vec::with_capacity(nj),
                    extent: Vec::with_capacity(nj),
                    bbox: [u32::MAX, 0, u32::MAX, 0],
                };
                for j in 0..nj {
                    s.extent.push([u16::MAX, 0]);
                    // `gap` is where the current transparent run began; `run` where the
                    // current non-transparent run began; `pending` counts the
                    // transparent voxels since its last non-transparent one
                    let (mut gap, mut run, mut pending): (usize, Option<usize>, usize) = (0, None, 0);
                    for i in 0..ni {
                        match pre.classify_voxel(stack, i, j, k) {
                            Some(v) => {
                                // a short gap inside the run: bridge it with its transparent voxels
                                if run.is_some() {
                                    s.voxels.extend((i - pending..i).map(|b| pre.bridge_voxel(stack, b, j, k)));
                                }
                                run.get_or_insert(i);
                                pending = 0;
                                s.voxels.push(v);
                            }
                            None => {
                                if let Some(start) = run {
                                    pending += 1;
                                    if pending > BRIDGE {
                                        let end = i + 1 - pending;
                                        s.push_pair(start - gap, end - start, start, end - 1, j);
                                        (gap, run, pending) = (end, None, 0);
                                    }
                                }
                            }
                        }
                    }
                    if let Some(start) = run {
                        let end = ni - pending;
                        s.push_pair(start - gap, end - start, start, end - 1, j);
                    }
                    s.ends.push((s.runs.len() as u32, s.voxels.len() as u32));
                }
                s
            })
            .collect();
        let total_runs: usize = slices.iter().map(|s| s.runs.len()).sum();
        let total_voxels: usize = slices.iter().map(|s| s.voxels.len()).sum();
        let mut rle = RleVolume {
            axis: stack.axis,
            n: stack.n,
            runs: Vec::with_capacity(total_runs),
            scan_runs: Vec::with_capacity(nj * nk + 1),
            scan_voxels: Vec::with_capacity(nj * nk + 1),
            voxels: Vec::with_capacity(total_voxels),
            extent: Vec::with_capacity(nj * nk),
            bbox: Vec::with_capacity(nk),
        };
        rle.scan_runs.push(0);
        rle.scan_voxels.push(0);
        for s in slices {
            // run and voxel counts fit u32: the volume has at most 2^30 voxels
            let (r0, v0) = (rle.runs.len() as u32, rle.voxels.len() as u32);
            rle.scan_runs.extend(s.ends.iter().map(|e| r0 + e.0));
            rle.scan_voxels.extend(s.ends.iter().map(|e| v0 + e.1));
            rle.runs.extend_from_slice(&s.runs);
            rle.voxels.extend_from_slice(&s.voxels);
            rle.extent.extend_from_slice(&s.extent);
            rle.bbox.push(s.bbox);
        }
        rle
    }

    /// Bytes held by the encoding.
    pub fn bytes(&self) -> usize {
        self.runs.len() * 2
            + (self.scan_runs.len() + self.scan_voxels.len() + self.extent.len()) * 4
            + self.voxels.len() * 4
            + self.bbox.len() * 16
    }

    /// Number of voxels stored: the non-transparent ones and the bridged transparent ones.
    pub fn voxel_count(&self) -> usize {
        self.voxels.len()
    }

    /// Number of bridged transparent voxels stored (see [`BRIDGE`]).
    pub fn bridged_count(&self) -> usize {
        self.voxels.iter().filter(|v| v.normal == BRIDGE_NORMAL).count()
    }

    /// Number of non-transparent runs.
    pub fn run_count(&self) -> usize {
        self.runs.len() / 2
    }

    /// The `(transparent, non-transparent)` run-length pairs of scanline `(j, k)`
    /// (a non-transparent run may contain bridged transparent voxels).
    pub fn scanline_runs(&self, j: usize, k: usize) -> &[u16] {
        let s = j + self.n[1] * k;
        &self.runs[self.scan_runs[s] as usize..self.scan_runs[s + 1] as usize]
    }

    /// Decodes scanline `(j, k)`: its non-transparent voxels with their `i`
    /// (bridged transparent voxels left out).
    pub fn decode_scanline(&self, j: usize, k: usize) -> impl Iterator<Item = (usize, RleVoxel)> + '_ {
        self.stored_scanline(j, k).filter(|(_, v)| v.normal != BRIDGE_NORMAL)
    }

    /// Every voxel stored for scanline `(j, k)` with its `i`, bridged
    /// transparent voxels included.
    pub fn stored_scanline(&self, j: usize, k: usize) -> impl Iterator<Item = (usize, RleVoxel)> + '_ {
        let s = j + self.n[1] * k;
        let vox = &self.voxels[self.scan_voxels[s] as usize..self.scan_voxels[s + 1] as usize];
        let mut pos = 0usize;
        let mut next = 0usize;
        self.scanline_runs(j, k).chunks_exact(2).flat_map(move |pair| {
            let start = pos + pair[0] as usize;
            let len = pair[1] as usize;
            pos = start + len;
            let first = next;
            next += len;
            (0..len).map(move |t| (start + t, vox[first + t]))
        })
    }

    /// Hints the cache to fetch scanline `s`'s voxels near columns `a` and `b`
    /// (assuming one run from its first non-transparent column: exact for solid
    /// objects, a harmless guess otherwise).
    #[inline(always)]
    fn prefetch_scanline(&self, s: usize, a: usize, b: usize) {
        if s + 1 >= self.scan_voxels.len() {
            return;
        }
        let (v0, v1) = (self.scan_voxels[s] as usize, self.scan_voxels[s + 1] as usize);
        if v0 == v1 {
            return;
        }
        let lo = self.extent[s][0] as usize;
        let at = |c: usize| (v0 + c.saturating_sub(lo)).min(v1 - 1);
        prefetch(&self.voxels, at(a));
        prefetch(&self.voxels, at(b));
    }

    /// A run cursor at the start of scanline `s = j + nj·k`.
    #[inline(always)]
    fn cursor(&self, s: usize) -> Cursor<'_> {
        let runs = &self.runs[self.scan_runs[s] as usize..self.scan_runs[s + 1] as usize];
        let vox = &self.voxels[self.scan_voxels[s] as usize..self.scan_voxels[s + 1] as usize];
        Cursor::new(runs, vox)
    }

    /// The rectangle of the intermediate grid this view can write: the union over
    /// slices of the pixels whose cell touches a non-transparent voxel.
    pub fn rect(&self, params: &SliceParams, pad: usize, grid: [usize; 2]) -> Option<Rect> {
        let [ni, nj, _] = self.n;
        if ni < 2 || nj < 2 {
            return None;
        }
        let (mut lo, mut hi) = ([i64::MAX; 2], [i64::MIN; 2]);
        for (k, b) in self.bbox.iter().enumerate() {
            if b[0] > b[1] {
                continue;
            }
            // voxel v touches cells v − 1 and v
            let span = [(b[0], b[1], ni), (b[2], b[3], nj)];
            for (a, &(v0, v1, n)) in span.iter().enumerate() {
                let off = pad as i64 - params.slices[k].floor[a] as i64;
                lo[a] = lo[a].min((v0 as i64 - 1).max(0) + off);
                hi[a] = hi[a].max((v1 as i64).min(n as i64 - 2) + off);
            }
        }
        if lo[0] > hi[0] {
            return None;
        }
        let clamp = |x: i64, a: usize| x.clamp(0, grid[a] as i64 - 1) as usize;
        Some(Rect { p0: clamp(lo[0], 0), p1: clamp(hi[0], 0), q0: clamp(lo[1], 1), q1: clamp(hi[1], 1) })
    }
}

impl SliceRuns {
    /// Appends a pair: `gap` transparent voxels, then `len` non-transparent ones
    /// spanning `i0..=i1` of row `j` (scanlines are at most 2^14 long, so u16 fits).
    fn push_pair(&mut self, gap: usize, len: usize, i0: usize, i1: usize, j: usize) {
        self.runs.push(gap as u16);
        self.runs.push(len as u16);
        // the scanline's extent (pairs come in increasing i)
        if let Some(e) = self.extent.last_mut() {
            e[0] = e[0].min(i0 as u16);
            e[1] = i1 as u16;
        }
        let b = &mut self.bbox;
        b[0] = b[0].min(i0 as u32);
        b[1] = b[1].max(i1 as u32);
        b[2] = b[2].min(j as u32);
        b[3] = b[3].max(j as u32);
    }
}

/// Walks the non-transparent runs of one scanline with a monotone column.
#[derive(Clone, Copy)]
struct Cursor<'a> {
    runs: &'a [u16],
    vox: &'a [RleVoxel],
    /// Next pair to read.
    r: usize,
    /// Current non-transparent run `[s, e)` (`INF` past the last one) ...
    s: u32,
    e: u32,
    /// ... whose voxel at column `x` is `vox[base + x]` (wrapping arithmetic).
    base: u32,
}

impl<'a> Cursor<'a> {
    #[inline(always)]
    fn new(runs: &'a [u16], vox: &'a [RleVoxel]) -> Self {
        let mut c = Cursor { runs, vox, r: 0, s: 0, e: 0, base: 0 };
        c.next_run();
        c
    }

    #[inline(always)]
    fn next_run(&mut self) {
        // the voxel index of the next run's first column is where this run ends
        let v = self.base.wrapping_add(self.e);
        if self.r + 1 < self.runs.len() {
            self.s = self.e + self.runs[self.r] as u32;
            self.e = self.s + self.runs[self.r + 1] as u32;
            self.r += 2;
        } else {
            self.s = INF;
            self.e = INF;
        }
        self.base = v.wrapping_sub(self.s);
    }

    /// Moves to the run containing or following column `x` (`x` never decreases).
    #[inline(always)]
    fn seek(&mut self, x: u32) {
        while self.e <= x {
            self.next_run();
        }
    }

    /// [`Cursor::seek`] to `x` from `x − 1`: runs are never empty and never
    /// adjacent, so at most one step.
    #[inline(always)]
    fn step(&mut self, x: u32) {
        if self.e <= x {
            self.next_run();
        }
    }

    /// First non-transparent column at or after `x` (after `seek(x)`).
    #[inline(always)]
    fn first_from(&self, x: u32) -> u32 {
        self.s.max(x)
    }

    /// The voxel at column `x` (after `seek(x)`), `None` if transparent.
    #[inline(always)]
    fn at(&self, x: u32) -> Option<RleVoxel> {
        if x >= self.s { Some(self.vox[self.base.wrapping_add(x) as usize]) } else { None }
    }
}

/// The per-view lookup tables of the pre-classified paths. Fixed-size arrays
/// indexed with masks, so lookups need no bounds checks.
#[derive(Clone, Debug)]
pub struct ViewTables {
    /// Per class node: opacity-corrected premultiplied colour `[α'r, α'g, α'b, α']`.
    lut: Box<[[f32; 4]; TABLE_NODES]>,
    /// Per normal code (shared with the binary path's table shading).
    shade: ShadeTable,
    lut_key: Option<(u64, u32)>,
}

impl Default for ViewTables {
    fn default() -> Self {
        ViewTables { lut: boxed([0.0; 4]), shade: ShadeTable::default(), lut_key: None }
    }
}

impl ViewTables {
    /// Brings the tables up to date for classification `pre`, sample-spacing
    /// `ratio`, object-space headlight direction `light` and material `shading`;
    /// rebuilds only what changed. Returns true if anything was rebuilt.
    pub fn update(&mut self, pre: &Preclass, ratio: f32, light: [f32; 3], shading: Shading) -> bool {
        let ratio = if ratio.is_finite() && ratio > 0.0 { ratio } else { 1.0 };
        let mut rebuilt = false;
        let lut_key = Some((pre.id, ratio.to_bits()));
        if self.lut_key != lut_key {
            for (i, out) in self.lut.iter_mut().enumerate() {
                let a = pre.alpha[i];
                // α' = 1 − (1 − α)^ratio = 1 − exp(ratio · ln(1 − α))
                let a = if a <= 0.0 || a >= 1.0 || ratio == 1.0 { a.clamp(0.0, 1.0) } else { 1.0 - (ratio * pre.ln_clear[i]).exp() };
                let c = pre.rgb[i];
                *out = [a * c[0], a * c[1], a * c[2], a];
            }
            self.lut_key = lut_key;
            rebuilt = true;
        }
        self.shade.update(light, shading) || rebuilt
    }

    /// Shaded, opacity-corrected, premultiplied colour of a voxel.
    #[inline(always)]
    pub fn voxel(&self, v: RleVoxel) -> [f32; 4] {
        // classes are < TABLE_NODES, a power of two
        let c = self.lut[v.class as usize & (TABLE_NODES - 1)];
        let [d, s] = self.shade.get(v.normal);
        // c·[d, d, d, 1] + α'·[s, s, s, 0]: the alpha lane stays α'
        let (dd, ss) = ([d, d, d, 1.0], [s, s, s, 0.0]);
        let mut out = [0f32; 4];
        for i in 0..4 {
            out[i] = c[i] * dd[i] + c[3] * ss[i];
        }
        out
    }

    /// [`ViewTables::voxel`], transparent black for `None`.
    #[inline(always)]
    fn get(&self, v: Option<RleVoxel>) -> [f32; 4] {
        match v {
            Some(v) => self.voxel(v),
            None => [0.0; 4],
        }
    }
}

/// Weights of the cell's voxels `(ci, cj)`, `(ci + 1, cj)`, `(ci, cj + 1)`,
/// `(ci + 1, cj + 1)`, each repeated over the four channels (so [`blend`] is
/// four plain vector multiply-adds).
type Weights = [[f32; 4]; 4];

#[inline(always)]
fn cell_weights(wi: f32, wj: f32) -> Weights {
    [(1.0 - wi) * (1.0 - wj), wi * (1.0 - wj), (1.0 - wi) * wj, wi * wj].map(|x| [x; 4])
}

/// The bilinear blend of four premultiplied voxels (both paths use exactly this).
#[inline(always)]
fn blend(c00: [f32; 4], c10: [f32; 4], c01: [f32; 4], c11: [f32; 4], w: &Weights) -> [f32; 4] {
    let mut s = [0f32; 4];
    for c in 0..4 {
        s[c] = c00[c] * w[0][c] + c10[c] * w[1][c] + c01[c] * w[2][c] + c11[c] * w[3][c];
    }
    s
}

/// First pixel at or after `x` that is not opaque, compressing the path.
///
/// `links[x] == 0` means pixel `x` is not opaque; otherwise `x + links[x]` is a
/// pixel further on to continue from. The row's last entry is a sentinel that
/// never becomes opaque, so the walk always ends.
#[inline(always)]
fn find(links: &mut [u32], x: usize) -> usize {
    if links[x] == 0 {
        return x;
    }
    let mut y = x;
    while links[y] != 0 {
        y += links[y] as usize;
    }
    // every pixel on the way now points straight at y
    let mut z = x;
    while z != y {
        let next = z + links[z] as usize;
        links[z] = (y - z) as u32;
        z = next;
    }
    y
}

/// Composites slice `k`'s cells between scanlines `bot` (row `cj`) and `top`
/// (row `cj + 1`) into one intermediate row: pixel `x = ci + off` for cell
/// columns `ci` in `[ci_lo, ci_hi]`.
///
/// Alternates two skips: opaque pixels through the links, transparent voxels
/// through the runs. Between them, [`span`] composites the pixels that touch
/// some non-transparent voxel.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn composite_row(
    mut bot: Cursor,
    mut top: Cursor,
    ci_lo: u32,
    ci_hi: u32,
    off: isize,
    w: &Weights,
    t: &ViewTables,
    ert: f32,
    px: &mut [[f32; 4]],
    links: &mut [u32],
) {
    let mut ci = ci_lo;
    loop {
        // skip opaque pixels through the links
        let x = find(links, (ci as isize + off) as usize);
        ci = (x as isize - off) as u32;
        if ci > ci_hi {
            return;
        }
        // skip transparent voxels: pixel ci reads columns ci and ci + 1 of both scanlines
        bot.seek(ci);
        top.seek(ci);
        let nx = bot.first_from(ci).min(top.first_from(ci));
        if nx > ci + 1 {
            if nx == INF || nx - 1 > ci_hi {
                return;
            }
            ci = nx - 1;
            continue;
        }
        ci = span(&mut bot, &mut top, ci, ci_hi, off, w, t, ert, px, links);
        if ci > ci_hi {
            return;
        }
    }
}

/// Composites the span of pixels from `ci` (not opaque, touching a
/// non-transparent voxel) up to the first pixel that is opaque or touches only
/// transparent voxels, or past `ci_hi`; returns where it stopped.
///
/// The span is walked in segments: columns over which both scanlines stay in the
/// same kind of run, so each is a plain loop over one or two voxel slices
/// ([`segment`]). The right column of one pixel is the left column of the next,
/// so each voxel is shaded once per row.
#[allow(clippy::too_many_arguments)]
#[inline(never)] // one small function per span keeps the loops' state in registers
fn span(
    bot: &mut Cursor,
    top: &mut Cursor,
    mut ci: u32,
    ci_hi: u32,
    off: isize,
    w: &Weights,
    t: &ViewTables,
    ert: f32,
    px: &mut [[f32; 4]],
    links: &mut [u32],
) -> u32 {
    let (vb, vt) = (bot.at(ci), top.at(ci));
    let mut left = Left { b: t.get(vb), t: t.get(vt), any: vb.is_some() || vt.is_some() };
    loop {
        let c1 = ci + 1;
        bot.step(c1);
        top.step(c1);
        let (bin, tin) = (c1 >= bot.s, c1 >= top.s);
        // the segment's right columns: [c1, end)
        let end = (if bin { bot.e } else { bot.s }).min(if tin { top.e } else { top.s }).min(ci_hi + 2);
        let n = (end - c1) as usize;
        let x0 = (ci as isize + off) as usize;
        let (p, l) = (&mut px[x0..x0 + n], &mut links[x0..x0 + n]);
        let bv = if bin { &bot.vox[bot.base.wrapping_add(c1) as usize..][..n] } else { &[][..] };
        let tv = if tin { &top.vox[top.base.wrapping_add(c1) as usize..][..n] } else { &[][..] };
        let (want, done) = match (bin, tin) {
            (true, true) => (n, segment::<true, true>(p, l, bv, tv, &mut left, w, t, ert)),
            (true, false) => (n, segment::<true, false>(p, l, bv, &[], &mut left, w, t, ert)),
            (false, true) => (n, segment::<false, true>(p, l, &[], tv, &mut left, w, t, ert)),
            (false, false) => {
                if !left.any {
                    return ci; // all four voxels transparent: back to run skipping
                }
                (1, segment::<false, false>(&mut p[..1], &mut l[..1], &[], &[], &mut left, w, t, ert))
            }
        };
        ci += done as u32;
        if done < want || ci > ci_hi {
            return ci; // an opaque pixel (back to the links), or the end
        }
    }
}

/// The left column of the next pixel: its two voxels' colours, and whether
/// either is non-transparent.
struct Left {
    b: [f32; 4],
    t: [f32; 4],
    any: bool,
}

/// Composites consecutive pixels `px` (their `links`) whose right columns are
/// `bv` / `tv` (bottom / top scanline; `B` / `T` false: transparent, the slice
/// is unused). Stops before the first opaque pixel; returns how many it did.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn segment<const B: bool, const T: bool>(
    px: &mut [[f32; 4]],
    links: &mut [u32],
    bv: &[RleVoxel],
    tv: &[RleVoxel],
    left: &mut Left,
    w: &Weights,
    t: &ViewTables,
    ert: f32,
) -> usize {
    // exact lengths, so the loop below needs no bounds checks
    let n = px.len();
    let links = &mut links[..n];
    let bv = &bv[..if B { n } else { 0 }];
    let tv = &tv[..if T { n } else { 0 }];
    let (mut lb, mut lt) = (left.b, left.t);
    let mut done = n;
    for s in 0..n {
        if links[s] != 0 {
            done = s;
            break;
        }
        let rb = if B { t.voxel(bv[s]) } else { [0.0; 4] };
        let rt = if T { t.voxel(tv[s]) } else { [0.0; 4] };
        let acc = &mut px[s];
        composite_premultiplied(acc, blend(lb, rb, lt, rt, w));
        if !(acc[3] < ert) {
            links[s] = 1;
        }
        (lb, lt) = (rb, rt);
    }
    if done > 0 {
        *left = Left { b: lb, t: lt, any: B || T };
    }
    done
}

/// Clears `rect`'s part of the intermediate rows in `px` / `depth` (row stride `gw`).
fn clear_rows(px: &mut [[f32; 4]], depth: &mut [f32], gw: usize, r: &Rect) {
    for (row, drow) in px.chunks_mut(gw).zip(depth.chunks_mut(gw)) {
        row[r.p0..=r.p1].fill([0.0; 4]);
        drow[r.p0..=r.p1].fill(f32::NAN);
    }
}

/// Slice indices front to back.
fn front_to_back(nk: usize, ascending: bool) -> impl Iterator<Item = usize> {
    (0..nk).map(move |s| if ascending { s } else { nk - 1 - s })
}

/// Composites `rle` into `rect` of the intermediate image (every pixel of `rect`
/// written, transparent where nothing composited; depth NaN) and seals it.
/// `links` is scratch space, sized for the whole grid on first use and reused
/// across frames.
#[allow(clippy::too_many_arguments)]
pub fn render_rle(
    rle: &RleVolume,
    tables: &ViewTables,
    params: &SliceParams,
    pad: usize,
    ascending: bool,
    ert: f32,
    rect: Option<Rect>,
    links: &mut Vec<u32>,
    out: &mut Intermediate,
) {
    out.seal(rect);
    let Some(r) = rect else { return };
    let gw = out.size[0];
    let width = r.p1 - r.p0 + 1;
    let lw = width + 1; // links per row, with the sentinel
    let rows = r.q1 - r.q0 + 1;
    // sized for the whole grid once, so no later rectangle grows it
    let most = out.size[1] * (out.size[0] + 1);
    if links.len() < most {
        links.resize(most, 0);
    }
    let fr = RleFrame { rle, tables, params, pad: pad as isize, ascending, ert, r, gw, lw };
    let px = &mut out.rgba[r.q0 * gw..(r.q1 + 1) * gw];
    let depth = &mut out.depth[r.q0 * gw..(r.q1 + 1) * gw];
    let bands = px.par_chunks_mut(gw * BAND).zip(depth.par_chunks_mut(gw * BAND)).zip(links[..rows * lw].par_chunks_mut(lw * BAND));
    bands.enumerate().for_each(|(b, ((px, depth), links))| fr.band(r.q0 + b * BAND, px, depth, links));
}

/// The per-frame constants of [`render_rle`].
struct RleFrame<'a> {
    rle: &'a RleVolume,
    tables: &'a ViewTables,
    params: &'a SliceParams,
    pad: isize,
    ascending: bool,
    ert: f32,
    /// The rectangle written.
    r: Rect,
    /// Row stride of the intermediate image and of the links.
    gw: usize,
    lw: usize,
}

impl RleFrame<'_> {
    /// Renders the band of intermediate rows from `q_first` (`px`, `depth` and
    /// `links` hold its rows): clears it, then composites every slice front to back.
    #[inline(never)]
    fn band(&self, q_first: usize, px: &mut [[f32; 4]], depth: &mut [f32], links: &mut [u32]) {
        let (r, gw, lw, rle) = (&self.r, self.gw, self.lw, self.rle);
        let [ni, nj, nk] = rle.n;
        clear_rows(px, depth, gw, r);
        links.fill(0);
        // nothing composites when even an empty pixel counts as terminated
        if !(self.ert > 0.0) {
            return;
        }
        let nrows = px.len() / gw;
        for k in front_to_back(nk, self.ascending) {
            let bb = rle.bbox[k];
            if bb[0] > bb[1] {
                continue;
            }
            let sp = self.params.slices[k];
            let w = cell_weights(sp.weight[0], sp.weight[1]);
            // cell column ci lands on pixel ci + op (row-relative: ci + off)
            let op = self.pad - sp.floor[0] as isize;
            let off = op - r.p0 as isize;
            // cells of the rect that touch the slice's non-transparent box
            let ci_lo = (r.p0 as isize - op).max(bb[0] as isize - 1).max(0);
            let ci_hi = (r.p1 as isize - op).min(bb[1] as isize).min(ni as isize - 2);
            if ci_lo > ci_hi {
                continue;
            }
            let fj = sp.floor[1] as isize;
            for row in 0..nrows {
                let cj = (q_first + row) as isize - self.pad + fj;
                if cj < 0 || cj > nj as isize - 2 || cj + 1 < bb[2] as isize || cj > bb[3] as isize {
                    continue;
                }
                let s = cj as usize + nj * k;
                // the pixels that touch the pair's non-transparent columns: from one
                // left of the first to the last (an empty pair gives lo > hi)
                let (eb, et) = (rle.extent[s], rle.extent[s + 1]);
                let lo = (eb[0].min(et[0]) as isize - 1).max(ci_lo);
                let hi = (eb[1].max(et[1]) as isize).min(ci_hi);
                if lo > hi {
                    continue;
                }
                // all of them opaque already: nothing to do
                let lrow = &mut links[row * lw..(row + 1) * lw];
                let first = find(lrow, (lo + off) as usize) as isize - off;
                if first > hi {
                    continue;
                }
                // the next row brings in scanline s + 2: ask for its voxels at the
                // edges this row starts and ends at (silhouettes move slowly)
                rle.prefetch_scanline(s + 2, first as usize, hi as usize);
                let prow = &mut px[row * gw + r.p0..row * gw + r.p1 + 1];
                composite_row(rle.cursor(s), rle.cursor(s + 1), first as u32, hi as u32, off, &w, self.tables, self.ert, prow, lrow);
            }
        }
    }
}

/// The reference for [`render_rle`]: slice by slice, front to back, every voxel
/// of the slice is classified from the densities into `slice_buf` (reused), then
/// every pixel of `rect` whose opacity is below `ert` composites its cell's
/// sample. No runs, no links; same positions, weights and arithmetic.
#[allow(clippy::too_many_arguments)]
pub fn render_brute_preclassified(
    stack: &SliceStack,
    pre: &Preclass,
    tables: &ViewTables,
    params: &SliceParams,
    pad: usize,
    ascending: bool,
    ert: f32,
    rect: Option<Rect>,
    slice_buf: &mut Vec<[f32; 4]>,
    out: &mut Intermediate,
) {
    out.seal(rect);
    let Some(r) = rect else { return };
    let [ni, nj, nk] = stack.n;
    let gw = out.size[0];
    let px = &mut out.rgba[r.q0 * gw..(r.q1 + 1) * gw];
    let depth = &mut out.depth[r.q0 * gw..(r.q1 + 1) * gw];
    px.par_chunks_mut(gw).zip(depth.par_chunks_mut(gw)).for_each(|(p, d)| clear_rows(p, d, gw, &r));
    slice_buf.resize(ni * nj, [0.0; 4]);
    for k in front_to_back(nk, ascending) {
        slice_buf.par_chunks_mut(ni).enumerate().for_each(|(j, row)| {
            for (i, c) in row.iter_mut().enumerate() {
                *c = tables.get(pre.classify_voxel(stack, i, j, k));
            }
        });
        let buf = &slice_buf[..];
        let sp = params.slices[k];
        let w = cell_weights(sp.weight[0], sp.weight[1]);
        let (fi, fj) = (sp.floor[0] as isize, sp.floor[1] as isize);
        px.par_chunks_mut(gw).enumerate().for_each(|(row, prow)| {
            let cj = (r.q0 + row) as isize - pad as isize + fj;
            if cj < 0 || cj > nj as isize - 2 {
                return;
            }
            for (p, acc) in prow.iter_mut().enumerate().take(r.p1 + 1).skip(r.p0) {
                let ci = p as isize - pad as isize + fi;
                if ci < 0 || ci > ni as isize - 2 {
                    continue;
                }
                if !(acc[3] < ert) {
                    continue;
                }
                let b = ci as usize + ni * cj as usize;
                composite_premultiplied(acc, blend(buf[b], buf[b + 1], buf[b + ni], buf[b + ni + 1], &w));
            }
        });
    }
}

/// What a [`RleCache`]'s encodings were built for (chosen by the owner).
pub type ClassKey = u64;

/// A renderer's pre-classified state: the classification, the encodings of the
/// axes views have needed so far, the per-view tables and the scratch buffers.
#[derive(Debug, Default)]
pub struct RleCache {
    key: Option<ClassKey>,
    pre: Option<Preclass>,
    axes: [Option<RleVolume>; 3],
    tables: ViewTables,
    links: Vec<u32>,
    slice_buf: Vec<[f32; 4]>,
}

impl RleCache {
    /// An empty cache.
    pub fn new() -> Self {
        Self::default()
    }

    /// True when the cache holds classification `key`.
    pub fn is_for(&self, key: ClassKey) -> bool {
        self.key == Some(key)
    }

    /// Adopts classification `cls` under `key`, dropping every encoding.
    pub fn reset(&mut self, key: ClassKey, cls: &Classifier, spacing: [f32; 3]) {
        self.key = Some(key);
        self.pre = Some(Preclass::new(cls, spacing));
        self.axes = [None, None, None];
    }

    /// The classification (after [`RleCache::reset`]).
    pub fn preclass(&self) -> Option<&Preclass> {
        self.pre.as_ref()
    }

    /// The encoding of `axis`, if built.
    pub fn axis(&self, axis: usize) -> Option<&RleVolume> {
        self.axes[axis].as_ref()
    }

    /// Encodes `stack`'s axis unless it is already encoded (on the current rayon
    /// pool). Returns true if it encoded; false also when there is no classification.
    pub fn ensure_axis(&mut self, stack: &SliceStack) -> bool {
        let Some(pre) = &self.pre else { return false };
        if self.axes[stack.axis].is_some() {
            return false;
        }
        self.axes[stack.axis] = Some(RleVolume::encode(stack, pre));
        true
    }

    /// Bytes of each axis's encoding (0 where not built).
    pub fn bytes(&self) -> [usize; 3] {
        [0, 1, 2].map(|a| self.axes[a].as_ref().map_or(0, RleVolume::bytes))
    }

    /// Brings the per-view tables up to date (see [`ViewTables::update`]).
    pub fn prepare_view(&mut self, f: &Factorization, ratio: f32, shading: Shading) -> bool {
        match &self.pre {
            Some(pre) => self.tables.update(pre, ratio, headlight_object(f), shading),
            None => false,
        }
    }

    /// The rectangle [`RleCache::render`] writes for view `f` (None if the axis
    /// is not encoded or nothing is visible).
    pub fn rect(&self, f: &Factorization, params: &SliceParams, pad: usize, grid: [usize; 2]) -> Option<Rect> {
        self.axes[f.axis].as_ref()?.rect(params, pad, grid)
    }

    /// Composites view `f` from the encoding of its axis (see [`render_rle`]);
    /// an axis that is not encoded renders transparent.
    pub fn render(&mut self, f: &Factorization, params: &SliceParams, pad: usize, ert: f32, rect: Option<Rect>, out: &mut Intermediate) {
        match &self.axes[f.axis] {
            Some(rle) => render_rle(rle, &self.tables, params, pad, f.ascending, ert, rect, &mut self.links, out),
            None => out.seal(None),
        }
    }

    /// The brute-force pre-classified reference of view `f` over `rect` (see
    /// [`render_brute_preclassified`]).
    #[allow(clippy::too_many_arguments)]
    pub fn render_brute(
        &mut self,
        stack: &SliceStack,
        f: &Factorization,
        params: &SliceParams,
        pad: usize,
        ert: f32,
        rect: Option<Rect>,
        out: &mut Intermediate,
    ) {
        match &self.pre {
            Some(pre) => {
                render_brute_preclassified(stack, pre, &self.tables, params, pad, f.ascending, ert, rect, &mut self.slice_buf, out)
            }
            None => out.seal(None),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn links_compress_paths() {
        let mut links = vec![0u32; 11];
        for x in [2, 3, 4, 5, 7, 8] {
            links[x] = 1;
        }
        assert_eq!(find(&mut links, 0), 0);
        assert_eq!(find(&mut links, 2), 6);
        assert_eq!(links[2], 4);
        assert_eq!(links[3], 3);
        assert_eq!(find(&mut links, 7), 9);
        // 6 becomes opaque: 2 → 6 → 7 → 9
        links[6] = 1;
        assert_eq!(find(&mut links, 2), 9);
        assert_eq!(links[2], 7);
        links[9] = 1;
        assert_eq!(find(&mut links, 0), 0);
        assert_eq!(find(&mut links, 3), 10);
    }

    #[test]
    fn cursor_walks_runs() {
        // columns 2..4 and 7..8 non-transparent
        let runs = [2u16, 2, 3, 1];
        let vox: Vec<RleVoxel> = (0..3).map(|c| RleVoxel { class: c, normal: 0 }).collect();
        let mut c = Cursor::new(&runs, &vox);
        let mut got = vec![];
        for x in 0..10 {
            c.seek(x);
            got.push(c.at(x).map(|v| v.class));
            if x == 4 {
                assert_eq!(c.first_from(x), 7);
            }
        }
        assert_eq!(got, [None, None, Some(0), Some(1), None, None, None, Some(2), None, None]);
        c.seek(50);
        assert_eq!(c.first_from(50), INF);
    }
}
