//! `shearwarp view --benchmark-drag N`: the viewer's own frame rate.
//!
//! Once the first frame is on screen and the preview worker has every principal
//! axis's masks, the window plays a scripted horizontal drag of N frames through
//! the path a mouse drag takes: a press in the view, then one cursor move of
//! [`STEP_DEG`] degrees (`STEP_DEG / --drag-speed` pixels) per frame into
//! [`super::state::State::handle`], the render request to the preview worker,
//! its frame back through the event loop, and the softbuffer present. The next
//! move waits until the previous frame is presented, so no request is coalesced
//! or dropped: N moves are N rendered and N presented frames.
//!
//! [`Bench`] keeps the script's position and the [`Marks`] of each frame; it
//! knows nothing about windows. [`Bench::report`] makes the JSON object printed
//! on stdout, with the field names of `shearwarp rotate --json` where they
//! apply, and the decomposition of each frame's wall time:
//! `queue + worker + deliver + redraw + present = frame`.

use std::time::Instant;

use serde_json::{Value, json};
use shearwarp::render::FrameStats;

use crate::app::median;

/// Degrees of rotation per benchmark frame, about the vertical screen axis.
pub const STEP_DEG: f64 = 1.0;

/// The instants one benchmark frame passes on its way to the screen.
#[derive(Clone, Copy, Debug)]
pub struct Marks {
    /// The cursor move went into the state (and the request to the worker).
    pub requested: Instant,
    /// The worker took the request from its mailbox.
    pub started: Instant,
    /// Wall milliseconds in the worker (render and conversion to `0RGB`).
    pub worker_ms: f64,
    /// The event loop received the frame.
    pub received: Instant,
    /// The present of the frame began (the redraw event arrived).
    pub present_start: Instant,
    /// The present returned.
    pub presented: Instant,
}

/// Wall milliseconds from `a` to `b` (0 when `b` is earlier).
fn ms(a: Instant, b: Instant) -> f64 {
    b.saturating_duration_since(a).as_secs_f64() * 1e3
}

/// One presented benchmark frame: its timings in milliseconds and the
/// renderer's statistics.
#[derive(Clone, Copy, Debug, Default)]
pub struct Sample {
    /// Request to present.
    pub frame_ms: f64,
    /// Request to the worker taking it.
    pub queue_ms: f64,
    pub worker_ms: f64,
    /// The worker's reply to the event loop receiving it.
    pub deliver_ms: f64,
    /// Receiving the frame to the redraw event that presents it.
    pub redraw_ms: f64,
    /// Copy into the framebuffer, overlay, softbuffer present.
    pub present_ms: f64,
    pub stats: FrameStats,
}

impl Sample {
    pub fn new(m: &Marks, stats: FrameStats) -> Self {
        let finished = m.started + std::time::Duration::from_secs_f64(m.worker_ms.max(0.0) / 1e3);
        Sample {
            frame_ms: ms(m.requested, m.presented),
            queue_ms: ms(m.requested, m.started),
            worker_ms: m.worker_ms,
            deliver_ms: ms(finished, m.received),
            redraw_ms: ms(m.received, m.present_start),
            present_ms: ms(m.present_start, m.presented),
            stats,
        }
    }
}

/// What the report says about the run besides the frames.
#[derive(Clone, Debug)]
pub struct Info {
    pub volume: String,
    pub dims: [usize; 3],
    /// The window's (and so the frames') size.
    pub size: [usize; 2],
    pub threads: usize,
    pub method: String,
    /// The iso surface's reconstruction between slices.
    pub reconstruction: &'static str,
    pub tissue: String,
    pub iso: f32,
    pub cell: usize,
    /// Loading (or building) the volume.
    pub load_ms: f64,
    /// Making both workers' renderers (classification, gradients).
    pub setup_ms: f64,
}

/// Where the benchmark is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Phase {
    /// Waiting for the first frame on screen and the preview worker's masks.
    Waiting,
    /// Frame `seq`, requested at `at`, is on its way.
    Pending { seq: u64, at: Instant },
    /// All frames presented.
    Done,
}

/// The scripted drag and its measurements.
#[derive(Clone, Debug)]
pub struct Bench {
    /// Frames to play.
    pub frames: usize,
    /// Cursor pixels per frame.
    pub dx: f64,
    pub phase: Phase,
    /// The virtual cursor.
    pub cursor: (f64, f64),
    /// The first move.
    pub begun: Option<Instant>,
    /// The last frame presented.
    pub ended: Option<Instant>,
    /// Command start to the first frame presented.
    pub first_frame_ms: Option<f64>,
    /// Command start to the first move (the masks of every axis built).
    pub ready_ms: Option<f64>,
    pub samples: Vec<Sample>,
}

impl Bench {
    /// A drag of `frames` frames of [`STEP_DEG`] degrees at `drag_speed` degrees per pixel.
    pub fn new(frames: usize, drag_speed: f64) -> Self {
        Bench {
            frames,
            dx: STEP_DEG / drag_speed,
            phase: Phase::Waiting,
            cursor: (0.0, 0.0),
            begun: None,
            ended: None,
            first_frame_ms: None,
            ready_ms: None,
            samples: Vec::with_capacity(frames),
        }
    }

    /// The cursor position of the next move (advances the script).
    pub fn next_move(&mut self) -> (f64, f64) {
        self.cursor.0 += self.dx;
        self.cursor
    }

    /// Records a presented benchmark frame; returns whether all are done.
    pub fn record(&mut self, s: Sample, presented: Instant) -> bool {
        self.samples.push(s);
        self.ended = Some(presented);
        if self.samples.len() >= self.frames {
            self.phase = Phase::Done;
        }
        self.phase == Phase::Done
    }

    /// Frames presented per wall second, from the first move to the last present.
    pub fn fps(&self) -> f64 {
        match (self.begun, self.ended) {
            (Some(a), Some(b)) if b > a => self.samples.len() as f64 / b.duration_since(a).as_secs_f64(),
            _ => 0.0,
        }
    }

    /// The JSON report.
    pub fn report(&self, info: &Info) -> Value {
        let col = |g: fn(&Sample) -> f64| median(&mut self.samples.iter().map(g).collect::<Vec<_>>()).unwrap_or(0.0);
        let max = |g: fn(&Sample) -> f64| self.samples.iter().map(g).fold(0.0, f64::max);
        let drag_ms = match (self.begun, self.ended) {
            (Some(a), Some(b)) => ms(a, b),
            _ => 0.0,
        };
        let switches = self.samples.windows(2).filter(|w| w[0].stats.axis != w[1].stats.axis).count();
        json!({
            "volume": info.volume, "dims": info.dims, "size": info.size[0], "window": info.size,
            "threads": info.threads, "method": info.method, "reconstruction": info.reconstruction, "mode": "iso", "tissue": info.tissue, "iso": info.iso, "cell": info.cell,
            "frames": self.samples.len(), "step_deg": STEP_DEG, "degrees": self.samples.len() as f64 * STEP_DEG, "drag_px_per_frame": self.dx,
            "fps": self.fps(), "degrees_per_second": self.fps() * STEP_DEG, "drag_ms": drag_ms,
            "frame_ms_median": col(|s| s.frame_ms), "frame_ms_max": max(|s| s.frame_ms),
            "queue_ms_median": col(|s| s.queue_ms), "worker_ms_median": col(|s| s.worker_ms),
            "deliver_ms_median": col(|s| s.deliver_ms), "redraw_ms_median": col(|s| s.redraw_ms),
            "present_ms_median": col(|s| s.present_ms),
            "shear_ms_median": col(|s| s.stats.shear_ms), "render_ms_median": col(|s| s.stats.render_ms),
            "warp_ms_median": col(|s| s.stats.warp_ms), "renderer_ms_median": col(|s| s.stats.frame_ms()),
            "build_ms_max": max(|s| s.stats.build_ms),
            "skipped_frames": self.samples.iter().filter(|s| s.stats.skipped).count(),
            "direct_shears": self.samples.iter().filter(|s| s.stats.shear_direct > 0).count(),
            "axis_switches": switches,
            "load_ms": info.load_ms, "setup_ms": info.setup_ms,
            "first_frame_ms": self.first_frame_ms, "ready_ms": self.ready_ms,
        })
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    #[test]
    fn the_script_moves_one_step_per_frame_and_the_report_adds_up() {
        let mut b = Bench::new(3, 0.5);
        assert_eq!(b.dx, 2.0, "1 degree at 0.5 degrees per pixel");
        b.cursor = (100.0, 50.0);
        assert_eq!(b.next_move(), (102.0, 50.0));
        assert_eq!(b.next_move(), (104.0, 50.0));
        let t0 = Instant::now();
        let at = |m: u64| t0 + Duration::from_millis(m);
        b.begun = Some(t0);
        for i in 0..3u64 {
            let m = Marks {
                requested: at(10 * i),
                started: at(10 * i + 1),
                worker_ms: 5.0,
                received: at(10 * i + 7),
                present_start: at(10 * i + 8),
                presented: at(10 * i + 10),
            };
            let s =
                Sample::new(&m, FrameStats { shear_ms: 1.0, render_ms: 2.0, warp_ms: 1.5, axis: (i / 2) as usize, ..Default::default() });
            let sum = s.queue_ms + s.worker_ms + s.deliver_ms + s.redraw_ms + s.present_ms;
            assert!((s.frame_ms - 10.0).abs() < 1e-9 && (sum - s.frame_ms).abs() < 1e-6, "{s:?}");
            assert_eq!(b.record(s, m.presented), i == 2);
        }
        assert_eq!(b.phase, Phase::Done);
        assert!((b.fps() - 100.0).abs() < 1e-9);
        let info = Info {
            volume: "head".into(),
            dims: [4, 5, 6],
            size: [512, 512],
            threads: 2,
            method: "binary".into(),
            reconstruction: "cubic",
            tissue: "skin".into(),
            iso: -500.0,
            cell: 1,
            load_ms: 1.0,
            setup_ms: 2.0,
        };
        let j = b.report(&info);
        assert_eq!(j["frames"], 3);
        assert_eq!(j["size"], 512);
        assert_eq!(j["mode"], "iso");
        assert_eq!(j["reconstruction"], "cubic");
        assert_eq!(j["axis_switches"], 1);
        assert_eq!(j["skipped_frames"], 0);
        for (k, v) in
            [("fps", 100.0), ("frame_ms_median", 10.0), ("present_ms_median", 2.0), ("render_ms_median", 2.0), ("worker_ms_median", 5.0)]
        {
            assert!((j[k].as_f64().unwrap() - v).abs() < 1e-6, "{k}: {}", j[k]);
        }
    }
}
