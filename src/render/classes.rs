//! What a renderer classifies by: one transfer function and its iso value,
//! or a set of tissue presets sharing one threshold-coded mask, and the
//! focus+context region classified by another tissue ([`Focus`]). A change
//! of classification bumps the generation the per-axis structures are keyed by.

use crate::classify::Classifier;
use crate::classify::presets::Tissue;
use crate::encode::depth::Matcher;
use crate::view::clip::{ClipRegion, Region};
use crate::view::plan::Limiter;

/// The classification state of a renderer.
pub(super) struct Classes {
    /// The single transfer function (when no tissue set is active).
    pub(super) classifier: Classifier,
    pub(super) iso: f32,
    pub(super) tissues: Option<TissueSet>,
    /// Bumped whenever the classification changes (invalidates masks).
    pub(super) generation: u64,
    /// Focus+context: the region, the focus tissue's index in the tissue
    /// set, and a counter bumped when the region changes.
    pub(super) focus: Option<(FocusShape, usize, u64)>,
}

/// Focus+context ([`super::Renderer::set_focus`]): inside `region` (voxel indices,
/// as [`ClipRegion`] takes it) the samples are classified by the tissue
/// preset named `tissue`, outside it by the renderer's current one.
#[derive(Clone, Debug, PartialEq)]
pub struct Focus {
    pub region: Region,
    /// A preset name of the renderer's tissue set (e.g. "bone").
    pub tissue: String,
}

impl Focus {
    /// A focus region classified by tissue preset `tissue`.
    pub fn new(region: Region, tissue: impl Into<String>) -> Self {
        Focus { region, tissue: tissue.into() }
    }
}

/// The region of focus+context: a fixed clip region
/// ([`Renderer::set_focus`]) or a producer of focus intervals set per frame
/// ([`Renderer::set_focus_limiter`], e.g. a convex mesh's
/// [`crate::geometry::MeshClip`] drawn with the frame's camera).
#[derive(Clone)]
pub(super) enum FocusShape {
    Region(ClipRegion),
    Limiter(std::sync::Arc<dyn Limiter>),
}

impl FocusShape {
    pub(super) fn limiter(&self) -> &dyn Limiter {
        match self {
            FocusShape::Region(r) => r,
            FocusShape::Limiter(l) => l.as_ref(),
        }
    }
}

/// Tissue presets sharing one threshold-coded mask.
pub(super) struct TissueSet {
    pub(super) tissues: Vec<Tissue>,
    /// Per tissue: the iso (threshold) classifier and the blend classifier.
    pub(super) iso_cls: Vec<Classifier>,
    pub(super) blend_cls: Vec<Classifier>,
    /// Ascending thresholds; tissue `i` is code `i + 1`.
    pub(super) thresholds: Vec<f32>,
    /// Matcher "code ≥ i + 1" per tissue.
    pub(super) matchers: Vec<Matcher>,
    pub(super) current: usize,
}

/// A new focus region's stamp (part of [`FrameKey`]).
pub(super) fn next_focus_stamp() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}
