//! `shearwarp bench --peers`: the peer renderers (VTK's
//! `vtkFixedPointVolumeRayCastMapper`, VolPack) rendered at the benchmark's
//! own views and measured by its own reference.
//!
//! Owns the *peer model* every renderer of a peer benchmark shares (VolPack's
//! opaque opacity ramp with its 0.05 cut, white, the headlight material of the
//! harnesses, black background), the conversion of a benchmark view into a
//! peer's volume matrix, running a peer's harness over a list of views, and
//! reading its frames back as [`Image`]s. The benchmark ([`crate::app::bench`])
//! renders the reference and every shearwarp variant with the same model, so a
//! peer's error measures its sampling and quantization, not a different
//! classification.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, bail};
use clap::ValueEnum;
use glam::DMat3;
use shearwarp::classify::TransferFunction;
use shearwarp::classify::shading::Shading;
use shearwarp::warp::Image;

/// A peer renderer.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Peer {
    /// VTK's `vtkFixedPointVolumeRayCastMapper` (CPU ray casting, trilinear,
    /// post-classified), through `benches/scripts/vtk/harness.py`.
    Vtk,
    /// VolPack (Lacroute's RLE shear-warp, pre-classified, 8-bit image,
    /// single-threaded), through `benches/scripts/volpack/harness.c`.
    Volpack,
}

impl Peer {
    /// The variant name of the peer's rows.
    pub fn name(self) -> &'static str {
        match self {
            Peer::Vtk => "vtk",
            Peer::Volpack => "volpack",
        }
    }
}

/// The harnesses' material (`benches/scripts/volpack/harness.c`,
/// `benches/scripts/vtk/harness.py`): `I = 0.10 + 0.60·|n·l| + 0.30·|n·l|^20`
/// for a white surface under a white headlight.
pub const MODEL_SHADING: Shading = Shading { ambient: 0.10, diffuse: 0.60, specular: 0.30, shininess: 20 };

/// Opacities at or below this are zero in the peers' tables (VolPack's
/// `VP_MIN_VOXEL_OPACITY`, mirrored by the VTK harness).
pub const MODEL_MIN_OPACITY: f32 = 0.05;

/// The peers' opaque classification at threshold `t` (8-bit density units):
/// `α = clamp((d − t)/4, 0, 1)` per voxel length, zero where that is at most
/// [`MODEL_MIN_OPACITY`], in white. As a piecewise-linear curve: 0 up to
/// `t + 0.2`, a step to 0.05 there, 1 from `t + 4` on.
pub fn model_tf(t: f32) -> Result<TransferFunction> {
    let cut = t + 4.0 * MODEL_MIN_OPACITY;
    let tf = TransferFunction::new(vec![(t, 0.0), (cut, 0.0), (cut, MODEL_MIN_OPACITY), (t + 4.0, 1.0)], vec![(t, [1.0, 1.0, 1.0])])?;
    Ok(tf)
}

/// The peer's volume matrix (row-major 3×3, about the volume centre) of a
/// benchmark view whose object-to-eye rotation is `r`: the harnesses keep the
/// camera on −z looking along +z with image down = +y, so their world is the
/// eye frame with y and z negated, `M = diag(1, −1, −1) · r`.
pub fn user_matrix(r: DMat3) -> [f64; 9] {
    let m = DMat3::from_diagonal(glam::DVec3::new(1.0, -1.0, -1.0)) * r;
    // glam is column-major: row i is (col0[i], col1[i], col2[i])
    let c = m.to_cols_array_2d();
    [c[0][0], c[1][0], c[2][0], c[0][1], c[1][1], c[2][1], c[0][2], c[1][2], c[2][2]]
}

/// A peer's frame read back: an 8-bit grey or RGB PNG, or a binary 8-bit PGM
/// (VolPack's), over a black background, as an [`Image`] whose alpha marks
/// the covered pixels (any channel above 0: the peers write no alpha), so the
/// silhouette metric compares coverage as it does for shearwarp's frames.
pub fn read_frame(path: &Path, size: usize) -> Result<Image> {
    let (w, h, px) = if path.extension().is_some_and(|e| e == "pgm") {
        let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read the peer's frame", path.display()))?;
        let (w, h, grey) = parse_pgm(&bytes).with_context(|| format!("{}: not a binary 8-bit PGM", path.display()))?;
        (w, h, grey.iter().map(|&g| [g, g, g]).collect::<Vec<_>>())
    } else {
        let img = image::open(path).with_context(|| format!("{}: cannot read the peer's frame", path.display()))?.to_rgb8();
        (img.width() as usize, img.height() as usize, img.pixels().map(|p| p.0).collect())
    };
    if w != size || h != size {
        bail!("{}: the peer wrote {w}×{h} pixels, the benchmark renders {size}×{size}", path.display());
    }
    Ok(frame_from_rgb8(size, size, px.into_iter()))
}

/// A binary PGM (`P5`, maxval ≤ 255, `#` comments): width, height, pixels.
fn parse_pgm(b: &[u8]) -> Result<(usize, usize, &[u8])> {
    let mut pos = 0usize;
    let mut field = || -> Result<&[u8]> {
        loop {
            while pos < b.len() && b[pos].is_ascii_whitespace() {
                pos += 1;
            }
            if pos < b.len() && b[pos] == b'#' {
                while pos < b.len() && b[pos] != b'\n' {
                    pos += 1;
                }
                continue;
            }
            break;
        }
        let start = pos;
        while pos < b.len() && !b[pos].is_ascii_whitespace() {
            pos += 1;
        }
        anyhow::ensure!(pos > start, "truncated header");
        Ok(&b[start..pos])
    };
    anyhow::ensure!(field()? == b"P5", "not P5");
    let mut num = || -> Result<usize> { Ok(std::str::from_utf8(field()?)?.parse::<usize>()?) };
    let (w, h, max) = (num()?, num()?, num()?);
    anyhow::ensure!(max > 0 && max <= 255, "maxval {max} (8-bit only)");
    let n = w.checked_mul(h).context("size overflows")?;
    let data = b.get(pos + 1..).context("truncated")?;
    anyhow::ensure!(data.len() >= n, "truncated pixels ({} of {n})", data.len());
    Ok((w, h, &data[..n]))
}

/// An [`Image`] from 8-bit RGB pixels over black (alpha 1 where any channel is
/// above 0): how a peer's frame enters the metrics.
pub fn frame_from_rgb8(width: usize, height: usize, px: impl Iterator<Item = [u8; 3]>) -> Image {
    let data = px
        .map(|[r, g, b]| {
            let a = if r > 0 || g > 0 || b > 0 { 1.0 } else { 0.0 };
            [r as f32 / 255.0, g as f32 / 255.0, b as f32 / 255.0, a]
        })
        .collect();
    Image::from_data(width, height, data)
}

/// One benchmark view as a peer renders it.
pub struct PeerView {
    pub name: String,
    pub rotation: DMat3,
}

/// How a peer is asked to project: shearwarp's resolved image scale (pixels
/// per voxel, the same pixel centres) and, in perspective, the vertical field
/// of view and the eye's distance from the volume centre in voxels.
#[derive(Clone, Copy, Debug)]
pub struct PeerCamera {
    pub size: usize,
    pub zoom: f64,
    pub perspective: Option<(f64, f64)>,
}

/// The classification model a peer renders with: the opaque ramp from
/// `threshold` and early ray termination at `ert` (VTK's is fixed at 0.9922).
#[derive(Clone, Copy, Debug)]
pub struct PeerModel {
    pub threshold: f32,
    pub ert: f32,
}

/// How a peer is timed: `threads` (0: the peer's default; VolPack is
/// single-threaded), `warmup` untimed and `reps` timed renders of each view.
#[derive(Clone, Copy, Debug)]
pub struct PeerSchedule {
    pub threads: usize,
    pub warmup: usize,
    pub reps: usize,
}

/// A peer's run over the views: per view the median frame time over the timed
/// renders, and the frame.
pub struct PeerRun {
    pub frames: Vec<(f64, Image)>,
}

/// The VTK harness: `$SHEARWARP_VTK_HARNESS`, else the one in this source tree.
fn vtk_harness() -> PathBuf {
    std::env::var_os("SHEARWARP_VTK_HARNESS")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/scripts/vtk/harness.py"))
}

/// The VolPack harness: `$SHEARWARP_VOLPACK_HARNESS`, else this source tree's
/// `benches/scripts/volpack/harness.c` built into `target/volpack/harness`
/// with `cc` when missing or older than its source (as
/// `benches/scripts/volpack/setup.sh` does; that script also installs
/// `libvolpack1-dev`).
fn volpack_harness() -> Result<PathBuf> {
    if let Some(p) = std::env::var_os("SHEARWARP_VOLPACK_HARNESS") {
        return Ok(PathBuf::from(p));
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let (src, bin) = (root.join("benches/scripts/volpack/harness.c"), root.join("target/volpack/harness"));
    let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    if modified(&bin).is_none() || modified(&bin) < modified(&src) {
        std::fs::create_dir_all(bin.parent().context("harness directory")?)?;
        let out = Command::new("cc")
            .args(["-O2", "-o"])
            .arg(&bin)
            .arg(&src)
            .args(["-lvolpack", "-lm"])
            .output()
            .context("cannot run cc to build the VolPack harness")?;
        if !out.status.success() {
            bail!(
                "cannot build the VolPack harness (is libvolpack1-dev installed? benches/scripts/volpack/setup.sh installs it): {}",
                String::from_utf8_lossy(&out.stderr).lines().next().unwrap_or("")
            );
        }
    }
    Ok(bin)
}

/// Runs `peer` on the `.den` volume `den` over `views` with the `model`,
/// timed by `schedule`; frames go to `dir`. An error says why the peer cannot
/// run here (not installed, no display, a perspective VolPack cannot do, a
/// failed render).
pub fn run(
    peer: Peer,
    den: &Path,
    views: &[PeerView],
    cam: PeerCamera,
    model: PeerModel,
    schedule: PeerSchedule,
    dir: &Path,
) -> Result<PeerRun> {
    let PeerModel { threshold, ert } = model;
    let PeerSchedule { threads, warmup, reps } = schedule;
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let list: Vec<serde_json::Value> =
        views.iter().map(|v| serde_json::json!({ "name": v.name, "matrix": user_matrix(v.rotation) })).collect();
    // the view list: JSON for VTK, one line per view for the C harness
    let (vfile, text) = match peer {
        Peer::Vtk => (dir.join("views.json"), serde_json::to_string(&list)?),
        Peer::Volpack => {
            let lines: Vec<String> = views
                .iter()
                .map(|v| {
                    let m = user_matrix(v.rotation).map(|x| format!("{x:.17e}"));
                    format!("{} {}", v.name, m.join(" "))
                })
                .collect();
            (dir.join("views.txt"), lines.join("\n") + "\n")
        }
    };
    std::fs::write(&vfile, text).with_context(|| format!("{}: cannot write", vfile.display()))?;
    let (mut c, ext) = match peer {
        Peer::Vtk => {
            let mut c = Command::new("python3");
            c.arg(vtk_harness());
            c.args(["--threads", &threads.to_string()]);
            (c, "png")
        }
        Peer::Volpack => {
            if cam.perspective.is_some() {
                bail!("VolPack renders parallel projections only (its perspective factorization is disabled)");
            }
            let mut c = Command::new(volpack_harness()?);
            c.args(["--max-ray-opacity", &ert.to_string()]);
            (c, "pgm")
        }
    };
    c.arg("--den").arg(den).arg("--views").arg(&vfile).arg("--frames-out").arg(dir);
    c.args(["--tf", "opaque", "--threshold", &threshold.to_string(), "--min-opacity", &MODEL_MIN_OPACITY.to_string()]);
    c.args(["--size", &cam.size.to_string(), "--zoom", &cam.zoom.to_string()]);
    c.args(["--warmup", &warmup.max(1).to_string(), "--reps", &reps.max(1).to_string()]);
    if let Some((fov, eye)) = cam.perspective {
        c.args(["--perspective", &fov.to_string(), "--eye-voxels", &eye.to_string()]);
    }
    let out = c.output().with_context(|| format!("cannot start the {} harness ({c:?})", peer.name()))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        let last: Vec<&str> = err.lines().rev().take(3).collect();
        bail!(
            "the {} harness failed ({}): {} (install: benches/scripts/compare-rotators.sh sets the peers up)",
            peer.name(),
            out.status,
            last.into_iter().rev().collect::<Vec<_>>().join(" / ")
        );
    }
    let line = String::from_utf8_lossy(&out.stdout);
    let json: serde_json::Value =
        serde_json::from_str(line.trim()).with_context(|| format!("the {} harness printed no JSON", peer.name()))?;
    let per_view = json["views"].as_array().context("the harness's JSON has no views")?;
    let mut frames = Vec::with_capacity(views.len());
    for v in views {
        let ms = per_view
            .iter()
            .find(|p| p["name"] == v.name.as_str())
            .and_then(|p| p["frame_ms_median"].as_f64())
            .with_context(|| format!("the {} harness reported no time for view {}", peer.name(), v.name))?;
        frames.push((ms, read_frame(&dir.join(format!("{}.{ext}", v.name)), cam.size)?));
    }
    Ok(PeerRun { frames })
}

/// A file-safe view name for the harnesses' frame files (`22.5°` → `22.5deg`).
pub fn file_safe(name: &str) -> String {
    name.chars()
        .map(|c| match c {
            '°' => "deg".to_string(),
            c if c.is_ascii_alphanumeric() || "._+-".contains(c) => c.to_string(),
            _ => "_".to_string(),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;
    use shearwarp::view::rotate_eye;

    #[test]
    fn user_matrix_flips_the_eye_frame_into_the_harness_world() {
        // the identity view: object x right, y up, z toward the viewer; the
        // harness world has y down and the viewer on −z
        assert_eq!(user_matrix(DMat3::IDENTITY), [1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0]);
        // a rotation maps object points as r does, then flips y and z
        let r = rotate_eye(DMat3::IDENTITY, 1, 30.0);
        let m = user_matrix(r);
        let p = DVec3::new(0.3, -0.7, 0.2);
        let e = r * p;
        let w = [m[0] * p.x + m[1] * p.y + m[2] * p.z, m[3] * p.x + m[4] * p.y + m[5] * p.z, m[6] * p.x + m[7] * p.y + m[8] * p.z];
        assert!((w[0] - e.x).abs() < 1e-12 && (w[1] + e.y).abs() < 1e-12 && (w[2] + e.z).abs() < 1e-12);
    }

    #[test]
    fn model_tf_is_the_peers_table_at_integer_densities() {
        let tf = model_tf(24.0).unwrap();
        for d in 0..=255 {
            let want = ((d as f32 - 24.0) / 4.0).clamp(0.0, 1.0);
            let want = if want <= MODEL_MIN_OPACITY { 0.0 } else { want };
            assert!((tf.opacity_at(d as f32) - want).abs() < 1e-6, "d {d}: {} vs {want}", tf.opacity_at(d as f32));
        }
    }

    /// A frame as a peer delivers it: `img` written as an 8-bit grey PNG by
    /// `degrade` (each displayed grey level in, the level written out), read
    /// back through [`read_frame`].
    fn as_peer_frame(img: &Image, dir: &Path, name: &str, degrade: impl Fn(usize, &[f64]) -> f64) -> Image {
        let grey = shearwarp::accuracy::metrics::luminance(img);
        let px: Vec<u8> = (0..grey.len()).map(|i| (degrade(i, &grey) * 255.0).round().clamp(0.0, 255.0) as u8).collect();
        let path = dir.join(name);
        image::GrayImage::from_raw(img.width as u32, img.height as u32, px).unwrap().save(&path).unwrap();
        read_frame(&path, img.width).unwrap()
    }

    /// The peer-error pipeline (a peer's PNG read back, measured against the
    /// reference) reads a frame degraded on purpose as worse by the expected
    /// amount: 8-bit output costs at most half a level, 4-bit quantization
    /// the uniform quantizer's `Δ/√12` over the covered pixels, a 3×3 box blur
    /// exactly the blur's own difference, with SSIM falling.
    #[test]
    fn peer_error_pipeline_measures_known_perturbations() {
        use shearwarp::accuracy::metrics::{compare, rmse};
        use shearwarp::accuracy::reference::{ReferenceOptions, ReferenceRenderer, Scene};
        use shearwarp::classify::Classifier;
        use shearwarp::composite::Mode;
        use shearwarp::view::{Camera, NamedView};

        let vol = shearwarp::data::phantom::sphere([48, 48, 48]).unwrap();
        let (lo, hi) = vol.value_range();
        let t = shearwarp::data::phantom::SPHERE_ISO;
        let scene = Scene::new(Mode::Blend, &Classifier::new(&model_tf(t).unwrap(), lo, hi), t, MODEL_SHADING);
        let cam = Camera::new(rotate_eye(NamedView::Anterior.rotation(), 1, 30.0), [96, 96]);
        let opts = ReferenceOptions { step: 0.25, ..Default::default() };
        let reference = ReferenceRenderer::new(&vol).render(&scene, &cam, &opts).unwrap().image;
        // grey: the model is white under a white light, so R = G = B
        assert!(reference.data.iter().all(|c| (c[0] - c[1]).abs() < 1e-6 && (c[1] - c[2]).abs() < 1e-6));
        let dir = tempfile::tempdir().unwrap();
        let n = reference.data.len();

        let exact = as_peer_frame(&reference, dir.path(), "exact.png", |i, g| g[i]);
        let e8 = compare(&exact, &reference).unwrap();
        assert!(e8.rmse <= 0.5 / 255.0 + 1e-9, "8-bit frame: RMSE {}", e8.rmse);
        assert!(e8.silhouette < 0.01, "coverage read back: {}", e8.silhouette);

        let levels = 15.0;
        let q4 = as_peer_frame(&reference, dir.path(), "q4.png", |i, g| (g[i] * levels).round() / levels);
        let covered = reference.data.iter().filter(|c| c[0] > 0.0).count() as f64 / n as f64;
        let want = (1.0 / levels) / 12f64.sqrt() * covered.sqrt();
        let got = rmse(&q4, &reference).unwrap();
        assert!((got - want).abs() < 0.15 * want, "4-bit: RMSE {got}, the uniform quantizer's {want}");

        let w = reference.width;
        let blur = |i: usize, g: &[f64]| {
            let (x, y) = ((i % w) as i64, (i / w) as i64);
            let mut s = 0.0;
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let (u, v) = ((x + dx).clamp(0, w as i64 - 1), (y + dy).clamp(0, w as i64 - 1));
                    s += g[v as usize * w + u as usize];
                }
            }
            s / 9.0
        };
        let blurred = as_peer_frame(&reference, dir.path(), "blur.png", blur);
        let grey = shearwarp::accuracy::metrics::luminance(&reference);
        let want = ((0..n).map(|i| (blur(i, &grey) - grey[i]).powi(2)).sum::<f64>() / n as f64).sqrt();
        let eb = compare(&blurred, &reference).unwrap();
        assert!((eb.rmse - want).abs() < 0.5 / 255.0 + 1e-9, "blur: RMSE {} vs {want}", eb.rmse);
        assert!(eb.rmse > 4.0 * e8.rmse && eb.ssim < e8.ssim, "blur reads as worse: {eb:?} vs {e8:?}");
    }

    #[test]
    fn pgm_frames_parse_and_bad_ones_are_errors() {
        let mut ok = b"P5\n# VolPack\n3 2\n255\n".to_vec();
        ok.extend([0, 10, 20, 30, 40, 255]);
        let (w, h, px) = parse_pgm(&ok).unwrap();
        assert_eq!((w, h, px), (3, 2, &[0u8, 10, 20, 30, 40, 255][..]));
        assert!(parse_pgm(&ok[..ok.len() - 1]).is_err(), "truncated pixels");
        assert!(parse_pgm(b"P6\n1 1\n255\n\0\0\0").is_err(), "colour PPM");
        assert!(parse_pgm(b"P5\n1 1\n65535\n\0\0").is_err(), "16-bit");
        assert!(parse_pgm(b"P5\n1").is_err(), "truncated header");
        assert!(parse_pgm(b"P5\n99999999999 99999999999\n255\n").is_err(), "absurd size");
    }

    #[test]
    fn file_safe_names() {
        assert_eq!(file_safe("22.5°"), "22.5deg");
        assert_eq!(file_safe("random-1"), "random-1");
        assert_eq!(file_safe("a b/c"), "a_b_c");
    }
}
