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
//!   ([`crate::data::slices::SliceStack::gradient_at`]) mapped to object (world) space with the voxel
//!   spacing, up to sign because the headlight shading is two-sided; code
//!   [`ZERO_NORMAL`] is a zero gradient, which faces the viewer like
//!   [`crate::classify::shading::headlight_ndl`]'s.
//! - [`RleVolume`]: one principal axis's encoding. Every scanline (row `j` of
//!   slice `k`, along `i`) is a list of `(transparent, non-transparent)` run-length
//!   pairs (u16; the transparent run after the last pair is implicit), and only
//!   the voxels of the non-transparent runs are stored. A gap of at most
//!   [`BRIDGE`] transparent voxels between two runs is bridged: stored as
//!   zero-opacity voxels, which shade to exact zeros, so the runs are longer and
//!   the compositing loop changes run less often. Built from a [`crate::data::slices::SliceStack`]
//!   when a view first needs the axis; a new transfer function or tissue
//!   re-encodes.
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

pub use preclass::{BRIDGE, BRIDGE_NORMAL, Preclass, RleVoxel, VoxelSource};
pub use runs::RleVolume;
pub use tables::ViewTables;

use crate::classify::Classifier;
use crate::classify::shading::Shading;
use crate::composite::Intermediate;
use crate::composite::Rect;
use crate::composite::slices::{render_brute_preclassified, render_rle};
pub use crate::data::normals::{NORMAL_CODES, NORMAL_SIDE, ZERO_NORMAL, decode_normal, encode_normal, headlight_object};
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
    /// (`stack` is a [`crate::data::slices::SliceStack`] or the interleaved slices of a BCC grid;
    /// the owner resets the cache when it switches between them.)
    pub fn ensure_axis<S: VoxelSource + ?Sized>(&mut self, stack: &S) -> bool {
        let Some(pre) = &self.pre else { return false };
        let axis = stack.slices().axis;
        if self.axes[axis].is_some() {
            return false;
        }
        self.axes[axis] = Some(RleVolume::encode(stack, pre));
        true
    }

    /// Frees the encoding of principal axis `axis` (rebuilt when a view needs it).
    pub fn drop_axis(&mut self, axis: usize) {
        if let Some(a) = self.axes.get_mut(axis) {
            *a = None;
        }
    }

    /// Bytes of each axis's encoding (0 where not built).
    pub fn bytes(&self) -> [usize; 3] {
        [0, 1, 2].map(|a| self.axes[a].as_ref().map_or(0, RleVolume::bytes))
    }

    /// Brings the per-view tables up to date (see [`ViewTables::update`]).
    pub fn prepare_view(&mut self, plan: &FramePlan, ratio: f32, shading: Shading) -> bool {
        match &self.pre {
            Some(pre) => self.tables.update(pre, ratio, headlight_object(&plan.view), shading),
            None => false,
        }
    }

    /// The rectangle [`RleCache::render`] writes for view `f` (None if the axis
    /// is not encoded or nothing is visible).
    pub fn rect(&self, plan: &FramePlan) -> Option<Rect> {
        self.axes[plan.view.axis].as_ref()?.rect(plan)
    }

    /// Composites view `f` from the encoding of its axis (see [`render_rle`]);
    /// an axis that is not encoded renders transparent.
    pub fn render(&mut self, plan: &FramePlan, ert: f32, rect: Option<Rect>, out: &mut Intermediate) {
        match &self.axes[plan.view.axis] {
            Some(rle) => render_rle(rle, &self.tables, plan, ert, rect, &mut self.links, out),
            None => out.seal(None),
        }
    }

    /// The brute-force pre-classified reference of view `f` over `rect` (see
    /// [`render_brute_preclassified`]).
    pub fn render_brute<S: VoxelSource + ?Sized>(
        &mut self,
        stack: &S,
        plan: &FramePlan,
        ert: f32,
        rect: Option<Rect>,
        out: &mut Intermediate,
    ) {
        match &self.pre {
            Some(pre) => render_brute_preclassified(stack, pre, &self.tables, plan, ert, rect, &mut self.slice_buf, out),
            None => out.seal(None),
        }
    }
}
