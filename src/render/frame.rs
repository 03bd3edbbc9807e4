//! A renderer's frame set-up: the projection, the intermediate image's
//! quality, the producer of per-pixel ray limits, the plan reused from frame
//! to frame, and the key of the last frame written (an unchanged frame is
//! skipped).

use std::sync::Arc;

use super::settings::Settings;
use crate::view::plan::{FramePlan, Limiter};
use crate::view::{Camera, PerspectiveView, Projection};

/// The frame set-up of a renderer.
pub(super) struct FrameSetup {
    /// Parallel or perspective.
    pub(super) projection: Projection,
    /// Intermediate pixels per voxel (the adaptive image size; 1 by default).
    pub(super) quality: f64,
    /// The producer of per-pixel ray limits, if any, and a counter bumped when it changes.
    pub(super) limiter: Option<(Arc<dyn Limiter>, u64)>,
    /// The plan of the last frame (its arrays reused by the next).
    pub(super) plan: Option<FramePlan>,
    /// The perspective views of the last frame (a buffer reused).
    pub(super) views: Vec<PerspectiveView>,
    /// The inputs and stamp of the last frame written.
    pub(super) last_frame: Option<(FrameKey, u64)>,
}

impl Default for FrameSetup {
    fn default() -> Self {
        FrameSetup { projection: Projection::Parallel, quality: 1.0, limiter: None, plan: None, views: vec![], last_frame: None }
    }
}

/// Everything a frame depends on besides the volume.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct FrameKey {
    pub(super) camera: Camera,
    pub(super) projection: Projection,
    pub(super) quality: f64,
    pub(super) settings: Settings,
    pub(super) generation: u64,
    pub(super) tissue: Option<usize>,
    pub(super) limiter: Option<u64>,
    pub(super) focus: Option<(u64, usize)>,
}

pub(super) static NEXT_STAMP: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
