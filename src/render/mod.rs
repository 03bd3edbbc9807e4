//! The renderer: one frame through every stage, from the volume to the image.
//!
//! Owns [`Renderer`], which holds the volume, the classification (one transfer
//! function, or a set of tissue presets sharing one threshold-coded mask), one
//! [`SliceStack`], one [`NormalStack`] (table shading) and one sheared mask per principal axis (each built only when a
//! view first needs it, and rebuilt only when the classification or cell size
//! changes), the reusable intermediate image and per-slice parameters, and a rayon
//! pool of the requested size. [`Renderer::render`] runs one frame and reports how
//! long each stage took. The output is the same for any thread count: every pixel
//! is computed by exactly one task from the same inputs. The pre-classified paths
//! ([`Method::Rle`], [`Method::BruteRle`]) keep their classification and per-axis
//! run-length encodings in a [`RleCache`], encoded lazily like the masks and
//! re-encoded when the classification (transfer function, iso value, tissue or
//! mode) changes.

pub mod checks;

use std::time::Instant;

use crate::classify::presets::Tissue;
use crate::classify::shade_table::{ShadeTable, headlight_object};
use crate::classify::shading::Shading;
use crate::classify::{Classifier, TransferFunction};
use crate::composite::Mode;
use crate::composite::raycast::{RayContext, occupied_scaled_rays, render_binary, render_brute, volume_rect, volume_rect_with_mids};
use crate::composite::{Intermediate, Rect};
use crate::data::bcc::{BccLattice, BccStack};
use crate::data::normals::CellSource;
use crate::data::normals::NormalStack;
use crate::data::slices::{Densities, SliceStack};
use crate::data::volume::Volume;
use crate::encode::depth::{Matcher, Search, binary_matcher};
use crate::encode::mask::{BinaryMask, CellCodes, MAX_CELL, PackedCodes, ShearWork};
use crate::encode::rle::{ClassKey, RleCache};
use crate::encode::walk::Drift;
use crate::error::{Error, Result};
use crate::memory::Memory;
use crate::view::clip::{ClipRegion, Region};
use crate::view::perspective::RayDirections;
use crate::view::plan::{FramePlan, Grid, Limiter, MapKind, RayLimits};
use crate::view::{Camera, Factorization, PerspectiveView, Projection};
use crate::warp::{Canvas, Owned, Texel, clear_for_pyramids, warp, warp_owned};

/// Largest sheared mask, in bytes, a renderer builds for one axis. It is
/// allocated zeroed (address space; only the occupied part is ever touched).
pub const MAX_MASK_BYTES: u64 = 1 << 34;
/// Largest intermediate image, in pixels, a renderer allocates.
pub const MAX_INTERMEDIATE_PIXELS: u64 = 1 << 29;
/// The smallest intermediate image resolution, in pixels per voxel ([`Renderer::set_quality`]).
pub const MIN_QUALITY: f64 = 0.25;
/// The largest intermediate image resolution, in pixels per voxel.
pub const MAX_QUALITY: f64 = 2.0;

/// The near plane of a perspective frame, in slices in front of the eye:
/// slices nearer the eye (where the per-slice scale grows without bound) are
/// not composited.
pub const NEAR_SLICES: f64 = 0.5;

/// Which render path.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Method {
    /// The bit-packed binary shear-warp fast rotator.
    Binary,
    /// Unaccelerated reference: every slice of every ray, same sample positions.
    Brute,
    /// Lacroute's run-length-encoded, pre-classified shear-warp: voxels are
    /// classified and shaded before interpolation, transparent voxels skipped
    /// run by run, opaque pixels through skip links, and every pixel stops at
    /// the early-ray-termination opacity — in iso mode too, where the transfer function
    /// is the iso threshold (opaque from the iso value on, in the iso colour).
    Rle,
    /// The pre-classified reference for the RLE method: the same samples,
    /// every voxel of every slice, no runs and no skip links.
    #[serde(rename = "brute-rle")]
    BruteRle,
}

impl Method {
    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Method::Binary => "binary",
            Method::Brute => "brute",
            Method::Rle => "rle",
            Method::BruteRle => "brute-rle",
        }
    }
}

/// Word width of the packed mask.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum WordSize {
    U32,
    U64,
}

impl WordSize {
    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            WordSize::U32 => "u32",
            WordSize::U64 => "u64",
        }
    }
}

/// How the RLE paths sample a slice whose intermediate pixels are wider than a
/// voxel (the far slices of a perspective view, a grid coarser than one pixel
/// per voxel: [`crate::view::plan::FramePlan::footprint`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Footprint {
    /// The area average of the voxels under the pixel's box (no voxel falls
    /// between two pixels; about 2–3× the bilinear sample's cost).
    #[default]
    Box,
    /// The bilinear sample at the pixel's centre (faster; voxels between
    /// pixels alias): for interaction.
    Bilinear,
}

impl Footprint {
    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Footprint::Box => "box",
            Footprint::Bilinear => "bilinear",
        }
    }
}

/// The Shear-Warp Deluxe options (Sweeney & Mueller 2002), each a sampler or a
/// producer of plans, combining freely. The paper's names: S (none of them,
/// standard shear-warp), I, P, M and their concatenations.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct Deluxe {
    /// I: one intermediate slice between each pair of slices, sampled at the
    /// midpoint of the ray between them (trilinear there), every sample with
    /// the half-step opacity `α_n = 1 − √(1 − α)`.
    pub intermediate: bool,
    /// P: post-interpolated classification and shading on the RLE paths (the
    /// runs carry densities and normal codes; a sample interpolates the
    /// density, then classifies). The raycast paths always classify after
    /// interpolation.
    pub post: bool,
    /// M: matched sampling on zoom: as many samples per voxel square as the
    /// warp magnifies (the paper's eq. 3), the warp divided by them.
    pub matched: bool,
}

impl Deluxe {
    /// Standard shear-warp (no option).
    pub const STANDARD: Deluxe = Deluxe { intermediate: false, post: false, matched: false };

    /// Every combination, standard first, in the paper's order of columns
    /// (S, I, P, IP, M, IM, MP, IMP).
    pub fn all() -> [Deluxe; 8] {
        std::array::from_fn(|b| Deluxe { intermediate: b & 1 != 0, post: b & 2 != 0, matched: b & 4 != 0 })
    }

    /// Parses a comma-separated subset of `I,P,M` (any order, either case;
    /// `S` or nothing is the standard algorithm).
    pub fn parse(list: &str) -> Result<Deluxe> {
        let mut d = Deluxe::STANDARD;
        for item in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let flag = match item.to_ascii_uppercase().as_str() {
                "I" => &mut d.intermediate,
                "P" => &mut d.post,
                "M" => &mut d.matched,
                "S" => continue,
                _ => {
                    return Err(Error::value(
                        "Shear-Warp Deluxe option",
                        format!(
                            "'{item}' (a comma-separated subset of I, P, M: intermediate slices, post-classification, matched sampling)"
                        ),
                    ));
                }
            };
            if *flag {
                return Err(Error::value("Shear-Warp Deluxe options", format!("'{list}' names {item} twice")));
            }
            *flag = true;
        }
        Ok(d)
    }

    /// The paper's label: `S`, or the options' letters in the order I, M, P
    /// (`I`, `IP`, `IM`, `IMP`, ...).
    pub fn label(self) -> String {
        let mut s = String::new();
        for (on, c) in [(self.intermediate, 'I'), (self.matched, 'M'), (self.post, 'P')] {
            if on {
                s.push(c);
            }
        }
        if s.is_empty() { "S".into() } else { s }
    }

    /// True for standard shear-warp.
    pub fn is_standard(self) -> bool {
        self == Deluxe::STANDARD
    }
}

/// The sample lattice the volume is rendered from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Lattice {
    /// The volume's own cartesian grid.
    #[default]
    Cartesian,
    /// A body-centred cubic grid resampled from it: two interleaved cubic
    /// sub-grids of spacing √2 voxels, offset by half a sub-grid cell on every
    /// axis (about 70 % of the samples; RLE paths).
    Bcc,
}

impl Lattice {
    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Lattice::Cartesian => "cartesian",
            Lattice::Bcc => "bcc",
        }
    }
}

/// How the raycast paths ([`Method::Binary`], [`Method::Brute`]) shade a sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Normals {
    /// VolPack's shading tables: every voxel's gradient
    /// direction quantized to a 14-bit code once per axis, a shade table per view,
    /// and a sample's shade blended from its cell's four corner entries.
    Codes,
    /// The exact central-difference gradient at the sample, normalized and shaded
    /// per sample (slower, no quantization).
    Gradient,
}

impl Normals {
    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Normals::Codes => "codes",
            Normals::Gradient => "gradient",
        }
    }
}

/// Render settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    pub method: Method,
    pub mode: Mode,
    pub word: WordSize,
    pub search: Search,
    /// Super-cell size (1..=8).
    pub cell: usize,
    /// Early ray termination threshold (blend mode; both modes of the
    /// pre-classified paths); 1.0 disables it.
    pub ert: f32,
    pub shading: Shading,
    /// Worker threads (0 = all cores).
    pub threads: usize,
    /// Binary path: cast rays only inside the bounding rectangle of the occupied
    /// (sheared) mask. `false` casts over the whole sheared volume's rectangle:
    /// a benchmark knob that shows what the rectangle skip buys (same image).
    pub occupied_rect: bool,
    /// Binary path: prefetch the voxel rows of each ray's first candidate slice
    /// while a group of rays is bit-scanned, before the group is traced. `false`
    /// leaves the prefetches out: a benchmark knob that shows what they buy
    /// (same image).
    pub prefetch: bool,
    /// Raycast paths: shade by normal code and table, or by exact gradient.
    pub normals: Normals,
    /// Raycast paths with [`Normals::Codes`]: pack each voxel's density and
    /// normal code into one u32 when the densities are integers spanning at
    /// most 65 535 (8- and 16-bit scans), so a ray reads both from the same
    /// cache lines ([`crate::data::normals::NormalStack`]). `false` keeps them
    /// apart: a benchmark knob that shows what packing buys (same image).
    pub pack: bool,
    /// CPU level of the kernels (the binary path's depth-search row loop and
    /// the mask's shear kernels), capped by what the CPU has: every level gives
    /// the same image; lower levels run the plain references. Defaults to
    /// [`crate::kernels::level`] (the detected level, capped by `SHEARWARP_CPU`).
    pub cpu: crate::kernels::CpuLevel,
    /// RLE paths: the footprint of a minified slice's pixel.
    pub footprint: Footprint,
    /// The Shear-Warp Deluxe options ([`Deluxe`]).
    pub deluxe: Deluxe,
    /// The sample lattice ([`Lattice`]).
    pub lattice: Lattice,
    /// RLE paths, parallel projection: one encoding serves the x and z axes
    /// (Sweeney & Mueller's re-use of RLE runs): z views read the volume
    /// through the mirrored permutation (y, x, z)
    /// ([`crate::view::reuse_permutation`]), whose scanlines are x's, through a
    /// pointer table (or x reads z's); y keeps its own encoding. The same samples (the
    /// intermediate image of a z view is transposed), so the image equals the
    /// separate encodings' to float rounding; about a third less RLE memory.
    /// A perspective frame uses the separate encodings (cyclic permutations).
    pub rle_reuse: bool,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            method: Method::Binary,
            mode: Mode::Iso,
            word: WordSize::U64,
            search: Search::Bitscan,
            cell: 1,
            ert: 0.99,
            shading: Shading::default(),
            threads: 0,
            occupied_rect: true,
            prefetch: true,
            normals: Normals::Codes,
            pack: true,
            cpu: crate::kernels::level(),
            footprint: Footprint::Box,
            deluxe: Deluxe::STANDARD,
            lattice: Lattice::Cartesian,
            rle_reuse: false,
        }
    }
}

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

#[derive(Clone, Debug)]
enum AnyMask {
    W32(BinaryMask<u32>),
    W64(BinaryMask<u64>),
}

impl AnyMask {
    fn bytes(&self) -> usize {
        match self {
            AnyMask::W32(m) => m.bytes(),
            AnyMask::W64(m) => m.bytes(),
        }
    }
    fn set_cpu_level(&mut self, cpu: crate::kernels::CpuLevel) {
        match self {
            AnyMask::W32(m) => m.set_cpu_level(cpu),
            AnyMask::W64(m) => m.set_cpu_level(cpu),
        }
    }
}

/// What a cached mask was built for.
#[derive(Clone, Copy, Debug, PartialEq)]
struct MaskKey {
    /// Predicate masks depend on the mode; code masks do not.
    mode: Option<Mode>,
    word: WordSize,
    cell: usize,
    generation: u64,
    /// Deluxe I: each bit also covers the midpoint after its slice
    /// ([`CellCodes::build_half`]).
    half: bool,
}

#[derive(Debug)]
struct AxisMask {
    key: MaskKey,
    mask: AnyMask,
}

/// Focus+context ([`Renderer::set_focus`]): inside `region` (voxel indices,
/// as [`ClipRegion`] takes it) the samples are classified by the tissue
/// preset named `tissue`, outside it by the renderer's current one.
#[derive(Clone, Debug, PartialEq)]
pub struct Focus {
    pub region: Region,
    /// A preset name of the renderer's tissue set (e.g. "bone").
    pub tissue: String,
}

impl Focus {
    /// A focus region classified by tissue preset `tissue`.
    pub fn new(region: Region, tissue: impl Into<String>) -> Self {
        Focus { region, tissue: tissue.into() }
    }
}

/// The region of focus+context: a fixed clip region
/// ([`Renderer::set_focus`]) or a producer of focus intervals set per frame
/// ([`Renderer::set_focus_limiter`], e.g. a convex mesh's
/// [`crate::geometry::MeshClip`] drawn with the frame's camera).
#[derive(Clone)]
enum FocusShape {
    Region(ClipRegion),
    Limiter(std::sync::Arc<dyn Limiter>),
}

impl FocusShape {
    fn limiter(&self) -> &dyn Limiter {
        match self {
            FocusShape::Region(r) => r,
            FocusShape::Limiter(l) => l.as_ref(),
        }
    }
}

/// Tissue presets sharing one threshold-coded mask.
struct TissueSet {
    tissues: Vec<Tissue>,
    /// Per tissue: the iso (threshold) classifier and the blend classifier.
    iso_cls: Vec<Classifier>,
    blend_cls: Vec<Classifier>,
    /// Ascending thresholds; tissue `i` is code `i + 1`.
    thresholds: Vec<f32>,
    /// Matcher "code ≥ i + 1" per tissue.
    matchers: Vec<Matcher>,
    current: usize,
}

/// Everything a frame depends on besides the volume.
#[derive(Clone, Copy, Debug, PartialEq)]
struct FrameKey {
    camera: Camera,
    projection: Projection,
    quality: f64,
    settings: Settings,
    generation: u64,
    tissue: Option<usize>,
    limiter: Option<u64>,
    focus: Option<(u64, usize)>,
}

/// A new focus region's stamp (part of [`FrameKey`]).
fn next_focus_stamp() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

static NEXT_STAMP: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

/// Renders frames of one volume.
pub struct Renderer {
    volume: Volume,
    range: (f32, f32),
    /// The single transfer function (when no tissue set is active).
    classifier: Classifier,
    iso: f32,
    tissues: Option<TissueSet>,
    settings: Settings,
    /// Bumped whenever the classification changes (invalidates masks).
    generation: u64,
    stacks: [Option<SliceStack>; 3],
    /// Per axis, the interleaved slices of the BCC grid ([`Lattice::Bcc`]; the
    /// RLE paths read them instead of [`Renderer::stacks`]).
    bcc: [Option<BccStack>; 3],
    /// Per axis, every voxel's normal code (raycast paths with [`Normals::Codes`]).
    normals: [Option<NormalStack>; 3],
    /// The shade table of the raycast paths' table shading (kept across frames,
    /// rebuilt when the light direction or the material changes).
    shade: ShadeTable,
    codes: [Option<(u64, CellCodes)>; 3],
    masks: [Option<AxisMask>; 3],
    /// The plan of the last frame (its arrays reused by the next).
    plan: Option<FramePlan>,
    /// The plans of the last split perspective frame, one per pyramid (reused
    /// likewise), and whether the last frame was split.
    pyramid_plans: Vec<FramePlan>,
    pyramid_count: usize,
    last_split: bool,
    /// Each pyramid's intermediate iso depth of the last split frame (only
    /// `depth`, `size` and `valid` are used; kept when [`Renderer::set_keep_depths`]
    /// is on, in iso mode), and the output pixels' rays that say which
    /// pyramid owns a pixel.
    pyramid_depths: Vec<Intermediate>,
    keep_depths: bool,
    last_rays: Option<RayDirections>,
    /// The perspective views of the last frame (a buffer reused).
    views: Vec<PerspectiveView>,
    /// The producer of per-pixel ray limits, if any, and a counter bumped when it changes.
    limiter: Option<(std::sync::Arc<dyn Limiter>, u64)>,
    /// Focus+context: the region, the focus tissue's index in the tissue
    /// set, and a counter bumped when the region changes.
    focus: Option<(FocusShape, usize, u64)>,
    inter: Intermediate,
    /// The inputs and stamp of the last frame written.
    last_frame: Option<(FrameKey, u64)>,
    pool: rayon::ThreadPool,
    /// Classification, encodings and tables of the pre-classified paths.
    rle: RleCache,
    /// Largest total of [`Renderer::memory`] a new structure may bring about.
    budget: Option<u64>,
    /// How long each structure took to build.
    build_times: BuildTimes,
    /// Parallel or perspective.
    projection: Projection,
    /// Intermediate pixels per voxel (the adaptive image size; 1 by default).
    quality: f64,
}

impl Renderer {
    /// A renderer for `volume` with transfer function `tf`; the iso value starts
    /// at the transfer function's lower threshold.
    pub fn new(volume: Volume, tf: &TransferFunction, settings: Settings) -> Result<Self> {
        let range = volume.value_range();
        let classifier = Classifier::new(tf, range.0, range.1);
        let iso = tf.lower_threshold().unwrap_or(f32::INFINITY);
        let pool = build_pool(settings.threads)?;
        check_settings(&settings)?;
        Ok(Renderer {
            volume,
            range,
            classifier,
            iso,
            tissues: None,
            settings,
            generation: 0,
            stacks: [None, None, None],
            bcc: [None, None, None],
            normals: [None, None, None],
            shade: ShadeTable::default(),
            codes: [None, None, None],
            masks: [None, None, None],
            plan: None,
            pyramid_plans: vec![],
            pyramid_count: 0,
            last_split: false,
            pyramid_depths: vec![],
            keep_depths: false,
            last_rays: None,
            views: vec![],
            limiter: None,
            focus: None,
            inter: Intermediate::default(),
            last_frame: None,
            pool,
            rle: RleCache::new(),
            budget: None,
            build_times: BuildTimes::default(),
            projection: Projection::Parallel,
            quality: 1.0,
        })
    }

    /// A renderer that switches between `tissues` (1..=15 presets with distinct
    /// lower thresholds) in O(1): one mask of adaptive threshold codes serves
    /// them all, so a switch changes a table, never the mask. Starts at tissue 0.
    pub fn with_tissues(volume: Volume, tissues: &[Tissue], settings: Settings) -> Result<Self> {
        let first = tissues.first().ok_or_else(|| Error::value("tissues", "need at least one preset"))?;
        let mut r = Self::new(volume, &first.tf, settings)?;
        let mut ts: Vec<Tissue> = tissues.to_vec();
        ts.sort_by(|a, b| a.threshold.total_cmp(&b.threshold));
        let thresholds: Vec<f32> = ts.iter().map(|t| t.threshold).collect();
        if thresholds.windows(2).any(|w| w[0] >= w[1]) || thresholds.iter().any(|t| !t.is_finite()) {
            return Err(Error::value("tissues", format!("thresholds must be finite and distinct, got {thresholds:?}")));
        }
        for t in &ts {
            // the code mask is conservative only if each tissue is transparent below its threshold
            if let Some(lt) = t.tf.lower_threshold() {
                if lt < t.threshold {
                    return Err(Error::value("tissues", format!("{} has opacity below its threshold {}", t.name, t.threshold)));
                }
            }
        }
        let nb = crate::encode::depth::code_width_for(ts.len()).ok_or_else(|| Error::value("tissues", "at most 15 presets"))?;
        let (lo, hi) = r.range;
        r.tissues = Some(TissueSet {
            iso_cls: ts.iter().map(|t| Classifier::new(&t.iso_tf(), lo, hi)).collect(),
            blend_cls: ts.iter().map(|t| Classifier::new(&t.tf, lo, hi)).collect(),
            matchers: (1..=ts.len() as u32).map(|c| Matcher::new(nb, c)).collect(),
            thresholds,
            tissues: ts,
            current: 0,
        });
        r.generation += 1;
        Ok(r)
    }

    /// The tissue presets (sorted by threshold) and the index of the current one.
    pub fn tissues(&self) -> Option<(&[Tissue], usize)> {
        self.tissues.as_ref().map(|t| (t.tissues.as_slice(), t.current))
    }

    /// Switches to tissue `i` of the set: O(1), no mask rebuild and no re-shear.
    pub fn select_tissue(&mut self, i: usize) -> Result<()> {
        let ts = self.tissues.as_mut().ok_or_else(|| Error::value("tissue", "this renderer has no tissue presets"))?;
        if i >= ts.tissues.len() {
            return Err(Error::value("tissue", format!("index {i} (have {})", ts.tissues.len())));
        }
        ts.current = i;
        Ok(())
    }

    /// Selects a tissue by name.
    pub fn select_tissue_named(&mut self, name: &str) -> Result<()> {
        let i = self.tissues.as_ref().and_then(|t| t.tissues.iter().position(|x| x.name == name));
        self.select_tissue(i.ok_or_else(|| Error::value("tissue", format!("'{name}' is not in this renderer's presets")))?)
    }

    /// The volume: borrowed, or rebuilt from the packed cells when this
    /// renderer let go of its voxels (see [`Renderer::memory`]; then this
    /// allocates a copy, or fails with [`Error::Memory`]).
    pub fn volume(&self) -> Result<std::borrow::Cow<'_, Volume>> {
        if !self.volume.is_parked() {
            return Ok(std::borrow::Cow::Borrowed(&self.volume));
        }
        let mut v = self.volume.clone();
        v.unpark(self.parked_voxels()?);
        Ok(std::borrow::Cow::Owned(v))
    }
    /// The volume's size in voxels.
    pub fn dims(&self) -> [usize; 3] {
        self.volume.dims()
    }
    /// The volume's voxel spacing.
    pub fn spacing(&self) -> [f32; 3] {
        self.volume.spacing()
    }
    /// The volume's smallest and largest density.
    pub fn value_range(&self) -> (f32, f32) {
        self.range
    }

    /// The voxels of a parked volume, from any packed cells that hold them.
    fn parked_voxels(&self) -> Result<std::sync::Arc<crate::data::volume::VoxelData>> {
        let lost = || Error::Other("internal: the volume's voxels were let go with no packed cells holding them".into());
        let ns = self.normals.iter().flatten().find(|n| n.holds_voxels()).ok_or_else(lost)?;
        Ok(std::sync::Arc::new(ns.voxels_in_volume_order()?.ok_or_else(lost)?))
    }

    /// Gives the volume its voxels back if this renderer let go of them.
    fn unpark(&mut self) -> Result<()> {
        if self.volume.is_parked() {
            let data = self.pool.install(|| self.parked_voxels())?;
            self.volume.unpark(data);
        }
        Ok(())
    }

    /// Lets go of the volume's voxels when packed cells of this renderer hold
    /// them (or a build of them is under way: `building`) and nothing outside
    /// it shares them: the binary path of an integer scan then holds the
    /// voxels once, in its cells, instead of twice ([`Renderer::volume`] and
    /// the builds of other paths get them back from the cells).
    fn park(&mut self, building: bool) {
        let held = building || self.normals.iter().flatten().any(NormalStack::holds_voxels);
        if held && self.can_let_go() {
            self.volume.park();
        }
    }

    /// True when the volume's voxels are resident and only this renderer holds them.
    fn can_let_go(&self) -> bool {
        !self.volume.is_parked() && self.volume.data_handles() == 1
    }
    /// Current settings.
    pub fn settings(&self) -> Settings {
        self.settings
    }
    /// Changes settings (rebuilding the thread pool if the count changed; masks
    /// follow on the next frame if the word size or cell size changed, normal
    /// codes if the packing did).
    pub fn set_settings(&mut self, s: Settings) -> Result<()> {
        check_settings(&s)?;
        if s.threads != self.settings.threads {
            self.pool = build_pool(s.threads)?;
        }
        if s.pack != self.settings.pack {
            self.unpark()?;
            self.normals = [None, None, None];
        }
        self.settings = s;
        Ok(())
    }
    /// Replaces the classification by one transfer function (leaves any tissue
    /// set; masks are rebuilt on the next frame).
    pub fn set_transfer_function(&mut self, tf: &TransferFunction) {
        self.classifier = Classifier::new(tf, self.range.0, self.range.1);
        self.iso = tf.lower_threshold().unwrap_or(f32::INFINITY);
        self.tissues = None;
        self.generation += 1;
    }
    /// Sets a custom iso value for the preview (leaves any tissue set; masks are
    /// rebuilt on the next frame).
    pub fn set_iso(&mut self, iso: f32) -> Result<()> {
        if iso.is_nan() {
            return Err(Error::value("iso value", "NaN"));
        }
        if let Some(ts) = self.tissues.take() {
            self.classifier = ts.blend_cls[ts.current].clone();
        }
        self.iso = iso;
        self.generation += 1;
        Ok(())
    }
    /// The iso value of the preview.
    pub fn iso(&self) -> f32 {
        match &self.tissues {
            Some(ts) => ts.thresholds[ts.current],
            None => self.iso,
        }
    }
    /// Name of the current classification (tissue name or "custom").
    pub fn classification_name(&self) -> &str {
        match &self.tissues {
            Some(ts) => ts.tissues[ts.current].name,
            None => "custom",
        }
    }
    /// The classifier the current mode uses.
    pub fn classifier(&self) -> &Classifier {
        match (&self.tissues, self.settings.mode) {
            (Some(ts), Mode::Iso) => &ts.iso_cls[ts.current],
            (Some(ts), Mode::Blend) => &ts.blend_cls[ts.current],
            (None, _) => &self.classifier,
        }
    }
    /// Sets the projection of the following frames (checked: a field of view
    /// in (0°, 180°), an eye distance finite and > 0). A perspective frame
    /// renders with [`Method::Rle`] or [`Method::BruteRle`]; the raycast paths
    /// refuse it with an error.
    pub fn set_projection(&mut self, projection: Projection) -> Result<()> {
        projection.check()?;
        self.projection = projection;
        Ok(())
    }
    /// The projection of the following frames.
    pub fn projection(&self) -> Projection {
        self.projection
    }
    /// Sets the intermediate image's resolution of the following frames:
    /// `q` intermediate pixels per voxel, in `[MIN_QUALITY, MAX_QUALITY]`
    /// (0.25–2; 1, the default, is the classic one pixel per voxel). Below 1
    /// the frame composites fewer rays (a coarser, faster preview, each slice
    /// point-sampled bilinearly at the coarser pitch); above 1 it samples the
    /// slices finer (less blur where the output magnifies). Both projections;
    /// the plan is the projection's own, resampled ([`FramePlan::set_pitch`]).
    pub fn set_quality(&mut self, q: f64) -> Result<()> {
        if !(q.is_finite() && (MIN_QUALITY..=MAX_QUALITY).contains(&q)) {
            return Err(Error::value(
                "quality",
                format!("intermediate pixels per voxel must be in [{MIN_QUALITY}, {MAX_QUALITY}], got {q}"),
            ));
        }
        self.quality = q;
        Ok(())
    }
    /// Intermediate pixels per voxel of the following frames.
    pub fn quality(&self) -> f64 {
        self.quality
    }
    /// Sets (or, with `None`, removes) the producer of per-pixel ray limits
    /// that narrows every following frame's plan: a clip region or geometry.
    pub fn set_limiter(&mut self, limiter: Option<std::sync::Arc<dyn Limiter>>) {
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
        self.limiter = limiter.map(|l| (l, NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)));
    }
    /// Sets (or, with `None`, removes) focus+context: inside the focus
    /// region every following frame classifies its samples by the focus's
    /// tissue preset, outside it by the current one ([`Renderer::select_tissue`]).
    /// O(1) like a tissue switch: the binary path's walks visit the union of
    /// the two presets' codes of the one threshold-coded mask; the RLE paths'
    /// tables are per-view (a pre-classified encoding holds the voxels either
    /// preset shows, so it is rebuilt when the focus tissue changes, as for a
    /// tissue switch; Deluxe P's keeps every preset's already). Needs a
    /// renderer with tissue presets ([`Renderer::with_tissues`]); the region
    /// is checked as [`ClipRegion::new`] checks it.
    pub fn set_focus(&mut self, focus: Option<Focus>) -> Result<()> {
        let Some(f) = focus else {
            self.focus = None;
            return Ok(());
        };
        let i = self.focus_tissue_index(&f.tissue)?;
        let region = ClipRegion::new(f.region, self.volume.spacing())?;
        // the same region keeps its stamp (a focus tissue switch alone redraws nothing twice)
        let stamp = match &self.focus {
            Some((FocusShape::Region(r), _, s)) if *r == region => *s,
            _ => next_focus_stamp(),
        };
        self.focus = Some((FocusShape::Region(region), i, stamp));
        Ok(())
    }

    /// Focus+context in a region given as a producer of focus intervals
    /// (for example a convex mesh's [`crate::geometry::MeshClip`] keeping its
    /// inside, drawn with each frame's camera and set again per frame): as
    /// [`Renderer::set_focus`], the samples each ray's interval
    /// ([`FramePlan::apply_focus`]) holds are classified by tissue preset
    /// `tissue`. The same `Arc` set again keeps the frame's key (nothing is
    /// redrawn for a tissue switch); a limiter that cuts holes (an outside
    /// region) is refused: a focus is one interval per ray.
    pub fn set_focus_limiter(&mut self, limiter: std::sync::Arc<dyn Limiter>, tissue: &str) -> Result<()> {
        let i = self.focus_tissue_index(tissue)?;
        if limiter.holes() > 0 {
            return Err(Error::value("focus", "a focus region is one interval per ray: a limiter keeping an outside is not one"));
        }
        let stamp = match &self.focus {
            Some((FocusShape::Limiter(l), _, s)) if std::sync::Arc::ptr_eq(l, &limiter) => *s,
            _ => next_focus_stamp(),
        };
        self.focus = Some((FocusShape::Limiter(limiter), i, stamp));
        Ok(())
    }

    /// The index of focus tissue `name` in the tissue set (an error without
    /// presets or for a name not among them).
    fn focus_tissue_index(&self, name: &str) -> Result<usize> {
        let ts = self.tissues.as_ref().ok_or_else(|| {
            Error::value("focus", "focus+context needs a renderer with tissue presets (not a custom iso value or transfer function)")
        })?;
        ts.tissues.iter().position(|t| t.name == name).ok_or_else(|| {
            let names: Vec<&str> = ts.tissues.iter().map(|t| t.name).collect();
            Error::value("focus tissue", format!("'{name}' is not in this renderer's presets ({})", names.join(", ")))
        })
    }

    /// The focus region and the name of its tissue preset, if any (`None`
    /// too for a focus set by [`Renderer::set_focus_limiter`]).
    pub fn focus(&self) -> Option<Focus> {
        let (FocusShape::Region(r), i, _) = self.focus.as_ref()? else { return None };
        let ts = self.tissues.as_ref()?;
        Some(Focus { region: r.region(), tissue: ts.tissues.get(*i)?.name.to_string() })
    }

    /// The focus tissue's index in the tissue set (when both exist).
    fn focus_tissue(&self) -> Option<usize> {
        self.focus.as_ref().filter(|_| self.tissues.is_some()).map(|f| f.1)
    }

    /// The intermediate image of the last frame.
    pub fn intermediate(&self) -> &Intermediate {
        &self.inter
    }
    /// The factorization of the last frame.
    pub fn last_factorization(&self) -> Option<&Factorization> {
        self.last_plan().map(|p| &p.view)
    }
    /// The frame plan of the last frame (of a frame split into pyramids, the
    /// plan of the pyramid owning the image centre, if any).
    pub fn last_plan(&self) -> Option<&FramePlan> {
        if self.last_split { self.pyramid_plans[..self.pyramid_count].first() } else { self.plan.as_ref() }
    }

    /// The frame plans of the last frame: one, or one per pyramid of a split
    /// perspective frame (the pyramid owning the image centre first).
    pub fn last_plans(&self) -> &[FramePlan] {
        if self.last_split { &self.pyramid_plans[..self.pyramid_count] } else { self.plan.as_slice() }
    }

    /// Keeps (`on`) the intermediate iso depth of every pyramid of a split
    /// perspective frame after it is warped (a copy of the depth plane per
    /// pyramid, iso mode only), for [`Renderer::last_depth_at`]: the
    /// volume's hit under an output pixel of any frame
    /// ([`crate::geometry::volume_hit`]). Off by default (a frame that is not
    /// split reads the intermediate image itself and costs nothing either way).
    pub fn set_keep_depths(&mut self, on: bool) {
        self.keep_depths = on;
    }

    /// The index in [`Renderer::last_plans`] of the plan whose image holds
    /// output pixel `(u, v)` of the last frame: the one plan, or the pyramid
    /// that owns the pixel's ray ([`crate::view::perspective::ray_owner`]) in a
    /// split frame (`None`: no plan, or no pyramid of the frame owns it).
    pub fn last_owner(&self, u: f64, v: f64) -> Option<usize> {
        let plans = self.last_plans();
        match (self.last_split, &self.last_rays) {
            (true, Some(rays)) => {
                let owner = rays.owner(u, v);
                plans.iter().position(|p| (p.view.axis, p.view.ascending) == owner)
            }
            (true, None) => None,
            (false, _) => (!plans.is_empty()).then_some(0),
        }
    }

    /// The output pixels' rays of the last frame if it was split into
    /// pyramids (which pyramid owns a pixel: [`Renderer::last_owner`]).
    pub fn last_rays(&self) -> Option<RayDirections> {
        self.last_rays.filter(|_| self.last_split)
    }

    /// The image whose depth plane [`Renderer::last_depth_at`] reads for plan
    /// `i` (only its `size`, `valid` and `depth`), if any.
    pub(crate) fn last_depth_image(&self, i: usize) -> Option<&Intermediate> {
        if self.last_split { self.pyramid_depths.get(i) } else { Some(&self.inter) }
    }

    /// The iso depth (fractional slice index, NaN where none) at intermediate
    /// pixel `(p, q)` of plan `i` of [`Renderer::last_plans`]: the
    /// intermediate image's own for a frame that is not split, the kept copy
    /// for a pyramid of a split one (NaN unless [`Renderer::set_keep_depths`]
    /// was on for that frame), NaN when the image does not match the plan.
    pub fn last_depth_at(&self, i: usize, p: usize, q: usize) -> f32 {
        let Some(plan) = self.last_plans().get(i) else { return f32::NAN };
        match self.last_depth_image(i) {
            Some(d) if d.holds_depths_of(plan.grid.size) => d.depth_at(p, q),
            _ => f32::NAN,
        }
    }

    /// Runs `f` on the renderer's thread pool (where its frames' limiters
    /// run: to time one as a frame does).
    pub fn install<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        self.pool.install(f)
    }

    /// Runs limiter `l` on `plan` as a frame does: on the renderer's thread
    /// pool when it asks for it ([`Limiter::parallel`]), else on this thread.
    pub fn run_limiter(&self, l: &dyn Limiter, plan: &FramePlan, limits: &mut RayLimits) {
        self.install_if(l.parallel(plan), || l.limit(plan, limits));
    }

    /// Runs `f` on the renderer's thread pool if `on`, else on this thread.
    fn install_if<R: Send>(&self, on: bool, f: impl FnOnce() -> R + Send) -> R {
        if on { self.pool.install(f) } else { f() }
    }

    /// Bytes of the packed masks that exist now.
    pub fn mask_bytes(&self) -> usize {
        self.masks.iter().flatten().map(|m| m.mask.bytes()).sum()
    }

    /// Bytes of the run-length encodings that exist now, per axis.
    pub fn rle_axis_bytes(&self) -> [usize; 3] {
        self.rle.bytes()
    }

    /// Bytes of the run-length encodings that exist now.
    pub fn rle_bytes(&self) -> usize {
        self.rle.bytes().iter().sum()
    }

    /// The pre-classified state (classification and encodings) of the RLE paths.
    pub fn rle_cache(&self) -> &RleCache {
        &self.rle
    }

    /// How long the last build of each structure took, per axis.
    pub fn build_times(&self) -> BuildTimes {
        self.build_times
    }

    /// Bytes held now, per structure and axis.
    pub fn memory(&self) -> Memory {
        let per = |f: &dyn Fn(usize) -> usize| [0, 1, 2].map(|a| f(a) as u64);
        Memory {
            volume: self.volume.bytes(),
            stacks: per(&|a| self.stacks[a].as_ref().map_or(0, SliceStack::bytes) + self.bcc[a].as_ref().map_or(0, BccStack::bytes)),
            normals: per(&|a| self.normals[a].as_ref().map_or(0, NormalStack::bytes)),
            cell_codes: per(&|a| self.codes[a].as_ref().map_or(0, |c| c.1.bytes())),
            masks: per(&|a| {
                self.masks[a].as_ref().map_or(0, |m| match &m.mask {
                    AnyMask::W32(m) => m.held_bytes(),
                    AnyMask::W64(m) => m.held_bytes(),
                })
            }),
            rle: self.rle.bytes().map(|b| b as u64),
            intermediate: self.inter.bytes() as u64,
        }
    }

    /// Limits what the renderer may hold ([`Renderer::memory`]'s total): before
    /// it builds the structures a view needs, it predicts their size
    /// ([`estimate_axis`]); when they would not fit it first frees the other
    /// axes' structures (rebuilt when a view needs them again), and when they
    /// still would not fit the frame fails with [`Error::Memory`], before
    /// anything is allocated. `None` (the default) sets no limit.
    pub fn set_memory_budget(&mut self, budget: Option<u64>) {
        self.budget = budget;
    }

    /// The memory budget, if any.
    pub fn memory_budget(&self) -> Option<u64> {
        self.budget
    }

    /// The code width of the current classification's mask.
    fn code_bits(&self) -> u32 {
        self.tissues.as_ref().and_then(|t| crate::encode::depth::code_width_for(t.thresholds.len())).unwrap_or(1)
    }

    /// The bytes `ensure_axis(axis)` would allocate now (structures that exist
    /// and are current count 0), and the intermediate image's growth.
    fn missing_bytes(&self, axis: usize) -> Memory {
        let mut m = estimate_axis(&self.volume, &self.settings, self.code_bits(), axis);
        if self.stacks[axis].as_ref().is_some_and(|s| s.is_resident() && s.perm() == self.axis_perm(axis))
            && self.settings.lattice == Lattice::Cartesian
        {
            m.stacks[axis] = 0;
        }
        if self.bcc[axis].is_some() && self.settings.lattice == Lattice::Bcc {
            m.stacks[axis] = 0;
        }
        if self.normals[axis].is_some() {
            m.normals[axis] = 0;
        }
        if self.masks[axis].as_ref().map(|m| m.key) == Some(self.mask_key()) {
            m.masks[axis] = 0;
            m.cell_codes[axis] = 0;
        }
        m.volume = 0;
        m.intermediate = m.intermediate.saturating_sub(self.inter.bytes() as u64);
        m
    }

    /// Frees every structure of principal axis `axis` (first giving the volume
    /// its voxels back if they were let go).
    fn drop_axis(&mut self, axis: usize) -> Result<()> {
        if self.normals[axis].is_some() {
            self.unpark()?;
        }
        self.stacks[axis] = None;
        self.bcc[axis] = None;
        self.normals[axis] = None;
        self.codes[axis] = None;
        self.masks[axis] = None;
        self.rle.drop_axis(axis);
        Ok(())
    }

    /// True when building `axis` now fits the budget beside everything held
    /// (less the volume, when the build lets go of it). The build allocates
    /// the cell array while the volume is still held, but touches only its
    /// last third (one byte a voxel of an 8-bit scan) before the volume goes,
    /// so what is resident stays below the total counted here; under a
    /// virtual-memory limit (`ulimit -v`) the allocation itself may be refused,
    /// which is [`Error::Memory`], never an abort.
    fn fits_budget(&self, axis: usize) -> bool {
        let needed = self.missing_bytes(axis).total();
        needed == 0 || self.budget.is_none_or(|b| (self.memory().total() + needed).saturating_sub(self.releasable(axis)) <= b)
    }

    /// The bytes of volume that building `axis` lets go of: all of it when the
    /// compact binary path builds packed cells while the volume is resident
    /// and nothing outside this renderer shares the voxels.
    fn releasable(&self, axis: usize) -> u64 {
        let building = compact_binary(&self.volume, &self.settings) && self.normals[axis].is_none();
        if building && self.can_let_go() { self.volume.bytes() } else { 0 }
    }

    /// Checks the budget for building `axis` now; frees the other axes first
    /// if that makes it fit.
    fn fit_budget(&mut self, axis: usize) -> Result<()> {
        let Some(budget) = self.budget else { return Ok(()) };
        if self.fits_budget(axis) {
            return Ok(());
        }
        for a in (0..3).filter(|&a| a != axis) {
            self.drop_axis(a)?;
        }
        if !self.fits_budget(axis) {
            let (needed, held) = (self.missing_bytes(axis).total(), self.memory().total());
            let d = self.volume.dims();
            return Err(Error::Memory {
                what: format!(
                    "rendering the {}×{}×{} volume along {} ({})",
                    d[0],
                    d[1],
                    d[2],
                    ["x", "y", "z"][axis],
                    self.settings.method.name()
                ),
                needed,
                held,
                budget,
            });
        }
        Ok(())
    }

    /// The object axes `(i, j, k)` of principal axis `axis` this renderer's
    /// frames use: the cyclic [`crate::view::permutation`], or with
    /// [`Settings::rle_reuse`] on an RLE path under a parallel projection
    /// [`crate::view::reuse_permutation`] (z mirrored to share x's scanlines).
    fn axis_perm(&self, axis: usize) -> [usize; 3] {
        let rle = matches!(self.settings.method, Method::Rle | Method::BruteRle);
        if self.settings.rle_reuse && rle && !self.projection.is_perspective() {
            crate::view::reuse_permutation(axis)
        } else {
            crate::view::permutation(axis)
        }
    }

    /// What the pre-classified state depends on: classification generation,
    /// tissue, mode and the sampler (pre- or post-classified, Deluxe P).
    fn rle_key(&self) -> ClassKey {
        let tissue = self.tissues.as_ref().map_or(0, |t| t.current as u64 + 1);
        // (a pre-classified encoding holds the voxels the focus tissue shows too)
        let focus = self.focus_tissue().map_or(0, |f| f as u64 + 1);
        self.rle_enc_key() | (tissue << 2) | (focus << 12)
    }

    /// What a post-classified encoding depends on (the key without the
    /// tissue: it keeps the cells every tissue preset may show), and the lattice.
    fn rle_enc_key(&self) -> ClassKey {
        let bcc = (self.settings.lattice == Lattice::Bcc) as u64;
        (self.generation << 20) | (bcc << 9) | ((self.settings.deluxe.post as u64) << 1) | (self.settings.mode == Mode::Blend) as u64
    }

    /// The classifier the pre-classified paths encode: the current mode's, with
    /// a custom iso value as a threshold transfer function in the iso colour.
    fn preclass_classifier(&self) -> std::borrow::Cow<'_, Classifier> {
        match (&self.tissues, self.settings.mode) {
            (None, Mode::Iso) => {
                let c = self.classifier.classify(self.iso);
                let tf = TransferFunction::threshold(self.iso, [c.r, c.g, c.b]);
                std::borrow::Cow::Owned(Classifier::new(&tf, self.range.0, self.range.1))
            }
            _ => std::borrow::Cow::Borrowed(self.classifier()),
        }
    }

    fn mask_key(&self) -> MaskKey {
        MaskKey {
            mode: if self.tissues.is_some() { None } else { Some(self.settings.mode) },
            word: self.settings.word,
            cell: self.settings.cell,
            generation: self.generation,
            half: self.settings.deluxe.intermediate,
        }
    }

    /// Fails when the intermediate image or (binary path) the sheared mask of
    /// principal axis `axis` would exceed [`MAX_INTERMEDIATE_PIXELS`] or
    /// [`MAX_MASK_BYTES`] — very elongated volumes (e.g. 16384×4×4 seen along its
    /// long axis), whose padding for shears up to 45° dwarfs the data. Without
    /// this the allocation fails and aborts the process.
    fn check_axis_size(&self, axis: usize) -> Result<()> {
        let dims = self.volume.dims();
        let p = crate::view::permutation(axis);
        let n = [dims[p[0]], dims[p[1]], dims[p[2]]];
        let cells = [n[0].saturating_sub(1), n[1].saturating_sub(1)];
        let Grid { size: grid, .. } = Grid::parallel(cells, n[2]);
        let too_big = |what: String| {
            Err(Error::value(
                "volume shape",
                format!(
                    "{}×{}×{} seen along {}: {what}; the volume is too elongated for shear-warp along this axis",
                    dims[0],
                    dims[1],
                    dims[2],
                    ["x", "y", "z"][axis]
                ),
            ))
        };
        let px = grid[0] as u64 * grid[1] as u64;
        if px > MAX_INTERMEDIATE_PIXELS {
            return too_big(format!("the intermediate image would need {}×{} pixels (limit {MAX_INTERMEDIATE_PIXELS})", grid[0], grid[1]));
        }
        if self.settings.method == Method::Binary {
            // an upper bound of what BinaryMask::from_codes allocates
            let bytes = estimate_axis(&self.volume, &self.settings, self.code_bits(), axis).masks[axis];
            if bytes > MAX_MASK_BYTES {
                return too_big(format!("its sheared mask would need {bytes} bytes (limit {MAX_MASK_BYTES})"));
            }
        }
        Ok(())
    }

    /// Makes sure the slice stack (and, for the binary path, the mask) of `axis`
    /// exist and are current. Returns the milliseconds spent building.
    fn ensure_axis(&mut self, axis: usize) -> Result<f64> {
        self.check_axis_size(axis)?;
        self.fit_budget(axis)?;
        let t = Instant::now();
        let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
        if self.settings.lattice == Lattice::Bcc {
            // the RLE paths on the BCC grid (check_deluxe allows no other):
            // the interleaved slices, their classification and encoding
            if self.bcc[axis].is_none() {
                let t = Instant::now();
                self.unpark()?;
                let vol = &self.volume;
                self.bcc[axis] = Some(self.pool.install(|| BccStack::try_new(vol, axis))?);
                self.build_times.stacks[axis] = ms(t);
            }
            self.ensure_rle(axis, true);
            return Ok(t.elapsed().as_secs_f64() * 1e3);
        }
        if self.bcc.iter().any(Option::is_some) {
            self.bcc = [None, None, None];
        }
        let compact = compact_binary(&self.volume, &self.settings);
        let raycast = matches!(self.settings.method, Method::Binary | Method::Brute);
        if compact && self.normals[axis].is_none() {
            // the densities and codes packed in 3 (8-bit) or 4 bytes a voxel,
            // no f32 stack, and the volume let go once the cells hold its voxels
            let t = Instant::now();
            let threads = self.pool.current_num_threads();
            let vol = &self.volume;
            let src = match self.normals.iter().flatten().find(|n| n.holds_voxels()) {
                // the volume was let go: re-lay another axis's cells
                Some(ns) if vol.is_parked() => CellSource::Cells(ns),
                _ => CellSource::Volume(vol),
            };
            let build =
                self.pool.install(|| NormalStack::try_cells(src, axis, threads))?.ok_or_else(|| missing("the packed cells", axis))?;
            if self.stacks[axis].is_none() {
                self.stacks[axis] = Some(SliceStack::shell(vol, axis));
            }
            // the build holds the voxels now: the volume can go before the codes are computed
            self.park(true);
            let spacing = self.volume.spacing();
            self.normals[axis] = Some(self.pool.install(|| build.finish(spacing)));
            self.build_times.normals[axis] = ms(t);
        }
        let perm = self.axis_perm(axis);
        if !compact && self.stacks[axis].as_ref().is_none_or(|s| !s.is_resident() || s.perm() != perm) {
            let t = Instant::now();
            self.unpark()?;
            let vol = &self.volume;
            self.stacks[axis] = Some(self.pool.install(|| SliceStack::try_permuted(vol, perm))?);
            self.build_times.stacks[axis] = ms(t);
        }
        if raycast && self.settings.normals == Normals::Codes && self.normals[axis].is_none() {
            let t = Instant::now();
            let (stack, spacing, pack) =
                (self.stacks[axis].as_ref().expect("stack built above"), self.volume.spacing(), self.settings.pack);
            self.normals[axis] = Some(self.pool.install(|| NormalStack::try_with_packing(stack, spacing, pack))?);
            self.build_times.normals[axis] = ms(t);
        }
        if self.settings.method == Method::Binary {
            let key = self.mask_key();
            if self.masks[axis].as_ref().map(|m| m.key) != Some(key) {
                // the densities come from the resident stack, or from the packed cells
                let stack: &dyn Densities = match (&self.stacks[axis], &self.normals[axis]) {
                    (Some(s), _) if s.is_resident() => s,
                    (_, Some(ns)) => ns,
                    _ => return Err(missing("the densities", axis)),
                };
                // cell codes depend only on the classification (and Deluxe I's
                // dilation); cell size and word size reuse them
                let codes_key = key.generation * 4 + key.mode.map_or(0, |m| (m == Mode::Blend) as u64) * 2 + key.half as u64;
                if self.codes[axis].as_ref().map(|c| c.0) != Some(codes_key) {
                    let t = Instant::now();
                    let half = key.half;
                    let codes = self.pool.install(|| match (&self.tissues, self.settings.mode) {
                        (Some(ts), _) if half => {
                            CellCodes::thresholds_half(stack, &ts.thresholds).expect("thresholds validated in with_tissues")
                        }
                        (Some(ts), _) => CellCodes::thresholds(stack, &ts.thresholds).expect("thresholds validated in with_tissues"),
                        (None, Mode::Iso) => {
                            let iso = self.iso;
                            if half {
                                CellCodes::binary_half(stack, |_, hi| hi >= iso)
                            } else {
                                CellCodes::binary(stack, |_, hi| hi >= iso)
                            }
                        }
                        (None, Mode::Blend) => {
                            let cls = &self.classifier;
                            let visible = |lo, hi| cls.may_be_visible(lo, hi);
                            if half { CellCodes::binary_half(stack, visible) } else { CellCodes::binary(stack, visible) }
                        }
                    });
                    self.codes[axis] = Some((codes_key, codes));
                    self.build_times.cell_codes[axis] = ms(t);
                }
                let t = Instant::now();
                let codes = &self.codes[axis].as_ref().expect("built above").1;
                let mask = self.pool.install(|| match key.word {
                    WordSize::U32 => AnyMask::W32(BinaryMask::from_codes(codes, key.cell)),
                    WordSize::U64 => AnyMask::W64(BinaryMask::from_codes(codes, key.cell)),
                });
                self.masks[axis] = Some(AxisMask { key, mask });
                self.build_times.masks[axis] = ms(t);
            }
            // the mask carries the settings' CPU level to its shear kernels and to
            // the ray loop's bit scan (`render_binary`); a mask outlives a settings change
            if let Some(m) = self.masks[axis].as_mut() {
                m.mask.set_cpu_level(self.settings.cpu);
            }
        }
        if matches!(self.settings.method, Method::Rle | Method::BruteRle) {
            self.ensure_rle(axis, false);
        }
        Ok(t.elapsed().as_secs_f64() * 1e3)
    }

    /// The pre-classified state of `axis`: the classification, and (for
    /// [`Method::Rle`]) the encoding of the axis's slices — the cartesian
    /// stack, or the interleaved BCC slices when `bcc` (the classification
    /// key tells the two apart).
    fn ensure_rle(&mut self, axis: usize, bcc: bool) {
        let key = self.rle_key();
        if !self.rle.is_for(key) {
            let cls = self.preclass_classifier().into_owned();
            if self.settings.deluxe.post {
                // the encoding keeps the cells any tissue preset of the mode may show
                let visible: Vec<&Classifier> = match (&self.tissues, self.settings.mode) {
                    (Some(ts), Mode::Iso) => ts.iso_cls.iter().collect(),
                    (Some(ts), Mode::Blend) => ts.blend_cls.iter().collect(),
                    (None, _) => vec![&cls],
                };
                self.rle.reset_post(key, self.rle_enc_key(), &cls, &visible, self.volume.spacing());
            } else {
                self.rle.reset(key, &cls, self.volume.spacing());
            }
            // focus+context: the focus tissue's classification of the mode
            let focus = match (&self.tissues, self.focus_tissue(), self.settings.mode) {
                (Some(ts), Some(f), Mode::Iso) => Some(&ts.iso_cls[f]),
                (Some(ts), Some(f), Mode::Blend) => Some(&ts.blend_cls[f]),
                _ => None,
            };
            self.rle.set_focus(focus, self.volume.spacing());
        }
        if self.settings.method == Method::Rle {
            // (an encoding, or a pointer table over another axis's: see RleCache::ensure_axis)
            let t = Instant::now();
            let rle = &mut self.rle;
            // (asked first: a frame whose encoding is current sends no job to the pool)
            let built = if bcc {
                let src = self.bcc[axis].as_ref().expect("BCC slices built above");
                !rle.is_current(src) && self.pool.install(|| rle.ensure_axis(src))
            } else {
                let stack = self.stacks[axis].as_ref().expect("stack built above");
                !rle.is_current(stack) && self.pool.install(|| rle.ensure_axis(stack))
            };
            if built {
                self.build_times.rle[axis] = t.elapsed().as_secs_f64() * 1e3;
            }
        }
    }

    /// Builds the stack and mask of every axis now (so frames measure only shear,
    /// render and warp). Returns the milliseconds spent. An axis beyond the
    /// memory limits is skipped; a frame that needs it returns the error.
    pub fn prepare_all_axes(&mut self) -> f64 {
        (0..3).map(|a| self.ensure_axis(a).unwrap_or(0.0)).sum()
    }

    /// Builds the stack and mask of principal axis `axis` (0..3) now if they are
    /// missing or stale, so a later view along it does not pay for it. Returns the
    /// milliseconds spent (0 when current), or the error when the axis is beyond
    /// the memory limits.
    pub fn prepare_axis(&mut self, axis: usize) -> Result<f64> {
        self.ensure_axis(axis.min(2))
    }

    /// Builds principal axis `axis` ahead of need, but only if it fits the
    /// memory budget beside everything held now: unlike [`Renderer::prepare_axis`]
    /// it never frees another axis to make room (a prefetch that evicted the
    /// axis on screen would make the next frame rebuild it). Returns whether
    /// the axis is built now.
    pub fn prefetch_axis(&mut self, axis: usize) -> Result<bool> {
        let axis = axis.min(2);
        if !self.fits_budget(axis) {
            return Ok(false);
        }
        self.ensure_axis(axis).map(|_| true)
    }

    /// Renders one frame of `camera` into `out` (resized if needed).
    ///
    /// When the camera, settings and classification are those of the frame this
    /// renderer last wrote into this same `out`, nothing is rendered and the stats
    /// say `skipped` (the image's pixels are assumed untouched since).
    ///
    /// `out` is a [`crate::warp::Image`] (f32) or a [`crate::warp::Image8`]
    /// (the same pixels rounded to 8 bits, as a display wants them).
    pub fn render<T: Texel>(&mut self, camera: &Camera, out: &mut Canvas<T>) -> Result<FrameStats> {
        let key = FrameKey {
            camera: *camera,
            projection: self.projection,
            quality: self.quality,
            settings: self.settings,
            generation: self.generation,
            tissue: self.tissues.as_ref().map(|t| t.current),
            limiter: self.limiter.as_ref().map(|l| l.1),
            focus: self.focus.as_ref().map(|f| (f.2, f.1)),
        };
        if let Some((k, stamp)) = self.last_frame {
            if k == key && out.stamp == stamp && out.width == camera.size[0] && out.height == camera.size[1] {
                return Ok(FrameStats { skipped: true, axis: self.last_plan().map_or(0, |p| p.view.axis), ..Default::default() });
            }
        }
        let (dims, spacing) = (self.volume.dims(), self.volume.spacing());
        let bcc = self.settings.lattice == Lattice::Bcc;
        if bcc && self.projection.is_perspective() {
            return Err(Error::value("settings", "the BCC grid (--grid bcc) renders parallel projections only"));
        }
        if bcc && self.limiter.is_some() {
            return Err(Error::value("settings", "the BCC grid (--grid bcc) does not take clip regions or geometry"));
        }
        if self.focus.is_some() {
            self.check_focus()?;
        }
        // a perspective frame: the camera scaled by its field of view, and its views
        let persp = match self.projection.resolve(camera, dims, spacing)? {
            None => None,
            Some((cam, distance)) => {
                // (the views' buffer is kept across frames: no allocation per frame)
                let mut views = std::mem::take(&mut self.views);
                let made = PerspectiveView::frame_into(&cam, distance, dims, spacing, NEAR_SLICES, &mut views);
                if made.is_ok() && (views.len() != 1 || views[0].window.is_some()) {
                    // the eye near or inside the volume: Lacroute's pyramid split
                    let stats = self.render_pyramids(camera, &cam, distance, &views, out);
                    self.views = views;
                    return Ok(self.finish_frame(key, out, stats?));
                }
                let one = views.pop();
                self.views = views;
                made?;
                Some((cam, one.expect("one view")))
            }
        };
        let perms = [0, 1, 2].map(|a| self.axis_perm(a));
        let f = Factorization::with_permutations(persp.as_ref().map_or(camera, |p| &p.0), dims, spacing, perms)?;
        if let Some((_, pv)) = &persp {
            // the eye lies on the view axis: same principal axis, same slice order
            if (pv.axis, pv.ascending) != (f.axis, f.ascending) {
                return Err(Error::Other("internal: the perspective and parallel factorizations disagree on the principal axis".into()));
            }
        }
        let mut stats = FrameStats { axis: f.axis, ..Default::default() };
        stats.build_ms = self.ensure_axis(f.axis)?;
        // the frame plan, from the projection's producer
        let mut plan = self.plan.take().unwrap_or_else(|| FramePlan::parallel(&f, spacing));
        let limits = plan.take_limits();
        let focus = plan.take_focus();
        match &persp {
            // the BCC grid: the interleaved slices' factorization (the opacity
            // ratio relative to the volume's own spacing), sub-grid B's slices
            // half a cell off A's, whose samples the sheared grid meets
            None if bcc => {
                let lattice = BccLattice::new(dims)?;
                plan.set_parallel(&lattice.factorization(camera, spacing, f.axis, f.zoom)?, spacing);
                plan.offset_slices(BccLattice::slice_offset);
                plan.shift_sheared(BccLattice::SHEARED_SHIFT);
            }
            None => plan.set_parallel(&f, spacing),
            Some((_, pv)) => plan.set_perspective(pv, &f, spacing, NEAR_SLICES),
        }
        if let Err(e) = self.finish_plan(&mut plan, limits, focus) {
            self.plan = Some(plan);
            return Err(e);
        }
        self.last_split = false;
        let result = self.composite_plan(&plan, &mut stats, |inter: &Intermediate| {
            out.prepare(camera.size[0], camera.size[1]);
            warp(inter, &plan, out);
        });
        self.plan = Some(plan);
        result?;
        Ok(self.finish_frame(key, out, stats))
    }

    /// What every plan takes after its projection's producer made it (one
    /// place for the plain frame and each pyramid of a split one): each ray's
    /// opacity correction in blend mode (iso opacities are 0 or 1: never
    /// corrected), the intermediate image's pitch (the same rays resampled:
    /// the adaptive image size of `--quality`, and Deluxe M's matched
    /// sampling), the footprint of minified slices, and the limiter's ray
    /// limits (on the renderer's pool: a limiter may work in parallel), into
    /// `limits`, the buffer the plan held before.
    ///
    /// Deluxe M sets `ns = max(ns_a, ns_b)` samples per voxel along both axes
    /// ([`FramePlan::matched_samples`]: from the warp's magnification; a
    /// perspective plan's largest, at its base plane, the front slice): the
    /// grid is isotropic (one pitch; [`Grid::pitch`] is read by the clip
    /// regions, the reference and the RLE traversal as a scalar), so an
    /// anisotropic warp takes `ns²` rather than `ns_a·ns_b` samples a voxel
    /// square. With `--quality` the finer pitch wins: M never samples coarser
    /// than matched, a quality above it still refines. A grid past
    /// [`MAX_INTERMEDIATE_PIXELS`] is an error naming it.
    fn finish_plan(&self, plan: &mut FramePlan, limits: Option<RayLimits>, focus: Option<RayLimits>) -> Result<()> {
        plan.set_ray_opacity(self.settings.mode == Mode::Blend);
        let mut pitch = 1.0 / self.quality;
        if self.settings.deluxe.matched {
            let ns = plan.matched_samples();
            pitch = pitch.min(1.0 / ns[0].max(ns[1]) as f64);
        }
        if pitch != 1.0 {
            plan.set_pitch(pitch);
        }
        let [w, h] = plan.grid.size;
        if w as u64 * h as u64 > MAX_INTERMEDIATE_PIXELS {
            return Err(Error::value(
                "intermediate image",
                format!(
                    "{w}×{h} pixels at {:.3} samples per voxel (limit {MAX_INTERMEDIATE_PIXELS}): lower the zoom, --quality or matched sampling (Deluxe M)",
                    1.0 / pitch
                ),
            ));
        }
        plan.set_box_footprint(self.settings.footprint == Footprint::Box);
        plan.set_intermediate(self.settings.deluxe.intermediate);
        if let Some((l, _)) = &self.limiter {
            self.install_if(l.parallel(plan), || plan.apply_limiter(l.as_ref(), limits.unwrap_or_default()));
        }
        // focus+context: each ray's slices inside the focus region (the clip
        // region's analytic interval, checked on the samples)
        if let Some((shape, _, _)) = &self.focus {
            self.pool.install(|| plan.apply_focus(shape.limiter(), focus.unwrap_or_default()));
        }
        Ok(())
    }

    /// The settings focus+context renders (an error names what it does not).
    fn check_focus(&self) -> Result<()> {
        let refuse = |what: &str| Err(Error::value("focus", format!("focus+context is not available with {what}")));
        if self.tissues.is_none() {
            return refuse("a custom iso value or transfer function (it needs the tissue presets)");
        }
        if self.settings.lattice == Lattice::Bcc {
            return refuse("the BCC grid (--grid bcc)");
        }
        Ok(())
    }

    /// Stamps `out` as this frame's image (see [`Renderer::render`]'s skip).
    fn finish_frame<T: Texel>(&mut self, key: FrameKey, out: &mut Canvas<T>, stats: FrameStats) -> FrameStats {
        let stamp = NEXT_STAMP.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        out.stamp = stamp;
        self.last_frame = Some((key, stamp));
        stats
    }

    /// A perspective frame split into Lacroute's pyramids (`views`, from
    /// [`PerspectiveView::frame`]; `cam` is `camera` with the perspective
    /// zoom, the eye `distance` world units from the volume centre). The
    /// image is cleared, then each pyramid in turn gets its plan (its own
    /// axis, slices and window), is composited by the one per-plan function
    /// every frame uses ([`Renderer::composite_plan`]) and warped into its own
    /// output pixels only ([`warp_owned`]). No pyramid: an empty image.
    fn render_pyramids<T: Texel>(
        &mut self,
        camera: &Camera,
        cam: &Camera,
        distance: f64,
        views: &[PerspectiveView],
        out: &mut Canvas<T>,
    ) -> Result<FrameStats> {
        let (dims, spacing) = (self.volume.dims(), self.volume.spacing());
        let rays = PerspectiveView::ray_directions(cam, distance, dims, spacing)?;
        let mut stats = FrameStats { axis: views.first().map_or(2, |v| v.axis), ..Default::default() };
        let t = Instant::now();
        clear_for_pyramids(out, camera.size[0], camera.size[1]);
        stats.warp_ms = t.elapsed().as_secs_f64() * 1e3;
        self.last_split = true;
        self.last_rays = Some(rays);
        self.pyramid_count = 0;
        let mut plans = std::mem::take(&mut self.pyramid_plans);
        // each pyramid's iso depth, kept past the next pyramid's composite (geometry's depth test, the lens)
        let keep = self.keep_depths && self.settings.mode == Mode::Iso;
        let mut depths = std::mem::take(&mut self.pyramid_depths);
        if keep && depths.len() < views.len() {
            depths.resize_with(views.len(), Intermediate::default);
        }
        for d in depths.iter_mut() {
            // (a pyramid not kept this frame reads as no hit)
            d.valid = None;
        }
        let mut result = Ok(());
        for (i, pv) in views.iter().enumerate() {
            let step = (|| -> Result<()> {
                let mut f = Factorization::with_axis(cam, dims, spacing, pv.axis)?;
                f.ascending = pv.ascending;
                stats.build_ms += self.ensure_axis(pv.axis)?;
                if plans.len() <= i {
                    plans.push(FramePlan::parallel(&f, spacing));
                }
                let plan = &mut plans[i];
                let limits = plan.take_limits();
                let focus = plan.take_focus();
                plan.set_perspective(pv, &f, spacing, NEAR_SLICES);
                self.finish_plan(plan, limits, focus)?;
                let plan = &plans[i];
                let owned = Owned { rays, pyramid: (pv.axis, pv.ascending) };
                let kept = if keep { depths.get_mut(i) } else { None };
                self.composite_plan(plan, &mut stats, |inter: &Intermediate| {
                    warp_owned(inter, plan, out, &owned);
                    if let Some(k) = kept {
                        k.size = inter.size;
                        k.valid = inter.valid;
                        k.depth.clear();
                        k.depth.extend_from_slice(&inter.depth);
                    }
                })
            })();
            if step.is_err() {
                result = step;
                break;
            }
        }
        // (plans past this frame's pyramids are kept, with their arrays, for later frames)
        self.pyramid_count = views.len().min(plans.len());
        self.pyramid_plans = plans;
        self.pyramid_depths = depths;
        result.map(|_| stats)
    }

    /// Composites one frame plan into the intermediate image by the
    /// renderer's method (its axis's structures must exist: see
    /// [`Renderer::ensure_axis`]), then runs `then_warp` on it (in the same
    /// job on the pool), adding the shear, render and warp times and the
    /// rays to `stats`. The one per-plan step of every frame: a parallel or
    /// one-pyramid frame has one plan, a split perspective frame one per
    /// pyramid.
    fn composite_plan(&mut self, plan: &FramePlan, stats: &mut FrameStats, then_warp: impl FnOnce(&Intermediate) + Send) -> Result<()> {
        let axis = plan.view.axis;
        let mode = self.settings.mode;
        let focus = self.focus_tissue();
        if mode == Mode::Blend {
            match &mut self.tissues {
                Some(ts) => {
                    ts.blend_cls[ts.current].set_sample_ratio(plan.opacity_ratio);
                    if let Some(f) = focus {
                        ts.blend_cls[f].set_sample_ratio(plan.opacity_ratio);
                    }
                }
                None => self.classifier.set_sample_ratio(plan.opacity_ratio),
            }
        }
        // the BCC grid's interleaved slices (RLE paths only), else the cartesian stack
        let bcc = self.bcc[axis].as_ref().filter(|_| self.settings.lattice == Lattice::Bcc);
        let stack = match bcc {
            Some(b) => &b.stack,
            None => self.stacks[axis].as_ref().expect("ensure_axis builds the stack"),
        };
        let (cls, iso, matcher): (&Classifier, f32, &Matcher) = match (&self.tissues, mode) {
            (Some(ts), Mode::Iso) => (&ts.iso_cls[ts.current], ts.thresholds[ts.current], &ts.matchers[ts.current]),
            (Some(ts), Mode::Blend) => (&ts.blend_cls[ts.current], ts.thresholds[ts.current], &ts.matchers[ts.current]),
            (None, _) => (&self.classifier, self.iso, binary_matcher()),
        };
        // focus+context: the focus tissue's classifier and iso value; the walks
        // visit the union of both tissues' codes, the lower threshold's matcher
        // (thresholds ascend, tissue i is "code ≥ i + 1")
        let (focus, matcher): (Option<(&Classifier, f32)>, &Matcher) = match (&self.tissues, focus) {
            (Some(ts), Some(f)) => {
                let fc = if mode == Mode::Iso { &ts.iso_cls[f] } else { &ts.blend_cls[f] };
                (Some((fc, ts.thresholds[f])), &ts.matchers[f.min(ts.current)])
            }
            _ => (None, matcher),
        };
        let settings = self.settings;
        let (inter, masks, rle) = (&mut self.inter, &mut self.masks, &mut self.rle);
        let (normals, shade) = (&self.normals, &mut self.shade);
        // one job on the pool per plan: shear and render run inside it
        let result: Result<()> = self.pool.install(|| {
            let t = Instant::now();
            let rect: Option<Rect> = match settings.method {
                Method::Binary => {
                    let m = masks[axis].as_mut().ok_or_else(|| missing("the sheared mask", axis))?;
                    let w: ShearWork = match &mut m.mask {
                        AnyMask::W32(m) => m.shear_to(&plan.shear),
                        AnyMask::W64(m) => m.shear_to(&plan.shear),
                    };
                    if plan.kind == MapKind::ScaleTranslate {
                        // what the diverging rays' walks skip blocks by (rays
                        // that do not drift read the shear's fractions only)
                        let tables = !Drift::for_plan(plan).is_still();
                        match &mut m.mask {
                            AnyMask::W32(m) => m.update_occupancy(matcher, &plan.shear, tables),
                            AnyMask::W64(m) => m.update_occupancy(matcher, &plan.shear, tables),
                        }
                    }
                    (stats.shear_steps, stats.shear_direct, stats.shear_words) = (w.steps, w.direct, w.words);
                    let scaled = plan.kind == MapKind::ScaleTranslate;
                    let rect = match &m.mask {
                        _ if !settings.occupied_rect => volume_rect(plan, stack.cells()),
                        // the mask's occupied columns are the translated rays'; a
                        // scaled plan's rays meet the occupied cells elsewhere
                        AnyMask::W32(m) if scaled => occupied_scaled_rays(plan, m, stack.cells()),
                        AnyMask::W64(m) if scaled => occupied_scaled_rays(plan, m, stack.cells()),
                        AnyMask::W32(m) => m.occupied_rays(plan.grid.size),
                        AnyMask::W64(m) => m.occupied_rays(plan.grid.size),
                    };
                    stats.shear_ms += t.elapsed().as_secs_f64() * 1e3;
                    let t = Instant::now();
                    inter.prepare(plan.grid.size);
                    let ctx = ray_context(stack, cls, plan, iso, focus, settings, normals[axis].as_ref(), shade);
                    match &m.mask {
                        AnyMask::W32(m) => render_binary(&ctx, m, settings.search, matcher, settings.prefetch, rect, inter),
                        AnyMask::W64(m) => render_binary(&ctx, m, settings.search, matcher, settings.prefetch, rect, inter),
                    }
                    stats.render_ms += t.elapsed().as_secs_f64() * 1e3;
                    rect
                }
                Method::Brute => {
                    let rect = volume_rect(plan, stack.cells());
                    stats.shear_ms += t.elapsed().as_secs_f64() * 1e3;
                    let t = Instant::now();
                    inter.prepare(plan.grid.size);
                    let ctx = ray_context(stack, cls, plan, iso, focus, settings, normals[axis].as_ref(), shade);
                    render_brute(&ctx, rect, inter);
                    stats.render_ms += t.elapsed().as_secs_f64() * 1e3;
                    rect
                }
                Method::Rle | Method::BruteRle => {
                    // the per-view tables, corrected to the plan's sample spacing (half
                    // the slices' with Deluxe I); iso opacities are 0 or 1, so iso needs no correction
                    let ratio = if mode == Mode::Blend { plan.sample_ratio() } else { 1.0 };
                    rle.prepare_view(plan, ratio, settings.shading);
                    let rect = match settings.method {
                        Method::Rle => {
                            rle.axis_for(plan).ok_or_else(|| missing("the run-length encoding", axis))?;
                            rle.rect(plan)
                        }
                        _ => volume_rect_with_mids(plan, stack.cells()),
                    };
                    stats.shear_ms += t.elapsed().as_secs_f64() * 1e3;
                    let t = Instant::now();
                    inter.prepare(plan.grid.size);
                    match (settings.method, bcc) {
                        (Method::Rle, _) => rle.render(plan, settings.ert, rect, inter),
                        (_, Some(b)) => rle.render_brute(b, plan, settings.ert, rect, inter),
                        (_, None) => rle.render_brute(stack, plan, settings.ert, rect, inter),
                    }
                    stats.render_ms += t.elapsed().as_secs_f64() * 1e3;
                    rect
                }
            };
            stats.rays += rect.map_or(0, |r| ((r.p1 - r.p0 + 1) * (r.q1 - r.q0 + 1)) as u64);
            // the warp in the same job (one job sent into the pool per plan)
            let t = Instant::now();
            then_warp(inter);
            stats.warp_ms += t.elapsed().as_secs_f64() * 1e3;
            Ok(())
        });
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::warp::Image;
    use glam::DMat3;

    #[test]
    fn unchanged_frames_are_skipped_and_changes_are_not() {
        let vol = Volume::from_fn([12, 10, 14], [1.0; 3], |x, y, z| ((x + y + z) % 7) as f32 * 30.0).unwrap();
        let tissues = crate::classify::presets::tissues_for(&vol);
        let mut r = Renderer::with_tissues(vol, &tissues, Settings::default()).unwrap();
        let cam = Camera::new(DMat3::from_rotation_y(0.3), [32, 32]);
        let mut img = Image::new(32, 32);
        assert!(!r.render(&cam, &mut img).unwrap().skipped);
        let first = img.clone();
        assert!(r.render(&cam, &mut img).unwrap().skipped);
        assert_eq!(img, first);
        // another image, another camera, another tissue: all render
        let mut other = Image::new(32, 32);
        assert!(!r.render(&cam, &mut other).unwrap().skipped);
        assert!(!r.render(&Camera::new(DMat3::from_rotation_y(0.31), [32, 32]), &mut img).unwrap().skipped);
        r.select_tissue(tissues.len() - 1).unwrap();
        assert!(!r.render(&cam, &mut img).unwrap().skipped);
        assert!(r.render(&cam, &mut img).unwrap().skipped);
        r.set_settings(Settings { mode: Mode::Blend, ..r.settings() }).unwrap();
        assert!(!r.render(&cam, &mut img).unwrap().skipped);
    }
}

/// True when the binary path keeps no f32 stack for `volume`: table shading
/// with packed cells, whose 8- or 16-bit densities are all its rays read (8-
/// and 16-bit scans). Every other path samples a resident [`SliceStack`].
fn compact_binary(volume: &Volume, settings: &Settings) -> bool {
    settings.method == Method::Binary
        && settings.normals == Normals::Codes
        && settings.pack
        && volume.data().voxel_type() != crate::data::volume::VoxelType::F32
}

/// The bytes a renderer with `settings` holds for principal axis `axis` of
/// `volume` once a frame along it is rendered (with a mask of `code_bits`-bit
/// codes: 1 for one transfer function, 2 for up to three tissue presets, 4 for
/// up to fifteen), before anything is built: the volume (none on the binary
/// path of an 8/16-bit scan, which lets go of it once its packed cells hold
/// the voxels — if the renderer holds the only handle of them), the slice
/// stack (none on that path either), the normal codes (there: 2 bytes a voxel
/// packed with the densities in their own type; otherwise 4 bytes when packed with
/// the densities of an f32 stack, an upper bound, else 2), the cell codes and
/// the mask's words (binary path; the words are allocated, the pages touched
/// are fewer) and the intermediate image. The run-length encoding (RLE
/// paths) depends on the data and is not predicted (0).
pub fn estimate_axis(volume: &Volume, settings: &Settings, code_bits: u32, axis: usize) -> Memory {
    let dims = volume.dims();
    let p = crate::view::permutation(axis.min(2));
    let n = [dims[p[0]], dims[p[1]], dims[p[2]]];
    let voxels = (n[0] * n[1] * n[2]) as u64;
    let cells = [n[0].saturating_sub(1), n[1].saturating_sub(1)];
    let grid = Grid::parallel(cells, n[2]);
    let compact = compact_binary(volume, settings);
    let mut m = Memory {
        // the compact path lets go of the volume once its packed cells hold the voxels
        volume: if compact { 0 } else { volume.bytes() },
        intermediate: grid.size[0] as u64 * grid.size[1] as u64 * 20,
        ..Default::default()
    };
    let a = axis.min(2);
    m.stacks[a] = match settings.lattice {
        _ if compact => 0,
        Lattice::Cartesian => voxels * 4,
        // the interleaved BCC slices (f32)
        Lattice::Bcc => BccLattice::new(dims).map_or(0, |l| l.samples() as u64 * 4),
    };
    let raycast = matches!(settings.method, Method::Binary | Method::Brute);
    if raycast && settings.normals == Normals::Codes {
        m.normals[a] = if compact {
            // the densities in their own type packed with 2-byte codes
            voxels * (2 + volume.data().voxel_type().size() as u64)
        } else {
            // an f32 stack's codes are packed with its densities when they are
            // integers spanning at most 65 535, which depends on the values,
            // so 4 is an upper bound
            voxels * if settings.pack { 4 } else { 2 }
        };
    }
    if settings.method == Method::Binary {
        let nb = code_bits.max(1);
        m.cell_codes[a] = PackedCodes::bytes_for(nb, cells[0], cells[1] * n[2]);
        m.masks[a] = match settings.word {
            WordSize::U32 => BinaryMask::<u32>::bytes_for(cells, n[2], nb, settings.cell),
            WordSize::U64 => BinaryMask::<u64>::bytes_for(cells, n[2], nb, settings.cell),
        };
    }
    m
}

fn check_settings(s: &Settings) -> Result<()> {
    if !(1..=MAX_CELL).contains(&s.cell) {
        return Err(Error::value("cell size", format!("{} (must be 1..={MAX_CELL})", s.cell)));
    }
    if s.ert.is_nan() {
        return Err(Error::value("early ray termination threshold", "NaN (give an opacity; 1 disables termination)"));
    }
    check_deluxe(s)
}

/// The Deluxe options and lattices each path renders (a combination a path
/// does not render is an error naming it, never a silent fall-back).
///
/// - I (intermediate slices): every method — the RLE slice traversal's
///   intermediate pass and the raycast paths' midpoint samples.
/// - P (post-classification): the RLE path and its brute force; the raycast
///   paths (`binary`, `brute`) classify after interpolation already, so P is
///   accepted there and changes nothing.
/// - M (matched sampling): every method (a producer of plans: the pitch,
///   [`Renderer::finish_plan`]).
fn check_deluxe(s: &Settings) -> Result<()> {
    let unsupported = |what: &str| Err(Error::value("settings", format!("{what} is not available with --method {}", s.method.name())));
    // the BCC grid: the pre-classified paths (parallel projection; the
    // renderer refuses a perspective BCC frame)
    if s.lattice == Lattice::Bcc && !matches!(s.method, Method::Rle | Method::BruteRle) {
        return unsupported("the BCC grid (--grid bcc)");
    }
    if s.lattice == Lattice::Bcc && s.rle_reuse {
        return Err(Error::value("settings", "--rle-reuse shares a cartesian grid's scanlines; it does not combine with --grid bcc"));
    }
    Ok(())
}

fn build_pool(threads: usize) -> Result<rayon::ThreadPool> {
    checks::check_threads(threads)?;
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| Error::Other(format!("cannot start {threads} worker threads: {e}")))
}

/// A pipeline's artefact that `ensure_axis` should have built is missing: an
/// error, never a silent fall-back to another path.
fn missing(what: &str, axis: usize) -> Error {
    Error::Other(format!("internal: {what} of axis {} was not built for this frame", ["x", "y", "z"][axis]))
}

/// The rays' context of a frame of `plan`: the classification, iso value and
/// material, with table shading when the settings ask for it and the normal
/// codes exist (the shade table brought up to date for the view).
#[allow(clippy::too_many_arguments)]
fn ray_context<'a>(
    stack: &'a SliceStack,
    cls: &'a Classifier,
    plan: &'a FramePlan,
    iso: f32,
    focus: Option<(&'a Classifier, f32)>,
    settings: Settings,
    normals: Option<&'a NormalStack>,
    shade: &'a mut ShadeTable,
) -> RayContext<'a> {
    let mut ctx =
        RayContext::new(stack, cls, plan, settings.mode, iso, settings.shading, settings.ert).with_intermediate(plan.intermediate());
    if let Some((fc, fiso)) = focus {
        ctx = ctx.with_focus(fc, fiso);
    }
    match (settings.normals, normals) {
        (Normals::Codes, Some(ns)) => {
            shade.update(headlight_object(&plan.view), settings.shading);
            ctx.with_normals(ns, shade)
        }
        _ => ctx,
    }
}
