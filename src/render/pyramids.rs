//! The split perspective frame: one plan per pyramid of the volume (an eye
//! inside or beside the volume sees it along several principal axes), the
//! pyramids' intermediate iso depths kept for hit lookups, and the output
//! pixels' rays that say which pyramid owns a pixel.

use crate::composite::Intermediate;
use crate::view::perspective::RayDirections;
use crate::view::plan::FramePlan;

/// The pyramids of the last split perspective frame.
#[derive(Default)]
pub(super) struct Pyramids {
    /// The plans of the last split perspective frame, one per pyramid (reused
    /// frame to frame), and how many the frame used.
    pub(super) plans: Vec<FramePlan>,
    pub(super) count: usize,
    /// Whether the last frame was split.
    pub(super) last_split: bool,
    /// Each pyramid's intermediate iso depth of the last split frame (only
    /// `depth`, `size` and `valid` are used; kept when
    /// [`super::Renderer::set_keep_depths`] is on, in iso mode).
    pub(super) depths: Vec<Intermediate>,
    pub(super) keep_depths: bool,
    /// The output pixels' rays of the last split frame.
    pub(super) last_rays: Option<RayDirections>,
}
