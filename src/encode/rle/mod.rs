//! The run-length-encoded, pre-classified volume (Lacroute's shear-warp).
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
//!   re-encodes. Two axes may share one encoding (Sweeney & Mueller's re-use
//!   of RLE runs, §3.1): when the RLE paths read z through the mirrored
//!   permutation (y, x, z) ([`crate::view::reuse_permutation`]), its scanlines
//!   run along y like x's (y, z, x), and the second of the two to be needed is the
//!   first's [`RleVolume::transposed`]: a pointer table over the same runs and
//!   voxels, nothing encoded.
//! - [`ViewTables`]: the per-view lookup tables: the opacity-corrected,
//!   premultiplied colour of every class node (`α' = 1 − (1 − α)^ratio`, rebuilt
//!   when the ratio changes — VolPack's opacity-correction table) and the shade
//!   table `[ambient + diffuse·|n·l|, specular·|n·l|^shininess]` of every normal
//!   code for the headlight (rebuilt when the view direction or the material
//!   changes). A voxel's shaded, premultiplied colour is
//!   `[α'r·d + α'·s, α'g·d + α'·s, α'b·d + α'·s, α']`.
//! - The compositing (the slice traversal, [`crate::composite::slices`]): slice by slice, front to back, into the
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
//! - Its reference ([`crate::composite::slices::render_brute_preclassified`]): the same samples at the same
//!   positions, classifying every voxel of every slice from the densities, with no
//!   runs and no links. Skipping (and bridging) adds nothing but exact zeros
//!   (for non-negative shading coefficients), so the two images are equal bit
//!   for bit; the tests assert that with early termination off and allow 1e-5
//!   otherwise.
//!
//! The sample geometry is the frame plan's ([`crate::view::plan::FramePlan`]):
//! intermediate pixel `(p, q)` samples cell `(p − pad + floor_i[k], q − pad +
//! floor_j[k])` of slice `k` with in-cell weights `(weight_i[k], weight_j[k])`,
//! over the plan's slice range and, where it has them, each pixel's ray limits.
//! The sample is the bilinear blend of the four voxels' premultiplied colours,
//! composited "over" ([`crate::composite::composite_premultiplied`]).
//!
//! Files: [`preclass`] (the classification per voxel), [`runs`] (the encoding
//! and its run cursors), [`tables`] (the per-view tables), and here the
//! [`RleCache`] a renderer keeps.

pub mod preclass;
pub mod runs;
pub mod tables;

pub use preclass::{BRIDGE, BRIDGE_NORMAL, Preclass, RleVoxel};
pub use runs::RleVolume;
pub use tables::ViewTables;

use crate::classify::Classifier;
use crate::classify::shading::Shading;
use crate::composite::Intermediate;
use crate::composite::Rect;
use crate::composite::slices::{render_brute_preclassified, render_rle};
pub use crate::data::normals::{NORMAL_CODES, NORMAL_SIDE, ZERO_NORMAL, decode_normal, encode_normal, headlight_object};
use crate::data::slices::SliceStack;
use crate::view::plan::FramePlan;

/// What a [`RleCache`]'s encodings were built for (chosen by the owner).
pub type ClassKey = u64;

/// A renderer's pre-classified state: the classification, the encodings of the
/// axes views have needed so far, the per-view tables and the scratch buffers.
#[derive(Debug, Default)]
pub struct RleCache {
    key: Option<ClassKey>,
    pre: Option<Preclass>,
    axes: [Option<RleVolume>; 3],
    /// Encodings built since the last [`RleCache::reset`] (a transposed axis
    /// builds none).
    encoded: usize,
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
        self.encoded = 0;
    }

    /// The classification (after [`RleCache::reset`]).
    pub fn preclass(&self) -> Option<&Preclass> {
        self.pre.as_ref()
    }

    /// The encoding of `axis`, if built.
    pub fn axis(&self, axis: usize) -> Option<&RleVolume> {
        self.axes[axis].as_ref()
    }

    /// Makes the encoding of `stack`'s axis, with `stack`'s permutation,
    /// unless it is already there (on the current rayon pool): the
    /// [`RleVolume::transposed`] of another axis's encoding whose scanlines are
    /// the same (its permutation with `j` and `k` swapped), else a new
    /// encoding of `stack`. An encoding of the axis under another permutation
    /// is replaced. Returns true if it built anything; false also when there
    /// is no classification.
    pub fn ensure_axis(&mut self, stack: &SliceStack) -> bool {
        let Some(pre) = &self.pre else { return false };
        let (axis, perm) = (stack.axis, stack.perm());
        if self.axes[axis].as_ref().is_some_and(|e| e.perm == perm && e.n == stack.n) {
            return false;
        }
        let swapped = [perm[0], perm[2], perm[1]];
        let shared = self.axes.iter().flatten().find(|e| e.perm == swapped && e.n == [stack.n[0], stack.n[2], stack.n[1]]);
        self.axes[axis] = Some(match shared {
            Some(e) => e.transposed(),
            None => {
                self.encoded += 1;
                RleVolume::encode(stack, pre)
            }
        });
        true
    }

    /// Encodings built since the classification was adopted (an axis that
    /// re-uses another's scanlines counts none).
    pub fn encodings_built(&self) -> usize {
        self.encoded
    }

    /// Frees the encoding of principal axis `axis` (rebuilt when a view needs it).
    pub fn drop_axis(&mut self, axis: usize) {
        if let Some(a) = self.axes.get_mut(axis) {
            *a = None;
        }
    }

    /// Bytes of each axis's encoding (0 where not built). Runs and voxels two
    /// axes share count once, at the first of them: the sum is what is held.
    pub fn bytes(&self) -> [usize; 3] {
        [0, 1, 2].map(|a| {
            self.axes[a].as_ref().map_or(0, |e| {
                let counted = self.axes[..a].iter().flatten().any(|o| o.shares_scanlines(e));
                e.table_bytes() + if counted { 0 } else { e.shared_bytes() }
            })
        })
    }

    /// Brings the per-view tables up to date (see [`ViewTables::update`]).
    pub fn prepare_view(&mut self, plan: &FramePlan, ratio: f32, shading: Shading) -> bool {
        match &self.pre {
            Some(pre) => self.tables.update(pre, ratio, headlight_object(&plan.view), shading),
            None => false,
        }
    }

    /// The rectangle [`RleCache::render`] writes for view `f` (None if the axis
    /// is not encoded under the plan's permutation, or nothing is visible).
    pub fn rect(&self, plan: &FramePlan) -> Option<Rect> {
        self.axis_for(plan)?.rect(plan)
    }

    /// The encoding view `plan` reads: its axis's, if built under the plan's permutation.
    pub fn axis_for(&self, plan: &FramePlan) -> Option<&RleVolume> {
        self.axes[plan.view.axis].as_ref().filter(|e| e.perm == plan.view.perm)
    }

    /// Composites view `f` from the encoding of its axis (see [`render_rle`]);
    /// an axis that is not encoded (under the plan's permutation) renders transparent.
    pub fn render(&mut self, plan: &FramePlan, ert: f32, rect: Option<Rect>, out: &mut Intermediate) {
        match self.axes[plan.view.axis].as_ref().filter(|e| e.perm == plan.view.perm) {
            Some(rle) => render_rle(rle, &self.tables, plan, ert, rect, &mut self.links, out),
            None => out.seal(None),
        }
    }

    /// The brute-force pre-classified reference of view `f` over `rect` (see
    /// [`render_brute_preclassified`]).
    pub fn render_brute(&mut self, stack: &SliceStack, plan: &FramePlan, ert: f32, rect: Option<Rect>, out: &mut Intermediate) {
        match &self.pre {
            Some(pre) => render_brute_preclassified(stack, pre, &self.tables, plan, ert, rect, &mut self.slice_buf, out),
            None => out.seal(None),
        }
    }
}
