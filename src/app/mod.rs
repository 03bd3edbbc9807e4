//! The application around the renderer: everything a person runs, nothing a
//! library user needs.
//!
//! - [`args`]: the argument types the commands share (volume, render
//!   settings) and their parsers;
//! - [`cli`]: argument parsing, loading, the `render` / `rotate` / `info` /
//!   `export` commands, reports and image/animation output;
//! - [`bench`]: `shearwarp bench`, the speed-against-error matrix of every
//!   variant against the reference renderer, with tables and plots;
//! - [`peers`]: `shearwarp bench --peers`, VTK run at the benchmark's views
//!   with the shared peer model, its frames read back for the metrics;
//! - [`output`]: output image types, animations, plots and the signal
//!   handler around the library's atomic outputs;
//! - [`scene`]: the meshes and clip regions of the command line, per frame;
//! - [`viewer`] (feature `viewer`): `shearwarp view`, the interactive window.

/// Prints a line to stdout through [`output::print_text`]: a closed pipe
/// (`shearwarp … | head`) ends the program quietly instead of panicking like
/// `println!`, a failed write is an error naming standard output.
macro_rules! say {
    ($($t:tt)*) => {
        crate::app::output::print_text(&format!("{}\n", format_args!($($t)*)))?
    };
}

/// Returns a [`Usage`] error from the current function.
macro_rules! usage {
    ($($t:tt)*) => {
        return Err(anyhow::Error::new($crate::app::Usage(format!($($t)*))))
    };
}

/// What `render --distributed` takes of the command line.
// (read by the MPI build only)
#[cfg_attr(not(feature = "mpi"), allow(dead_code))]
pub struct RenderJob<'a> {
    pub volume: &'a args::VolumeArgs,
    pub render: &'a args::RenderArgs,
    pub output: &'a std::path::Path,
    pub json: bool,
}

/// What `rotate --distributed` takes of the command line.
#[cfg_attr(not(feature = "mpi"), allow(dead_code))]
pub struct RotateJob<'a> {
    pub volume: &'a args::VolumeArgs,
    pub render: &'a args::RenderArgs,
    /// The eye axis turned about (0 = x, 1 = y, 2 = z).
    pub axis: usize,
    pub degrees: f64,
    pub step_deg: &'a str,
    pub frames_dir: Option<&'a std::path::Path>,
    /// `--gif` or `--apng` given (refused).
    pub animation: bool,
    pub json: bool,
    pub cycle_tissues: usize,
}

/// `--distributed` in a build without the feature `mpi`: an error saying how to get it.
#[cfg(not(feature = "mpi"))]
pub mod distributed {
    use anyhow::Result;

    fn unavailable() -> Result<()> {
        usage!(
            "--distributed needs the MPI build: install Open MPI and libclang (Debian: libopenmpi-dev openmpi-bin libclang-dev), \
             build with `cargo build --release --features mpi` and launch with `mpirun -np N shearwarp …`"
        )
    }

    pub fn render(_: &crate::app::RenderJob) -> Result<()> {
        unavailable()
    }

    pub fn rotate(_: &crate::app::RotateJob) -> Result<()> {
        unavailable()
    }

    pub fn bench(_: &crate::app::bench::BenchCmd) -> Result<()> {
        unavailable()
    }
}

pub mod args;
pub mod bench;
pub mod cli;
#[cfg(feature = "mpi")]
pub mod distributed;
pub mod output;
pub mod peers;
pub mod scene;
pub mod viewer;

use std::io::IsTerminal;
use std::sync::OnceLock;
use std::time::Instant;

/// When `main` started (the origin of every report's `first_frame_ms`).
static START: OnceLock<Instant> = OnceLock::new();

/// Marks the process start; the first call wins.
pub fn mark_start() {
    START.get_or_init(Instant::now);
}

/// Milliseconds since [`mark_start`].
pub fn since_start_ms() -> f64 {
    START.get_or_init(Instant::now).elapsed().as_secs_f64() * 1e3
}

/// The memory budget every renderer of this process gets: `--max-memory` when
/// given (set by [`set_budget`] while the volume loads), else the machine's
/// physical memory or the process's address-space limit, whichever is lower
/// (Linux; none elsewhere).
static BUDGET: OnceLock<Option<u64>> = OnceLock::new();

/// Sets the budget (`None`: the default); the first call wins.
pub fn set_budget(b: Option<u64>) {
    BUDGET.get_or_init(|| b.or_else(system_memory));
}

/// The budget for a new renderer.
pub fn budget() -> Option<u64> {
    *BUDGET.get_or_init(system_memory)
}

/// Physical memory (`MemTotal`), capped by `ulimit -v` (`Max address space`).
fn system_memory() -> Option<u64> {
    let total = std::fs::read_to_string("/proc/meminfo").ok().and_then(|s| {
        s.lines().find(|l| l.starts_with("MemTotal:")).and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok()).map(|kb| kb * 1024)
    });
    let limit = std::fs::read_to_string("/proc/self/limits").ok().and_then(|s| {
        s.lines().find(|l| l.starts_with("Max address space")).and_then(|l| l.split_whitespace().nth(3)?.parse::<u64>().ok())
    });
    match (total, limit) {
        (Some(t), Some(l)) => Some(t.min(l)),
        (t, l) => t.or(l),
    }
}

/// Peak resident memory of this process so far (`VmHWM`, Linux), in bytes.
pub fn peak_rss_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let kb: u64 = s.lines().find(|l| l.starts_with("VmHWM:"))?.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// The renderer's memory per structure (bytes; per axis x, y, z where there
/// is one), its total, the budget and the process's peak resident memory.
pub fn memory_json(r: &shearwarp::render::Renderer) -> serde_json::Value {
    let m = r.memory();
    serde_json::json!({
        "volume": m.volume, "stacks": m.stacks, "normals": m.normals, "cell_codes": m.cell_codes, "masks": m.masks,
        "rle": m.rle, "intermediate": m.intermediate, "total": m.total(), "budget": r.memory_budget(),
        "peak_rss_bytes": crate::app::peak_rss_bytes(),
    })
}

/// The median of `v` (sorted in place), `None` for no values: each report
/// says what an empty column shows.
pub fn median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) })
}

/// A problem with the arguments or the input (exit code 2), as opposed to a
/// failure while running (exit code 1).
#[derive(Debug)]
pub struct Usage(pub String);

impl std::fmt::Display for Usage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Usage {}

/// A spinner on stderr while something of unknown length runs (hidden when
/// stderr is not a terminal).
pub fn spinner(msg: &str) -> indicatif::ProgressBar {
    if !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let pb = indicatif::ProgressBar::new_spinner();
    pb.set_message(msg.to_string());
    pb.enable_steady_tick(std::time::Duration::from_millis(100));
    pb
}
