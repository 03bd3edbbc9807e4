//! The per-voxel classification both pre-classified paths share ([`Preclass`])
//! and the stored voxel ([`RleVoxel`]: class node and normal code).

use std::sync::atomic::{AtomicU64, Ordering};

use crate::classify::{Classifier, TABLE_NODES};
pub use crate::data::normals::VoxelSource;
use crate::data::slices::SliceStack;

/// Gaps of at most this many transparent voxels between two non-transparent
/// runs of a scanline are stored as explicit transparent voxels ("bridged"):
/// they shade to exact zeros, exactly what skipping them would give, and the
/// longer runs mean fewer run changes in the compositing loop. Measured on
/// brainsmall (VolPack's ramp, 512², one thread): compositing 1.65 ms without
/// bridging, 1.44 / 1.33 / 1.30 ms with gaps up to 3 / 6 / 10, slower again at 32;
/// the encoding grows by about a fifth at 8.
pub const BRIDGE: usize = 8;

/// The normal code that marks a bridged transparent voxel (real codes are below
/// [`crate::data::normals::NORMAL_CODES`]; masked, it indexes a real shade entry, multiplied by zero).
pub const BRIDGE_NORMAL: u16 = u16::MAX;

/// One stored voxel of the encoding (non-transparent, or a bridged transparent one).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[repr(C)]
pub struct RleVoxel {
    /// Classifier table node of the voxel's density: indexes its raw opacity and colour.
    pub class: u16,
    /// Hemi-octahedral code of its object-space gradient direction ([`crate::data::normals::ZERO_NORMAL`] if none):
    /// the [`VoxelSource`]'s normal.
    pub normal: u16,
}

/// Source of [`Preclass`] ids (tables remember which classification they were built for).
static PRECLASS_IDS: AtomicU64 = AtomicU64::new(1);

/// The per-voxel classification shared by the RLE path and its brute-force reference.
#[derive(Clone, Debug)]
pub struct Preclass {
    pub(crate) id: u64,
    cls: Classifier,
    /// Raw opacity of each table node (before the per-view correction).
    pub(crate) alpha: Vec<f32>,
    /// `ln(1 − α)` of each node (−∞ for α = 1), for the per-view correction.
    pub(crate) ln_clear: Vec<f32>,
    /// Colour of each node.
    pub(crate) rgb: Vec<[f32; 3]>,
    /// Whether a voxel of each node is stored (non-transparent here, or in
    /// a focus's classification: [`Preclass::keep_visible_under`]).
    keep: Vec<bool>,
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
            keep: nodes.iter().map(|n| n.a > 0.0).collect(),
            inv_spacing: spacing.map(|s| 1.0 / s),
        }
    }

    /// The classifier this classification quantizes to.
    pub fn classifier(&self) -> &Classifier {
        &self.cls
    }

    /// Focus+context: also stores (classifies as `Some`) the voxels `other`
    /// shows, so one encoding holds every voxel either classification needs;
    /// a voxel transparent here still shades to exact zeros. `other` must have
    /// this classifier's density range (the same nodes).
    pub fn keep_visible_under(&mut self, other: &Classifier) {
        for (i, k) in self.keep.iter_mut().enumerate() {
            *k |= other.raw_node(i).a > 0.0;
        }
    }

    /// Voxel `(i, j, k)` of `stack`, or `None` when it is not stored
    /// (transparent, and under a focus transparent there too).
    #[inline]
    pub fn classify_voxel<S: VoxelSource + ?Sized>(&self, stack: &S, i: usize, j: usize, k: usize) -> Option<RleVoxel> {
        let node = self.cls.nearest_node(stack.slices().at(i, j, k));
        if !self.keep[node] {
            return None;
        }
        Some(RleVoxel { class: node as u16, normal: stack.normal(i, j, k, self.inv_spacing) })
    }

    /// Voxel `(i, j, k)` of `stack` as the post-classified encoding stores it
    /// (Deluxe P): its node and normal code, transparent or not.
    #[inline]
    pub fn post_voxel<S: VoxelSource + ?Sized>(&self, stack: &S, i: usize, j: usize, k: usize) -> RleVoxel {
        RleVoxel { class: self.cls.nearest_node(stack.slices().at(i, j, k)) as u16, normal: stack.normal(i, j, k, self.inv_spacing) }
    }

    /// The class node of voxel `(i, j, k)`.
    #[inline]
    pub(crate) fn node(&self, stack: &SliceStack, i: usize, j: usize, k: usize) -> u16 {
        self.cls.nearest_node(stack.at(i, j, k)) as u16
    }

    /// The stored form of transparent voxel `(i, j, k)` inside a bridged gap:
    /// its own (zero-opacity) class, so it shades to exact zeros, and the
    /// [`BRIDGE_NORMAL`] code.
    #[inline]
    pub(crate) fn bridge_voxel(&self, stack: &SliceStack, i: usize, j: usize, k: usize) -> RleVoxel {
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

/// Which cells the post-classified encoding (Deluxe P) keeps: the union of
/// the non-transparent nodes of a set of classifiers (a renderer's tissue
/// presets, so a switch between them needs no re-encoding), asked per cell
/// by its range of nodes.
#[derive(Clone, Debug)]
pub struct PostVisible {
    /// `prefix[i]`: how many nodes below `i` have non-zero opacity in some classifier.
    prefix: Vec<u32>,
}

impl PostVisible {
    /// The union of `classifiers`' non-transparent nodes (each with the
    /// same node densities: one density range).
    pub fn new(classifiers: &[&Classifier]) -> Self {
        let mut prefix = Vec::with_capacity(TABLE_NODES + 1);
        prefix.push(0);
        for i in 0..TABLE_NODES {
            let on = classifiers.iter().any(|c| c.raw_node(i).a > 0.0);
            prefix.push(prefix[i] + on as u32);
        }
        PostVisible { prefix }
    }

    /// True when a sample interpolated between voxels of nodes `lo ..= hi` may
    /// have non-zero opacity: some node of `lo − 1 ..= hi + 1` is non-transparent
    /// (the node on each side covers an interpolated node that rounding put
    /// just outside `[lo, hi]`; the opacity is linear between nodes).
    #[inline(always)]
    pub fn cell(&self, lo: u16, hi: u16) -> bool {
        let a = (lo as usize).saturating_sub(1);
        let b = (hi as usize + 2).min(TABLE_NODES);
        self.prefix[b] > self.prefix[a]
    }
}
