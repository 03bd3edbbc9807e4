//! The argument types every command shares: where the volume comes from
//! ([`VolumeArgs`], and loading it), the render settings ([`RenderArgs`]:
//! settings, classification, camera, projection, clip planes, the scene),
//! and the value parsers they use. The commands (`cli`, `bench`, `viewer`)
//! build on these; these import none of them.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;

use shearwarp::classify::presets;
use shearwarp::composite::Mode;
use shearwarp::data::io;
use shearwarp::data::orientation::{PatientFrame, view_rotation};
use shearwarp::data::phantom::Phantom;
use shearwarp::data::volume::{Volume, VoxelType};
use shearwarp::encode::depth::Search;
use shearwarp::render::{Method, Normals, Renderer, Settings, WordSize};
use shearwarp::view::clip::{ClipPlane, ClipPlanes};
use shearwarp::view::{Camera, NamedView, Projection, rotate_eye};

use crate::app::{Usage, spinner};

/// `--eye-distance` when `--perspective` is given without it, in volume diagonals.
pub const DEFAULT_EYE_DISTANCE: f64 = 2.0;

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
    /// Phantom size X,Y,Z (default: head 128,128,113; sphere 128³; marschner-lobb 41³;
    /// cube 64³; engine, ellipsoid and torus 128³).
    #[arg(long, value_parser = parse_dims)]
    pub phantom_dims: Option<[usize; 3]>,
    /// Sample the phantom's analytic shape at this voxel spacing X,Y,Z in mm
    /// (e.g. 1,1,3 or clinical thick slices 0.6,0.6,5): the same physical
    /// shape (its size at spacing 1 is --phantom-dims), ⌊size / spacing⌋ + 1
    /// voxels per axis, and the volume's spacing set to match, so every view
    /// shows it at its true proportions. Sphere, marschner-lobb, ellipsoid and
    /// torus only (the phantoms with an analytic surface).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_phantom_spacing)]
    pub phantom_spacing: Option<[f64; 3]>,
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
    /// Under --reconstruction cubic (iso mode) codes are the cubic's normals
    /// at the voxels and the hit is found as the linear samples find it, then
    /// placed at the cubic's crossing (the fast preview); gradient follows
    /// the cubic to its first crossing and shades it with its own B-spline
    /// gradient (the still frame). Default: codes, except `render` under the
    /// cubic, which takes gradient.
    #[arg(long, value_enum)]
    pub normals: Option<Normals>,
    /// How the iso surface is reconstructed between samples: linear (the
    /// straight line between two slices) or cubic: Catmull–Rom through four
    /// samples along the volume's z axis, so thick-slice scans show no
    /// terraces or rings. On the binary and brute paths in iso mode, with
    /// --normals codes (the preview: `rotate`, `view`, `bench`) a ray finds
    /// its hit as the linear samples do and places it at the cubic's
    /// crossing, shaded by the cubic's normal at the voxels (the B-spline
    /// gradient, as codes): on a 0.6×0.6×5 ellipsoid the preview's normal
    /// error drops from 3.3° to 1.1° mean, and the frame costs 1.15–1.3×
    /// linear's on thick-slice volumes (benches/README.md); with --normals
    /// gradient (`render`'s still frame) the ray follows the cubic to its
    /// first crossing and shades it by the B-spline gradient there (0.85°
    /// mean; 1.4–1.6× linear's frame on a 5 mm-slice CT). Blend mode ignores
    /// it there. On --method rle and brute-rle (both modes, pre-classified or
    /// --deluxe P) cubic keeps the samples and gives each voxel the cubic's
    /// normal there as its normal code, so the shading terraces less on thick
    /// slices (the codes' error on the ellipsoid drops from 4.4° to 1.8°
    /// mean). Default: cubic for a scan whose slices are at least 1.5× as
    /// far apart as its pixels, on the binary and brute paths in iso mode
    /// and on the RLE paths (`render`, `rotate`, `view`; on the chest CT's
    /// 5 mm slices the RLE frame costs the same within 2 %), else linear
    /// (on isotropic scans both err alike and the linear frame is cheaper);
    /// `bench` and --distributed take linear. --deluxe I, --grid bcc and
    /// --distributed refuse cubic.
    #[arg(long, value_enum)]
    pub reconstruction: Option<shearwarp::kernels::Reconstruction>,
    /// Worker threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Tissue preset: skin, fat, soft, bone (CT in Hounsfield units); low, mid,
    /// high (other volumes, from the histogram); or auto (the first).
    #[arg(long)]
    pub tissue: Option<String>,
    /// Super-cell size S (1..=8) or auto: the mask shrinks by S², a shear
    /// step moves S voxels; every size renders the same image. auto: `rotate`
    /// and `view` take the smallest S at which a ray's depth row of the mask
    /// is at most one cache line (64 bytes): 1 for a one-bit mask of up to
    /// 512 slices, 2 for the tissue presets (two-bit codes) of a scan with
    /// more than 256 slices, where the shear's memory traffic would otherwise
    /// set the frame rate; `render`, `bench` and --distributed take 1 (a
    /// still frame shears once).
    #[arg(long, default_value = "auto", value_parser = parse_cell)]
    pub cell: CellArg,
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
    /// samples per voxel as the output magnifies). E.g. --deluxe I,P; S
    /// for none. Default: none, except that `render` of a scan whose slices
    /// are at least 1.5× as far apart as its pixels takes P on --method rle
    /// in iso mode (pre-classified opacity, interpolated across thick
    /// slices, draws each slice as a band: on the 0.6×0.6×5 ellipsoid P's
    /// image error is an eighth, for about 3× the frame, benches/README.md).
    #[arg(long, value_name = "LIST", value_parser = parse_deluxe)]
    pub deluxe: Option<shearwarp::Deluxe>,
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

pub(crate) fn parse_window(s: &str) -> std::result::Result<[f32; 2], String> {
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

pub(crate) fn parse_dims(s: &str) -> std::result::Result<[usize; 3], String> {
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

fn parse_phantom_spacing(s: &str) -> std::result::Result<[f64; 3], String> {
    let d: [f64; 3] = parse_triple(s, "numbers")?;
    if d.iter().any(|x| !x.is_finite() || *x <= 0.0) {
        return Err(format!("the phantom spacing must be three finite numbers of mm > 0, got {s}"));
    }
    Ok(d)
}

/// `--opacity`: a blend-mode transfer function from (density, opacity) control
/// points, in a constant bone-white colour.
/// `--cell`: a super-cell size, or auto (chosen by the command).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CellArg {
    Auto,
    Size(usize),
}

impl CellArg {
    /// The size given, or `auto` for auto.
    pub fn or(self, auto: usize) -> usize {
        match self {
            CellArg::Auto => auto,
            CellArg::Size(s) => s,
        }
    }

    /// The size given, or the cell size `r` takes for a rotation
    /// ([`Renderer::auto_cell`]), set on `r`.
    pub fn resolve(self, r: &mut Renderer) -> Result<usize> {
        let cell = self.or(r.auto_cell());
        if r.settings().cell != cell {
            r.set_settings(Settings { cell, ..r.settings() })?;
        }
        Ok(cell)
    }
}

fn parse_cell(s: &str) -> std::result::Result<CellArg, String> {
    let max = shearwarp::encode::mask::MAX_CELL;
    match s {
        "auto" => Ok(CellArg::Auto),
        _ => match s.parse::<usize>() {
            Ok(n) if (1..=max).contains(&n) => Ok(CellArg::Size(n)),
            _ => Err(format!("must be auto or 1..={max}, got '{s}'")),
        },
    }
}

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
    shearwarp::memory::parse_bytes(s).map_err(|e| e.to_string())
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
    if let Err(e) = shearwarp::render::checks::check_renderable(vol.dims()) {
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
            let f = shearwarp::fmt::fmt_bytes;
            usage!("{name}: the volume alone holds {}, over the memory budget of {} (--max-memory)", f(bytes), f(b));
        }
        Ok((vol, name))
    }

    /// The analytic shape of the phantom as loaded (`None` for a file, and
    /// for a phantom without one unless `--phantom-spacing` asks to resample
    /// it, which is an error naming the phantom).
    pub fn analytic(&self) -> Result<Option<shearwarp::data::shapes::AnalyticPhantom>> {
        if self.file.is_some() || self.raw.is_some() || self.den.is_some() {
            if self.phantom_spacing.is_some() {
                usage!(
                    "--phantom-spacing samples a built-in phantom; it does not apply to a volume file (--spacing sets a file's spacing)"
                );
            }
            return Ok(None);
        }
        let p = self.phantom;
        let dims = self.phantom_dims.unwrap_or_else(|| p.default_dims());
        match p.analytic(dims, self.phantom_spacing) {
            Ok(None) if self.phantom_spacing.is_some() => usage!(
                "--phantom-spacing: the {} phantom has no analytic shape to sample at another spacing \
                 (sphere, marschner-lobb, ellipsoid and torus do)",
                p.name()
            ),
            Ok(a) => Ok(a),
            Err(e) => usage!("--phantom-spacing: {e}"),
        }
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
                // (a phantom without an analytic shape, or a spacing too fine to allocate: named)
                self.analytic()?;
                // checked before a byte is allocated
                let bytes = p.bytes_sampled(dims, self.phantom_spacing).unwrap_or(u64::MAX);
                if let Some(b) = crate::app::budget().filter(|&b| bytes > b) {
                    let f = shearwarp::fmt::fmt_bytes;
                    let d = self.analytic()?.map_or(dims, |a| a.grid.dims);
                    usage!(
                        "{} phantom {}×{}×{}: its voxels need {}, over the memory budget of {} (--max-memory)",
                        p.name(),
                        d[0],
                        d[1],
                        d[2],
                        f(bytes),
                        f(b)
                    );
                }
                p.build_sampled(dims, self.phantom_spacing)?
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
            None => match self.phantom_spacing {
                Some(s) => format!("{} phantom at {}×{}×{} mm", self.phantom.name(), s[0], s[1], s[2]),
                None => format!("{} phantom", self.phantom.name()),
            },
        };
        Ok((vol, name))
    }
}

/// Whether a scan's slices lie at least 1.5× as far apart as its pixels
/// (`spacing` per volume axis, z the slice axis): where linear
/// reconstruction shows terraces and every command takes the cubic.
fn thick_slices(spacing: [f32; 3]) -> bool {
    spacing[2] >= 1.5 * spacing[0].min(spacing[1])
}

impl RenderArgs {
    /// The settings `s` (its reconstruction chosen) of a still frame
    /// (`render`) of a volume of voxel `spacing`, where the options leave it
    /// open:
    /// - without --deluxe, on the RLE path in iso mode over thick slices
    ///   ([`thick_slices`]), the post-classified sampler (Deluxe P):
    ///   pre-classification interpolates each voxel's classified opacity, so
    ///   across slices several voxels apart a sharp transfer function turns
    ///   every slice into a band; P classifies the interpolated density;
    /// - without --normals, the cubic iso ray cast follows the cubic to its
    ///   first crossing and shades it by the cubic's own gradient (the
    ///   preview's codes are for speed).
    pub fn with_still_settings(&self, s: Settings, spacing: [f32; 3]) -> Settings {
        let iso = s.mode == Mode::Iso;
        let mut s = s;
        if self.deluxe.is_none() && thick_slices(spacing) && s.method.is_rle() && iso {
            s.deluxe = shearwarp::Deluxe { post: true, ..s.deluxe };
        }
        if self.normals.is_none() && s.reconstruction == shearwarp::kernels::Reconstruction::Cubic && s.method.is_raycast() && iso {
            s.normals = Normals::Gradient;
        }
        s
    }

    /// The settings `s` with the reconstruction a command takes for a volume
    /// of voxel `spacing` when --reconstruction is not given: the cubic where
    /// the slices are thick ([`thick_slices`]) and the method renders it (the
    /// raycast paths' iso hit, or the RLE paths' normal codes: either mode,
    /// their shading reads them), else `s`'s. On thick slices the cubic's
    /// preview costs 1.0–1.3× the linear frame and cuts the normal error to a
    /// third (benches/README.md); on isotropic volumes both err alike and the
    /// linear frame is cheaper.
    pub fn with_default_reconstruction(&self, s: Settings, spacing: [f32; 3]) -> Settings {
        if self.reconstruction.is_some() || !thick_slices(spacing) {
            return s;
        }
        let raycast = s.mode == Mode::Iso && s.method.is_raycast();
        let rle = s.method.is_rle() && s.lattice == shearwarp::render::Lattice::Cartesian;
        if (raycast || rle) && !s.deluxe.intermediate {
            Settings { reconstruction: shearwarp::kernels::Reconstruction::Cubic, ..s }
        } else {
            s
        }
    }

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
        shearwarp::render::checks::check_renderable(vol.dims())?;
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
        if !(self.ert > 0.0 && self.ert <= 1.0) {
            usage!("--ert must be in (0, 1], got {}", self.ert);
        }
        if self.size == 0 || self.size > 16384 {
            usage!("--size must be 1..=16384, got {}", self.size);
        }
        shearwarp::render::checks::check_threads(self.threads)?;
        Ok(Settings {
            method: self.method,
            mode: self.mode,
            word: self.word,
            search: self.search,
            normals: self.normals.unwrap_or(Normals::Codes),
            footprint: self.footprint,
            deluxe: self.deluxe.unwrap_or_default(),
            lattice: self.grid,
            rle_reuse: self.rle_reuse,
            reconstruction: self.reconstruction.unwrap_or_default(),
            ert: self.ert,
            cell: self.cell.or(1),
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
        if let Some(z) = self.zoom
            && !(z.is_finite() && z > 0.0)
        {
            usage!("--zoom must be finite and > 0, got {z}");
        }
        Ok(Camera { rotation: r, zoom: self.zoom, size: [self.size, self.size] })
    }
}
