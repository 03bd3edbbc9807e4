//! What a renderer classifies by: one transfer function and its iso value,
//! or a set of tissue presets sharing one threshold-coded mask, and the
//! focus+context region classified by another tissue ([`Focus`]). A change
//! of classification bumps the generation the per-axis structures are keyed by.
//! The [`super::Renderer`] methods that set and read them (tissue switches, iso
//! value, transfer function, focus) live here too.

use super::{Lattice, Renderer};

use crate::classify::presets::Tissue;
use crate::classify::{Classifier, TransferFunction};
use crate::composite::Mode;
use crate::encode::depth::Matcher;
use crate::error::{Error, Result};
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

impl Renderer {
    /// The tissue presets (sorted by threshold) and the index of the current one.
    pub fn tissues(&self) -> Option<(&[Tissue], usize)> {
        self.classes.tissues.as_ref().map(|t| (t.tissues.as_slice(), t.current))
    }

    /// Switches to tissue `i` of the set: O(1), no mask rebuild. The frames
    /// after it read the presets' threshold-coded mask (the first one shears
    /// it to the view when the previous preset's own one-bit mask served the
    /// frames before) until [`Renderer::prefetch_axis`] builds the new
    /// preset's own mask.
    pub fn select_tissue(&mut self, i: usize) -> Result<()> {
        let ts = self.classes.tissues.as_mut().ok_or_else(|| Error::value("tissue", "this renderer has no tissue presets"))?;
        if i >= ts.tissues.len() {
            return Err(Error::value("tissue", format!("index {i} (have {})", ts.tissues.len())));
        }
        ts.current = i;
        Ok(())
    }

    /// Selects a tissue by name.
    pub fn select_tissue_named(&mut self, name: &str) -> Result<()> {
        let i = self.classes.tissues.as_ref().and_then(|t| t.tissues.iter().position(|x| x.name == name));
        self.select_tissue(i.ok_or_else(|| Error::value("tissue", format!("'{name}' is not in this renderer's presets")))?)
    }

    /// Replaces the classification by one transfer function (leaves any tissue
    /// set; masks are rebuilt on the next frame).
    pub fn set_transfer_function(&mut self, tf: &TransferFunction) {
        self.classes.classifier = Classifier::new(tf, self.range.0, self.range.1);
        self.classes.iso = tf.lower_threshold().unwrap_or(f32::INFINITY);
        self.classes.tissues = None;
        self.classes.generation += 1;
    }

    /// Sets a custom iso value for the preview (leaves any tissue set; masks are
    /// rebuilt on the next frame).
    pub fn set_iso(&mut self, iso: f32) -> Result<()> {
        if iso.is_nan() {
            return Err(Error::value("iso value", "NaN"));
        }
        if let Some(ts) = self.classes.tissues.take() {
            self.classes.classifier = ts.blend_cls[ts.current].clone();
        }
        self.classes.iso = iso;
        self.classes.generation += 1;
        Ok(())
    }

    /// The iso value of the preview.
    pub fn iso(&self) -> f32 {
        match &self.classes.tissues {
            Some(ts) => ts.thresholds[ts.current],
            None => self.classes.iso,
        }
    }

    /// Name of the current classification (tissue name or "custom").
    pub fn classification_name(&self) -> &str {
        match &self.classes.tissues {
            Some(ts) => ts.tissues[ts.current].name,
            None => "custom",
        }
    }

    /// The classifier the current mode uses.
    pub fn classifier(&self) -> &Classifier {
        match (&self.classes.tissues, self.settings.mode) {
            (Some(ts), Mode::Iso) => &ts.iso_cls[ts.current],
            (Some(ts), Mode::Blend) => &ts.blend_cls[ts.current],
            (None, _) => &self.classes.classifier,
        }
    }

    /// Sets (or, with `None`, removes) focus+context: inside the focus
    /// region every following frame classifies its samples by the focus's
    /// tissue preset, outside it by the current one ([`Renderer::select_tissue`]).
    /// O(1) like a tissue switch: the binary path's walks visit the union of
    /// the two presets' codes of the one threshold-coded mask; the RLE paths'
    /// tables are per-view (a pre-classified encoding holds the voxels either
    /// preset shows, so it is rebuilt when the focus tissue changes, as for a
    /// tissue switch; Deluxe P's keeps every preset's already). Needs a
    /// renderer with tissue presets ([`Renderer::with_tissues`]); the region
    /// is checked as [`ClipRegion::new`] checks it.
    pub fn set_focus(&mut self, focus: Option<Focus>) -> Result<()> {
        let Some(f) = focus else {
            self.classes.focus = None;
            return Ok(());
        };
        let i = self.focus_tissue_index(&f.tissue)?;
        let region = ClipRegion::new(f.region, self.volume.spacing())?;
        // the same region keeps its stamp (a focus tissue switch alone redraws nothing twice)
        let stamp = match &self.classes.focus {
            Some((FocusShape::Region(r), _, s)) if *r == region => *s,
            _ => next_focus_stamp(),
        };
        self.classes.focus = Some((FocusShape::Region(region), i, stamp));
        Ok(())
    }

    /// Focus+context in a region given as a producer of focus intervals
    /// (for example a convex mesh's [`crate::geometry::MeshClip`] keeping its
    /// inside, drawn with each frame's camera and set again per frame): as
    /// [`Renderer::set_focus`], the samples each ray's interval
    /// ([`FramePlan::apply_focus`](crate::view::plan::FramePlan::apply_focus)) holds are classified by tissue preset
    /// `tissue`. The same `Arc` set again keeps the frame's key (nothing is
    /// redrawn for a tissue switch); a limiter that cuts holes (an outside
    /// region) is refused: a focus is one interval per ray.
    pub fn set_focus_limiter(&mut self, limiter: std::sync::Arc<dyn Limiter>, tissue: &str) -> Result<()> {
        let i = self.focus_tissue_index(tissue)?;
        if limiter.holes() > 0 {
            return Err(Error::value("focus", "a focus region is one interval per ray: a limiter keeping an outside is not one"));
        }
        let stamp = match &self.classes.focus {
            Some((FocusShape::Limiter(l), _, s)) if std::sync::Arc::ptr_eq(l, &limiter) => *s,
            _ => next_focus_stamp(),
        };
        self.classes.focus = Some((FocusShape::Limiter(limiter), i, stamp));
        Ok(())
    }

    /// The index of focus tissue `name` in the tissue set (an error without
    /// presets or for a name not among them).
    pub(super) fn focus_tissue_index(&self, name: &str) -> Result<usize> {
        let ts = self.classes.tissues.as_ref().ok_or_else(|| {
            Error::value("focus", "focus+context needs a renderer with tissue presets (not a custom iso value or transfer function)")
        })?;
        ts.tissues.iter().position(|t| t.name == name).ok_or_else(|| {
            let names: Vec<&str> = ts.tissues.iter().map(|t| t.name).collect();
            Error::value("focus tissue", format!("'{name}' is not in this renderer's presets ({})", names.join(", ")))
        })
    }

    /// The focus region and the name of its tissue preset, if any (`None`
    /// too for a focus set by [`Renderer::set_focus_limiter`]).
    pub fn focus(&self) -> Option<Focus> {
        let (FocusShape::Region(r), i, _) = self.classes.focus.as_ref()? else { return None };
        let ts = self.classes.tissues.as_ref()?;
        Some(Focus { region: r.region(), tissue: ts.tissues.get(*i)?.name.to_string() })
    }

    /// The focus tissue's index in the tissue set (when both exist).
    pub(super) fn focus_tissue(&self) -> Option<usize> {
        self.classes.focus.as_ref().filter(|_| self.classes.tissues.is_some()).map(|f| f.1)
    }

    /// The code width of the current classification's mask.
    pub(super) fn code_bits(&self) -> u32 {
        self.classes.tissues.as_ref().and_then(|t| crate::encode::depth::code_width_for(t.thresholds.len())).unwrap_or(1)
    }

    /// The classifier the pre-classified paths encode: the current mode's, with
    /// a custom iso value as a threshold transfer function in the iso colour.
    pub(super) fn preclass_classifier(&self) -> std::borrow::Cow<'_, Classifier> {
        match (&self.classes.tissues, self.settings.mode) {
            (None, Mode::Iso) => {
                let c = self.classes.classifier.classify(self.classes.iso);
                let tf = TransferFunction::threshold(self.classes.iso, [c.r, c.g, c.b]);
                std::borrow::Cow::Owned(Classifier::new(&tf, self.range.0, self.range.1))
            }
            _ => std::borrow::Cow::Borrowed(self.classifier()),
        }
    }

    /// The settings focus+context renders (an error names what it does not).
    pub(super) fn check_focus(&self) -> Result<()> {
        let refuse = |what: &str| Err(Error::value("focus", format!("focus+context is not available with {what}")));
        if self.classes.tissues.is_none() {
            return refuse("a custom iso value or transfer function (it needs the tissue presets)");
        }
        if self.settings.lattice == Lattice::Bcc {
            return refuse("the BCC grid (--grid bcc)");
        }
        Ok(())
    }
}
