//! What a renderer reports: the timings and work of a frame ([`FrameStats`])
//! and how long each per-axis structure took to build ([`BuildTimes`]).

/// Milliseconds the last build of each structure took, per principal axis
/// (0 where it was never built).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct BuildTimes {
    /// The f32 slice stacks.
    pub stacks: [f64; 3],
    /// The normal codes (with the packed densities on the binary path of 8- and 16-bit scans).
    pub normals: [f64; 3],
    /// The cell codes.
    pub cell_codes: [f64; 3],
    /// Packing and first shear of the masks.
    pub masks: [f64; 3],
    /// The run-length encodings.
    pub rle: [f64; 3],
}

/// Timings and work of one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct FrameStats {
    /// Building stacks/masks for a newly needed axis (0 when cached).
    pub build_ms: f64,
    pub shear_ms: f64,
    pub render_ms: f64,
    pub warp_ms: f64,
    /// Principal axis of the view.
    pub axis: usize,
    /// One-step shears, direct shears and words touched by the shear.
    pub shear_steps: u32,
    pub shear_direct: u32,
    pub shear_words: u64,
    /// Rays cast (pixels of the valid rectangle of the intermediate image).
    pub rays: u64,
    /// True when the binary frame took a lean iso path
    /// ([`crate::composite::lean`], or [`crate::composite::lean_cubic`]
    /// under the cubic reconstruction; every plan of the frame did).
    pub lean: bool,
    /// True when the binary frame read the current tissue preset's own
    /// one-bit mask rather than the presets' threshold-coded one (the same
    /// image; see [`crate::render::Renderer::prefetch_axis`]).
    pub preset_mask: bool,
    /// True when nothing changed since this renderer last wrote the same image,
    /// so nothing was rendered.
    pub skipped: bool,
}

impl FrameStats {
    /// Shear + render + warp (the per-frame cost once masks exist).
    pub fn frame_ms(&self) -> f64 {
        self.shear_ms + self.render_ms + self.warp_ms
    }
}
