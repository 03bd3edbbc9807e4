//! Stage 8 — the command-line interface (`shearwarp render | rotate`).
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
use shearwarp::composite::Mode;
use shearwarp::data::io;
use shearwarp::data::orientation::{PatientFrame, view_rotation};
use shearwarp::data::phantom::Phantom;
use shearwarp::data::volume::{Volume, VoxelType};
use shearwarp::encode::depth::Search;
use shearwarp::kernels;
use shearwarp::render::{FrameStats, Method, Normals, Renderer, Settings, WordSize, estimate_axis};
use shearwarp::view::clip::{ClipPlane, ClipPlanes};
use shearwarp::view::{Camera, NamedView, Projection, one_bit_step_deg, rotate_eye};
use shearwarp::warp::Image;

const AXES: [&str; 3] = ["x", "y", "z"];
/// `--eye-distance` when `--perspective` is given without it, in volume diagonals.
pub const DEFAULT_EYE_DISTANCE: f64 = 2.0;

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

/// Prints a line to stdout; a closed pipe (`shearwarp … | head`) ends the
/// program quietly instead of panicking like `println!`.
macro_rules! say {
    ($($t:tt)*) => {{
        use std::io::Write;
        let mut out = std::io::stdout().lock();
        if let Err(e) = writeln!(out, $($t)*) {
            if e.kind() == std::io::ErrorKind::BrokenPipe {
                std::process::exit(0);
            }
            // (a write failure, as for every output: exit 2, the destination named)
            return Err(shearwarp::Error::file("standard output", format!("cannot write: {e}")).into());
        }
    }};
}

/// Returns a [`Usage`] error from the current function.
macro_rules! usage {
    ($($t:tt)*) => {
        return Err(anyhow::Error::new(Usage(format!($($t)*))))
    };
}

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

/// Where the volume comes from.
#[derive(Args, Debug, Clone)]
pub struct VolumeArgs {
    /// Volume file: .nrrd/.nhdr, .nii/.nii.gz, .den, .raw (with --dims/--type or a JSON
    /// sidecar), or a directory (or one .dcm file) of a DICOM series. Without it, a phantom.
    #[arg(value_name = "FILE")]
    pub file: Option<PathBuf>,
    /// File format (default: from the extension or the content).
    #[arg(long, value_enum)]
    pub format: Option<io::Format>,
    /// Built-in phantom (used when no file is given).
    #[arg(long, value_enum, default_value = "head")]
    pub phantom: Phantom,
    /// Phantom size X,Y,Z (default: head 128,128,113; sphere 128³; marschner-lobb 41³).
    #[arg(long, value_parser = parse_dims)]
    pub phantom_dims: Option<[usize; 3]>,
    /// Raw voxel file (same as FILE with --format raw; needs --dims and --type unless it has a JSON sidecar).
    #[arg(long, value_name = "FILE", conflicts_with = "file")]
    pub raw: Option<PathBuf>,
    /// VolPack .den file (same as FILE with --format den).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["file", "raw"])]
    pub den: Option<PathBuf>,
    /// Raw file dimensions X,Y,Z.
    #[arg(long, value_parser = parse_dims)]
    pub dims: Option<[usize; 3]>,
    /// Raw voxel type.
    #[arg(long = "type", value_enum)]
    pub voxel_type: Option<VoxelType>,
    /// Raw data is big-endian.
    #[arg(long)]
    pub big_endian: bool,
    /// Bytes to skip at the start of a raw file.
    #[arg(long, default_value_t = 0)]
    pub header_bytes: u64,
    /// Voxel spacing X,Y,Z (overrides the file's).
    #[arg(long, value_parser = parse_spacing)]
    pub spacing: Option<[f32; 3]>,
    /// Patient orientation of the index axes: where x, y, z point, e.g. RAS, LPS, LAS
    /// (raw and .den files carry none; replaces a file's own). Named views follow it.
    #[arg(long, value_name = "CODE")]
    pub orientation: Option<String>,
    /// Largest memory the renderer may hold, in bytes with an optional k/M/G
    /// suffix (e.g. 512M). Structures a view needs are predicted before they
    /// are built; other axes are freed to make room; what still does not fit
    /// fails with a clear error. Default: the machine's physical memory (or
    /// `ulimit -v`, if lower)
    #[arg(long, value_name = "BYTES", value_parser = parse_max_memory)]
    pub max_memory: Option<u64>,
}

/// Render settings shared by every command.
#[derive(Args, Debug, Clone)]
pub struct RenderArgs {
    /// Output image size N (N×N pixels).
    #[arg(long, default_value_t = 512)]
    pub size: usize,
    /// Render path: binary (bit-packed mask + post-classified raycaster), rle
    /// (run-length-encoded pre-classified shear-warp), brute or brute-rle (their
    /// unaccelerated references).
    #[arg(long, value_enum, default_value = "binary")]
    pub method: Method,
    /// Iso-surface preview or full alpha blending.
    #[arg(long, value_enum, default_value = "iso")]
    pub mode: Mode,
    /// Mask word width.
    #[arg(long, value_enum, default_value = "u64")]
    pub word: WordSize,
    /// First-bit search.
    #[arg(long, value_enum, default_value = "bitscan")]
    pub search: Search,
    /// Shading of the binary and brute paths: codes (each voxel's gradient
    /// direction quantized once, VolPack's per-view shade table, four lookups
    /// per sample) or gradient (the exact gradient at every sample: slower).
    #[arg(long, value_enum, default_value = "codes")]
    pub normals: Normals,
    /// Worker threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Tissue preset: skin, fat, soft, bone (CT in Hounsfield units); low, mid,
    /// high (other volumes, from the histogram); or auto (the first).
    #[arg(long)]
    pub tissue: Option<String>,
    /// Super-cell size S (1..=8): the mask shrinks by S², a shear step moves S voxels.
    #[arg(long, default_value_t = 1)]
    pub cell: usize,
    /// Iso value (overrides the preset's threshold).
    #[arg(long, allow_negative_numbers = true)]
    pub iso: Option<f32>,
    /// Blend-mode opacity curve: density:opacity control points, sorted by density,
    /// linear in between, constant outside; two points at one density make a step
    /// (e.g. "24:0,28:1", or VolPack's ramp with its 0.05 cut: "62.5:0,62.5:0.05,255:0.3").
    #[arg(long, value_parser = parse_opacity, allow_hyphen_values = true, conflicts_with = "iso")]
    pub opacity: Option<OpacityCurve>,
    /// Early ray termination threshold in blend mode, and in both modes with
    /// --method rle / brute-rle (1 disables it).
    #[arg(long, default_value_t = 0.99)]
    pub ert: f32,
    /// Pixels per world unit (default: fit the bounding diagonal).
    #[arg(long)]
    pub zoom: Option<f64>,
    /// Perspective projection with this vertical field of view, in degrees
    /// (0 < FOV < 180), from an eye on the view axis --eye-distance volume
    /// diagonals from the volume's centre (the field of view sets the scale:
    /// no --zoom). Every method renders it (the binary rotator walks each
    /// ray across the mask's columns as it diverges); the eye inside or very
    /// near the volume (rays more than 63.4° off the principal axis) is
    /// rendered by Lacroute's pyramid split, e.g. --eye-distance 0.1.
    #[arg(long, value_name = "FOV_DEGREES", allow_negative_numbers = true, conflicts_with = "zoom")]
    pub perspective: Option<f64>,
    /// With --perspective: the eye's distance from the volume's centre, in
    /// volume diagonals [default: 2].
    #[arg(long, value_name = "D", allow_negative_numbers = true, requires = "perspective")]
    pub eye_distance: Option<f64>,
    /// Clipping plane NX,NY,NZ,D (repeatable, at most 6): keeps the side
    /// where NX·x + NY·y + NZ·z ≤ D, with (x, y, z) the volume's voxel
    /// indices; what is on the other side is not rendered. E.g. on a 256³
    /// volume 1,0,0,127.5 removes the half at larger x; 0,0,-1,-100 keeps
    /// z ≥ 100.
    #[arg(long, value_name = "NX,NY,NZ,D", value_parser = parse_clip_plane, allow_hyphen_values = true)]
    pub clip_plane: Vec<ClipPlane>,
    /// Intermediate image resolution Q in pixels per voxel (0.25–2; Schulze's
    /// adaptive image size): below 1 a coarser, faster frame, above 1 finer
    /// sampling of each slice. Both projections, every method.
    #[arg(long, value_name = "Q", allow_negative_numbers = true)]
    pub quality: Option<f64>,
    /// RLE paths: how a slice whose intermediate pixels are wider than a voxel
    /// (perspective's far slices, --quality below 1) is sampled: the box
    /// average of the voxels under each pixel, or (faster, aliasing) the
    /// bilinear sample at its centre.
    #[arg(long, value_enum, default_value = "box")]
    pub footprint: shearwarp::render::Footprint,
    /// Shear-Warp Deluxe options (Sweeney & Mueller), a comma-separated
    /// subset of I,P,M in any order: I one intermediate slice between each
    /// pair of slices (less inter-slice aliasing), P post-interpolated
    /// classification and shading on the RLE path (sharp edges, tissue
    /// switches without re-encoding), M matched sampling on zoom (as many
    /// samples per voxel as the output magnifies). E.g. --deluxe I,P.
    #[arg(long, value_name = "LIST", value_parser = parse_deluxe, default_value = "S")]
    pub deluxe: shearwarp::Deluxe,
    /// The sample lattice: the volume's own cartesian grid, or a
    /// body-centred cubic grid resampled from it (about 70 % of the samples).
    #[arg(long = "grid", value_name = "GRID", value_enum, default_value = "cartesian")]
    pub grid: shearwarp::Lattice,
    /// RLE paths, parallel projection: one run-length encoding serves the x
    /// and z axes (z read through the mirrored permutation, a pointer table
    /// over x's scanlines; Sweeney & Mueller): about a third less RLE memory,
    /// the same image to float rounding.
    #[arg(long)]
    pub rle_reuse: bool,
    #[command(flatten)]
    pub scene: crate::app::scene::SceneArgs,
    /// Starting view: anterior (face), posterior, left, right, superior, inferior.
    #[arg(long, value_enum, default_value = "anterior")]
    pub view: NamedView,
    /// Extra rotation RX,RY,RZ in degrees about the eye's x, y, z axes (after --view).
    #[arg(long, value_parser = parse_rotation, allow_hyphen_values = true)]
    pub rotate: Option<[f64; 3]>,
    /// No progress bar.
    #[arg(long, short)]
    pub quiet: bool,
}

/// `--deluxe LIST`: a comma-separated subset of I, P, M.
pub fn parse_deluxe(s: &str) -> std::result::Result<shearwarp::Deluxe, String> {
    shearwarp::Deluxe::parse(s).map_err(|e| e.to_string())
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
    /// Print one JSON object with the timing summary.
    #[arg(long)]
    pub json: bool,
    /// Switch to the next tissue preset every N frames (0 = never).
    #[arg(long, default_value_t = 0)]
    pub cycle_tissues: usize,
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

fn parse_window(s: &str) -> std::result::Result<[f32; 2], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let [lo, hi] = parts.as_slice() else { return Err(format!("expected LO,HI, got '{s}'")) };
    let (lo, hi) = (
        lo.parse::<f32>().map_err(|_| format!("'{lo}' is not a number"))?,
        hi.parse::<f32>().map_err(|_| format!("'{hi}' is not a number"))?,
    );
    if !(lo.is_finite() && hi.is_finite() && lo < hi) {
        return Err(format!("the window needs finite LO < HI, got {s}"));
    }
    Ok([lo, hi])
}

fn parse_triple<T: std::str::FromStr>(s: &str, what: &str) -> std::result::Result<[T; 3], String> {
    let parts: Vec<&str> = s.split([',', 'x', 'X']).map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!("expected three {what} separated by commas, got '{s}'"));
    }
    let mut out = Vec::with_capacity(3);
    for p in parts {
        out.push(p.parse::<T>().map_err(|_| format!("'{p}' is not a valid {what}"))?);
    }
    out.try_into().map_err(|_| "three values".to_string())
}

fn parse_dims(s: &str) -> std::result::Result<[usize; 3], String> {
    let d: [usize; 3] = parse_triple(s, "whole numbers")?;
    shearwarp::data::volume::check_dims(d.map(|x| x as u64)).map_err(|e| e.to_string())
}

fn parse_spacing(s: &str) -> std::result::Result<[f32; 3], String> {
    let d: [f32; 3] = parse_triple(s, "numbers")?;
    if d.iter().any(|x| !x.is_finite() || *x <= 0.0) {
        return Err(format!("spacing must be finite and > 0, got {s}"));
    }
    Ok(d)
}

/// `--opacity`: a blend-mode transfer function from (density, opacity) control
/// points, in a constant bone-white colour.
#[derive(Clone, Debug, PartialEq)]
pub struct OpacityCurve(pub shearwarp::classify::TransferFunction);

fn parse_opacity(s: &str) -> std::result::Result<OpacityCurve, String> {
    let mut pts = Vec::new();
    for p in s.split(',').map(str::trim) {
        let Some((d, a)) = p.split_once(':') else { return Err(format!("'{p}' is not DENSITY:OPACITY")) };
        let d: f32 = d.trim().parse().map_err(|_| format!("'{d}' is not a density"))?;
        let a: f32 = a.trim().parse().map_err(|_| format!("'{a}' is not an opacity"))?;
        pts.push((d, a));
    }
    // the same checks as every transfer function: finite, sorted, opacities in [0, 1]
    let colour = vec![(pts[0].0, [0.92, 0.9, 0.85])];
    shearwarp::classify::TransferFunction::new(pts, colour).map(OpacityCurve).map_err(|e| e.to_string())
}

fn parse_max_memory(s: &str) -> std::result::Result<u64, String> {
    shearwarp::checks::parse_bytes(s).map_err(|e| e.to_string())
}

fn parse_clip_plane(s: &str) -> std::result::Result<ClipPlane, String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 4 {
        return Err(format!("expected NX,NY,NZ,D (four numbers separated by commas), got '{s}'"));
    }
    let mut v = [0.0f64; 4];
    for (o, p) in v.iter_mut().zip(&parts) {
        *o = p.parse::<f64>().map_err(|_| format!("'{p}' is not a number"))?;
    }
    ClipPlane::new([v[0], v[1], v[2]], v[3]).map_err(|e| e.to_string())
}

fn parse_rotation(s: &str) -> std::result::Result<[f64; 3], String> {
    let r: [f64; 3] = parse_triple(s, "angles")?;
    if r.iter().any(|x| !x.is_finite()) {
        return Err(format!("angles must be finite, got {s}"));
    }
    Ok(r)
}

/// A [`Usage`] error naming the volume when it cannot be rendered (one
/// voxel thick along an axis).
pub fn renderable(name: &str, vol: &Volume) -> Result<()> {
    if let Err(e) = shearwarp::checks::check_renderable(vol.dims()) {
        usage!("{name}: {e}");
    }
    Ok(())
}

impl VolumeArgs {
    /// Loads or builds the volume and names it for reports. Any failure is a
    /// [`Usage`] error: the input is what is wrong.
    pub fn load(&self) -> Result<(Volume, String)> {
        crate::app::set_budget(self.max_memory);
        let (vol, name) = self.load_inner().map_err(|e| anyhow::Error::new(Usage(format!("{e:#}"))))?;
        let bytes = vol.bytes();
        if let Some(b) = crate::app::budget().filter(|&b| bytes > b) {
            let f = shearwarp::checks::fmt_bytes;
            usage!("{name}: the volume alone holds {}, over the memory budget of {} (--max-memory)", f(bytes), f(b));
        }
        Ok((vol, name))
    }

    fn load_inner(&self) -> Result<(Volume, String)> {
        let (path, format) = match (&self.file, &self.raw, &self.den) {
            (Some(p), _, _) => (Some(p), self.format),
            (_, Some(p), _) => (Some(p), Some(io::Format::Raw)),
            (_, _, Some(p)) => (Some(p), Some(io::Format::Den)),
            _ => (None, None),
        };
        let mut vol = match path {
            Some(path) => {
                let raw = match (self.dims, self.voxel_type) {
                    (Some(dims), Some(t)) => {
                        let mut spec = io::RawSpec::new(dims, t);
                        spec.big_endian = self.big_endian;
                        spec.header_bytes = self.header_bytes;
                        Some(spec)
                    }
                    (None, None) => None,
                    _ => usage!("raw files need both --dims X,Y,Z and --type (or a JSON sidecar)"),
                };
                let spinner = spinner(&format!("loading {}", path.display()));
                let v = io::load(path, &io::LoadOptions { format, raw })?;
                spinner.finish_and_clear();
                v
            }
            None => {
                let p = self.phantom;
                let dims = self.phantom_dims.unwrap_or_else(|| p.default_dims());
                // checked before a byte is allocated
                let bytes = p.bytes(dims).unwrap_or(u64::MAX);
                if let Some(b) = crate::app::budget().filter(|&b| bytes > b) {
                    let f = shearwarp::checks::fmt_bytes;
                    usage!(
                        "{} phantom {}×{}×{}: its voxels need {}, over the memory budget of {} (--max-memory)",
                        p.name(),
                        dims[0],
                        dims[1],
                        dims[2],
                        f(bytes),
                        f(b)
                    );
                }
                p.build(dims)?
            }
        };
        if let Some(sp) = self.spacing {
            vol.set_spacing(sp)?;
        }
        match (&self.orientation, path) {
            (Some(code), _) => {
                let frame = PatientFrame::from_code(code)?;
                if let Some(old) = vol.frame().copied() {
                    eprintln!("note: --orientation {code} replaces the file's own orientation {}", old.stored_code());
                    // back to the file's voxel order before the new frame is applied
                    if let Some(a) = old.reversed_axis {
                        vol.reverse_axis(a);
                    }
                    vol.set_frame(None);
                }
                vol.set_frame(Some(frame));
            }
            // the phantoms are built RAS, centred on the origin
            (None, None) => vol.set_frame(Some(PatientFrame::centred_ras(vol.dims(), vol.spacing()))),
            (None, Some(_)) => {}
        }
        let name = match path {
            Some(p) => p.display().to_string(),
            None => format!("{} phantom", self.phantom.name()),
        };
        Ok((vol, name))
    }
}

impl RenderArgs {
    /// A renderer for `vol` set up from these arguments: the volume's tissue
    /// presets (CT in Hounsfield units, else from the histogram) share one
    /// threshold-coded mask, so `--tissue` and `--cycle-tissues` switch in O(1);
    /// `--iso` makes a custom threshold instead.
    /// With it, the scene of `--mesh` / `--clip-box` /
    /// `--clip-sphere` / `--clip-plane` (its clip limiter installed; render
    /// each frame through [`crate::app::scene::Scene::render`] so the meshes
    /// are drawn).
    pub fn renderer_and_scene(&self, vol: Volume) -> Result<(Renderer, crate::app::scene::Scene)> {
        let settings = self.settings()?;
        shearwarp::checks::check_renderable(vol.dims())?;
        let tissues = presets::tissues_for(&vol);
        let hi = vol.value_range().1;
        let mut r = Renderer::with_tissues(vol, &tissues, settings)?;
        r.set_memory_budget(crate::app::budget());
        r.set_projection(self.projection()?)?;
        if let Some(q) = self.quality()? {
            r.set_quality(q)?;
        }
        let scene = crate::app::scene::Scene::new(&self.scene, self.clip_planes(r.dims(), r.spacing())?, r.dims(), r.spacing())?;
        scene.install(&mut r);
        match self.tissue.as_deref() {
            None | Some("auto") => {}
            Some(name) => {
                if r.select_tissue_named(name).is_err() {
                    let names: Vec<&str> = tissues.iter().map(|t| t.name).collect();
                    usage!("unknown tissue '{name}' for this volume (its presets: {}, or auto)", names.join(", "));
                }
            }
        }
        if let Some(OpacityCurve(tf)) = &self.opacity {
            if settings.mode != Mode::Blend {
                usage!("--opacity sets the blend-mode transfer function; add --mode blend (iso mode takes --iso)");
            }
            r.set_transfer_function(tf);
        }
        if self.scene.focus.is_some() && (self.opacity.is_some() || self.iso.is_some()) {
            usage!("--focus classifies with the tissue presets (--tissue, --focus-tissue); it does not combine with --iso or --opacity");
        }
        if let Some(iso) = self.iso {
            if !iso.is_finite() {
                usage!("--iso must be a finite number");
            }
            if settings.mode == Mode::Blend {
                r.set_transfer_function(&presets::generic(iso, hi).tf);
            } else {
                r.set_iso(iso)?;
            }
        }
        crate::app::scene::install_focus(&self.scene, &mut r)?;
        Ok((r, scene))
    }

    /// The `--clip-plane` half-spaces in the library's frame (world
    /// millimetres from the volume centre), checked (at most 6).
    pub fn clip_plane_list(&self, dims: [usize; 3], spacing: [f32; 3]) -> Result<Vec<ClipPlane>> {
        let usage = |e: shearwarp::Error| anyhow::Error::new(Usage(format!("--clip-plane: {e}")));
        let planes = self
            .clip_plane
            .iter()
            .map(|p| ClipPlane::in_voxel_coordinates(p.normal, p.offset, dims, spacing))
            .collect::<std::result::Result<Vec<_>, _>>()
            .map_err(usage)?;
        ClipPlanes::new(&planes, spacing).map_err(usage)?;
        Ok(planes)
    }

    /// `--quality Q`, checked (a bad value, or a path that cannot resample its
    /// intermediate image, is a usage error).
    pub fn quality(&self) -> Result<Option<f64>> {
        let Some(q) = self.quality else { return Ok(None) };
        let (lo, hi) = (shearwarp::render::MIN_QUALITY, shearwarp::render::MAX_QUALITY);
        if !(q.is_finite() && (lo..=hi).contains(&q)) {
            usage!("--quality must be {lo}..={hi} intermediate pixels per voxel, got {q}");
        }
        Ok(Some(q))
    }

    /// The `--clip-plane` half-spaces (voxel index coordinates) as ray limits
    /// for a volume of `dims` voxels with voxel `spacing` (`None` without
    /// any); a bad plane is a usage error.
    pub fn clip_planes(&self, dims: [usize; 3], spacing: [f32; 3]) -> Result<Option<std::sync::Arc<dyn shearwarp::view::plan::Limiter>>> {
        if self.clip_plane.is_empty() {
            return Ok(None);
        }
        let planes = self.clip_plane_list(dims, spacing)?;
        let clip = ClipPlanes::new(&planes, spacing).map_err(|e| anyhow::Error::new(Usage(format!("--clip-plane: {e}"))))?;
        Ok(Some(std::sync::Arc::new(clip)))
    }

    /// The projection: `--perspective FOV` (with `--eye-distance D`, default
    /// 2 diagonals), else parallel. Bad numbers are usage errors.
    pub fn projection(&self) -> Result<Projection> {
        let Some(fov) = self.perspective else { return Ok(Projection::Parallel) };
        if !(fov > 0.0 && fov < 180.0) {
            usage!("--perspective takes a vertical field of view in degrees, 0 < FOV < 180, got {fov}");
        }
        let d = self.eye_distance.unwrap_or(DEFAULT_EYE_DISTANCE);
        if !(d.is_finite() && d > 0.0) {
            usage!("--eye-distance must be a finite number of volume diagonals > 0, got {d}");
        }
        Ok(Projection::perspective(fov, d)?)
    }

    /// Render settings.
    pub fn settings(&self) -> Result<Settings> {
        if !(1..=shearwarp::encode::mask::MAX_CELL).contains(&self.cell) {
            usage!("--cell must be 1..={}, got {}", shearwarp::encode::mask::MAX_CELL, self.cell);
        }
        if !(self.ert > 0.0 && self.ert <= 1.0) {
            usage!("--ert must be in (0, 1], got {}", self.ert);
        }
        if self.size == 0 || self.size > 16384 {
            usage!("--size must be 1..=16384, got {}", self.size);
        }
        shearwarp::checks::check_threads(self.threads)?;
        Ok(Settings {
            method: self.method,
            mode: self.mode,
            word: self.word,
            search: self.search,
            normals: self.normals,
            footprint: self.footprint,
            deluxe: self.deluxe,
            lattice: self.grid,
            rle_reuse: self.rle_reuse,
            ert: self.ert,
            cell: self.cell,
            threads: self.threads,
            ..Settings::default()
        })
    }

    /// The starting camera for a volume placed in the patient by `frame`
    /// ([`Volume::frame`]; `None`: index axes taken as RAS).
    pub fn camera(&self, frame: Option<&PatientFrame>) -> Result<Camera> {
        let mut r = view_rotation(self.view, frame);
        if let Some([rx, ry, rz]) = self.rotate {
            r = rotate_eye(rotate_eye(rotate_eye(r, 0, rx), 1, ry), 2, rz);
        }
        if let Some(z) = self.zoom {
            if !(z.is_finite() && z > 0.0) {
                usage!("--zoom must be finite and > 0, got {z}");
            }
        }
        Ok(Camera { rotation: r, zoom: self.zoom, size: [self.size, self.size] })
    }
}

/// A spinner on stderr while something of unknown length runs (hidden when
/// stderr is not a terminal).
fn spinner(msg: &str) -> indicatif::ProgressBar {
    if !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let pb = indicatif::ProgressBar::new_spinner();
    pb.set_message(msg.to_string());
    pb.enable_steady_tick(std::time::Duration::from_millis(100));
    pb
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

/// The renderer's memory per structure (bytes; per axis x, y, z where there
/// is one), its total, the budget and the process's peak resident memory.
fn memory_json(r: &Renderer) -> serde_json::Value {
    let m = r.memory();
    serde_json::json!({
        "volume": m.volume, "stacks": m.stacks, "normals": m.normals, "cell_codes": m.cell_codes, "masks": m.masks,
        "rle": m.rle, "intermediate": m.intermediate, "total": m.total(), "budget": r.memory_budget(),
        "peak_rss_bytes": crate::app::peak_rss_bytes(),
    })
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
    let dims = vol.dims();
    let cam = cmd.render.camera(vol.frame())?;
    let (mut r, scene) = cmd.render.renderer_and_scene(vol)?;
    let mut img = Image::new(cam.size[0], cam.size[1]);
    let build_ms = prepare_first(&mut r, &cam)?;
    let (stats, geometry) = scene.render(&mut r, &cam, &mut img)?;
    crate::app::output::write_image(&cmd.output, kind, &img.to_rgb8())?;
    let first_frame_ms = crate::app::since_start_ms();
    let warnings = shearwarp::checks::frame_warnings(&r, img.coverage());
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    if cmd.json {
        let s = r.settings();
        let j = serde_json::json!({
            "volume": name, "dims": dims, "tissue": r.classification_name(), "iso": r.iso(),
            "method": s.method.name(), "mode": s.mode.name(), "word": s.word.name(), "search": s.search.name(), "cell": s.cell,
            "projection": projection_json(r.projection()), "quality": r.quality(), "deluxe": r.settings().deluxe.label(), "grid": r.settings().lattice.name(),
            "cpu": s.cpu.capped().name(), "size": cam.size[0], "output": cmd.output, "build_ms": build_ms + stats.build_ms, "shear_ms": stats.shear_ms,
            "render_ms": stats.render_ms, "warp_ms": stats.warp_ms, "frame_ms": stats.frame_ms(),
            "axis": AXES[stats.axis], "rays": stats.rays, "coverage": img.coverage(), "warnings": warnings,
            "load_ms": load_ms, "first_frame_ms": first_frame_ms, "memory": memory_json(&r), "build": build_json(&r),
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
    let (vol, name) = cmd.volume.load()?;
    renderable(&name, &vol)?;
    let load_ms = crate::app::since_start_ms();
    let dims = vol.dims();
    let step = match cmd.step_deg.as_str() {
        "auto" => one_bit_step_deg(vol.dims()) * cmd.render.cell as f64,
        s => match s.parse::<f64>().ok().filter(|x| x.is_finite() && *x > 0.0) {
            Some(x) => x,
            None => usage!("--step-deg must be 'auto' or a positive number of degrees, got '{s}'"),
        },
    };
    if !(cmd.degrees.is_finite() && cmd.degrees > 0.0) {
        usage!("--degrees must be a positive number, got {}", cmd.degrees);
    }
    let frames = ((cmd.degrees / step).round() as usize).max(1);
    if frames > 1_000_000 {
        usage!("{frames} frames is too many (raise --step-deg)");
    }
    let cam0 = cmd.render.camera(vol.frame())?;
    let (mut r, scene) = cmd.render.renderer_and_scene(vol)?;
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
        if let Some(d) = &cmd.frames_dir {
            // (each frame whole or not at all; one sync for the directory after the loop)
            shearwarp::output::write_png_unsynced(d.join(format!("frame_{f:05}.png")), &img.to_rgb8())?;
        }
        first_frame_ms.get_or_insert_with(crate::app::since_start_ms);
        if keep_frames {
            kept.push(img.to_rgb8());
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
    let warnings = shearwarp::checks::frame_warnings(&r, img.coverage());
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    let col = |g: fn(&FrameStats) -> f64| median(&mut all.iter().map(g).collect::<Vec<_>>());
    let (shear, render, warp, frame) = (col(|s| s.shear_ms), col(|s| s.render_ms), col(|s| s.warp_ms), col(|s| s.frame_ms()));
    let fps = if frame > 0.0 { 1000.0 / frame } else { f64::INFINITY };
    // an animation of every frame of a long turn is huge (801 frames, 45 MB
    // for a full turn of a large scan): keep at most MAX_ANIMATION_FRAMES
    let kept = if kept.len() > MAX_ANIMATION_FRAMES {
        let every = kept.len().div_ceil(MAX_ANIMATION_FRAMES);
        let kept: Vec<_> = kept.into_iter().step_by(every).collect();
        eprintln!(
            "note: the animation keeps every {every}th of the {frames} frames ({} frames); --step-deg sets the step, --frames-dir keeps them all",
            kept.len()
        );
        kept
    } else {
        kept
    };
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
        j["memory"] = memory_json(&r);
        j["build"] = build_json(&r);
        j["quality"] = r.quality().into();
        j["deluxe"] = r.settings().deluxe.label().into();
        j["grid"] = r.settings().lattice.name().into();
        j["rle_reuse"] = r.settings().rle_reuse.into();
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
        shearwarp::checks::fmt_density(lo),
        shearwarp::checks::fmt_density(hi),
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
        let f = shearwarp::checks::fmt_bytes;
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
    if let Some(d) = cmd.out_dims {
        if d.iter().any(|&x| x > i16::MAX as usize) {
            usage!("--out-dims {d:?}: a .den file holds at most {} voxels per edge", i16::MAX);
        }
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
