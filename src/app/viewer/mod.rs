//! `shearwarp view` — an interactive window over the renderer (cargo feature `viewer`).
//!
//! The viewer is structured as input → state → render → present:
//! - `app` (winit + softbuffer) owns the window and its software framebuffer,
//!   turns window events into [`state::Input`]s, hands render requests to the
//!   workers and presents their frames with the overlay. It blocks on events:
//!   an idle window costs no CPU.
//! - [`state`] holds everything the user changes — camera, tissue or custom iso
//!   value, display mode, super-cell size, the drag in progress, which renders
//!   are pending — and decides what each input changes and which renders to
//!   request. It knows nothing about windows, so it is unit-tested directly.
//! - [`worker`] runs the renders off the UI thread, each worker with its own
//!   [`shearwarp::render::Renderer`]s: the *preview* worker renders iso previews of
//!   the latest request only (drag events coalesce; the renderer's incremental
//!   one-bit shears or a direct shear catch up), the *blend* worker renders the
//!   full alpha-blended frame in the background once the view is still. Mask
//!   rebuilds (a custom iso value, another cell size) run there too, so the
//!   window stays responsive and shows them as progress.
//! - [`bench`] (`--benchmark-drag N`) plays a scripted drag of N frames through
//!   that same path once the first frame is on screen, one frame at a time, and
//!   prints the frame rate and where each frame's time went as JSON.
//! - [`overlay`] draws the statistics, the clickable tissue buttons and the iso
//!   slider into the framebuffer with an embedded 8×8 bitmap font (no system
//!   fonts).
//!
//! The core renderer stays in the library; nothing here changes how a frame is
//! computed.

use std::path::PathBuf;

use clap::Args;

use crate::app::args::{RenderArgs, VolumeArgs};

#[cfg(feature = "viewer")]
mod app;
#[cfg(feature = "viewer")]
pub mod bench;
#[cfg(feature = "viewer")]
pub mod overlay;
#[cfg(feature = "viewer")]
pub mod state;
#[cfg(feature = "viewer")]
pub mod worker;

/// `shearwarp view`.
#[derive(Args, Debug)]
pub struct ViewCmd {
    #[command(flatten)]
    pub volume: VolumeArgs,
    /// Render settings; `--size` is the initial window size, `--mode blend`
    /// starts in the alpha-blended display.
    #[command(flatten)]
    pub render: RenderArgs,
    /// Directory for the PNGs saved with the S key.
    #[arg(long, default_value = ".")]
    pub save_dir: PathBuf,
    /// Degrees of rotation per pixel of mouse drag.
    #[arg(long, default_value_t = 0.5)]
    pub drag_speed: f64,
    /// Log every presented frame, the control layout and state changes to stderr.
    #[arg(long, short)]
    pub verbose: bool,
    /// Measure the window's frame rate: once the first frame is shown, play a
    /// horizontal drag of N frames (1 degree each, one frame presented before the
    /// next move), print one JSON object (fps, frame_ms_median, the time of each
    /// stage) on stdout and exit. N is 1..=100000.
    #[arg(long, value_name = "N")]
    pub benchmark_drag: Option<usize>,
    /// Adaptive intermediate image size: while the view is dragged, the
    /// preview's resolution (0.25–1 pixels per voxel) follows this frame rate
    /// (Schulze et al.: q · sqrt(target / measured), with hysteresis); the frame
    /// on release renders at --quality (at least 1). 1..=1000.
    #[arg(long, value_name = "FPS")]
    pub target_fps: Option<f64>,
}

/// The largest `--benchmark-drag`.
pub const MAX_BENCH_FRAMES: usize = 100_000;

/// Runs `shearwarp view`.
pub fn run(cmd: &ViewCmd) -> anyhow::Result<()> {
    if let Some(n) = cmd.benchmark_drag.filter(|n| !(1..=MAX_BENCH_FRAMES).contains(n)) {
        return Err(anyhow::Error::new(crate::app::Usage(format!("--benchmark-drag must be 1..={MAX_BENCH_FRAMES} frames, got {n}"))));
    }
    if let Some(f) = cmd.target_fps.filter(|f| !(f.is_finite() && (1.0..=1000.0).contains(f))) {
        return Err(anyhow::Error::new(crate::app::Usage(format!("--target-fps must be 1..=1000 frames a second, got {f}"))));
    }
    #[cfg(feature = "viewer")]
    {
        app::run(cmd)
    }
    #[cfg(not(feature = "viewer"))]
    {
        let _ = cmd;
        Err(anyhow::Error::new(crate::app::Usage(
            "this shearwarp was built without the `viewer` feature; rebuild with `cargo build --release --features viewer`".into(),
        )))
    }
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use crate::app::cli::{Cli, Command};

    #[test]
    fn view_takes_the_volume_and_render_options() {
        let cli = Cli::try_parse_from([
            "shearwarp",
            "view",
            "--phantom",
            "sphere",
            "--cell",
            "2",
            "--mode",
            "blend",
            "--save-dir",
            "shots",
            "-v",
        ])
        .expect("parses");
        let Command::View(v) = cli.command else { panic!("not the view command") };
        assert_eq!(v.render.cell, crate::app::args::CellArg::Size(2));
        assert_eq!(v.save_dir, std::path::PathBuf::from("shots"));
        assert!(v.verbose);
        assert_eq!(v.drag_speed, 0.5);
        assert_eq!(v.benchmark_drag, None);
    }

    #[test]
    fn benchmark_drag_counts_are_checked_before_any_window_opens() {
        for n in ["0", "100001"] {
            let cli = Cli::try_parse_from(["shearwarp", "view", "--benchmark-drag", n]).expect("parses");
            let Command::View(v) = cli.command else { panic!("not the view command") };
            let err = super::run(&v).expect_err("out of range");
            assert!(err.chain().any(|e| e.downcast_ref::<crate::app::Usage>().is_some()), "{err:#}");
            assert!(format!("{err:#}").contains("--benchmark-drag must be 1..=100000 frames"), "{err:#}");
        }
        assert!(Cli::try_parse_from(["shearwarp", "view", "--benchmark-drag", "-3"]).is_err());
        assert!(Cli::try_parse_from(["shearwarp", "view", "--benchmark-drag", "ten"]).is_err());
        let cli = Cli::try_parse_from(["shearwarp", "view", "--benchmark-drag", "60"]).expect("parses");
        let Command::View(v) = cli.command else { panic!("not the view command") };
        assert_eq!(v.benchmark_drag, Some(60));
    }

    #[test]
    fn bad_view_options_fail_before_any_window_opens() {
        let err = Cli::try_parse_from(["shearwarp", "view", "--cell", "9"]).expect_err("cell 9 is out of range");
        assert!(err.to_string().contains("must be auto or 1..=8, got '9'"), "{err}");
        let cli = Cli::try_parse_from(["shearwarp", "view", "--ert", "2"]).expect("parses");
        let Command::View(v) = cli.command else { panic!("not the view command") };
        let err = super::run(&v).expect_err("an ert of 2 is out of range");
        assert!(err.chain().any(|e| e.downcast_ref::<crate::app::Usage>().is_some()), "{err:#}");
    }
}
