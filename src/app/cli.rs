//! The command-line interface (`shearwarp render | rotate`).
//!
//! Owns argument parsing (clap), turning arguments into a volume, a transfer
//! function, a camera and render settings, the frame loop of `rotate`, the
//! reports (readable or `--json`), and writing PNG / GIF / APNG output. Every
//! error reaches the user as one line naming the problem, with exit code 2 for
//! bad usage or input and 1 for failures while running.

use std::io::IsTerminal;
use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand, ValueEnum};

use shearwarp::classify::presets;
use shearwarp::data::io;
use shearwarp::data::volume::Volume;
use shearwarp::kernels;
use shearwarp::render::{FrameStats, Renderer, Settings, estimate_axis};
use shearwarp::view::{Camera, Projection, one_bit_step_deg, rotate_eye};
use shearwarp::warp::Image;

use crate::app::args::{RenderArgs, VolumeArgs, parse_dims, parse_window, renderable};
use crate::app::{Usage, spinner};

const AXES: [&str; 3] = ["x", "y", "z"];

const EXAMPLES: &str = "\
Examples:
  shearwarp render -o head.png                         # built-in CT head, skin iso-surface
  shearwarp render --tissue bone --rotate 0,30,0 -o bone.png
  shearwarp render --mode blend --tissue soft -o soft.png
  shearwarp rotate --degrees 360 --json                # benchmark a full turn
  shearwarp rotate --degrees 90 --gif turn.gif
  shearwarp rotate --cell 2 --cycle-tissues 30 --json  # super cells, switch tissues every 30 frames
  shearwarp info --phantom head                        # size, range, histogram, thresholds
  shearwarp render scan.nrrd --tissue bone -o bone.png  # NRRD, NIfTI, DICOM directory, .den, raw
  shearwarp info brain.nii.gz                          # dims, spacing, histogram, thresholds
  shearwarp render --perspective 40 --eye-distance 1.5 -o persp.png   # perspective
  shearwarp view                                       # interactive window: drag to rotate, keys 1-4 tissues
  shearwarp render --phantom ellipsoid --phantom-spacing 0.6,0.6,5 --iso 100 -o thick.png  # analytic shape, thick slices
  shearwarp bench --suite surfaces --size 512 --threads 1  # depth and normal error against the analytic surfaces
  shearwarp render --raw ct.raw --dims 512,512,48 --type i16 --spacing 0.57,0.57,5 -o ct.png";

/// Fast CPU volume rendering with the binary shear-warp fast rotator.
#[derive(Parser, Debug)]
#[command(name = "shearwarp", version, about, after_help = EXAMPLES)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

/// Subcommands.
#[derive(Subcommand, Debug)]
pub enum Command {
    /// Render one view to a PNG.
    #[command(after_help = EXAMPLES)]
    Render(RenderCmd),
    /// Rotate about an axis with the incremental shear, timing every frame.
    #[command(after_help = EXAMPLES)]
    Rotate(RotateCmd),
    /// Describe a volume: size, type, spacing, value range, histogram, suggested thresholds.
    #[command(after_help = EXAMPLES)]
    Info(InfoCmd),
    /// Benchmark every render variant: median frame time against error versus a reference renderer.
    Bench(crate::app::bench::BenchCmd),
    /// Interactive window: drag to rotate, 1-4 tissues, [ ] iso, +/- cell, Space blend, R reset, S save, Q quit.
    #[command(after_help = EXAMPLES)]
    View(crate::app::viewer::ViewCmd),
    /// Write the volume as an 8-bit VolPack .den file (windowed, optionally resampled): the common input of side-by-side comparisons.
    Export(ExportCmd),
}

/// `shearwarp render`.
#[derive(Args, Debug)]
pub struct RenderCmd {
    #[command(flatten)]
    pub volume: VolumeArgs,
    #[command(flatten)]
    pub render: RenderArgs,
    /// Output image: .png, .gif or .apng (by the extension); `-` writes a
    /// PNG to standard output.
    #[arg(long, short, default_value = "shearwarp.png")]
    pub output: PathBuf,
    /// Print the frame's statistics as JSON.
    #[arg(long)]
    pub json: bool,
    /// How the still frame samples where the output magnifies the
    /// intermediate image (zoom, the eye near the volume).
    #[arg(long, value_enum, default_value = "matched")]
    pub sampling: StillSampling,
    /// Render one volume split over the ranks of an MPI job (launch with
    /// `mpirun -np N`; needs the build with feature `mpi`): each rank reads
    /// and renders its own brick, rank 0 composites and writes. Parallel
    /// projection; a still samples one ray per voxel (as `--sampling voxel`).
    #[arg(long)]
    pub distributed: bool,
}

/// The sampling of a still frame.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum StillSampling {
    /// As many rays per voxel as the output magnifies, along each axis
    /// (Deluxe M): no intermediate pixel is drawn wider than an output pixel,
    /// so a zoomed or close-up surface shows no steps. Where the output does
    /// not magnify, the same frame as `voxel`.
    Matched,
    /// One ray per voxel (or per --quality), as a rotation frame: faster,
    /// steps where the output magnifies.
    Voxel,
}

/// Eye axes to rotate about.
#[derive(ValueEnum, Clone, Copy, Debug)]
pub enum AxisArg {
    /// Horizontal screen axis.
    X,
    /// Vertical screen axis.
    Y,
    /// Viewing axis.
    Z,
}

/// `shearwarp rotate`.
#[derive(Args, Debug)]
pub struct RotateCmd {
    #[command(flatten)]
    pub volume: VolumeArgs,
    #[command(flatten)]
    pub render: RenderArgs,
    /// Eye axis to rotate about.
    #[arg(long, value_enum, default_value = "y")]
    pub axis: AxisArg,
    /// Total rotation in degrees.
    #[arg(long, default_value_t = 360.0)]
    pub degrees: f64,
    /// Degrees per frame, or "auto": the angle that moves the outermost slice by
    /// one voxel (one bit of the mask) per frame.
    #[arg(long, default_value = "auto")]
    pub step_deg: String,
    /// Write every frame as PNG into this directory.
    #[arg(long)]
    pub frames_dir: Option<PathBuf>,
    /// Write an animated GIF.
    #[arg(long)]
    pub gif: Option<PathBuf>,
    /// Write an animated PNG.
    #[arg(long)]
    pub apng: Option<PathBuf>,
    /// How the frames written to --gif, --apng and --frames-dir sample where
    /// the output magnifies (`matched`: each written frame is rendered again
    /// as a still, after the timed frame and outside its time, as `render`
    /// samples; `voxel`: the timed frame itself; a distributed rotation
    /// writes its timed frames).
    #[arg(long, value_enum, default_value = "matched")]
    pub sampling: StillSampling,
    /// Print one JSON object with the timing summary.
    #[arg(long)]
    pub json: bool,
    /// Switch to the next tissue preset every N frames (0 = never).
    #[arg(long, default_value_t = 0)]
    pub cycle_tissues: usize,
    /// Render one volume split over the ranks of an MPI job (launch with
    /// `mpirun -np N`; needs the build with feature `mpi`): each rank reads
    /// and renders its own brick, rank 0 composites and writes. Parallel
    /// projection; rank 0 times the frames and writes `--frames-dir` (not
    /// `--gif` or `--apng`).
    #[arg(long)]
    pub distributed: bool,
}

/// `shearwarp info`.
#[derive(Args, Debug)]
pub struct InfoCmd {
    #[command(flatten)]
    pub volume: VolumeArgs,
    /// Histogram bins to print.
    #[arg(long, default_value_t = 16)]
    pub bins: usize,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// `shearwarp export`.
#[derive(Args, Debug)]
pub struct ExportCmd {
    #[command(flatten)]
    pub volume: VolumeArgs,
    /// Output .den file.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Density window LO,HI mapped onto 0..=255 (clamped); default: the value range.
    #[arg(long, value_parser = parse_window, allow_hyphen_values = true)]
    pub window: Option<[f32; 2]>,
    /// Resample (trilinear) to X,Y,Z voxels over the same physical box.
    #[arg(long, value_parser = parse_dims, conflicts_with = "max_dim")]
    pub out_dims: Option<[usize; 3]>,
    /// Resample (trilinear) to cubic voxels, the longest physical edge N voxels long
    /// (VolPack has no voxel spacing, so anisotropic scans need this to keep their shape).
    #[arg(long)]
    pub max_dim: Option<usize>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

fn progress(len: u64, quiet: bool, msg: &str) -> indicatif::ProgressBar {
    if quiet || !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let pb = indicatif::ProgressBar::new(len);
    pb.set_style(
        indicatif::ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} {per_sec} eta {eta}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    pb.set_message(msg.to_string());
    pb
}

/// [`crate::app::median`]; 0 for no values (e.g. no tissue switches in `rotate --json`).
fn median(v: &mut [f64]) -> f64 {
    crate::app::median(v).unwrap_or(0.0)
}

/// Milliseconds of the last build of each structure, per axis x, y, z.
fn build_json(r: &Renderer) -> serde_json::Value {
    serde_json::to_value(r.build_times()).unwrap_or_default()
}

/// Builds what the first view of `cam` needs, with a spinner on a terminal
/// (a clinical-size scan takes about a second). Returns the milliseconds.
fn prepare_first(r: &mut Renderer, cam: &Camera) -> Result<f64> {
    let axis = shearwarp::view::Factorization::new(cam, r.dims(), r.spacing())?.axis;
    let sp = spinner(&format!("building what a view along {} needs", AXES[axis]));
    let ms = r.prepare_axis(axis)?;
    sp.finish_and_clear();
    Ok(ms)
}

/// The projection as JSON: `"parallel"`, or the field of view and eye distance.
fn projection_json(p: Projection) -> serde_json::Value {
    match p {
        Projection::Parallel => serde_json::json!("parallel"),
        Projection::Perspective { fov_deg, eye_distance } => serde_json::json!({"fov_deg": fov_deg, "eye_distance": eye_distance}),
    }
}

/// The code width of a mask for `tissues` presets.
fn code_bits(tissues: usize) -> u32 {
    shearwarp::encode::depth::code_width_for(tissues.max(1)).unwrap_or(4)
}

/// What the binary iso preview (default settings, the volume's presets) would
/// hold along each principal axis, predicted without building anything.
fn memory_estimate(vol: &Volume, tissues: usize) -> serde_json::Value {
    let per: Vec<serde_json::Value> = (0..3)
        .map(|a| {
            let m = estimate_axis(vol, &Settings::default(), code_bits(tissues), a);
            serde_json::json!({
                "axis": AXES[a], "volume": m.volume, "stack": m.stacks[a], "normals": m.normals[a], "cell_codes": m.cell_codes[a],
                "mask": m.masks[a], "intermediate": m.intermediate, "total": m.total(),
            })
        })
        .collect();
    serde_json::json!({
        "volume": vol.bytes(), "binary_iso_per_axis": per,
        "budget": crate::app::budget(),
    })
}

/// Runs `shearwarp render`.
pub fn run_render(cmd: &RenderCmd) -> Result<()> {
    if cmd.distributed {
        let job = crate::app::RenderJob { volume: &cmd.volume, render: &cmd.render, output: &cmd.output, json: cmd.json };
        return crate::app::distributed::render(&job);
    }
    let kind = match crate::app::output::image_kind(&cmd.output) {
        Ok(k) => k,
        Err(why) => usage!("-o {why}"),
    };
    if cmd.json && cmd.output.as_os_str() == "-" {
        usage!("-o - and --json both write to standard output; give the image a file");
    }
    let (vol, name) = cmd.volume.load()?;
    renderable(&name, &vol)?;
    let load_ms = crate::app::since_start_ms();
    let (dims, spacing) = (vol.dims(), vol.spacing());
    let cam = cmd.render.camera(vol.frame())?;
    let (mut r, scene) = cmd.render.renderer_and_scene(vol)?;
    if cmd.sampling == StillSampling::Matched {
        r.set_settings(matched(r.settings()))?;
    }
    r.set_settings(cmd.render.with_default_reconstruction(r.settings(), spacing))?;
    r.set_settings(cmd.render.with_still_settings(r.settings(), spacing))?;
    let mut img = Image::new(cam.size[0], cam.size[1]);
    let build_ms = prepare_first(&mut r, &cam)?;
    let (stats, geometry) = scene.render(&mut r, &cam, &mut img)?;
    crate::app::output::write_image(&cmd.output, kind, &img.to_rgb8())?;
    let first_frame_ms = crate::app::since_start_ms();
    let warnings = shearwarp::render::checks::frame_warnings(&r, img.coverage());
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    if cmd.json {
        let s = r.settings();
        let j = serde_json::json!({
            "volume": name, "dims": dims, "tissue": r.classification_name(), "iso": r.iso(),
            "method": s.method.name(), "mode": s.mode.name(), "word": s.word.name(), "search": s.search.name(), "cell": s.cell,
            "projection": projection_json(r.projection()), "quality": r.quality(), "sampling": cmd.sampling.to_possible_value().map(|v| v.get_name().to_string()), "deluxe": r.settings().deluxe.label(), "grid": r.settings().lattice.name(), "reconstruction": r.settings().reconstruction.name(),
            "cpu": s.cpu.capped().name(), "size": cam.size[0], "output": cmd.output, "build_ms": build_ms + stats.build_ms, "shear_ms": stats.shear_ms,
            "render_ms": stats.render_ms, "warp_ms": stats.warp_ms, "frame_ms": stats.frame_ms(),
            "axis": AXES[stats.axis], "rays": stats.rays, "coverage": img.coverage(), "warnings": warnings,
            "load_ms": load_ms, "first_frame_ms": first_frame_ms, "memory": crate::app::memory_json(&r), "build": build_json(&r),
            "geometry": scene.has_meshes().then(|| serde_json::json!({
                "raster_ms": geometry.raster_ms, "inverse_warp_ms": geometry.inverse_warp_ms, "composite_ms": geometry.composite_ms,
                "inverse_warp_ns_per_output_pixel": geometry.inverse_warp_ms * 1e6 / (cam.size[0] * cam.size[1]) as f64,
            })),
        });
        say!("{j}");
    } else {
        eprintln!(
            "{name} {}×{}×{} → {} ({}×{}, {} {}, tissue {}): build {:.1} ms, shear {:.2} ms, render {:.2} ms, warp {:.2} ms",
            dims[0],
            dims[1],
            dims[2],
            cmd.output.display(),
            cam.size[0],
            cam.size[1],
            r.settings().method.name(),
            r.settings().mode.name(),
            r.classification_name(),
            build_ms + stats.build_ms,
            stats.shear_ms,
            stats.render_ms,
            stats.warp_ms
        );
    }
    Ok(())
}

/// Runs `shearwarp rotate`.
pub fn run_rotate(cmd: &RotateCmd) -> Result<()> {
    if cmd.distributed {
        return crate::app::distributed::rotate(&crate::app::RotateJob {
            volume: &cmd.volume,
            render: &cmd.render,
            axis: cmd.axis as usize,
            degrees: cmd.degrees,
            step_deg: &cmd.step_deg,
            frames_dir: cmd.frames_dir.as_deref(),
            animation: cmd.gif.is_some() || cmd.apng.is_some(),
            json: cmd.json,
            cycle_tissues: cmd.cycle_tissues,
        });
    }
    let (vol, name) = cmd.volume.load()?;
    renderable(&name, &vol)?;
    let load_ms = crate::app::since_start_ms();
    let dims = vol.dims();
    let step = match cmd.step_deg.as_str() {
        "auto" => None,
        s => match s.parse::<f64>().ok().filter(|x| x.is_finite() && *x > 0.0) {
            Some(x) => Some(x),
            None => usage!("--step-deg must be 'auto' or a positive number of degrees, got '{s}'"),
        },
    };
    if !(cmd.degrees.is_finite() && cmd.degrees > 0.0) {
        usage!("--degrees must be a positive number, got {}", cmd.degrees);
    }
    let cam0 = cmd.render.camera(vol.frame())?;
    let spacing = vol.spacing();
    let (mut r, scene) = cmd.render.renderer_and_scene(vol)?;
    r.set_settings(cmd.render.with_default_reconstruction(r.settings(), spacing))?;
    // a rotation takes the cell size that balances shear and render (`--cell auto`)
    let cell = cmd.render.cell.resolve(&mut r)?;
    let step = step.unwrap_or_else(|| one_bit_step_deg(dims) * cell as f64);
    let frames = ((cmd.degrees / step).round() as usize).max(1);
    if frames > 1_000_000 {
        usage!("{frames} frames is too many (raise --step-deg)");
    }
    if cmd.cycle_tissues > 0 && r.tissues().is_none_or(|(t, _)| t.len() < 2) {
        usage!("--cycle-tissues needs tissue presets (it cannot be combined with --iso)");
    }
    // A tissue switch costs the selection plus whatever the next frame would
    // otherwise rebuild: the RLE paths re-encode the volume for the new
    // classification (per principal axis), the binary path only swaps a table.
    let reencodes = matches!(r.settings().method, shearwarp::render::Method::Rle | shearwarp::render::Method::BruteRle);
    let (mut select_ns, mut switch_ms, mut after_switch_ms): (Vec<f64>, Vec<f64>, Vec<f64>) = (Vec::new(), Vec::new(), Vec::new());
    // only what the first view needs is built before it (its principal axis);
    // a later frame whose view needs another axis builds it (its build_ms)
    let mut first_frame_ms = None;
    let build_ms_first = prepare_first(&mut r, &cam0)?;
    if let Some(d) = &cmd.frames_dir {
        std::fs::create_dir_all(d).with_context(|| format!("{}: cannot create directory", d.display()))?;
    }
    let keep_frames = cmd.gif.is_some() || cmd.apng.is_some();
    let mut kept: Vec<image::RgbImage> = Vec::new();
    // an animation of every frame of a long turn is huge (801 frames, 45 MB
    // for a full turn of a large scan): keep at most MAX_ANIMATION_FRAMES
    let every = frames.div_ceil(MAX_ANIMATION_FRAMES).max(1);
    let mut still = Image::new(cam0.size[0], cam0.size[1]);
    let axis = match cmd.axis {
        AxisArg::X => 0,
        AxisArg::Y => 1,
        AxisArg::Z => 2,
    };
    let pb = progress(frames as u64, cmd.render.quiet || cmd.json, "rotating");
    let mut img = Image::new(cam0.size[0], cam0.size[1]);
    let mut all: Vec<FrameStats> = Vec::with_capacity(frames);
    let mut costs: Vec<crate::app::scene::GeometryCost> = Vec::with_capacity(frames);
    let loop_start = std::time::Instant::now();
    let mut frames_wall_ms = 0.0;
    for f in 0..frames {
        let mut cam = cam0;
        cam.rotation = rotate_eye(cam0.rotation, axis, f as f64 * step);
        let switched = cmd.cycle_tissues > 0 && f > 0 && f % cmd.cycle_tissues == 0;
        if switched {
            let n = r.tissues().map_or(1, |(t, _)| t.len());
            let next = (r.tissues().map_or(0, |(_, c)| c) + 1) % n;
            let t = std::time::Instant::now();
            r.select_tissue(next)?;
            select_ns.push(t.elapsed().as_secs_f64() * 1e9);
            // the rebuild the switch causes, for the principal axis of the coming frame
            let principal = shearwarp::view::Factorization::new(&cam, r.dims(), r.spacing())?.axis;
            r.prepare_axis(principal)?;
            switch_ms.push(t.elapsed().as_secs_f64() * 1e3);
        }
        let t = std::time::Instant::now();
        let (st, cost) = scene.render(&mut r, &cam, &mut img)?;
        costs.push(cost);
        let wall = t.elapsed().as_secs_f64() * 1e3;
        frames_wall_ms += wall;
        if switched {
            after_switch_ms.push(wall);
        }
        all.push(st);
        first_frame_ms.get_or_insert_with(crate::app::since_start_ms);
        let keep = keep_frames && f % every == 0;
        if keep || cmd.frames_dir.is_some() {
            let out = if cmd.sampling == StillSampling::Matched && matched_still(&mut r, &scene, &cam, &mut still) { &still } else { &img };
            if let Some(d) = &cmd.frames_dir {
                // (each frame whole or not at all; one sync for the directory after the loop)
                shearwarp::output::write_png_unsynced(d.join(format!("frame_{f:05}.png")), &out.to_rgb8())?;
            }
            if keep {
                kept.push(out.to_rgb8());
            }
        }
        pb.inc(1);
    }
    let loop_ms = loop_start.elapsed().as_secs_f64() * 1e3;
    if let Some(d) = &cmd.frames_dir {
        shearwarp::output::sync_written(d)?;
    }
    pb.finish_and_clear();
    let frames_ms_total: f64 = all.iter().map(|s| s.build_ms + s.frame_ms()).sum();
    let build_ms: f64 = build_ms_first + all.iter().map(|s| s.build_ms).sum::<f64>();
    let switch_ms_total: f64 = switch_ms.iter().fold(0.0, |a, b| a + b); // not sum(): an empty sum is -0.0
    let warnings = shearwarp::render::checks::frame_warnings(&r, img.coverage());
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    let col = |g: fn(&FrameStats) -> f64| median(&mut all.iter().map(g).collect::<Vec<_>>());
    let (shear, render, warp, frame) = (col(|s| s.shear_ms), col(|s| s.render_ms), col(|s| s.warp_ms), col(|s| s.frame_ms()));
    let fps = if frame > 0.0 { 1000.0 / frame } else { f64::INFINITY };
    if keep_frames && every > 1 {
        eprintln!(
            "note: the animation keeps every {every}th of the {frames} frames ({} frames); --step-deg sets the step, --frames-dir keeps them all",
            kept.len()
        );
    }
    if let Some(p) = &cmd.gif {
        crate::app::output::write_gif(p, &kept)?;
    }
    if let Some(p) = &cmd.apng {
        crate::app::output::write_apng(p, &kept)?;
    }
    let s = r.settings();
    if cmd.json {
        let j = serde_json::json!({
            "volume": name, "dims": dims, "tissue": r.classification_name(), "iso": r.iso(),
            "method": s.method.name(), "mode": s.mode.name(), "word": s.word.name(), "search": s.search.name(), "cell": s.cell,
            "cpu": s.cpu.capped().name(), "projection": projection_json(r.projection()), "tissue_switches": switch_ms.len(),
            // the full cost of a switch: selection plus the rebuild it causes (re-encoding on the RLE paths)
            "tissue_switch_ns_median": median(&mut switch_ms.clone()) * 1e6,
            "tissue_switch_ms_median": median(&mut switch_ms.clone()), "tissue_switch_ms_total": switch_ms_total,
            "tissue_switch_reencodes": reencodes, "tissue_select_ns_median": median(&mut select_ns),
            "tissue_switch_next_frame_ms_median": median(&mut after_switch_ms),
            "frames_ms_total": frames_ms_total, "frames_wall_ms_total": frames_wall_ms, "loop_ms": loop_ms, "warnings": warnings,
            "threads": if s.threads == 0 { rayon::current_num_threads() } else { s.threads },
            "size": cam0.size[0], "axis": AXES[axis],
            "frames": frames, "degrees": frames as f64 * step, "step_deg": step, "build_ms": build_ms,
            "shear_ms_median": shear, "render_ms_median": render, "warp_ms_median": warp, "frame_ms_median": frame,
            "fps": fps, "degrees_per_second": fps * step, "mask_bytes": r.mask_bytes(), "rle_bytes": r.rle_bytes(),
            "rle_axis_bytes": r.rle_axis_bytes(),
            "load_ms": load_ms, "first_frame_ms": first_frame_ms, "build_ms_first": build_ms_first,
        });
        // added apart: one json! of all the fields exceeds the macro's recursion limit
        let mut j = j;
        j["memory"] = crate::app::memory_json(&r);
        j["build"] = build_json(&r);
        j["quality"] = r.quality().into();
        j["deluxe"] = r.settings().deluxe.label().into();
        j["grid"] = r.settings().lattice.name().into();
        j["rle_reuse"] = r.settings().rle_reuse.into();
        j["reconstruction"] = r.settings().reconstruction.name().into();
        j["normals"] = r.settings().normals.name().into();
        if scene.has_meshes() {
            // the geometry's own cost per frame, beside the volume's frame (medians
            // over the turn: warm, as a user rotating the scene sees them)
            let g = |f: fn(&crate::app::scene::GeometryCost) -> f64| median(&mut costs.iter().map(f).collect::<Vec<_>>());
            let mut share: Vec<f64> = costs.iter().zip(&all).map(|(c, s)| c.inverse_warp_ms / s.frame_ms()).collect();
            // (of the whole frame a user waits for: the volume's, the meshes' drawing and the composite)
            let mut share_scene: Vec<f64> =
                costs.iter().zip(&all).map(|(c, s)| c.inverse_warp_ms / (s.frame_ms() + c.raster_ms + c.composite_ms)).collect();
            j["geometry"] = serde_json::json!({
                "raster_ms_median": g(|c| c.raster_ms), "inverse_warp_ms_median": g(|c| c.inverse_warp_ms),
                "composite_ms_median": g(|c| c.composite_ms), "inverse_warp_share_median": median(&mut share),
                "inverse_warp_share_of_scene_frame_median": median(&mut share_scene),
            });
        }
        say!("{j}");
    } else {
        say!(
            "{name} {}×{}×{}, {}×{}, {} {} ({} words, {} search, cell {}), tissue {} (iso {}):",
            dims[0],
            dims[1],
            dims[2],
            cam0.size[0],
            cam0.size[1],
            s.method.name(),
            s.mode.name(),
            s.word.name(),
            s.search.name(),
            s.cell,
            r.classification_name(),
            r.iso()
        );
        if !switch_ms.is_empty() {
            say!(
                "  {} tissue switches, median {:.3} ms each ({}; selection alone {:.0} ns), next frame {:.3} ms",
                switch_ms.len(),
                median(&mut switch_ms.clone()),
                if reencodes { "re-encodes the volume for the new classification" } else { "a table swap, no rebuild" },
                median(&mut select_ns),
                median(&mut after_switch_ms)
            );
        }
        say!(
            "  {frames} frames × {step:.3}° = {:.1}°; stacks and masks built in {build_ms:.1} ms (as frames needed them)",
            frames as f64 * step
        );
        say!("  median per frame: shear {shear:.3} ms, render {render:.3} ms, warp {warp:.3} ms, total {frame:.3} ms");
        say!("  {fps:.1} frames/s, {:.1} degrees/s", fps * step);
    }
    Ok(())
}

/// Runs `shearwarp info`.
pub fn run_info(cmd: &InfoCmd) -> Result<()> {
    if cmd.bins == 0 || cmd.bins > 4096 {
        usage!("--bins must be 1..=4096, got {}", cmd.bins);
    }
    let (vol, name) = cmd.volume.load()?;
    let (lo, hi) = vol.value_range();
    let hist = vol.histogram(cmd.bins);
    let tissues = presets::tissues_for(&vol);
    let ct = presets::looks_like_ct(&vol);
    let range = presets::data_range(&vol);
    let sentinel_note = range.sentinel_note();
    let frame = vol.frame().copied();
    let source = if cmd.volume.orientation.is_some() {
        "--orientation"
    } else if cmd.volume.file.is_none() && cmd.volume.raw.is_none() && cmd.volume.den.is_none() {
        "phantom"
    } else {
        "file"
    };
    if cmd.json {
        let j = serde_json::json!({
            "volume": name, "dims": vol.dims(), "type": vol.data().voxel_type().name(), "spacing": vol.spacing(),
            "min": lo, "max": hi, "histogram": hist, "ct_hounsfield": ct,
            "cpu": kernels::level().name(), "cpu_detected": kernels::detected().name(),
            "tissues": tissues.iter().map(|t| serde_json::json!({"name": t.name, "threshold": t.threshold})).collect::<Vec<_>>(),
            "orientation": frame.map(|f| f.code()), "orientation_source": frame.map(|_| source),
            "stored_orientation": frame.map(|f| f.stored_code()), "reversed_axis": frame.and_then(|f| f.reversed_axis.map(|a| AXES[a])),
            "origin_ras": frame.map(|f| f.origin.to_array()), "origin_lps": frame.map(|f| f.origin_lps().to_array()),
            "directions_ras": frame.map(|f| [f.directions.x_axis.to_array(), f.directions.y_axis.to_array(), f.directions.z_axis.to_array()]),
            "oblique_deg": frame.map(|f| f.obliquity_deg()), "skew_deg": frame.map(|f| f.skew_deg),
            "sentinel": range.sentinel, "sentinel_voxels": range.sentinel_voxels, "warnings": sentinel_note.iter().collect::<Vec<_>>(),
            "memory": memory_estimate(&vol, tissues.len()),
        });
        say!("{j}");
        return Ok(());
    }
    let d = vol.dims();
    let sp = vol.spacing();
    say!("{name}");
    say!("  dims      {} × {} × {} ({} voxels, {})", d[0], d[1], d[2], vol.len(), vol.data().voxel_type().name());
    say!("  spacing   {} × {} × {}", sp[0], sp[1], sp[2]);
    match frame {
        Some(f) => {
            say!("  orientation {}, from the {source}", f.describe());
            let (o, l) = (f.origin, f.origin_lps());
            say!("  origin    RAS ({:.3}, {:.3}, {:.3}) mm = LPS ({:.3}, {:.3}, {:.3}) mm", o.x, o.y, o.z, l.x, l.y, l.z);
        }
        None => say!("  orientation {}", shearwarp::data::orientation::UNKNOWN),
    }
    say!(
        "  range     {} … {}{}",
        shearwarp::fmt::fmt_density(lo),
        shearwarp::fmt::fmt_density(hi),
        if ct { "  (looks like CT in Hounsfield units)" } else { "" }
    );
    if let Some(n) = &sentinel_note {
        say!("  warning   {n}");
    }
    say!(
        "  cpu       {} kernels (detected {}; SHEARWARP_CPU=scalar|avx2|native caps it)",
        kernels::level().name(),
        kernels::detected().name()
    );
    {
        let est: Vec<u64> = (0..3).map(|a| estimate_axis(&vol, &Settings::default(), code_bits(tissues.len()), a).total()).collect();
        let f = shearwarp::fmt::fmt_bytes;
        let volume = vol.bytes();
        say!(
            "  memory    {} of voxels; the binary iso preview holds about {} along x / {} along y / {} along z (all it holds, the volume included), budget {}",
            f(volume),
            f(est[0]),
            f(est[1]),
            f(est[2]),
            crate::app::budget().map_or("none".to_string(), f)
        );
    }
    say!("  histogram ({} bins, log scale):", cmd.bins);
    let maxl = hist.iter().map(|&c| ((c + 1) as f64).ln()).fold(0.0, f64::max).max(1e-9);
    for (i, &c) in hist.iter().enumerate() {
        // in f64: hi − lo overflows f32 for ±FLT_MAX data
        let a = (lo as f64 + (hi as f64 - lo as f64) * i as f64 / cmd.bins as f64) as f32;
        let a = if a.abs() >= 1e9 { format!("{a:.3e}") } else { format!("{a:.1}") };
        let bar = "#".repeat((((c + 1) as f64).ln() / maxl * 40.0) as usize);
        say!("    {a:>10} {c:>10} {bar}");
    }
    say!("  suggested tissue thresholds ({}):", if ct { "CT presets" } else { "from the histogram" });
    for t in &tissues {
        say!("    --tissue {:<5} threshold {}", t.name, t.threshold);
    }
    Ok(())
}

/// Output grid of `export`: cubic voxels with the longest physical edge `n` voxels long.
fn cubic_dims(dims: [usize; 3], spacing: [f32; 3], n: usize) -> Result<[usize; 3]> {
    if n < 2 || n > i16::MAX as usize {
        usage!("--max-dim must be 2..={}, got {n}", i16::MAX);
    }
    let ext: [f64; 3] = std::array::from_fn(|a| (dims[a].max(2) - 1) as f64 * spacing[a] as f64);
    let longest = ext.iter().cloned().fold(0.0, f64::max);
    let voxel = longest / (n - 1) as f64;
    Ok(std::array::from_fn(|a| if dims[a] == 1 { 1 } else { (ext[a] / voxel).round() as usize + 1 }))
}

pub fn run_export(cmd: &ExportCmd) -> Result<()> {
    if cmd.output.extension().and_then(|e| e.to_str()).map(|e| e.eq_ignore_ascii_case("den")) != Some(true) {
        usage!("{}: export writes VolPack .den files; give the output a .den extension", cmd.output.display());
    }
    if let Some(d) = cmd.out_dims
        && d.iter().any(|&x| x > i16::MAX as usize)
    {
        usage!("--out-dims {d:?}: a .den file holds at most {} voxels per edge", i16::MAX);
    }
    let (vol, name) = cmd.volume.load()?;
    let target = match (cmd.out_dims, cmd.max_dim) {
        (Some(d), _) => Some(d),
        (None, Some(n)) => Some(cubic_dims(vol.dims(), vol.spacing(), n)?),
        (None, None) => None,
    };
    let vol = match target {
        Some(d) if d != vol.dims() => vol.resampled(d).map_err(|e| anyhow::Error::new(Usage(format!("{e}"))))?,
        _ => vol,
    };
    let (lo, hi) = match cmd.window {
        Some([lo, hi]) => (lo, hi),
        None => {
            let (lo, hi) = vol.value_range();
            if hi > lo { (lo, hi) } else { (lo, lo + 1.0) }
        }
    };
    let out = vol.window_u8(lo, hi)?;
    let shearwarp::data::volume::VoxelData::U8(bytes) = out.data() else { unreachable!("window_u8 makes u8 voxels") };
    io::den::save_den(&cmd.output, out.dims(), bytes)?;
    let (d, sp) = (out.dims(), vol.spacing());
    if cmd.json {
        say!(
            "{}",
            serde_json::json!({"volume": name, "output": cmd.output, "dims": d, "spacing": sp, "window": [lo, hi], "units_per_step": (hi - lo) / 255.0})
        );
    } else {
        say!(
            "{} → {}: {}×{}×{} u8, window [{lo}, {hi}] ({} units per step), voxel spacing {}×{}×{} (not stored: .den has none)",
            name,
            cmd.output.display(),
            d[0],
            d[1],
            d[2],
            (hi - lo) / 255.0,
            sp[0],
            sp[1],
            sp[2]
        );
    }
    Ok(())
}

/// `s` with matched sampling (Deluxe M): how a still frame samples.
fn matched(s: Settings) -> Settings {
    Settings { deluxe: shearwarp::Deluxe { matched: true, ..s.deluxe }, ..s }
}

/// Renders the still of `cam` (matched sampling, Deluxe M: as many rays per
/// voxel as the output magnifies along each axis, as `render` samples) into
/// `still`, the renderer's settings as they were afterwards; false when the
/// view does not magnify (the timed frame is that still) or its matched grid
/// is past the renderer's pixel limit (the timed frame stands in for it).
fn matched_still(r: &mut Renderer, scene: &crate::app::scene::Scene, cam: &shearwarp::view::Camera, still: &mut Image) -> bool {
    if r.last_plan().is_none_or(|p| p.matched_samples() == [1, 1]) {
        return false;
    }
    let s = r.settings();
    if r.set_settings(matched(s)).is_err() {
        return false;
    }
    let ok = scene.render(r, cam, still).is_ok();
    // (the settings the timed frames had: valid, so restoring cannot fail)
    let restored = r.set_settings(s).is_ok();
    ok && restored
}

/// Most frames an animation (`--gif`, `--apng`) keeps; longer runs keep every n-th.
pub const MAX_ANIMATION_FRAMES: usize = 200;

/// Rejects a `SHEARWARP_CPU` that names no CPU level: the library would
/// quietly run the scalar kernels, so the command line says so and stops.
fn check_cpu_env() -> Result<()> {
    if let Err(e) = kernels::env_override() {
        usage!("{e}; unset it to run the kernels at the level the CPU has");
    }
    Ok(())
}

/// Entry point of the binary: parses arguments, runs, maps errors to exit codes.
pub fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    crate::app::output::install_signal_handlers();
    let res = check_cpu_env().and_then(|()| match &cli.command {
        Command::Render(c) => run_render(c),
        Command::Rotate(c) => run_rotate(c),
        Command::Info(c) => run_info(c),
        Command::Bench(c) if c.distributed => crate::app::distributed::bench(c),
        Command::Bench(c) => crate::app::bench::run(c),
        Command::View(c) => crate::app::viewer::run(c),
        Command::Export(c) => run_export(c),
    });
    match res {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            // bad arguments and bad input are usage errors (2); failures while running are 1
            let input = e.chain().any(|c| c.downcast_ref::<Usage>().is_some() || c.downcast_ref::<shearwarp::Error>().is_some());
            std::process::ExitCode::from(if input { 2 } else { 1 })
        }
    }
}
