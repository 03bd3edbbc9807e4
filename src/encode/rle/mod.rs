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
//!   ([`crate::data::normals::encode_normal`]) of the central-difference gradient
//!   ([`crate::data::slices::SliceStack::gradient_at`]) mapped to object (world) space with the voxel
//!   spacing, up to sign because the headlight shading is two-sided; code
//!   [`crate::data::normals::ZERO_NORMAL`] is a zero gradient, which faces the viewer like
//!   [`crate::classify::shading::headlight_ndl`]'s. Under the cubic
//!   reconstruction ([`crate::render::Settings::reconstruction`]) the gradient is
//!   instead the cubic's B-spline gradient along the volume's z at the voxel
//!   ([`crate::data::normals::cubic_voxel_normal`], read through
//!   [`crate::data::normals::StackNormals`] by the encoder and the brute force
//!   alike), which terraces less on thick slices; the samples stay as below.
//! - [`RleVolume`]: one principal axis's encoding. Every scanline (row `j` of
//!   slice `k`, along `i`) is a list of `(transparent, non-transparent)` run-length
//!   pairs (u16; the transparent run after the last pair is implicit), and only
//!   the voxels of the non-transparent runs are stored. A gap of at most
//!   [`BRIDGE`] transparent voxels between two runs is bridged: stored as
//!   zero-opacity voxels, which shade to exact zeros, so the runs are longer and
//!   the compositing loop changes run less often. Built from a [`crate::data::slices::SliceStack`]
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
//! Shear-Warp Deluxe (Sweeney & Mueller 2002), options I and P, on this path:
//!
//! - **I, intermediate slices** (a producer of plans:
//!   [`FramePlan::set_intermediate`]): between each pair of consecutive
//!   slices one more sample, at the ray's point at depth `k + ½`
//!   ([`FramePlan::mid_map`]: the mean of the two slices' maps, exact for a
//!   straight ray, parallel or perspective), the mean of the two slices'
//!   bilinear blends there (trilinear interpolation). Every sample's opacity
//!   is corrected to half the slice spacing ([`FramePlan::sample_ratio`]:
//!   the tables' own correction at half the ratio, `α_n = 1 − √(1 − α)`,
//!   colour premultiplied with it; the perspective rays' exponents are
//!   ratios of spacings and stay). A pass per slice pair walks the four
//!   scanlines under each row with one set of weights, skipping opaque
//!   pixels through the links and pixels whose eight voxels are all outside
//!   the runs; minified slices' intermediate samples are bilinear (the box
//!   footprint is the slices'). Its cost is measured in the issue: several
//!   times a slice pass, not the paper's third.
//! - **P, post-classification** (a sampler,
//!   [`crate::composite::slices::Sampler`]): the same traversal reads each
//!   stored voxel as `[node, normal]` ([`PostTables`]), blends it with the
//!   same bilinear (trilinear with I) weights (the cell's normals turned to
//!   one side first: a normal code holds a direction up to sign), then classifies the
//!   interpolated node and shades the normalized interpolated normal with the
//!   one shading model. Its encoding ([`RleVolume::encode_post`]) stores a
//!   voxel, transparent or not, whenever one of the 2×2×2 cells around it may
//!   be visible ([`PostVisible`]: any non-transparent node of the cell's node
//!   range widened by one, so rounding in the blend cannot reach a visible
//!   node), so a sample reading a voxel left out (NaN, finished to zero) is
//!   invisible and skipping stays lossless. The visible set is the union of
//!   the renderer's tissue presets of the mode ([`RleCache::reset_post`]), so
//!   a tissue switch re-classifies without re-encoding. Minified slices are
//!   sampled bilinearly (a box average of densities would classify densities
//!   no voxel has).
//!
//! Both options have brute forces in the same reference
//! ([`crate::composite::slices::render_brute_preclassified`] with the plan and
//! sampler), equal to the accelerated images bit for bit with early ray
//! termination off (tests/deluxe_rle.rs).
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

pub use preclass::{BRIDGE, BRIDGE_NORMAL, PostVisible, Preclass, RleVoxel, VoxelSource};
pub use runs::RleVolume;
pub use tables::{PostTables, ViewTables};

use crate::classify::Classifier;
use crate::classify::shade_table::headlight_object;
use crate::classify::shading::Shading;
use crate::view::plan::FramePlan;
use crate::view::plan::Rect;

/// What a [`RleCache`]'s encodings were built for (chosen by the owner).
pub type ClassKey = u64;

/// The slice traversal's scratch space, sized on first use and reused
/// across frames (so a steady frame allocates nothing): the per-pixel skip
/// links, and each band's shaded voxels of its last row's top scanline
/// with the rows that shaded them (the compositor's `render_rle`).
#[derive(Clone, Debug, Default)]
pub struct RleScratch {
    pub(crate) links: Vec<u32>,
    pub(crate) shaded: Vec<[f32; 4]>,
    pub(crate) stamps: Vec<u32>,
}

/// A renderer's pre-classified state: the classification, the encodings of the
/// axes views have needed so far, the per-view tables and the scratch buffers.
#[derive(Debug, Default)]
pub struct RleCache {
    key: Option<ClassKey>,
    pub(crate) pre: Option<Preclass>,
    /// What the encodings were built for: the classification's key
    /// (pre-classified), or the post-classified encoding's own.
    enc_key: Option<ClassKey>,
    /// The post-classified encoding's cells (Deluxe P; None: pre-classified).
    pub(crate) post: Option<PostVisible>,
    pub(crate) axes: [Option<RleVolume>; 3],
    /// Encodings built since the last [`RleCache::reset`] (a transposed axis
    /// builds none).
    encoded: usize,
    pub(crate) tables: ViewTables,
    pub(crate) post_tables: Option<Box<PostTables>>,
    /// Focus+context: the focus's classification (same density range as the
    /// context's, so the same nodes) and its per-view tables
    /// ([`RleCache::set_focus`]).
    pub(crate) focus: Option<Preclass>,
    pub(crate) focus_tables: ViewTables,
    pub(crate) focus_post_tables: Option<Box<PostTables>>,
    pub(crate) scratch: RleScratch,
    pub(crate) slice_buf: Vec<[f32; 4]>,
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
        (self.enc_key, self.post) = (Some(key), None);
        self.axes = [None, None, None];
        self.encoded = 0;
    }

    /// Adopts classification `cls` under `key` for the post-classified
    /// sampler (Deluxe P), its encodings keyed by `enc_key` and keeping every
    /// cell that may be visible under one of `visible` (a renderer's tissue
    /// presets, `cls` among them; all with `cls`'s density range). The
    /// encodings are kept when `enc_key` is the one they were built for (a
    /// switch between the presets re-classifies, it does not re-encode).
    pub fn reset_post(&mut self, key: ClassKey, enc_key: ClassKey, cls: &Classifier, visible: &[&Classifier], spacing: [f32; 3]) {
        self.key = Some(key);
        self.pre = Some(Preclass::new(cls, spacing));
        if self.post.is_none() || self.enc_key != Some(enc_key) {
            (self.enc_key, self.post) = (Some(enc_key), Some(PostVisible::new(visible)));
            self.axes = [None, None, None];
            self.encoded = 0;
        }
        self.post_tables.get_or_insert_with(Default::default);
    }

    /// Focus+context: classifies the samples inside a plan's focus intervals
    /// by `focus` (None: no focus), for a volume with voxel `spacing`. Call it
    /// right after [`RleCache::reset`] / [`RleCache::reset_post`]: a
    /// pre-classified encoding made after it stores every voxel either
    /// classification shows ([`Preclass::keep_visible_under`]), so the owner
    /// must key the pre-classified encodings by the focus as well; the
    /// post-classified encoding keeps the union of its `visible` presets
    /// already, so a focus among them needs no re-encoding.
    pub fn set_focus(&mut self, focus: Option<&Classifier>, spacing: [f32; 3]) {
        self.focus = focus.map(|c| Preclass::new(c, spacing));
        if let (Some(f), Some(pre)) = (focus, &mut self.pre)
            && self.post.is_none()
        {
            pre.keep_visible_under(f);
        }
        if self.focus.is_some() && self.post.is_some() {
            self.focus_post_tables.get_or_insert_with(Default::default);
        }
    }

    /// The focus's classification, if any ([`RleCache::set_focus`]).
    pub fn focus(&self) -> Option<&Preclass> {
        self.focus.as_ref()
    }

    /// True when the encodings are post-classified ones (Deluxe P).
    pub fn is_post(&self) -> bool {
        self.post.is_some()
    }

    /// The classification (after [`RleCache::reset`]).
    pub fn preclass(&self) -> Option<&Preclass> {
        self.pre.as_ref()
    }

    /// The encoding of `axis`, if built.
    pub fn axis(&self, axis: usize) -> Option<&RleVolume> {
        self.axes[axis].as_ref()
    }

    /// True when the encoding of `src`'s axis exists under its permutation
    /// and size (nothing for [`RleCache::ensure_axis`] to build: a frame asks
    /// this before sending a job to the pool).
    pub fn is_current<S: VoxelSource + ?Sized>(&self, src: &S) -> bool {
        let stack = src.slices();
        self.axes[stack.axis].as_ref().is_some_and(|e| e.perm == stack.perm() && e.n == stack.n)
    }

    /// Makes the encoding of `src`'s axis, with its permutation, unless it
    /// is already there (on the current rayon pool): the
    /// [`RleVolume::transposed`] of another axis's encoding whose scanlines are
    /// the same (its permutation with `j` and `k` swapped), else a new
    /// encoding of `src`. An encoding of the axis under another permutation
    /// is replaced. Returns true if it built anything; false also when there
    /// is no classification. (`src` is a [`crate::data::slices::SliceStack`] or the interleaved
    /// slices of a BCC grid; the owner resets the cache when it switches
    /// between them.)
    pub fn ensure_axis<S: VoxelSource + ?Sized>(&mut self, src: &S) -> bool {
        let Some(pre) = &self.pre else { return false };
        if self.is_current(src) {
            return false;
        }
        let stack = src.slices();
        let (axis, perm) = (stack.axis, stack.perm());
        let swapped = [perm[0], perm[2], perm[1]];
        let shared = self.axes.iter().flatten().find(|e| e.perm == swapped && e.n == [stack.n[0], stack.n[2], stack.n[1]]);
        self.axes[axis] = Some(match (shared, &self.post) {
            (Some(e), _) => e.transposed(),
            (None, post) => {
                self.encoded += 1;
                match post {
                    None => RleVolume::encode(src, pre),
                    Some(vis) => RleVolume::encode_post(src, pre, vis),
                }
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
        let light = headlight_object(&plan.view);
        let focus = match (&self.focus, &mut self.focus_post_tables) {
            (Some(f), Some(pt)) if self.post.is_some() => pt.update(f, ratio, light, shading),
            (Some(f), _) => self.focus_tables.update(f, ratio, light, shading),
            (None, _) => false,
        };
        focus
            | match (&self.pre, &mut self.post_tables) {
                (Some(pre), Some(pt)) if self.post.is_some() => pt.update(pre, ratio, headlight_object(&plan.view), shading),
                (Some(pre), _) => self.tables.update(pre, ratio, headlight_object(&plan.view), shading),
                (None, _) => false,
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
}
