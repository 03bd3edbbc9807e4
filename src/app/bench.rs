//! `shearwarp bench`: speed against accuracy, for every render variant.
//!
//! Runs a matrix of render variants ([`registry`]: named [`Settings`]) over one
//! volume and a set of views ([`standard_views`]), and for each measures
//!
//! * the **median frame time** (shear + render + warp, [`FrameStats::frame_ms`])
//!   of several repetitions after untimed warm-up frames, with every axis's
//!   stack and mask prebuilt by [`Renderer::prepare_all_axes`], repeated in
//!   several rounds over the whole matrix so that a change in machine load
//!   biases no variant; the first frame of each view also reports its *cold*
//!   shear (moving the mask from the previous state), which the repeated
//!   frames of a still view do not pay;
//! * the **error against the reference** ([`shearwarp::accuracy::reference`], same camera,
//!   pixel for pixel): RMSE, PSNR, maximum absolute error, SSIM and the
//!   silhouette error of [`shearwarp::accuracy::metrics`];
//! * in iso mode, the **iso depth error** in voxels of the finest spacing
//!   against the analytic truth ([`shearwarp::accuracy::truth::surface_truth`])
//!   when the volume is a phantom with an analytic surface (the sphere,
//!   Marschner–Lobb, the ellipsoid, the torus, at any `--phantom-spacing`),
//!   in both projections, else against the reference's depth; against the
//!   analytic truth also the **normal-angle error** in degrees between the
//!   normal the variant shades with ([`fast_path_normals`]) and the
//!   surface's, and the silhouette (pixels hit in only one of them). Every
//!   row names the `reconstruction` of its iso hit ([`reconstruction`]).
//!
//! `--suite surfaces` runs the surface cases ([`SUITE_SURFACES`]) one after
//! the other and adds a table of depth and normal error and frame time per
//! case and variant.
//!
//! The RLE paths keep no iso hit (they composite opacity, in iso mode too),
//! so their rows carry image error only. A perspective frame split into
//! pyramids is rendered once more, untimed, keeping the pyramids' depths
//! for its depth and normal error.
//!
//! Results go out as Markdown tables (one row per variant, aggregated over the
//! views), CSV and JSON (one record per variant and view), and a plot of time
//! against error (RMSE, depth or normal error: [`PlotError`]) with the Pareto
//! front of each mode by that error marked.
//!
//! New render options join the benchmark by adding a [`Variant`] to
//! [`registry`]; nothing else in the harness needs to change.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;

use crate::app::Usage;
use crate::app::args::VolumeArgs;
use crate::app::peers::{self, MODEL_SHADING, Peer, PeerCamera, PeerModel, PeerSchedule, PeerView};
use shearwarp::accuracy::metrics::{DepthError, ImageError, NormalError, compare, depth_error, normal_error};
use shearwarp::accuracy::reference::{ReferenceImage, ReferenceOptions, ReferenceRenderer, Scene, fast_path_depth, fast_path_normals};
use shearwarp::accuracy::truth::surface_truth;
use shearwarp::classify::presets;
use shearwarp::classify::shading::Shading;
use shearwarp::composite::Mode;
use shearwarp::data::phantom::Phantom;
use shearwarp::data::volume::Volume;
use shearwarp::encode::depth::Search;
use shearwarp::kernels::Reconstruction;
use shearwarp::render::{Deluxe, FrameStats, Lattice, Method, Normals, Renderer, Settings, WordSize};
use shearwarp::view::{Camera, Factorization, NamedView, Projection, View, standard_views};
use shearwarp::warp::Image;

/// `shearwarp bench`.
#[derive(Args, Debug, Clone)]
pub struct BenchCmd {
    #[command(flatten)]
    pub volume: VolumeArgs,
    /// Output image size N (N×N pixels).
    #[arg(long, default_value_t = 256)]
    pub size: usize,
    /// Modes to benchmark, comma-separated.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "iso,blend")]
    pub modes: Vec<Mode>,
    /// Tissue preset (as for `render`; default: the first of the volume's presets).
    #[arg(long)]
    pub tissue: Option<String>,
    /// Iso value (default: 100 for the sphere, ellipsoid and torus phantoms, 0.5 for Marschner–Lobb, else the tissue's threshold).
    #[arg(long, allow_negative_numbers = true)]
    pub iso: Option<f32>,
    /// Timed repetitions per view and round (the median over all rounds is reported).
    #[arg(long, default_value_t = 3)]
    pub reps: usize,
    /// Rounds over the whole matrix: spreads each variant's frames over the run,
    /// so a change in machine load biases no variant.
    #[arg(long, default_value_t = 3)]
    pub rounds: usize,
    /// Untimed warm-up frames per view (at least 1; the first one records the cold shear).
    #[arg(long, default_value_t = 1)]
    pub warmup: usize,
    /// Seeded random views in addition to the fixed ones.
    #[arg(long, default_value_t = 2)]
    pub random_views: usize,
    /// Seed of the random views.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Reference step along each ray, in voxels of the smallest spacing.
    #[arg(long, default_value_t = shearwarp::accuracy::reference::DEFAULT_STEP)]
    pub ref_step: f64,
    /// The reconstructions of the iso surface, comma-separated: `linear`
    /// (trilinear: the straight line between two slices) and/or `cubic`
    /// (Catmull–Rom through four z slices, bilinear in-plane; the normal
    /// from B-spline-blended central differences). Each iso variant of the
    /// raycast paths (binary, brute; not Deluxe I) runs once per
    /// reconstruction, a cubic one named `…-cubic`; the other variants stay
    /// linear. The reference reconstructs with the last one listed (image
    /// and depth errors are measured against it; the suite's table gets one
    /// `reference` row per case with its own depth and normal error).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "linear")]
    pub reconstruction: Vec<Reconstruction>,
    /// Only these variants (comma-separated): a variant's exact name selects
    /// just that variant; any other string selects every variant containing it.
    #[arg(long, value_delimiter = ',')]
    pub only: Vec<String>,
    /// Early ray termination threshold of the fast paths in blend mode.
    #[arg(long, default_value_t = 0.99)]
    pub ert: f32,
    /// Worker threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Write one CSV row per variant and view.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Print JSON (records and summary) instead of the Markdown tables.
    #[arg(long)]
    pub json: bool,
    /// Also write the JSON report to this file (the Markdown still goes to stdout).
    #[arg(long, value_name = "FILE")]
    pub json_out: Option<PathBuf>,
    /// Write a plot of frame time against error (.svg or .png; repeat for
    /// both), the error --plot-error names; with --suite one panel per case.
    #[arg(long)]
    pub plot: Vec<PathBuf>,
    /// The error the plot draws against frame time, with each mode's Pareto
    /// front by that error.
    #[arg(long, value_enum, default_value = "rmse")]
    pub plot_error: PlotError,
    /// Also print one Markdown row per variant and view.
    #[arg(long)]
    pub per_view: bool,
    /// Also benchmark every path under perspective projections with these
    /// vertical fields of view in degrees (comma-separated or repeated), from
    /// each of the --eye-distance values, beside the parallel rows: variants
    /// "rle-persp", "brute-rle-persp", "binary-persp", "brute-persp" (suffixed
    /// "-f<FOV>-d<D>" when more than one projection is measured); errors
    /// against the perspective reference. A path that cannot render a view is
    /// listed as skipped, with the reason.
    #[arg(long, value_name = "FOV_DEGREES", allow_negative_numbers = true, value_delimiter = ',')]
    pub perspective: Vec<f64>,
    /// With --perspective: the eye's distances from the volume's centre in
    /// volume diagonals (comma-separated or repeated) [default: 2].
    #[arg(long, value_name = "D", allow_negative_numbers = true, value_delimiter = ',', requires = "perspective")]
    pub eye_distance: Vec<f64>,
    /// The perspective matrix: fields of view 20°, 40° and 60°
    /// from 3, 1.5 and 0.75 volume diagonals, and the eye inside the volume
    /// (60° from 0.1 diagonals), beside the parallel rows (adds to any
    /// --perspective).
    #[arg(long)]
    pub perspective_matrix: bool,
    /// Peer renderers measured beside shearwarp's variants (comma-separated):
    /// each renders the benchmark's own views (parallel and every
    /// perspective) through its harness, and its frames are measured against
    /// the same reference. Blend mode only, on a `.den` volume (`shearwarp
    /// export` writes one); the blend rows then all use the peers' model:
    /// VolPack's opaque ramp at the --iso threshold (default: the tissue's)
    /// with its 0.05 cut, white, ambient 0.1 / diffuse 0.6 / specular 0.3^20.
    #[arg(long, value_enum, value_delimiter = ',')]
    pub peers: Vec<Peer>,
    /// Directory for the peers' frames and view lists (default: a fresh
    /// directory under the system's temporary directory).
    #[arg(long, requires = "peers")]
    pub peer_dir: Option<PathBuf>,
    /// Shear-Warp Deluxe options (a comma-separated subset of I,P,M; `S` for
    /// none) applied to every variant, whose names then end in
    /// `-deluxe-<LABEL>` (e.g. `rle-deluxe-IP`). Repeat it to measure every
    /// variant under each set in the same run (`--deluxe S --deluxe I`: the
    /// plain rows and their I rows side by side). Without it the matrix
    /// already holds every option combination of the RLE path and the
    /// raycast paths' I, M and IM (parallel only).
    #[arg(long, value_name = "LIST", value_parser = crate::app::args::parse_deluxe, action = clap::ArgAction::Append)]
    pub deluxe: Vec<shearwarp::Deluxe>,
    /// The sample lattice of every variant: `bcc` renders each variant on the
    /// body-centred cubic grid (names end in `-bcc`); without it the matrix
    /// holds the RLE path's BCC variants beside the cartesian ones.
    #[arg(long = "grid", value_name = "GRID", value_enum)]
    pub grid: Option<shearwarp::Lattice>,
    /// Run a list of cases instead of one volume: `surfaces` measures iso
    /// mode against the analytic surface on the sphere (128³) and
    /// Marschner–Lobb (41³) phantoms, each at isotropic and 1×1×3 spacing,
    /// and the ellipsoid at 0.6×0.6×5 (thick slices): depth error in voxels
    /// of the finest spacing, normal-angle error in degrees and frame time per
    /// case and variant, beside each case's own tables. The variants are
    /// --only's, by default the binary iso preview and the RLE path; the
    /// volume options do not apply.
    #[arg(long, value_enum)]
    pub suite: Option<Suite>,
    /// No progress bar.
    #[arg(long, short)]
    pub quiet: bool,
    /// Time the frames of one volume split over the ranks of an MPI job
    /// (launch with `mpirun -np N`; needs the build with feature `mpi`):
    /// each rank reads and renders its own brick, rank 0 composites, warps
    /// and reports every variant's frame time with each rank's render and
    /// compositing times and bytes. The binary and RLE variants of the
    /// parallel, cartesian matrix run; the others are listed as skipped.
    /// No reference, accuracy columns, CSV, plots or peers (a distributed
    /// frame equals the single process's).
    #[arg(long)]
    pub distributed: bool,
}

/// The error a plot draws against frame time (`--plot-error`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum PlotError {
    /// Mean RMSE of the displayed image against the reference.
    Rmse,
    /// Mean iso depth error in voxels of the finest spacing (against the
    /// analytic surface where the volume has one, else the reference's
    /// depth; iso mode).
    Depth,
    /// Mean angle in degrees between the normal each variant shades with and
    /// the analytic surface's (iso mode, phantoms with an analytic surface).
    Normal,
}

impl PlotError {
    /// A variant's value of this error (`None`: not measured for it).
    pub fn of(self, s: &Summary) -> Option<f64> {
        match self {
            PlotError::Rmse => Some(s.rmse_mean),
            PlotError::Depth => s.depth_mean_vox,
            PlotError::Normal => s.normal_deg_mean,
        }
        .filter(|v| v.is_finite())
    }

    /// The plot's axis label.
    fn label(self) -> &'static str {
        match self {
            PlotError::Rmse => "mean RMSE vs reference (log scale)",
            PlotError::Depth => "mean depth error, voxels (log scale)",
            PlotError::Normal => "mean normal error, degrees (log scale)",
        }
    }

    /// Its short name, for titles.
    fn name(self) -> &'static str {
        match self {
            PlotError::Rmse => "RMSE",
            PlotError::Depth => "depth error",
            PlotError::Normal => "normal error",
        }
    }
}

/// A list of benchmark cases (`--suite`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Suite {
    /// The analytic surfaces at isotropic and thick-slice spacings.
    Surfaces,
}

/// One case of a suite: a phantom, its size at spacing 1 and the spacing it
/// is sampled at (`None`: its own).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Case {
    pub name: &'static str,
    pub phantom: Phantom,
    pub dims: [usize; 3],
    pub spacing: Option<[f64; 3]>,
}

/// The cases of `--suite surfaces`: the ball and Marschner–Lobb at their
/// standard sizes, isotropic and with slices three times thicker than the
/// pixels, and a smooth shape at a clinical thick-slice spacing.
pub const SUITE_SURFACES: [Case; 5] = [
    Case { name: "ball 128³", phantom: Phantom::Sphere, dims: [128; 3], spacing: None },
    Case { name: "ball 1×1×3", phantom: Phantom::Sphere, dims: [128; 3], spacing: Some([1.0, 1.0, 3.0]) },
    Case { name: "marschner-lobb 41³", phantom: Phantom::MarschnerLobb, dims: [41; 3], spacing: None },
    Case { name: "marschner-lobb 1×1×3", phantom: Phantom::MarschnerLobb, dims: [41; 3], spacing: Some([1.0, 1.0, 3.0]) },
    Case { name: "ellipsoid 0.6×0.6×5", phantom: Phantom::Ellipsoid, dims: [128; 3], spacing: Some([0.6, 0.6, 5.0]) },
];

/// The variants a suite runs when `--only` names none: the binary iso
/// preview and the RLE path.
pub const SUITE_VARIANTS: [&str; 2] = ["binary-c1-u64-bitscan", "rle"];

/// The same under each `--perspective` projection ([`perspective_variants`]).
pub const SUITE_PERSPECTIVE_VARIANTS: [&str; 2] = ["binary-persp", "rle-persp"];

/// How a variant reconstructs the iso hit between samples: `linear` (the
/// crossing on the straight line between two slices, the normal the
/// trilinear gradient or the corners' codes), today for every variant.
pub fn reconstruction(settings: &Settings) -> &'static str {
    match settings.mode {
        Mode::Iso => settings.reconstruction.name(),
        Mode::Blend => Reconstruction::Linear.name(),
    }
}

/// `variants` once per reconstruction of `recons`: as they are for
/// `linear`, and for `cubic` the iso variants that render it (the raycast
/// paths without Deluxe I), named `…-cubic` (with normal codes: the hit of
/// the linear samples placed by the cubic's crossing, shaded by the cubic's
/// codes) and, for a variant with codes, `…-cubic-gradient` (the cubic's
/// first crossing, shaded by its B-spline gradient).
pub fn with_reconstructions(variants: Vec<Variant>, recons: &[Reconstruction]) -> Vec<Variant> {
    let mut out = vec![];
    for &r in recons {
        for v in &variants {
            match r {
                Reconstruction::Linear => out.push(v.clone()),
                Reconstruction::Cubic => {
                    let s = v.settings;
                    if s.mode == Mode::Iso && s.method.is_raycast() && !s.deluxe.intermediate {
                        let settings = Settings { reconstruction: r, ..s };
                        out.push(Variant { name: format!("{}-cubic", v.name), settings, ..v.clone() });
                        if s.normals == Normals::Codes {
                            // the cubic's own first crossing and gradient (what `render` takes)
                            let settings = Settings { normals: Normals::Gradient, ..settings };
                            out.push(Variant { name: format!("{}-cubic-gradient", v.name), settings, ..v.clone() });
                        }
                    }
                }
            }
        }
    }
    out.dedup_by(|a, b| a.name == b.name);
    out
}

/// A named render variant of the benchmark matrix.
#[derive(Clone, Debug, PartialEq)]
pub struct Variant {
    pub name: String,
    pub settings: Settings,
    /// Parallel, or the perspective of `--perspective`.
    pub projection: Projection,
    /// Intermediate image pixels per voxel ([`Renderer::set_quality`]): 1,
    /// or 2 for the `-q2` variants (finer slices where the output magnifies).
    pub quality: f64,
}

/// The intermediate resolution of the `-q2` variants: Schulze's adaptive
/// size at its finest, two pixels per voxel (what a zoomed-in view needs
/// for the output's sampling rate; Deluxe's matched sampling generalizes it).
pub const FINE_QUALITY: f64 = 2.0;

/// Every variant benchmarked for the mode and shared settings of `base`:
/// the binary fast rotator with cell sizes 1–4, u32 and u64 words, LUT and
/// bit-scan search; in blend mode also without early ray termination; and
/// brute force; Lacroute's RLE path and its pre-classified brute-force
/// reference. Register new render options here.
pub fn registry(base: Settings) -> Vec<Variant> {
    let mut v = Vec::new();
    for cell in 1..=4 {
        for word in [WordSize::U32, WordSize::U64] {
            for search in [Search::Lut, Search::Bitscan] {
                v.push(Variant {
                    name: format!("binary-c{cell}-{}-{}", word.name(), search.name()),
                    settings: Settings { method: Method::Binary, cell, word, search, ..base },
                    projection: Projection::Parallel,
                    quality: 1.0,
                });
            }
        }
    }
    if base.mode == Mode::Blend && base.ert < 1.0 {
        // what early ray termination costs in accuracy and buys in time
        v.push(Variant {
            name: "binary-c1-u64-bitscan-noert".into(),
            settings: Settings { method: Method::Binary, ert: 1.0, ..base },
            projection: Projection::Parallel,
            quality: 1.0,
        });
    }
    let par = Projection::Parallel;
    let binary = Settings { method: Method::Binary, cell: 1, word: WordSize::U64, search: Search::Bitscan, ..base };
    let rle = Settings { method: Method::Rle, cell: 1, ..base };
    let variant = |name: &str, settings: Settings, quality: f64| Variant { name: name.into(), settings, projection: par, quality };
    v.push(variant("binary-c1-u64-bitscan-q2", binary, FINE_QUALITY));
    v.push(variant("brute", Settings { method: Method::Brute, cell: 1, ..base }, 1.0));
    v.push(variant("rle", rle, 1.0));
    v.push(variant("rle-q2", rle, FINE_QUALITY));
    v.push(variant("brute-rle", Settings { method: Method::BruteRle, cell: 1, ..base }, 1.0));
    if base.deluxe.is_standard() && base.lattice == Lattice::Cartesian {
        v.extend(deluxe_variants(base));
    }
    v
}

/// The Shear-Warp Deluxe variants: the RLE path with every
/// combination of I, P and M (`rle-deluxe-I`, …, `rle-deluxe-IMP`), the binary
/// rotator with I, M and IM (it classifies after interpolation already: P
/// adds nothing), the RLE path with one encoding serving two axes
/// (`rle-reuse`), and the RLE path on the BCC grid with S and the paper's
/// columns I, IP, IM, IMP (`rle-bcc`, `rle-bcc-deluxe-I`, …).
pub fn deluxe_variants(base: Settings) -> Vec<Variant> {
    let par = Projection::Parallel;
    let binary = Settings { method: Method::Binary, cell: 1, word: WordSize::U64, search: Search::Bitscan, ..base };
    let rle = Settings { method: Method::Rle, cell: 1, ..base };
    let named = |settings: Settings, prefix: &str, d: Deluxe| Variant {
        name: format!("{prefix}-deluxe-{}", d.label()),
        settings: Settings { deluxe: d, ..settings },
        projection: par,
        quality: 1.0,
    };
    let mut v: Vec<Variant> = Deluxe::all().into_iter().filter(|d| !d.is_standard()).map(|d| named(rle, "rle", d)).collect();
    v.extend(Deluxe::all().into_iter().filter(|d| !d.is_standard() && !d.post).map(|d| named(binary, "binary-c1-u64-bitscan", d)));
    // one encoding serving two axes (Deluxe's RLE reuse)
    v.push(Variant { name: "rle-reuse".into(), settings: Settings { rle_reuse: true, ..rle }, projection: par, quality: 1.0 });
    let bcc = Settings { lattice: Lattice::Bcc, ..rle };
    v.push(Variant { name: "rle-bcc".into(), settings: bcc, projection: par, quality: 1.0 });
    v.extend(PAPER_COLUMNS.iter().map(|l| named(bcc, "rle-bcc", Deluxe::parse(l).expect("a valid label"))));
    v
}

/// The option columns of the paper's Table 1 at 512² (after S).
pub const PAPER_COLUMNS: [&str; 4] = ["I", "I,P", "I,M", "I,M,P"];

/// `variants` with the benchmark's `--deluxe` sets and `--grid` applied to
/// every one (each variant once per set, in the order given), their names
/// suffixed `-deluxe-<LABEL>` and `-bcc`; a name met twice is kept once.
pub fn with_options(variants: Vec<Variant>, deluxe: &[Deluxe], grid: Option<Lattice>) -> Vec<Variant> {
    let sets: &[Deluxe] = if deluxe.is_empty() { &[Deluxe::default()] } else { deluxe };
    let mut out: Vec<Variant> = vec![];
    for &d in sets {
        for mut v in variants.iter().cloned() {
            if let Some(g) = grid.filter(|&g| g != Lattice::Cartesian) {
                v.settings.lattice = g;
                v.name = format!("{}-{}", v.name, g.name());
            }
            if !d.is_standard() {
                v.settings.deluxe = d;
                v.name = format!("{}-deluxe-{}", v.name, d.label());
            }
            if !out.iter().any(|o| o.name == v.name) {
                out.push(v);
            }
        }
    }
    out
}

/// The variants that render `projection` (a perspective one): the RLE path
/// and its brute force, the binary rotator (cell 1, u64 words, bit scan) and
/// its brute force, named `rle-persp`, `brute-rle-persp`, `binary-persp` and
/// `brute-persp`, and the two fast paths at [`FINE_QUALITY`]
/// (`binary-persp-q2`, `rle-persp-q2`), each followed by `suffix`.
pub fn perspective_variants(base: Settings, projection: Projection, suffix: &str) -> Vec<Variant> {
    let binary = Settings { method: Method::Binary, cell: 1, word: WordSize::U64, search: Search::Bitscan, ..base };
    let rle = Settings { method: Method::Rle, cell: 1, ..base };
    [
        (binary, "binary-persp", 1.0),
        (binary, "binary-persp-q2", FINE_QUALITY),
        (Settings { method: Method::Brute, cell: 1, ..base }, "brute-persp", 1.0),
        (rle, "rle-persp", 1.0),
        (rle, "rle-persp-q2", FINE_QUALITY),
        (Settings { method: Method::BruteRle, cell: 1, ..base }, "brute-rle-persp", 1.0),
    ]
    .map(|(settings, name, quality)| Variant { name: format!("{name}{suffix}"), settings, projection, quality })
    .to_vec()
}

/// The perspective projections of `--perspective-matrix`: fields
/// of view 20°, 40°, 60° from 3, 1.5 and 0.75 volume diagonals, and 60° from
/// 0.1 diagonals (the eye inside).
pub fn perspective_matrix() -> Vec<Projection> {
    let mut v: Vec<Projection> = [20.0, 40.0, 60.0]
        .iter()
        .flat_map(|&fov_deg| [3.0, 1.5, 0.75].map(|eye_distance| Projection::Perspective { fov_deg, eye_distance }))
        .collect();
    v.push(Projection::Perspective { fov_deg: 60.0, eye_distance: 0.1 });
    v
}

/// One variant at one view.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Record {
    pub mode: &'static str,
    pub variant: String,
    pub view: String,
    /// Principal axis of the view (0 = x).
    pub axis: usize,
    /// Medians over the timed repetitions.
    pub frame_ms: f64,
    pub shear_ms: f64,
    pub render_ms: f64,
    pub warp_ms: f64,
    /// Shear time of the view's first frame (from the previous view's state).
    pub cold_shear_ms: f64,
    pub error: ImageError,
    /// `analytic` or `reference` (iso mode only).
    pub depth_truth: Option<&'static str>,
    pub depth: Option<DepthError>,
    /// How the iso hit is reconstructed ([`reconstruction`]).
    pub reconstruction: &'static str,
    /// The shading normal's angle to the analytic surface's (iso mode, analytic truth only).
    pub normal: Option<NormalError>,
}

/// One variant aggregated over the views.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Summary {
    pub mode: &'static str,
    pub variant: String,
    /// Median over the views of the per-view median frame time.
    pub frame_ms: f64,
    /// Median over the views of the cold shear.
    pub cold_shear_ms: f64,
    pub rmse_mean: f64,
    pub psnr_worst: f64,
    pub max_abs: f64,
    pub ssim_mean: f64,
    pub silhouette_max: f64,
    /// Depth error over all pixels hit in both, pooled over views (mean), and the worst view's 99th percentile.
    pub depth_mean_vox: Option<f64>,
    pub depth_p99_vox: Option<f64>,
    /// How the iso hit is reconstructed ([`reconstruction`]).
    pub reconstruction: &'static str,
    /// Against the analytic truth only: the worst view's 99th percentile of
    /// the depth error, in voxels of the finest spacing.
    pub depth_p99: Option<f64>,
    /// Against the analytic truth only: the normal-angle error in degrees,
    /// pooled over the views (mean) and the worst view's 99th percentile and maximum.
    pub normal_deg_mean: Option<f64>,
    pub normal_deg_p99: Option<f64>,
    pub normal_deg_max: Option<f64>,
    /// On the Pareto front of (frame time, mean RMSE) within its mode.
    pub pareto: bool,
}

/// Measurements of one variant at one view, over the rounds.
#[derive(Default)]
struct Acc {
    frames: Vec<FrameStats>,
    cold: Vec<f64>,
    axis: usize,
    error: Option<ImageError>,
    depth: Option<(&'static str, DepthError)>,
    normal: Option<NormalError>,
    /// Why this variant cannot render this view (it is left out of the records).
    skipped: Option<String>,
}

/// The reference of one mode and view.
struct RefFrame {
    image: ReferenceImage,
    /// The depth the fast paths are compared with, and what it is.
    truth: Option<(Vec<f64>, &'static str)>,
    /// The analytic surface's normals (analytic truth only).
    normals: Option<Vec<glam::DVec3>>,
}

fn usage(msg: String) -> anyhow::Error {
    anyhow::Error::new(Usage(msg))
}

/// [`crate::app::median`]; NaN for no values (a table cell with nothing measured).
fn median(v: &mut [f64]) -> f64 {
    crate::app::median(v).unwrap_or(f64::NAN)
}

impl BenchCmd {
    pub(crate) fn check(&self) -> Result<()> {
        if self.size == 0 || self.size > 8192 {
            return Err(usage(format!("--size must be 1..=8192, got {}", self.size)));
        }
        if self.reps == 0 || self.reps > 10_000 {
            return Err(usage(format!("--reps must be 1..=10000, got {}", self.reps)));
        }
        if self.rounds == 0 || self.rounds > 1000 {
            return Err(usage(format!("--rounds must be 1..=1000, got {}", self.rounds)));
        }
        if self.warmup == 0 || self.warmup > 10_000 {
            return Err(usage(format!("--warmup must be 1..=10000, got {}", self.warmup)));
        }
        if self.random_views > 10_000 {
            return Err(usage(format!("--random-views must be at most 10000, got {}", self.random_views)));
        }
        if self.modes.is_empty() {
            return Err(usage("--modes needs at least one of iso, blend".into()));
        }
        if !(self.ert > 0.0 && self.ert <= 1.0) {
            return Err(usage(format!("--ert must be in (0, 1], got {}", self.ert)));
        }
        if let Some(iso) = self.iso
            && !iso.is_finite()
        {
            return Err(usage("--iso must be a finite number".into()));
        }
        self.projections()?;
        if !self.peers.is_empty() {
            if !self.modes.contains(&Mode::Blend) {
                return Err(usage("--peers measures blend mode (the peers composite); add blend to --modes".into()));
            }
            if self.den_path().is_none() {
                return Err(usage(
                    "--peers needs the volume as a VolPack .den file (--den FILE or FILE.den), the one format every peer reads; \
                     `shearwarp export` writes one"
                        .into(),
                ));
            }
        }
        ReferenceOptions { step: self.ref_step, ..Default::default() }.check().map_err(|e| usage(format!("--ref-step: {e}")))?;
        for p in &self.plot {
            plot_format(p)?;
        }
        if self.plot_error != PlotError::Rmse && !self.plot.is_empty() && !self.modes.contains(&Mode::Iso) && self.suite.is_none() {
            return Err(usage(format!("--plot-error: the {} is measured in iso mode: add iso to --modes", self.plot_error.name())));
        }
        Ok(())
    }

    /// The perspective projections measured: every `--perspective` field of
    /// view from every `--eye-distance` (default 2 diagonals), then the
    /// `--perspective-matrix`, without repeats.
    fn projections(&self) -> Result<Vec<Projection>> {
        let mut out: Vec<Projection> = vec![];
        let default = [crate::app::args::DEFAULT_EYE_DISTANCE];
        let ds: &[f64] = if self.eye_distance.is_empty() { &default } else { &self.eye_distance };
        for &fov in &self.perspective {
            if !(fov > 0.0 && fov < 180.0) {
                return Err(usage(format!("--perspective takes a vertical field of view in degrees, 0 < FOV < 180, got {fov}")));
            }
            for &d in ds {
                if !(d.is_finite() && d > 0.0) {
                    return Err(usage(format!("--eye-distance must be a finite number of volume diagonals > 0, got {d}")));
                }
                out.push(Projection::perspective(fov, d)?);
            }
        }
        if self.perspective_matrix {
            out.extend(perspective_matrix());
        }
        let mut uniq: Vec<Projection> = vec![];
        for p in out {
            if !uniq.contains(&p) {
                uniq.push(p);
            }
        }
        Ok(uniq)
    }

    /// The `.den` file of the volume, if it is one (what the peers read).
    fn den_path(&self) -> Option<&Path> {
        let v = &self.volume;
        v.den.as_deref().or(v.file.as_deref().filter(|f| {
            matches!(v.format, Some(shearwarp::data::io::Format::Den)) || f.extension().is_some_and(|e| e.eq_ignore_ascii_case("den"))
        }))
    }

    /// The analytic surface of the volume (a phantom that has one), at the
    /// spacing it is sampled at.
    fn analytic(&self) -> Result<Option<shearwarp::data::shapes::AnalyticPhantom>> {
        self.volume.analytic()
    }

    /// The phantom the volume was built from (None for files).
    fn phantom(&self) -> Option<Phantom> {
        if self.volume.file.is_some() || self.volume.raw.is_some() || self.volume.den.is_some() {
            return None;
        }
        Some(self.volume.phantom)
    }

    /// The settings every variant of `mode` starts from: the peers' material
    /// in blend mode when peers are measured.
    /// The reconstruction of the reference: the last of `--reconstruction`.
    pub fn reference_reconstruction(&self) -> Reconstruction {
        self.reconstruction.last().copied().unwrap_or_default()
    }

    pub(crate) fn base_settings(&self, mode: Mode) -> Settings {
        let shading = if self.peer_model(mode) { MODEL_SHADING } else { Settings::default().shading };
        Settings { mode, ert: self.ert, threads: self.threads, shading, ..Settings::default() }
    }

    /// True when `mode`'s rows use the peers' model (blend mode with --peers).
    fn peer_model(&self, mode: Mode) -> bool {
        mode == Mode::Blend && !self.peers.is_empty()
    }

    /// A renderer for `mode` with the benchmark's classification, and the
    /// peers' threshold when `mode` uses their model.
    pub(crate) fn renderer(&self, vol: Volume, mode: Mode) -> Result<(Renderer, Option<f32>)> {
        let base = self.base_settings(mode);
        let tissues = presets::tissues_for(&vol);
        let hi = vol.value_range().1;
        let mut r = Renderer::with_tissues(vol, &tissues, base)?;
        r.set_memory_budget(crate::app::budget());
        if let Some(name) = self.tissue.as_deref().filter(|n| *n != "auto")
            && r.select_tissue_named(name).is_err()
        {
            let names: Vec<&str> = tissues.iter().map(|t| t.name).collect();
            return Err(usage(format!("unknown tissue '{name}' for this volume (its presets: {}, or auto)", names.join(", "))));
        }
        let iso = self.iso.or(self.phantom().and_then(Phantom::iso));
        if let Some(iso) = iso {
            match mode {
                Mode::Blend => r.set_transfer_function(&presets::generic(iso, hi).tf),
                Mode::Iso => r.set_iso(iso)?,
            }
        }
        let mut threshold = None;
        if self.peer_model(mode) {
            let t = iso.unwrap_or(r.iso());
            r.set_transfer_function(&peers::model_tf(t)?);
            threshold = Some(t);
        }
        Ok((r, threshold))
    }
}

/// Output format of a plot path.
fn plot_format(p: &Path) -> Result<&'static str> {
    match p.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).as_deref() {
        Some("svg") => Ok("svg"),
        Some("png") => Ok("png"),
        _ => Err(usage(format!("--plot {}: the file name must end in .svg or .png", p.display()))),
    }
}

fn progress(len: u64, quiet: bool) -> indicatif::ProgressBar {
    if quiet || !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let pb = indicatif::ProgressBar::new(len);
    pb.set_style(
        indicatif::ProgressStyle::with_template("{msg:32} [{bar:30}] {pos}/{len} eta {eta}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    pb
}

/// Everything one run measured.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Report {
    pub volume: String,
    pub dims: [usize; 3],
    pub spacing: [f32; 3],
    pub size: usize,
    pub threads: usize,
    /// CPU level of the kernels (`scalar`, `avx2`): [`shearwarp::kernels::level`].
    pub cpu: &'static str,
    pub reps: usize,
    pub rounds: usize,
    pub warmup: usize,
    pub reference_step: f64,
    pub views: Vec<String>,
    /// Per mode: the classification used (`tissue` name and iso value).
    pub classification: Vec<(String, String, f32)>,
    /// Per mode and view: reference render time (ms) and its depth error against the analytic truth.
    pub reference: Vec<ReferenceRecord>,
    pub records: Vec<Record>,
    pub summary: Vec<Summary>,
    /// Variants and views that could not be rendered, and why.
    pub skipped: Vec<Skipped>,
    /// With `--peers`: the error floor of the shared model, per parallel view
    /// ([`MODEL_FLOOR_DELTA`]).
    pub model_floor: Vec<ModelFloor>,
    /// With `--peers`: per peer row, the shearwarp row that matches or beats
    /// it on both time and error, or by how much none does ([`dominance`]).
    pub dominance: Vec<String>,
}

/// How far the peers' material constants are moved to show the model's error
/// floor: the reference re-rendered with ambient, diffuse and specular each
/// this much higher reads as this error against the reference itself, a
/// scale for what an unmatched detail of a peer's shading costs.
pub const MODEL_FLOOR_DELTA: f32 = 0.01;

/// The reference with the material moved by [`MODEL_FLOOR_DELTA`] against the
/// reference, at one view.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ModelFloor {
    pub view: String,
    pub rmse: f64,
    pub ssim: f64,
}

/// A variant that cannot render a view (a perspective the path does not do yet).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Skipped {
    pub mode: &'static str,
    pub variant: String,
    pub view: String,
    pub reason: String,
}

/// The reference's own cost and accuracy at one view.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ReferenceRecord {
    pub mode: &'static str,
    pub view: String,
    pub ms: f64,
    pub samples: u64,
    /// How the reference reconstructs densities between slices (`--reconstruction`).
    pub reconstruction: &'static str,
    /// Depth error of the reference against the analytic truth (when there is one).
    pub depth: Option<DepthError>,
    /// Angle between the normal the reference shades its iso hit with and the
    /// analytic surface's (when there is one).
    pub normal: Option<NormalError>,
    pub truth_ms: f64,
}

/// One row of a suite's table: a case and a variant.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SuiteRow {
    pub case: String,
    pub dims: [usize; 3],
    pub spacing: [f32; 3],
    pub variant: String,
    pub reconstruction: &'static str,
    /// Depth error in voxels of the finest spacing (mean pooled over views, worst view's p99) and the p99 in mm.
    pub depth_mean: Option<f64>,
    pub depth_p99: Option<f64>,
    pub depth_p99_mm: Option<f64>,
    pub normal_deg_mean: Option<f64>,
    pub normal_deg_p99: Option<f64>,
    pub frame_ms: f64,
    pub rmse_mean: f64,
}

/// Everything a suite measured: each case's report and the table over them.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SuiteReport {
    pub suite: &'static str,
    pub size: usize,
    pub threads: usize,
    pub table: Vec<SuiteRow>,
    /// Per case, the reference's own row (variant `reference`, its
    /// `--reconstruction`), against the analytic truth.
    pub reference: Vec<SuiteRow>,
    pub cases: Vec<Report>,
}

/// The variants `cmd` measures in `mode`: the matrix ([`registry`]), its
/// perspective rows, `--deluxe` and `--grid`, picked by `--only`, once per
/// `--reconstruction`.
pub fn variants_of(cmd: &BenchCmd, mode: Mode) -> Vec<Variant> {
    let base = cmd.base_settings(mode);
    let mut all = registry(base);
    let projections = cmd.projections().unwrap_or_default();
    for p in &projections {
        all.extend(perspective_variants(base, *p, &projection_suffix(p, projections.len())));
    }
    let mut all = with_options(all, &cmd.deluxe, cmd.grid);
    if cmd.deluxe.iter().any(|d| !d.is_standard()) || cmd.grid.is_some_and(|g| g != Lattice::Cartesian) {
        // (the matrix's own Deluxe rows would repeat the options)
        all.retain(|v| v.name.matches("-deluxe-").count() < 2 && v.name.matches("-bcc").count() < 2);
    }
    let exact = |o: &str| all.iter().any(|v| v.name == o);
    let picked = |v: &Variant| cmd.only.iter().any(|o| if exact(o) { v.name == *o } else { v.name.contains(o.as_str()) });
    let vs: Vec<Variant> = all.iter().filter(|v| cmd.only.is_empty() || picked(v)).cloned().collect();
    with_reconstructions(vs, &cmd.reconstruction)
}

/// Runs `shearwarp bench`.
pub fn run(cmd: &BenchCmd) -> Result<()> {
    if let Some(suite) = cmd.suite {
        return run_suite(cmd, suite);
    }
    cmd.check()?;
    shearwarp::render::checks::check_threads(cmd.threads)?;
    let (vol, name) = cmd.volume.load()?;
    crate::app::args::renderable(&name, &vol)?;
    let report = measure(cmd, vol, name)?;
    if let Some(p) = &cmd.csv {
        crate::app::output::write_text(p, &to_csv(&report))?;
    }
    for p in &cmd.plot {
        write_plot(p, &[&report], cmd.plot_error)?;
    }
    if let Some(p) = &cmd.json_out {
        crate::app::output::write_text(p, &serde_json::to_string_pretty(&report)?)?;
    }
    if cmd.json {
        crate::app::output::print_text(&(serde_json::to_string_pretty(&report)? + "\n"))?;
    } else {
        crate::app::output::print_text(&to_markdown(&report, cmd.per_view))?;
    }
    Ok(())
}

/// The command of one case of a suite: `cmd` on the case's phantom, iso
/// mode, the suite's variants unless `--only` names some.
pub fn case_command(cmd: &BenchCmd, case: &Case) -> BenchCmd {
    let mut c = cmd.clone();
    c.suite = None;
    c.volume.phantom = case.phantom;
    c.volume.phantom_dims = Some(case.dims);
    c.volume.phantom_spacing = case.spacing;
    c.modes = vec![Mode::Iso];
    if c.only.is_empty() {
        c.only = SUITE_VARIANTS.iter().map(|s| s.to_string()).collect();
        // and their perspective rows, by their exact names
        let projections = cmd.projections().unwrap_or_default();
        for p in &projections {
            let suffix = projection_suffix(p, projections.len());
            c.only.extend(SUITE_PERSPECTIVE_VARIANTS.iter().map(|v| format!("{v}{suffix}")));
        }
    }
    c
}

/// The suite row of a case's reference (iso mode, parallel views, against the
/// analytic truth): depth and normal error pooled over the views as the
/// variants' rows pool them (mean over every pixel, p99 of the worst view),
/// its median time per view as the frame time, and no image error (0).
fn reference_row(case: &Case, r: &Report, unit: f64) -> Option<SuiteRow> {
    let refs: Vec<&ReferenceRecord> =
        r.reference.iter().filter(|x| x.mode == Mode::Iso.name() && !x.view.ends_with("(perspective)")).collect();
    let first = refs.first()?;
    let depths: Vec<&DepthError> = refs.iter().filter_map(|x| x.depth.as_ref()).filter(|d| d.both > 0).collect();
    let normals: Vec<&NormalError> = refs.iter().filter_map(|x| x.normal.as_ref()).filter(|n| n.both > 0).collect();
    let pooled = |pairs: Vec<(f64, usize)>| {
        let n: usize = pairs.iter().map(|p| p.1).sum();
        (n > 0).then(|| pairs.iter().map(|&(m, k)| m * k as f64).sum::<f64>() / n as f64)
    };
    let worst = |v: Vec<f64>| v.into_iter().reduce(f64::max);
    let depth_p99 = worst(depths.iter().map(|d| d.p99).collect());
    let mut ms: Vec<f64> = refs.iter().map(|x| x.ms).collect();
    ms.sort_by(f64::total_cmp);
    Some(SuiteRow {
        case: case.name.into(),
        dims: r.dims,
        spacing: r.spacing,
        variant: "reference".into(),
        reconstruction: first.reconstruction,
        depth_mean: pooled(depths.iter().map(|d| (d.mean, d.both)).collect()),
        depth_p99,
        depth_p99_mm: depth_p99.map(|p| p * unit),
        normal_deg_mean: pooled(normals.iter().map(|n| (n.mean_deg, n.both)).collect()),
        normal_deg_p99: worst(normals.iter().map(|n| n.p99_deg).collect()),
        frame_ms: ms[ms.len() / 2],
        rmse_mean: 0.0,
    })
}

/// Runs `--suite`: every case, then the table over them.
fn run_suite(cmd: &BenchCmd, suite: Suite) -> Result<()> {
    let v = &cmd.volume;
    if v.file.is_some()
        || v.raw.is_some()
        || v.den.is_some()
        || v.phantom_spacing.is_some()
        || v.phantom_dims.is_some()
        || v.spacing.is_some()
    {
        return Err(usage(
            "--suite chooses its own volumes: leave out the volume file, --phantom-dims, --phantom-spacing and --spacing".into(),
        ));
    }
    if !cmd.peers.is_empty() {
        return Err(usage("--suite measures iso mode; --peers measures blend mode".into()));
    }
    let cases: &[Case] = match suite {
        Suite::Surfaces => &SUITE_SURFACES,
    };
    let mut rep = SuiteReport {
        suite: "surfaces",
        size: cmd.size,
        threads: if cmd.threads == 0 { rayon::current_num_threads() } else { cmd.threads },
        table: vec![],
        reference: vec![],
        cases: vec![],
    };
    for case in cases {
        let c = case_command(cmd, case);
        c.check()?;
        shearwarp::render::checks::check_threads(c.threads)?;
        let (vol, name) = c.volume.load()?;
        crate::app::args::renderable(&name, &vol)?;
        let r = measure(&c, vol, name)?;
        let unit = r.spacing.iter().fold(f32::MAX, |a, &b| a.min(b)) as f64;
        if let Some(row) = reference_row(case, &r, unit) {
            rep.reference.push(row);
        }
        for x in &r.summary {
            rep.table.push(SuiteRow {
                case: case.name.into(),
                dims: r.dims,
                spacing: r.spacing,
                variant: x.variant.clone(),
                reconstruction: x.reconstruction,
                depth_mean: x.depth_p99.and(x.depth_mean_vox),
                depth_p99: x.depth_p99,
                depth_p99_mm: x.depth_p99.map(|p| p * unit),
                normal_deg_mean: x.normal_deg_mean,
                normal_deg_p99: x.normal_deg_p99,
                frame_ms: x.frame_ms,
                rmse_mean: x.rmse_mean,
            });
        }
        rep.cases.push(r);
    }
    if let Some(p) = &cmd.csv {
        let body: String = rep
            .cases
            .iter()
            .map(to_csv)
            .enumerate()
            .map(|(i, c)| if i == 0 { c } else { c.lines().skip(1).map(|l| format!("{l}\n")).collect() })
            .collect();
        crate::app::output::write_text(p, &body)?;
    }
    for p in &cmd.plot {
        write_plot(p, &rep.cases.iter().collect::<Vec<_>>(), cmd.plot_error)?;
    }
    if let Some(p) = &cmd.json_out {
        crate::app::output::write_text(p, &serde_json::to_string_pretty(&rep)?)?;
    }
    if cmd.json {
        crate::app::output::print_text(&(serde_json::to_string_pretty(&rep)? + "\n"))?;
    } else {
        let mut s = suite_markdown(&rep);
        for r in &rep.cases {
            s.push_str(&to_markdown(r, cmd.per_view));
        }
        crate::app::output::print_text(&s)?;
    }
    Ok(())
}

/// The suite's table as Markdown.
pub fn suite_markdown(rep: &SuiteReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# shearwarp bench --suite {}: {}×{} px, {} threads\n\n\
         Depth error in voxels of the finest spacing (mean over every pixel hit in both, pooled over the views; p99 of the worst view) \
         against the analytic surface; normal error: the angle between the normal each variant shades with and the surface's, in degrees; \
         frame time: the median over the views.\n",
        rep.suite, rep.size, rep.size, rep.threads
    );
    let _ = writeln!(
        s,
        "| case | dims | spacing | variant | reconstruction | depth mean | depth p99 | p99 mm | normal ° mean | normal ° p99 | frame ms | RMSE |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|");
    // each case's reference row first, then its variants
    let rows = rep.reference.iter().map(|r| (r.case.as_str(), 0, r)).chain(rep.table.iter().map(|r| (r.case.as_str(), 1, r)));
    let order: Vec<&str> = rep.table.iter().chain(&rep.reference).map(|r| r.case.as_str()).fold(vec![], |mut v, c| {
        if !v.contains(&c) {
            v.push(c);
        }
        v
    });
    let mut rows: Vec<(&str, i32, &SuiteRow)> = rows.collect();
    rows.sort_by_key(|&(c, k, _)| (order.iter().position(|&o| o == c), k));
    for (_, _, r) in rows {
        let _ = writeln!(
            s,
            "| {} | {}×{}×{} | {}×{}×{} | {} | {} | {} | {} | {} | {} | {} | {:.3} | {:.5} |",
            r.case,
            r.dims[0],
            r.dims[1],
            r.dims[2],
            r.spacing[0],
            r.spacing[1],
            r.spacing[2],
            r.variant,
            r.reconstruction,
            fmt_opt(r.depth_mean, 3),
            fmt_opt(r.depth_p99, 3),
            fmt_opt(r.depth_p99_mm, 3),
            fmt_opt(r.normal_deg_mean, 2),
            fmt_opt(r.normal_deg_p99, 2),
            r.frame_ms,
            r.rmse_mean
        );
    }
    let _ = writeln!(s);
    s
}

/// Runs the matrix and returns the report (no output).
pub fn measure(cmd: &BenchCmd, vol: Volume, name: String) -> Result<Report> {
    let dims = vol.dims();
    let spacing = vol.spacing();
    let unit = spacing.iter().fold(f32::MAX, |a, &b| a.min(b)) as f64;
    let analytic = cmd.analytic()?.filter(|a| a.grid.dims == dims);
    let views = standard_views(NamedView::Anterior.rotation(), cmd.random_views, cmd.seed);
    let modes: Vec<Mode> = {
        let mut m: Vec<Mode> = cmd
            .modes
            .iter()
            .map(|m| match m {
                Mode::Iso => Mode::Iso,
                Mode::Blend => Mode::Blend,
            })
            .collect();
        m.dedup();
        m
    };
    let refr = ReferenceRenderer::new(&vol);
    let ref_recon = cmd.reference_reconstruction();
    let ropts = ReferenceOptions { step: cmd.ref_step, threads: cmd.threads, reconstruction: ref_recon, ..Default::default() };
    let camera = |v: &View| Camera { rotation: v.rotation, zoom: None, size: [cmd.size, cmd.size] };

    let per_mode: Vec<(Mode, Vec<Variant>)> = modes.iter().map(|&mode| (mode, variants_of(cmd, mode))).collect();
    if per_mode.iter().all(|(_, v)| v.is_empty()) {
        let names: Vec<String> = registry(Settings::default()).into_iter().map(|v| v.name).collect();
        return Err(usage(format!("--only {:?} matches no variant (variants: {})", cmd.only, names.join(", "))));
    }
    let total: usize = per_mode.iter().map(|(_, v)| views.len() * (1 + cmd.rounds * v.len())).sum();
    let pb = progress(total as u64, cmd.quiet);

    let mut report = Report {
        volume: name,
        dims,
        spacing,
        size: cmd.size,
        threads: if cmd.threads == 0 { rayon::current_num_threads() } else { cmd.threads },
        cpu: shearwarp::kernels::level().name(),
        reps: cmd.reps,
        rounds: cmd.rounds,
        warmup: cmd.warmup,
        reference_step: cmd.ref_step,
        views: views.iter().map(|v| v.name.clone()).collect(),
        classification: vec![],
        reference: vec![],
        records: vec![],
        summary: vec![],
        skipped: vec![],
        model_floor: vec![],
        dominance: vec![],
    };
    let mut vol = Some(vol);
    for (mode, variants) in &per_mode {
        let mode = *mode;
        // the last mode may take the volume itself
        let v = if per_mode.last().map(|l| l.0) == Some(mode) { vol.take().context("volume")? } else { vol.clone().context("volume")? };
        let (mut r, peer_threshold) = cmd.renderer(v, mode)?;
        report.classification.push((mode.name().into(), r.classification_name().into(), r.iso()));
        let scene = Scene::from_renderer(&r);
        let iso = r.iso();
        // references (and truth) per projection and view
        let mut projections: Vec<Projection> = vec![];
        let peer_projections = match peer_threshold {
            Some(_) => std::iter::once(Projection::Parallel).chain(cmd.projections()?).collect(),
            None => vec![],
        };
        for p in variants.iter().map(|v| v.projection).chain(peer_projections.iter().copied()) {
            if !projections.contains(&p) {
                projections.push(p);
            }
        }
        let mut refs: Vec<std::result::Result<RefFrame, String>> = Vec::with_capacity(views.len() * projections.len());
        for (proj, view) in projections.iter().flat_map(|p| views.iter().map(move |v| (p, v))) {
            pb.set_message(format!("{} reference {}", mode.name(), view.name));
            let cam = camera(view);
            let t = Instant::now();
            let image = match refr.render_projected(&scene, &cam, proj, &ropts) {
                Ok(i) => i,
                // (a perspective the reference cannot trace: every variant skips this view)
                Err(e) if proj.is_perspective() => {
                    refs.push(Err(format!("reference: {e}")));
                    pb.inc(1);
                    continue;
                }
                Err(e) => return Err(e.into()),
            };
            let ms = t.elapsed().as_secs_f64() * 1e3;
            if peer_threshold.is_some() && !proj.is_perspective() {
                let d = MODEL_FLOOR_DELTA;
                let sh = scene.shading;
                let moved = Scene {
                    shading: Shading { ambient: sh.ambient + d, diffuse: sh.diffuse + d, specular: sh.specular + d, ..sh },
                    ..scene.clone()
                };
                let e = compare(&refr.render_projected(&moved, &cam, proj, &ropts)?.image, &image.image)?;
                report.model_floor.push(ModelFloor { view: view.name.clone(), rmse: e.rmse, ssim: e.ssim });
            }
            let t = Instant::now();
            let surface = match (mode, &analytic) {
                (Mode::Iso, Some(a)) => Some(surface_truth(a, spacing, &cam, proj, iso as f64, ropts.near)?),
                _ => None,
            };
            let truth_ms = t.elapsed().as_secs_f64() * 1e3;
            let ref_depth = surface.as_ref().map(|a| depth_error(&image.depth, &a.depth, unit)).transpose()?;
            let ref_normal = surface.as_ref().map(|a| normal_error(&image.normal, &a.normal)).transpose()?;
            report.reference.push(ReferenceRecord {
                mode: mode.name(),
                view: if proj.is_perspective() { format!("{} (perspective)", view.name) } else { view.name.clone() },
                ms,
                samples: image.samples,
                reconstruction: ref_recon.name(),
                depth: ref_depth,
                normal: ref_normal,
                truth_ms,
            });
            let (truth, normals) = match (mode, surface) {
                (Mode::Iso, Some(a)) => (Some((a.depth, "analytic")), Some(a.normal)),
                (Mode::Iso, None) => (Some((image.depth.clone(), "reference")), None),
                _ => (None, None),
            };
            refs.push(Ok(RefFrame { image, truth, normals }));
            pb.inc(1);
        }
        // frames alternate between two images: a renderer skips a frame identical to
        // the one it last wrote into the same image, and every timed frame must be real
        let mut imgs = [Image::new(cmd.size, cmd.size), Image::new(cmd.size, cmd.size)];
        let mut flip = 0usize;
        let nv = views.len();
        let mut acc: Vec<Acc> = (0..variants.len() * nv).map(|_| Acc::default()).collect();
        for round in 0..cmd.rounds {
            for (vi, variant) in variants.iter().enumerate() {
                if let Err(e) = r.set_settings(variant.settings) {
                    // a combination no path renders (yet): listed, not fatal
                    for a in &mut acc[vi * nv..(vi + 1) * nv] {
                        a.skipped.get_or_insert_with(|| e.to_string());
                    }
                    pb.inc(nv as u64);
                    continue;
                }
                r.set_projection(variant.projection)?;
                r.set_quality(variant.quality)?;
                r.prepare_all_axes();
                let pi = projections.iter().position(|p| *p == variant.projection).context("projection")?;
                for (wi, (view, rf)) in views.iter().zip(&refs[pi * nv..(pi + 1) * nv]).enumerate() {
                    pb.set_message(format!("{} {} {}", mode.name(), variant.name, view.name));
                    let a = &mut acc[vi * nv + wi];
                    let cam = camera(view);
                    if a.skipped.is_some() {
                        pb.inc(1);
                        continue;
                    }
                    let rf = match rf {
                        Ok(rf) => rf,
                        Err(why) => {
                            a.skipped = Some(why.clone());
                            pb.inc(1);
                            continue;
                        }
                    };
                    let cold = match frame(&mut r, &cam, &mut imgs, &mut flip) {
                        Ok(c) => c,
                        // a perspective view a path cannot render (yet): listed, not fatal
                        Err(e) if variant.projection.is_perspective() => {
                            a.skipped = Some(e.to_string());
                            pb.inc(1);
                            continue;
                        }
                        Err(e) => return Err(e),
                    };
                    a.cold.push(cold.shear_ms);
                    a.axis = cold.axis;
                    for _ in 1..cmd.warmup {
                        frame(&mut r, &cam, &mut imgs, &mut flip)?;
                    }
                    for _ in 0..cmd.reps {
                        a.frames.push(frame(&mut r, &cam, &mut imgs, &mut flip)?);
                    }
                    if round == 0 {
                        // a perspective frame split into pyramids keeps their depths only when
                        // asked (a copy per pyramid): render it once more with them, untimed
                        if rf.truth.is_some() && r.last_plans().len() > 1 {
                            r.set_keep_depths(true);
                            let again = frame(&mut r, &cam, &mut imgs, &mut flip);
                            r.set_keep_depths(false);
                            again?;
                        }
                        // every render of a view is the same image: measure the error once
                        let img = &imgs[flip];
                        a.error = Some(compare(img, &rf.image.image)?);
                        if let Some((t, what)) = &rf.truth {
                            match fast_path_depth(&r, &cam) {
                                Ok(d) => a.depth = Some((*what, depth_error(&d, t, unit)?)),
                                // (a path that keeps no depth in perspective: no depth column)
                                Err(_) if variant.projection.is_perspective() => {}
                                Err(e) => return Err(e.into()),
                            }
                        }
                        if let (Some(truth), Some(_)) = (&rf.normals, &a.depth) {
                            a.normal = Some(normal_error(&fast_path_normals(&r, &cam, &refr)?, truth)?);
                        }
                    }
                    pb.inc(1);
                }
            }
        }
        for (vi, variant) in variants.iter().enumerate() {
            for (wi, view) in views.iter().enumerate() {
                let a = &mut acc[vi * nv + wi];
                if let Some(why) = a.skipped.take() {
                    report.skipped.push(Skipped { mode: mode.name(), variant: variant.name.clone(), view: view.name.clone(), reason: why });
                    continue;
                }
                let col = |g: fn(&FrameStats) -> f64| median(&mut a.frames.iter().map(g).collect::<Vec<_>>());
                report.records.push(Record {
                    mode: mode.name(),
                    variant: variant.name.clone(),
                    view: view.name.clone(),
                    axis: a.axis,
                    frame_ms: col(|s| s.frame_ms()),
                    shear_ms: col(|s| s.shear_ms),
                    render_ms: col(|s| s.render_ms),
                    warp_ms: col(|s| s.warp_ms),
                    cold_shear_ms: median(&mut a.cold),
                    error: a.error.context("error measured in round 0")?,
                    depth_truth: a.depth.map(|d| d.0),
                    depth: a.depth.map(|d| d.1),
                    reconstruction: reconstruction(&variant.settings),
                    normal: a.normal,
                });
            }
        }
        // the peers, at the same views and projections, against the same references
        if let Some(threshold) = peer_threshold {
            let den = cmd.den_path().context("--peers needs a .den volume")?;
            let dir = cmd.peer_dir.clone().unwrap_or_else(|| std::env::temp_dir().join(format!("shearwarp-peers-{}", std::process::id())));
            for &peer in &cmd.peers {
                for proj in &peer_projections {
                    let pi = projections.iter().position(|p| p == proj).context("projection")?;
                    let name = match proj {
                        Projection::Parallel => peer.name().to_string(),
                        _ => format!("{}-persp{}", peer.name(), projection_suffix(proj, peer_projections.len() - 1)),
                    };
                    pb.set_message(format!("{} {name}", mode.name()));
                    let shown: Vec<(&View, &RefFrame)> =
                        views.iter().zip(&refs[pi * nv..(pi + 1) * nv]).filter_map(|(v, rf)| rf.as_ref().ok().map(|rf| (v, rf))).collect();
                    let cam0 = camera(&views[0]);
                    let pcam = match proj.resolve(&cam0, dims, spacing)? {
                        None => PeerCamera { size: cmd.size, zoom: Factorization::new(&cam0, dims, spacing)?.zoom, perspective: None },
                        Some((c, distance)) => {
                            let Projection::Perspective { fov_deg, .. } = *proj else { unreachable!("resolved a parallel projection") };
                            PeerCamera { size: cmd.size, zoom: c.zoom.context("resolved zoom")?, perspective: Some((fov_deg, distance)) }
                        }
                    };
                    let pviews: Vec<PeerView> =
                        shown.iter().map(|(v, _)| PeerView { name: peers::file_safe(&v.name), rotation: v.rotation }).collect();
                    let reps = cmd.reps * cmd.rounds;
                    let model = PeerModel { threshold, ert: cmd.ert };
                    let schedule = PeerSchedule { threads: cmd.threads, warmup: cmd.warmup, reps };
                    match peers::run(peer, den, &pviews, pcam, model, schedule, &dir.join(&name)) {
                        Ok(run) => {
                            for ((view, rf), (ms, img)) in shown.iter().zip(run.frames) {
                                report.records.push(Record {
                                    mode: mode.name(),
                                    variant: name.clone(),
                                    view: view.name.clone(),
                                    axis: 0,
                                    frame_ms: ms,
                                    shear_ms: f64::NAN,
                                    render_ms: f64::NAN,
                                    warp_ms: f64::NAN,
                                    cold_shear_ms: f64::NAN,
                                    error: compare(&img, &rf.image.image)?,
                                    depth_truth: None,
                                    depth: None,
                                    reconstruction: "peer",
                                    normal: None,
                                });
                            }
                        }
                        Err(e) => {
                            for view in &views {
                                let reason = format!("{e:#}");
                                report.skipped.push(Skipped { mode: mode.name(), variant: name.clone(), view: view.name.clone(), reason });
                            }
                        }
                    }
                }
            }
        }
    }
    pb.finish_and_clear();
    report.summary = summarize(&report.records);
    report.dominance = ["iso", "blend"].iter().flat_map(|m| dominance(&report.summary, m)).collect();
    Ok(report)
}

/// Whether a shearwarp row matches each peer row of `mode`: for every peer
/// (a row without a shear time), the shearwarp rows at most as slow *and* at
/// most as wrong (the fastest of them), or, when there is none, by how much
/// the best shearwarp row at most as slow misses its error and the best at
/// most as wrong misses its time. Rows are compared within one projection
/// (parallel rows with parallel, each perspective with its own).
pub fn dominance(summary: &[Summary], mode: &str) -> Vec<String> {
    let projection = |v: &str| v.split_once("-persp").map(|(_, r)| projection_key(r));
    let rows: Vec<&Summary> = summary.iter().filter(|x| x.mode == mode).collect();
    let mut out = vec![];
    for p in rows.iter().filter(|x| x.cold_shear_ms.is_nan()) {
        let ours: Vec<&&Summary> =
            rows.iter().filter(|x| !x.cold_shear_ms.is_nan() && projection(&x.variant) == projection(&p.variant)).collect();
        let head = format!("{} ({:.3} ms, RMSE {:.5})", p.variant, p.frame_ms, p.rmse_mean);
        let both =
            ours.iter().filter(|x| x.frame_ms <= p.frame_ms && x.rmse_mean <= p.rmse_mean).min_by(|a, b| a.frame_ms.total_cmp(&b.frame_ms));
        if let Some(b) = both {
            out.push(format!("{head}: matched or beaten by {} ({:.3} ms, RMSE {:.5})", b.variant, b.frame_ms, b.rmse_mean));
            continue;
        }
        let faster = ours.iter().filter(|x| x.frame_ms <= p.frame_ms).min_by(|a, b| a.rmse_mean.total_cmp(&b.rmse_mean));
        let better = ours.iter().filter(|x| x.rmse_mean <= p.rmse_mean).min_by(|a, b| a.frame_ms.total_cmp(&b.frame_ms));
        let mut why = vec![];
        if let Some(f) = faster {
            why.push(format!(
                "the most accurate shearwarp row as fast, {}, has {:+.0} % RMSE",
                f.variant,
                100.0 * (f.rmse_mean / p.rmse_mean - 1.0)
            ));
        }
        if let Some(b) = better {
            why.push(format!("the fastest as accurate, {}, takes {:+.0} % time", b.variant, 100.0 * (b.frame_ms / p.frame_ms - 1.0)));
        }
        if why.is_empty() {
            why.push("no shearwarp row of its projection".into());
        }
        out.push(format!("{head}: NOT MATCHED, no shearwarp row is as fast and as accurate: {}", why.join("; ")));
    }
    out
}

/// Which perspective a variant's name after `-persp` names: its projection
/// suffix `-f<FOV>-d<D>` (empty for the single one), without the options
/// that do not change the projection (`-q2`, `-bcc`, `-deluxe-<LABEL>`), so
/// `binary-persp-q2-deluxe-I` meets `vtk-persp`.
fn projection_key(rest: &str) -> String {
    let mut key = String::new();
    let mut parts = rest.split('-').skip(1).peekable();
    while let Some(p) = parts.next() {
        match p {
            "q2" | "bcc" => {}
            "deluxe" => {
                parts.next();
            }
            _ => {
                key.push('-');
                key.push_str(p);
            }
        }
    }
    key
}

/// The suffix of a perspective variant's name when `n` projections are
/// measured: `-f<FOV>-d<D>`, none for a single one (or a parallel view).
fn projection_suffix(p: &Projection, n: usize) -> String {
    match (p, n) {
        (Projection::Perspective { fov_deg, eye_distance }, 2..) => format!("-f{fov_deg}-d{eye_distance}"),
        _ => String::new(),
    }
}

/// One real frame into the other of two images (see [`measure`]), returning its stats.
fn frame(r: &mut Renderer, cam: &Camera, imgs: &mut [Image; 2], flip: &mut usize) -> Result<FrameStats> {
    *flip ^= 1;
    let st = r.render(cam, &mut imgs[*flip])?;
    anyhow::ensure!(!st.skipped, "the renderer skipped a benchmark frame");
    Ok(st)
}

/// Aggregates the records per mode and variant and marks each mode's Pareto front.
pub fn summarize(records: &[Record]) -> Vec<Summary> {
    let mut keys: Vec<(&'static str, String)> = Vec::new();
    for r in records {
        if !keys.iter().any(|k| k.0 == r.mode && k.1 == r.variant) {
            keys.push((r.mode, r.variant.clone()));
        }
    }
    let mut out: Vec<Summary> = keys
        .into_iter()
        .map(|(mode, variant)| {
            let rs: Vec<&Record> = records.iter().filter(|r| r.mode == mode && r.variant == variant).collect();
            let n = rs.len() as f64;
            let depths: Vec<&DepthError> = rs.iter().filter_map(|r| r.depth.as_ref()).filter(|d| d.both > 0).collect();
            let hits: usize = depths.iter().map(|d| d.both).sum();
            let analytic: Vec<&DepthError> =
                rs.iter().filter(|r| r.depth_truth == Some("analytic")).filter_map(|r| r.depth.as_ref()).filter(|d| d.both > 0).collect();
            let normals: Vec<&NormalError> = rs.iter().filter_map(|r| r.normal.as_ref()).filter(|n| n.both > 0).collect();
            let nhits: usize = normals.iter().map(|n| n.both).sum();
            Summary {
                mode,
                variant,
                frame_ms: median(&mut rs.iter().map(|r| r.frame_ms).collect::<Vec<_>>()),
                cold_shear_ms: median(&mut rs.iter().map(|r| r.cold_shear_ms).collect::<Vec<_>>()),
                rmse_mean: rs.iter().map(|r| r.error.rmse).sum::<f64>() / n,
                psnr_worst: rs.iter().map(|r| r.error.psnr).fold(f64::INFINITY, f64::min),
                max_abs: rs.iter().map(|r| r.error.max_abs).fold(0.0, f64::max),
                ssim_mean: rs.iter().map(|r| r.error.ssim).sum::<f64>() / n,
                silhouette_max: rs.iter().map(|r| r.error.silhouette).fold(0.0, f64::max),
                depth_mean_vox: (hits > 0).then(|| depths.iter().map(|d| d.mean * d.both as f64).sum::<f64>() / hits as f64),
                depth_p99_vox: (hits > 0).then(|| depths.iter().map(|d| d.p99).fold(0.0, f64::max)),
                reconstruction: rs[0].reconstruction,
                depth_p99: (!analytic.is_empty()).then(|| analytic.iter().map(|d| d.p99).fold(0.0, f64::max)),
                normal_deg_mean: (nhits > 0).then(|| normals.iter().map(|n| n.mean_deg * n.both as f64).sum::<f64>() / nhits as f64),
                normal_deg_p99: (nhits > 0).then(|| normals.iter().map(|n| n.p99_deg).fold(0.0, f64::max)),
                normal_deg_max: (nhits > 0).then(|| normals.iter().map(|n| n.max_deg).fold(0.0, f64::max)),
                pareto: false,
            }
        })
        .collect();
    let marks = pareto_front(&out.iter().map(|s| (s.mode, s.frame_ms, s.rmse_mean)).collect::<Vec<_>>());
    for (s, m) in out.iter_mut().zip(marks) {
        s.pareto = m;
    }
    out
}

/// Which of the points `(mode, time, error)` lie on their mode's Pareto
/// front: no other point of the mode is at least as fast and at least as
/// accurate, and better in one.
fn pareto_front(pts: &[(&str, f64, f64)]) -> Vec<bool> {
    pts.iter().map(|a| !pts.iter().any(|b| b.0 == a.0 && b.1 <= a.1 && b.2 <= a.2 && (b.1 < a.1 || b.2 < a.2))).collect()
}

fn fmt_psnr(p: f64) -> String {
    if p.is_infinite() { "∞".into() } else { format!("{p:.2}") }
}

fn fmt_opt(x: Option<f64>, prec: usize) -> String {
    match x {
        Some(v) if v.is_finite() => format!("{v:.prec$}"),
        _ => "—".into(),
    }
}

/// The report as Markdown: a header, one table per mode (a row per variant,
/// aggregated over the views) and the reference's own cost and accuracy.
pub fn to_markdown(rep: &Report, per_view: bool) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let d = rep.dims;
    let _ = writeln!(
        s,
        "# shearwarp bench: {} {}×{}×{} (spacing {:?}), {}×{} px, {} threads, {} kernels\n",
        rep.volume, d[0], d[1], d[2], rep.spacing, rep.size, rep.size, rep.threads, rep.cpu
    );
    let _ = writeln!(
        s,
        "Views: {}. Frame time = median of {} rounds × {} timed frames per view, each round after {} warm-up frame(s) \
         (shear + render + warp, masks prebuilt), then the median over views; cold shear = the first frame's shear from the previous view. \
         Errors against the reference (true rays, {} reconstruction, step {} voxel, f64), displayed RGB in [0, 1].\n",
        rep.views.join(", "),
        rep.rounds,
        rep.reps,
        rep.warmup,
        rep.reference.first().map_or("linear", |r| r.reconstruction),
        rep.reference_step
    );
    for (mode, tissue, iso) in &rep.classification {
        let rows: Vec<&Summary> = rep.summary.iter().filter(|x| x.mode == mode).collect();
        let depth_what: Option<String> = {
            let mut w: Vec<&str> = vec![];
            for t in rep.records.iter().filter(|r| r.mode == mode).filter_map(|r| r.depth_truth) {
                if !w.contains(&t) {
                    w.push(t);
                }
            }
            (!w.is_empty()).then(|| w.join(" / "))
        };
        let _ = writeln!(s, "## {mode} (tissue {tissue}, iso {iso})\n");
        let dcol = match &depth_what {
            Some(w) => format!(" depth err vs {w} (vox): mean | p99 (worst view) |"),
            None => String::new(),
        };
        let with_normals = rows.iter().any(|x| x.normal_deg_mean.is_some());
        let ncol = if with_normals { " normal err vs analytic (°): mean | p99 (worst view) |" } else { "" };
        let _ = writeln!(
            s,
            "| variant | frame ms | cold shear ms | RMSE (mean) | PSNR dB (worst) | max abs | SSIM (mean) | silhouette (max) | reconstruction |{dcol}{ncol} Pareto |"
        );
        let _ = writeln!(
            s,
            "|---|---:|---:|---:|---:|---:|---:|---:|---|{}{}---|",
            if depth_what.is_some() { "---:|---:|" } else { "" },
            if with_normals { "---:|---:|" } else { "" }
        );
        for x in rows {
            let mut dc = if depth_what.is_some() {
                format!(" {} | {} |", fmt_opt(x.depth_mean_vox, 3), fmt_opt(x.depth_p99_vox, 3))
            } else {
                String::new()
            };
            if with_normals {
                dc += &format!(" {} | {} |", fmt_opt(x.normal_deg_mean, 2), fmt_opt(x.normal_deg_p99, 2));
            }
            let _ = writeln!(
                s,
                "| {} | {:.3} | {} | {:.5} | {} | {:.4} | {:.5} | {:.5} | {} |{dc} {} |",
                x.variant,
                x.frame_ms,
                fmt_opt(Some(x.cold_shear_ms), 3),
                x.rmse_mean,
                fmt_psnr(x.psnr_worst),
                x.max_abs,
                x.ssim_mean,
                x.silhouette_max,
                x.reconstruction,
                if x.pareto { "★" } else { "" }
            );
        }
        // perspective against parallel, side by side in this run
        let ratios: Vec<String> = rep
            .summary
            .iter()
            .filter(|x| x.mode == mode)
            .filter_map(|x| {
                let (base, rest) = x.variant.split_once("-persp")?;
                let fine = if rest.starts_with("-q2") { "-q2" } else { "" };
                let par = rep.summary.iter().find(|p| p.mode == mode && p.variant == base_parallel(base) + fine)?;
                Some(format!("{} {:.2}", x.variant, x.frame_ms / par.frame_ms))
            })
            .collect();
        if !ratios.is_empty() {
            let _ = writeln!(s, "\nPerspective / parallel frame time (same path, same run): {}.", ratios.join(", "));
        }
        let peer_rows: Vec<&str> =
            rep.summary.iter().filter(|x| x.mode == mode && x.cold_shear_ms.is_nan()).map(|x| x.variant.as_str()).collect();
        if !peer_rows.is_empty() {
            let _ = writeln!(
                s,
                "\nPeers ({}): the harness's own frame time (median of its timed renders per view, then over the views), \
                 their frames measured against the same reference; every row of this mode uses the peers' model \
                 (opaque ramp at the iso value with the 0.05 cut, white, ambient 0.1, diffuse 0.6, specular 0.3^20).",
                peer_rows.join(", ")
            );
            if !rep.model_floor.is_empty() {
                let n = rep.model_floor.len() as f64;
                let _ = writeln!(
                    s,
                    "Model floor: the reference with ambient, diffuse and specular each {MODEL_FLOOR_DELTA} higher reads \
                     RMSE {:.5}, SSIM {:.5} (mean over the parallel views) against the reference.",
                    rep.model_floor.iter().map(|f| f.rmse).sum::<f64>() / n,
                    rep.model_floor.iter().map(|f| f.ssim).sum::<f64>() / n
                );
            }
            for line in dominance(&rep.summary, mode) {
                let _ = writeln!(s, "- {line}");
            }
        }
        // skipped views, one line per variant and reason
        let mut skipped: Vec<(&str, &str, Vec<&str>)> = vec![];
        for k in rep.skipped.iter().filter(|k| k.mode == mode) {
            match skipped.iter_mut().find(|x| x.0 == k.variant && x.1 == k.reason) {
                Some(x) => x.2.push(&k.view),
                None => skipped.push((&k.variant, &k.reason, vec![&k.view])),
            }
        }
        if !skipped.is_empty() {
            let _ = writeln!(s, "\nSkipped (variant and views it cannot render):");
            for (v, why, views) in skipped {
                let _ = writeln!(s, "- {v} ({}): {why}", views.join(", "));
            }
        }
        let refs: Vec<&ReferenceRecord> = rep.reference.iter().filter(|r| r.mode == mode).collect();
        if !refs.is_empty() {
            let ms = median(&mut refs.iter().map(|r| r.ms).collect::<Vec<_>>());
            let _ = write!(s, "\nReference: median {ms:.0} ms per view");
            let depths: Vec<&DepthError> = refs.iter().filter_map(|r| r.depth.as_ref()).filter(|d| d.both > 0).collect();
            if !depths.is_empty() {
                let hits: usize = depths.iter().map(|d| d.both).sum();
                let mean = depths.iter().map(|d| d.mean * d.both as f64).sum::<f64>() / hits as f64;
                let p99 = depths.iter().map(|d| d.p99).fold(0.0, f64::max);
                let _ = write!(s, "; its depth error vs analytic: mean {mean:.4} vox, p99 (worst view) {p99:.4} vox");
            }
            let _ = writeln!(s, ".\n");
        }
        if per_view {
            let _ = writeln!(
                s,
                "| variant | view | axis | frame ms | cold shear ms | RMSE | PSNR dB | SSIM | silhouette | depth mean | depth p99 | normal ° mean | normal ° p99 |"
            );
            let _ = writeln!(s, "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
            for r in rep.records.iter().filter(|r| r.mode == mode) {
                let _ = writeln!(
                    s,
                    "| {} | {} | {} | {:.3} | {} | {:.5} | {} | {:.5} | {:.5} | {} | {} | {} | {} |",
                    r.variant,
                    r.view,
                    ["x", "y", "z"][r.axis.min(2)],
                    r.frame_ms,
                    fmt_opt(Some(r.cold_shear_ms), 3),
                    r.error.rmse,
                    fmt_psnr(r.error.psnr),
                    r.error.ssim,
                    r.error.silhouette,
                    fmt_opt(r.depth.map(|d| d.mean), 3),
                    fmt_opt(r.depth.map(|d| d.p99), 3),
                    fmt_opt(r.normal.map(|n| n.mean_deg), 2),
                    fmt_opt(r.normal.map(|n| n.p99_deg), 2)
                );
            }
            let _ = writeln!(s);
        }
    }
    s
}

/// The parallel variant a perspective one is compared with: `binary-persp`
/// with the binary rotator at the same settings (cell 1, u64, bit scan),
/// `brute-persp` with `brute`, the RLE ones with theirs.
fn base_parallel(persp_base: &str) -> String {
    match persp_base {
        "binary" => "binary-c1-u64-bitscan".into(),
        b => b.into(),
    }
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) { format!("\"{}\"", s.replace('"', "\"\"")) } else { s.to_string() }
}

/// One CSV row per variant and view (header first).
pub fn to_csv(rep: &Report) -> String {
    let mut s = String::from(
        "volume,dims,mode,variant,view,axis,frame_ms,shear_ms,render_ms,warp_ms,cold_shear_ms,rmse,psnr,max_abs,ssim,silhouette,\
         depth_truth,depth_mean_vox,depth_p99_vox,depth_max_vox,depth_both,depth_only_test,depth_only_truth,\
         reconstruction,normal_mean_deg,normal_p99_deg,normal_max_deg\n",
    );
    let d = rep.dims;
    for r in &rep.records {
        let dep = |f: fn(&DepthError) -> f64| r.depth.map(|x| f(&x)).filter(|v| v.is_finite()).map(|v| v.to_string()).unwrap_or_default();
        let cnt = |f: fn(&DepthError) -> usize| r.depth.map(|x| f(&x).to_string()).unwrap_or_default();
        let nrm = |f: fn(&NormalError) -> f64| r.normal.map(|x| f(&x)).filter(|v| v.is_finite()).map(|v| v.to_string()).unwrap_or_default();
        let fields = [
            csv_field(&rep.volume),
            format!("{}x{}x{}", d[0], d[1], d[2]),
            r.mode.to_string(),
            csv_field(&r.variant),
            csv_field(&r.view),
            r.axis.to_string(),
            r.frame_ms.to_string(),
            r.shear_ms.to_string(),
            r.render_ms.to_string(),
            r.warp_ms.to_string(),
            r.cold_shear_ms.to_string(),
            r.error.rmse.to_string(),
            if r.error.psnr.is_infinite() { "inf".into() } else { r.error.psnr.to_string() },
            r.error.max_abs.to_string(),
            r.error.ssim.to_string(),
            r.error.silhouette.to_string(),
            r.depth_truth.unwrap_or("").to_string(),
            dep(|x| x.mean),
            dep(|x| x.p99),
            dep(|x| x.max),
            cnt(|x| x.both),
            cnt(|x| x.only_test),
            cnt(|x| x.only_truth),
            r.reconstruction.to_string(),
            nrm(|x| x.mean_deg),
            nrm(|x| x.p99_deg),
            nrm(|x| x.max_deg),
        ];
        s.push_str(&fields.join(","));
        s.push('\n');
    }
    s
}

/// Writes the time-against-`error` plot (log-log, one colour per mode, each
/// mode's Pareto front by that error joined and labelled) as SVG or PNG by
/// the extension: one panel per report (a suite's cases), two a row.
pub fn write_plot(path: &Path, reps: &[&Report], error: PlotError) -> Result<()> {
    use plotters::prelude::*;
    // plotters lays out text with ab_glyph; give it a font without fontconfig
    plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
        .map_err(|_| anyhow::anyhow!("cannot load the embedded DejaVu Sans font"))?;
    if let Some(rep) = reps.iter().find(|r| !r.summary.iter().any(|s| error.of(s).is_some())) {
        return Err(anyhow::anyhow!(
            "{}: nothing to plot for {}: no variant has a {} (depth and normal errors are measured in iso mode, normal error on phantoms with an analytic surface)",
            path.display(),
            rep.volume,
            error.name()
        ));
    }
    let cols = if reps.len() > 1 { 2 } else { 1 };
    let rows = reps.len().div_ceil(cols);
    let panel = if reps.len() > 1 { (800u32, 520u32) } else { (1000, 640) };
    let size = (panel.0 * cols as u32, panel.1 * rows as u32);
    match plot_format(path)? {
        "svg" => {
            let mut svg = String::new();
            draw_panels(SVGBackend::with_string(&mut svg, size).into_drawing_area(), reps, (rows, cols), error)
                .with_context(|| format!("{}: cannot draw the plot", path.display()))?;
            crate::app::output::write_text(path, &svg)?;
        }
        _ => {
            let mut buf = vec![0u8; (size.0 * size.1 * 3) as usize];
            draw_panels(BitMapBackend::with_buffer(&mut buf, size).into_drawing_area(), reps, (rows, cols), error)
                .context("cannot draw the plot")?;
            let img = image::RgbImage::from_raw(size.0, size.1, buf).context("plot buffer size")?;
            shearwarp::output::write_png(path, &img)?;
        }
    }
    Ok(())
}

/// Each report's plot ([`draw_plot`]) in its panel of a `rows × cols` grid.
fn draw_panels<DB: plotters::prelude::DrawingBackend>(
    root: plotters::drawing::DrawingArea<DB, plotters::coord::Shift>,
    reps: &[&Report],
    (rows, cols): (usize, usize),
    error: PlotError,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&plotters::style::WHITE)?;
    for (area, rep) in root.split_evenly((rows, cols)).into_iter().zip(reps) {
        draw_plot(area, rep, error)?;
    }
    root.present()?;
    Ok(())
}

/// A number with about three significant digits, without trailing zeros.
fn fmt_sig(v: f64) -> String {
    let p = if v >= 100.0 {
        0
    } else if v >= 10.0 {
        1
    } else if v >= 1.0 {
        2
    } else {
        (3.0 - v.abs().max(1e-12).log10().floor()) as usize - 1
    };
    let s = format!("{v:.p$}");
    if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.').to_string() } else { s }
}

fn draw_plot<DB: plotters::prelude::DrawingBackend>(
    root: plotters::drawing::DrawingArea<DB, plotters::coord::Shift>,
    rep: &Report,
    error: PlotError,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    use plotters::prelude::*;
    // an error of 0 cannot sit on a log axis; no real fast path reaches it
    const FLOOR: f64 = 1e-7;
    let pts: Vec<(&Summary, f64, f64)> =
        rep.summary.iter().filter_map(|s| Some((s, s.frame_ms.max(1e-6), error.of(s)?.max(FLOOR)))).collect();
    // each mode's Pareto front by this error
    let on_front = pareto_front(&pts.iter().map(|p| (p.0.mode, p.1, p.2)).collect::<Vec<_>>());
    let (x0, x1) = pts.iter().fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.1), b.max(p.1)));
    let (y0, y1) = pts.iter().fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.2), b.max(p.2)));
    let d = rep.dims;
    let title = format!("{} {}×{}×{}, {} px: frame time vs {}", rep.volume, d[0], d[1], d[2], rep.size, error.name());
    // both axes are logarithmic: plot log10 on linear axes (whose ticks plotters
    // spaces well at any range) and label them with the values
    let widen = |lo: f64, hi: f64, pad: f64| {
        let (lo, hi) = (lo.log10() - pad, hi.log10() + pad);
        let extra = (0.6 - (hi - lo)).max(0.0) / 2.0;
        (lo - extra, hi + extra)
    };
    let (x0, x1) = widen(x0, x1, 0.2);
    let (y0, y1) = widen(y0, y1, 0.25);
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(&title, ("sans-serif", if title.chars().count() > 64 { 17 } else { 22 }))
        .margin(18)
        .x_label_area_size(48)
        .y_label_area_size(80)
        .build_cartesian_2d(x0..x1, y0..y1)?;
    chart
        .configure_mesh()
        .x_desc("median frame time (ms, log scale)")
        .y_desc(error.label())
        .label_style(("sans-serif", 14))
        .x_labels(8)
        .y_labels(8)
        .x_label_formatter(&|x| fmt_sig(10f64.powf(*x)))
        .y_label_formatter(&|y| format!("{:.1e}", 10f64.powf(*y)))
        .draw()?;
    let pts: Vec<(&Summary, f64, f64, bool)> = pts.iter().zip(on_front).map(|(p, f)| (p.0, p.1.log10(), p.2.log10(), f)).collect();
    // labels of points in the right part of the plot go to their left
    let label_dx = |x: f64, text: &str| if (x - x0) / (x1 - x0) > 0.6 { -(text.chars().count() as i32) * 7 - 12 } else { 10 };
    for (i, (mode, _, _)) in rep.classification.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        let mine: Vec<&(&Summary, f64, f64, bool)> = pts.iter().filter(|p| p.0.mode == mode).collect();
        chart
            .draw_series(mine.iter().map(|p| Circle::new((p.1, p.2), 4, color.filled())))?
            .label(format!("{mode} (ringed: Pareto front)"))
            .legend(move |(x, y)| Circle::new((x, y), 5, color.filled()));
        let mut front: Vec<&&(&Summary, f64, f64, bool)> = mine.iter().filter(|p| p.3).collect();
        front.sort_by(|a, b| a.1.total_cmp(&b.1));
        chart.draw_series(LineSeries::new(front.iter().map(|p| (p.1, p.2)), color.stroke_width(2)))?;
        chart.draw_series(front.iter().map(|p| {
            EmptyElement::at((p.1, p.2))
                + Circle::new((0, 0), 9, color.stroke_width(2))
                + Text::new(p.0.variant.clone(), (label_dx(p.1, &p.0.variant), -16), ("sans-serif", 13).into_font().color(&BLACK))
        }))?;
        // the peers (rows without a shear time): a black square, always named
        let peers: Vec<&&(&Summary, f64, f64, bool)> = mine.iter().filter(|p| p.0.cold_shear_ms.is_nan()).collect();
        if !peers.is_empty() {
            chart
                .draw_series(peers.iter().map(|p| {
                    EmptyElement::at((p.1, p.2))
                        + Rectangle::new([(-6, -6), (6, 6)], BLACK.filled())
                        + Text::new(p.0.variant.clone(), (label_dx(p.1, &p.0.variant), 8), ("sans-serif", 13).into_font().color(&BLACK))
                }))?
                .label("peers (VolPack, VTK)")
                .legend(|(x, y)| Rectangle::new([(x - 5, y - 5), (x + 5, y + 5)], BLACK.filled()));
        }
    }
    // the lower left (fast and exact) is the corner no method reaches
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerLeft)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 14))
        .draw()?;
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn registry_covers_the_matrix() {
        let v = registry(Settings::default());
        // (+ 7 RLE Deluxe combinations, 3 binary ones, RLE reuse, 5 BCC)
        assert_eq!(v.len(), 4 * 2 * 2 + 5 + 16);
        let b = registry(Settings { mode: Mode::Blend, ..Settings::default() });
        assert_eq!(b.len(), 4 * 2 * 2 + 6 + 16);
        assert!(b.iter().any(|x| x.settings.ert == 1.0 && x.name.ends_with("noert")));
        let names: std::collections::BTreeSet<&str> = v.iter().map(|x| x.name.as_str()).collect();
        assert_eq!(names.len(), v.len(), "names are unique");
        assert!(names.contains("binary-c1-u64-bitscan") && names.contains("binary-c4-u32-lut") && names.contains("brute"));
        assert!(names.contains("rle") && names.contains("brute-rle"));
        assert!(v.iter().all(|x| x.projection == Projection::Parallel));
        // the fine variants: the fast paths at two intermediate pixels per voxel, the rest at one
        // every Deluxe combination and the paper's BCC columns
        for d in Deluxe::all().into_iter().filter(|d| !d.is_standard()) {
            let n = format!("rle-deluxe-{}", d.label());
            assert!(v.iter().any(|x| x.name == n && x.settings.deluxe == d && x.settings.method == Method::Rle), "{n}");
        }
        for n in ["binary-c1-u64-bitscan-deluxe-I", "binary-c1-u64-bitscan-deluxe-IM", "rle-reuse", "rle-bcc", "rle-bcc-deluxe-IMP"] {
            assert!(names.contains(n), "{n}");
        }
        assert!(v.iter().filter(|x| x.name.starts_with("rle-bcc")).all(|x| x.settings.lattice == shearwarp::Lattice::Bcc));
        // --deluxe / --grid apply to every variant, renamed
        let w = with_options(vec![v[0].clone()], &[Deluxe::parse("P,I").unwrap()], Some(shearwarp::Lattice::Bcc));
        assert_eq!(w[0].name, format!("{}-bcc-deluxe-IP", v[0].name));
        assert!(w[0].settings.deluxe.intermediate && w[0].settings.deluxe.post && w[0].settings.lattice == shearwarp::Lattice::Bcc);
        // a repeated --deluxe measures every variant under each set, S keeping the plain name
        let w = with_options(vec![v[0].clone(), v[0].clone()], &[Deluxe::parse("S").unwrap(), Deluxe::parse("I").unwrap()], None);
        let names: Vec<&str> = w.iter().map(|x| x.name.as_str()).collect();
        assert_eq!(names, [v[0].name.clone(), format!("{}-deluxe-I", v[0].name)]);
        assert!(!w[0].settings.deluxe.intermediate && w[1].settings.deluxe.intermediate);
        let fine: Vec<&str> = v.iter().filter(|x| x.quality == FINE_QUALITY).map(|x| x.name.as_str()).collect();
        assert_eq!(fine, ["binary-c1-u64-bitscan-q2", "rle-q2"]);
        assert!(v.iter().all(|x| x.quality == FINE_QUALITY || x.quality == 1.0));
        let p = Projection::perspective(40.0, 2.0).unwrap();
        let pv = perspective_variants(Settings::default(), p, "-f40-d2");
        assert_eq!(
            pv.iter().map(|x| (x.name.as_str(), x.settings.method, x.projection, x.quality)).collect::<Vec<_>>(),
            [
                ("binary-persp-f40-d2", Method::Binary, p, 1.0),
                ("binary-persp-q2-f40-d2", Method::Binary, p, FINE_QUALITY),
                ("brute-persp-f40-d2", Method::Brute, p, 1.0),
                ("rle-persp-f40-d2", Method::Rle, p, 1.0),
                ("rle-persp-q2-f40-d2", Method::Rle, p, FINE_QUALITY),
                ("brute-rle-persp-f40-d2", Method::BruteRle, p, 1.0)
            ]
        );
        // the matrix: 3 fields of view × 3 distances and the eye inside
        let m = perspective_matrix();
        assert_eq!(m.len(), 10);
        assert!(m.contains(&Projection::Perspective { fov_deg: 20.0, eye_distance: 0.75 }));
        assert!(m.iter().all(|p| p.check().is_ok()));
    }

    #[test]
    fn pareto_front() {
        let rec = |variant: &str, t: f64, e: f64| Record {
            mode: "iso",
            variant: variant.into(),
            view: "0°".into(),
            axis: 2,
            frame_ms: t,
            shear_ms: 0.0,
            render_ms: t,
            warp_ms: 0.0,
            cold_shear_ms: 0.0,
            error: ImageError { rmse: e, psnr: shearwarp::accuracy::metrics::psnr(e), max_abs: e, ssim: 1.0, silhouette: 0.0 },
            depth_truth: None,
            depth: None,
            reconstruction: "linear",
            normal: None,
        };
        let s = summarize(&[rec("fast", 1.0, 0.1), rec("slow-good", 5.0, 0.01), rec("dominated", 6.0, 0.05), rec("tie", 1.0, 0.1)]);
        let front: Vec<&str> = s.iter().filter(|x| x.pareto).map(|x| x.variant.as_str()).collect();
        assert_eq!(front, ["fast", "slow-good", "tie"]);
    }

    /// A peer row (no shear time) is matched by the fastest shearwarp row of
    /// its projection at most as slow and as wrong, or reported as not
    /// matched with both margins; perspective rows meet only their own kind.
    #[test]
    fn peers_are_matched_or_reported() {
        let rec = |variant: &str, t: f64, e: f64, peer: bool| Record {
            mode: "blend",
            variant: variant.into(),
            view: "0°".into(),
            axis: 0,
            frame_ms: t,
            shear_ms: 0.0,
            render_ms: t,
            warp_ms: 0.0,
            cold_shear_ms: if peer { f64::NAN } else { 0.0 },
            error: ImageError { rmse: e, psnr: shearwarp::accuracy::metrics::psnr(e), max_abs: e, ssim: 1.0, silhouette: 0.0 },
            depth_truth: None,
            depth: None,
            reconstruction: "linear",
            normal: None,
        };
        let s = summarize(&[
            rec("rle", 1.0, 0.04, false),
            rec("binary", 2.0, 0.03, false),
            rec("rle-persp", 2.0, 0.03, false),
            rec("volpack", 1.5, 0.05, true),
            rec("vtk", 50.0, 0.02, true),
            rec("vtk-persp", 1.0, 0.05, true),
            rec("binary-persp-q2-f40-d2-deluxe-I", 3.0, 0.02, false),
            rec("vtk-persp-f40-d2", 4.0, 0.025, true),
        ]);
        let d = dominance(&s, "blend");
        assert_eq!(d.len(), 4);
        assert!(d[0].starts_with("volpack") && d[0].contains("matched or beaten by rle (1.000 ms"), "{}", d[0]);
        assert!(d[1].starts_with("vtk ") && d[1].contains("NOT MATCHED") && d[1].contains("binary, has +50 % RMSE"), "{}", d[1]);
        // the perspective peer meets only rle-persp, which is slower
        assert!(d[2].starts_with("vtk-persp") && d[2].contains("NOT MATCHED") && d[2].contains("rle-persp, takes +100 % time"), "{}", d[2]);
        // options after the projection (q2, deluxe, bcc) do not hide a row from its peer
        assert!(d[3].starts_with("vtk-persp-f40-d2") && d[3].contains("matched or beaten by binary-persp-q2-f40-d2-deluxe-I"), "{}", d[3]);
        assert!(dominance(&s, "iso").is_empty());
    }
}
