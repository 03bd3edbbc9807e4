//! What a renderer is asked for: the render path ([`Method`]), the word size,
//! the Deluxe options, the lattice, the normals, all gathered in [`Settings`];
//! the limits every renderer keeps (mask and intermediate sizes, quality
//! range, near plane); the checks a settings value passes before a renderer
//! takes it, and the thread pool of its thread count.

use crate::classify::shading::Shading;
use crate::composite::Mode;
use crate::encode::depth::Search;
use crate::encode::mask::MAX_CELL;
use crate::error::{Error, Result};
use crate::kernels::reconstruct::Reconstruction;

/// Largest sheared mask, in bytes, a renderer builds for one axis. It is
/// allocated zeroed (address space; only the occupied part is ever touched).
pub const MAX_MASK_BYTES: u64 = 1 << 34;
/// Largest intermediate image, in pixels, a renderer allocates.
pub const MAX_INTERMEDIATE_PIXELS: u64 = 1 << 29;
/// The smallest intermediate image resolution, in pixels per voxel ([`super::Renderer::set_quality`]).
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

    /// A raycast path ([`Method::Binary`], [`Method::Brute`]): classifies
    /// after interpolation, and may shade by normal codes.
    pub fn is_raycast(self) -> bool {
        matches!(self, Method::Binary | Method::Brute)
    }

    /// A pre-classified path ([`Method::Rle`], [`Method::BruteRle`]): keeps a
    /// classification per view in an [`crate::encode::rle::RleCache`].
    pub fn is_rle(self) -> bool {
        matches!(self, Method::Rle | Method::BruteRle)
    }

    /// The path that walks a sheared binary mask ([`Method::Binary`]).
    pub fn uses_mask(self) -> bool {
        self == Method::Binary
    }

    /// The path that run-length encodes the slices ([`Method::Rle`]).
    pub fn encodes_runs(self) -> bool {
        self == Method::Rle
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
    /// M: matched sampling on zoom: as many samples per voxel along each
    /// sheared axis as the warp magnifies it (the paper's eq. 3), the warp
    /// divided by them.
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
    /// Binary path: prefetch what the rays will read. The general path
    /// prefetches the voxel rows of each ray's first candidate slice while a
    /// group of rays is bit-scanned, before the group is traced; the lean
    /// frames, at every visit, the voxel row the next row of rays reads there (the
    /// lean cubic frame both). `false`
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
    /// How the iso surface is reconstructed between samples
    /// ([`Reconstruction`]). Raycast paths, iso mode: [`Reconstruction::Cubic`]
    /// follows the surface between thick slices (Catmull–Rom along the
    /// volume's z axis). With [`Normals::Gradient`] ([`Settings::cubic_rays`],
    /// [`crate::composite::raycast::RayContext::with_cubic`]) a ray follows
    /// the cubic to its first crossing and shades it by the gradient of the
    /// B-spline smoothing; with [`Normals::Codes`] ([`Settings::cubic_crossing`],
    /// [`crate::composite::raycast::RayContext::with_cubic_crossing`]) it
    /// finds its hit as the linear reconstruction does (the same mask, walk
    /// and lean frame) and places it at the cubic's crossing in the segment
    /// before it, shaded by the cubic's normal codes (the B-spline gradient at
    /// each voxel, [`crate::data::normals::cubic_voxel_normal`]): the preview,
    /// about 1.15–1.3× the linear frame on thick slices where the first
    /// takes 1.4–1.6×. Blend mode ignores it there, except that the codes are
    /// the cubic's. The RLE paths (both modes, pre- and post-classified:
    /// Deluxe P) keep their samples and take the cubic's normal at each voxel
    /// as its normal code, so their shading follows the surface between
    /// thick slices where the central differences terrace. The library's
    /// default is [`Reconstruction::Linear`]; the command-line tool takes the
    /// cubic for thick-slice scans, by measurement (`benches/README.md`): on
    /// isotropic volumes the two err alike, and the preview's cubic costs up
    /// to 2× the linear frame there (every hit solves its crossing). Deluxe
    /// I and the BCC grid refuse it.
    pub reconstruction: Reconstruction,
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
            reconstruction: Reconstruction::Linear,
        }
    }
}

impl Settings {
    /// Whether an iso frame's rays follow the cubic reconstruction to its
    /// first crossing and shade it by the cubic's own gradient: the raycast
    /// paths in iso mode under [`Reconstruction::Cubic`] with
    /// [`Normals::Gradient`] ([`crate::composite::raycast::RayContext::with_cubic`]).
    pub fn cubic_rays(&self) -> bool {
        self.cubic_iso() && self.normals == Normals::Gradient
    }

    /// Whether an iso frame's rays find their hit as the linear ones do and
    /// place it by the cubic's crossing, shaded by the cubic's normal codes:
    /// the raycast paths in iso mode under [`Reconstruction::Cubic`] with
    /// [`Normals::Codes`] ([`crate::composite::raycast::RayContext::with_cubic_crossing`]).
    pub fn cubic_crossing(&self) -> bool {
        self.cubic_iso() && self.normals == Normals::Codes
    }

    /// The raycast paths' iso hit under [`Reconstruction::Cubic`].
    fn cubic_iso(&self) -> bool {
        self.reconstruction == Reconstruction::Cubic && self.mode == Mode::Iso && self.method.is_raycast()
    }
}

pub(super) fn check_settings(s: &Settings) -> Result<()> {
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
///
/// The cubic reconstruction ([`Settings::reconstruction`]): every method on
/// the cartesian grid, without I (the raycast paths' midpoint samples and the
/// RLE paths' intermediate slices are linear). The BCC grid refuses it: its
/// interleaved slices differentiate across two sub-grids, not along the
/// volume's z slices.
pub(super) fn check_deluxe(s: &Settings) -> Result<()> {
    let unsupported = |what: &str| Err(Error::value("settings", format!("{what} is not available with --method {}", s.method.name())));
    // the BCC grid: the pre-classified paths (parallel projection; the
    // renderer refuses a perspective BCC frame)
    if s.lattice == Lattice::Bcc && !s.method.is_rle() {
        return unsupported("the BCC grid (--grid bcc)");
    }
    // the cubic reconstruction: the raycast paths, and the cartesian RLE
    // paths' normal codes (the BCC grid's slices are not the volume's z slices)
    if s.reconstruction == Reconstruction::Cubic && s.lattice == Lattice::Bcc {
        return Err(Error::value("settings", "--reconstruction cubic does not combine with the BCC grid (--grid bcc)"));
    }
    if s.reconstruction == Reconstruction::Cubic && s.deluxe.intermediate {
        return Err(Error::value("settings", "--reconstruction cubic does not combine with Deluxe I (intermediate slices)"));
    }
    if s.lattice == Lattice::Bcc && s.rle_reuse {
        return Err(Error::value("settings", "--rle-reuse shares a cartesian grid's scanlines; it does not combine with --grid bcc"));
    }
    Ok(())
}

pub(super) fn build_pool(threads: usize) -> Result<rayon::ThreadPool> {
    check_threads(threads)?;
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| Error::Other(format!("cannot start {threads} worker threads: {e}")))
}

/// The largest thread count accepted: 8 per core. More threads than that
/// only add start-up and scheduling cost (`--threads 100000` used to hang).
pub fn max_threads() -> usize {
    8 * std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Checks a `--threads` count (0 = every core) against [`max_threads`].
pub fn check_threads(threads: usize) -> Result<()> {
    let max = max_threads();
    if threads > max {
        return Err(Error::value(
            "--threads",
            format!("{threads} is more than {max} (8 per core on this machine's {} cores); 0 uses every core", max / 8),
        ));
    }
    Ok(())
}
