//! Error metrics between a rendered image and a reference, and between iso
//! depths and the truth.
//!
//! Images are compared as they are displayed: the premultiplied RGB channels
//! over black, each clamped to `[0, 1]` (what [`Image::to_rgb8`] writes), in
//! double precision.
//!
//! * [`rmse`] — root mean square error over all RGB channel values;
//!   [`psnr`] — `20·log10(1 / RMSE)` dB for a peak of 1 (∞ for identical images).
//! * [`max_abs_error`] — the largest absolute channel difference.
//! * [`ssim`] — the structural similarity of Wang, Bovik, Sheikh and Simoncelli
//!   (2004) on luminance `Y = 0.299 R + 0.587 G + 0.114 B`: an 11×11 Gaussian
//!   window (σ = 1.5, normalised) slid over every position where it fits
//!   entirely inside the image, `K1 = 0.01`, `K2 = 0.03`, `L = 1`, averaged over
//!   the positions (their reference implementation's "valid" mode). Images
//!   narrower or lower than 11 pixels use one window over the whole image with
//!   uniform weights.
//! * [`silhouette_error`] — the fraction of pixels whose coverage differs:
//!   alpha above the threshold in one image and not in the other
//!   ([`SILHOUETTE_ALPHA`] = 0.5, i.e. "mostly covered").
//! * [`depth_error`] — iso-surface depth error in voxels (mean, 99th percentile
//!   and maximum of `|depth − truth|`) over the pixels hit in both, plus the
//!   counts hit in only one of them (the silhouette of the surface).
//! * [`normal_error`] — the angle in degrees between two unit normals per
//!   pixel (mean, 99th percentile and maximum) over the pixels where both are
//!   defined; [`surface_error`] measures depth and normal against a
//!   [`SurfaceTruth`] at once.

use glam::DVec3;

use crate::accuracy::truth::SurfaceTruth;
use crate::error::{Error, Result};
use crate::warp::Image;

/// Alpha above which a pixel counts as covered by the silhouette metric.
pub const SILHOUETTE_ALPHA: f32 = 0.5;
/// SSIM window size.
pub const SSIM_WINDOW: usize = 11;
/// SSIM Gaussian σ.
pub const SSIM_SIGMA: f64 = 1.5;
const SSIM_C1: f64 = 0.01 * 0.01;
const SSIM_C2: f64 = 0.03 * 0.03;

/// Every image metric of one comparison.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ImageError {
    pub rmse: f64,
    /// dB; infinite for identical images (serialised as `null` in JSON).
    pub psnr: f64,
    pub max_abs: f64,
    pub ssim: f64,
    /// Fraction of pixels whose coverage (alpha > [`SILHOUETTE_ALPHA`]) differs.
    pub silhouette: f64,
}

/// Compares `test` against `reference` with every image metric.
pub fn compare(test: &Image, reference: &Image) -> Result<ImageError> {
    let r = rmse(test, reference)?;
    Ok(ImageError {
        rmse: r,
        psnr: psnr(r),
        max_abs: max_abs_error(test, reference)?,
        ssim: ssim(test, reference)?,
        silhouette: silhouette_error(test, reference, SILHOUETTE_ALPHA)?,
    })
}

fn same_size(a: &Image, b: &Image) -> Result<()> {
    if a.width != b.width || a.height != b.height || a.data.len() != b.data.len() {
        return Err(Error::value("image comparison", format!("sizes differ: {}×{} vs {}×{}", a.width, a.height, b.width, b.height)));
    }
    if a.data.is_empty() {
        return Err(Error::value("image comparison", "the images are empty"));
    }
    Ok(())
}

/// A displayed channel value: clamped to `[0, 1]`.
#[inline]
fn shown(c: f32) -> f64 {
    c.clamp(0.0, 1.0) as f64
}

/// Root mean square error over the RGB channels of the displayed images.
pub fn rmse(a: &Image, b: &Image) -> Result<f64> {
    same_size(a, b)?;
    let sum: f64 = a.data.iter().zip(&b.data).map(|(x, y)| (0..3).map(|c| (shown(x[c]) - shown(y[c])).powi(2)).sum::<f64>()).sum();
    Ok((sum / (3 * a.data.len()) as f64).sqrt())
}

/// Peak signal-to-noise ratio in dB for a peak of 1: `20·log10(1 / rmse)`
/// (infinite when `rmse` is 0).
pub fn psnr(rmse: f64) -> f64 {
    if rmse <= 0.0 { f64::INFINITY } else { -20.0 * rmse.log10() }
}

/// Largest absolute difference of a displayed RGB channel.
pub fn max_abs_error(a: &Image, b: &Image) -> Result<f64> {
    same_size(a, b)?;
    Ok(a.data.iter().zip(&b.data).flat_map(|(x, y)| (0..3).map(move |c| (shown(x[c]) - shown(y[c])).abs())).fold(0.0, f64::max))
}

/// Fraction of pixels covered (alpha > `threshold`) in exactly one of the images.
pub fn silhouette_error(a: &Image, b: &Image, threshold: f32) -> Result<f64> {
    same_size(a, b)?;
    let n = a.data.iter().zip(&b.data).filter(|(x, y)| (x[3] > threshold) != (y[3] > threshold)).count();
    Ok(n as f64 / a.data.len() as f64)
}

/// Luminance `0.299 R + 0.587 G + 0.114 B` of the displayed image.
pub fn luminance(img: &Image) -> Vec<f64> {
    img.data.iter().map(|c| 0.299 * shown(c[0]) + 0.587 * shown(c[1]) + 0.114 * shown(c[2])).collect()
}

/// The normalised 1-D Gaussian of the SSIM window.
fn gaussian_taps() -> [f64; SSIM_WINDOW] {
    let c = (SSIM_WINDOW / 2) as f64;
    let mut g = [0.0; SSIM_WINDOW];
    for (i, x) in g.iter_mut().enumerate() {
        *x = (-((i as f64 - c).powi(2)) / (2.0 * SSIM_SIGMA * SSIM_SIGMA)).exp();
    }
    let s: f64 = g.iter().sum();
    g.map(|x| x / s)
}

/// SSIM of one window from its weighted moments.
#[inline]
fn ssim_window(mx: f64, my: f64, xx: f64, yy: f64, xy: f64) -> f64 {
    let (vx, vy, cxy) = (xx - mx * mx, yy - my * my, xy - mx * my);
    ((2.0 * mx * my + SSIM_C1) * (2.0 * cxy + SSIM_C2)) / ((mx * mx + my * my + SSIM_C1) * (vx + vy + SSIM_C2))
}

/// Mean SSIM on luminance (see the module documentation for the exact definition).
pub fn ssim(a: &Image, b: &Image) -> Result<f64> {
    same_size(a, b)?;
    let (x, y) = (luminance(a), luminance(b));
    let (w, h) = (a.width, a.height);
    if w < SSIM_WINDOW || h < SSIM_WINDOW {
        let n = x.len() as f64;
        let m = |f: &dyn Fn(usize) -> f64| (0..x.len()).map(f).sum::<f64>() / n;
        return Ok(ssim_window(m(&|i| x[i]), m(&|i| y[i]), m(&|i| x[i] * x[i]), m(&|i| y[i] * y[i]), m(&|i| x[i] * y[i])));
    }
    let g = gaussian_taps();
    // the five moment images, filtered horizontally then vertically ("valid" positions only)
    let (ow, oh) = (w - SSIM_WINDOW + 1, h - SSIM_WINDOW + 1);
    let fields: [&dyn Fn(usize) -> f64; 5] = [&|i| x[i], &|i| y[i], &|i| x[i] * x[i], &|i| y[i] * y[i], &|i| x[i] * y[i]];
    let mut filtered: Vec<Vec<f64>> = Vec::with_capacity(5);
    for f in fields {
        let mut horiz = vec![0.0; ow * h];
        for r in 0..h {
            for c in 0..ow {
                horiz[r * ow + c] = (0..SSIM_WINDOW).map(|k| g[k] * f(r * w + c + k)).sum();
            }
        }
        let mut out = vec![0.0; ow * oh];
        for r in 0..oh {
            for c in 0..ow {
                out[r * ow + c] = (0..SSIM_WINDOW).map(|k| g[k] * horiz[(r + k) * ow + c]).sum();
            }
        }
        filtered.push(out);
    }
    let total: f64 =
        (0..ow * oh).map(|i| ssim_window(filtered[0][i], filtered[1][i], filtered[2][i], filtered[3][i], filtered[4][i])).sum();
    Ok(total / (ow * oh) as f64)
}

/// Iso depth error against the truth, in voxels.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct DepthError {
    /// Pixels hit in both.
    pub both: usize,
    /// Pixels hit only in the tested depth map / only in the truth.
    pub only_test: usize,
    pub only_truth: usize,
    /// Mean, 99th percentile (nearest rank) and maximum of `|test − truth|`
    /// over the pixels hit in both (NaN when there are none).
    pub mean: f64,
    pub p99: f64,
    pub max: f64,
}

/// Compares per-pixel depths (NaN = no hit); `unit` is the size of one voxel
/// in the depths' units (for world depths: the smallest voxel spacing).
pub fn depth_error(test: &[f64], truth: &[f64], unit: f64) -> Result<DepthError> {
    if test.len() != truth.len() {
        return Err(Error::value("depth comparison", format!("sizes differ: {} vs {} pixels", test.len(), truth.len())));
    }
    if !(unit.is_finite() && unit > 0.0) {
        return Err(Error::value("depth unit", format!("{unit} (must be finite and > 0)")));
    }
    let mut errs = Vec::new();
    let (mut only_test, mut only_truth) = (0, 0);
    for (&a, &b) in test.iter().zip(truth) {
        match (a.is_finite(), b.is_finite()) {
            (true, true) => errs.push((a - b).abs() / unit),
            (true, false) => only_test += 1,
            (false, true) => only_truth += 1,
            (false, false) => {}
        }
    }
    let (mean, p99, max) = spread(&mut errs);
    Ok(DepthError { both: errs.len(), only_test, only_truth, mean, p99, max })
}

/// Mean, 99th percentile (nearest rank) and maximum of `errs` (sorted in
/// place; NaN for none).
fn spread(errs: &mut [f64]) -> (f64, f64, f64) {
    if errs.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    errs.sort_by(f64::total_cmp);
    let n = errs.len();
    let rank = ((0.99 * n as f64).ceil() as usize).clamp(1, n);
    (errs.iter().sum::<f64>() / n as f64, errs[rank - 1], errs[n - 1])
}

/// Normal-angle error against the truth, in degrees.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct NormalError {
    /// Pixels where both normals are defined.
    pub both: usize,
    /// Mean, 99th percentile (nearest rank) and maximum angle in degrees
    /// (NaN when no pixel has both).
    pub mean_deg: f64,
    pub p99_deg: f64,
    pub max_deg: f64,
}

/// The angle between `a` and `b` in degrees (`atan2(|a × b|, a · b)`,
/// accurate at small angles; any lengths).
pub fn angle_deg(a: DVec3, b: DVec3) -> f64 {
    a.cross(b).length().atan2(a.dot(b)).to_degrees()
}

/// Compares per-pixel normals (any non-zero length; a NaN or zero vector is
/// "none"): the angle between them where both are defined.
pub fn normal_error(test: &[DVec3], truth: &[DVec3]) -> Result<NormalError> {
    if test.len() != truth.len() {
        return Err(Error::value("normal comparison", format!("sizes differ: {} vs {} pixels", test.len(), truth.len())));
    }
    let ok = |v: &DVec3| v.is_finite() && v.length_squared() > 0.0;
    let mut errs: Vec<f64> = test.iter().zip(truth).filter(|(a, b)| ok(a) && ok(b)).map(|(&a, &b)| angle_deg(a, b)).collect();
    let (mean_deg, p99_deg, max_deg) = spread(&mut errs);
    Ok(NormalError { both: errs.len(), mean_deg, p99_deg, max_deg })
}

/// Depth and normal error of one image against the analytic surface.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct SurfaceError {
    /// In voxels of `unit` (see [`depth_error`]); `only_test` and
    /// `only_truth` are the silhouette.
    pub depth: DepthError,
    pub normal: NormalError,
}

/// [`depth_error`] and [`normal_error`] of a tested depth map and normal map
/// against `truth`, depths in voxels of `unit`.
pub fn surface_error(depth: &[f64], normal: &[DVec3], truth: &SurfaceTruth, unit: f64) -> Result<SurfaceError> {
    Ok(SurfaceError { depth: depth_error(depth, &truth.depth, unit)?, normal: normal_error(normal, &truth.normal)? })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(w: usize, h: usize, f: impl Fn(usize, usize) -> [f32; 4]) -> Image {
        Image::from_data(w, h, (0..w * h).map(|i| f(i % w, i / w)).collect())
    }

    /// A textured test image (so SSIM has structure to compare).
    fn texture(w: usize, h: usize) -> Image {
        image(w, h, |x, y| {
            let v = 0.5 + 0.3 * ((x as f32 * 0.4).sin() * (y as f32 * 0.3).cos());
            [v, v * 0.8, 1.0 - v, 1.0]
        })
    }

    #[test]
    fn identical_images() {
        let a = texture(40, 30);
        let e = compare(&a, &a).unwrap();
        assert_eq!(e.rmse, 0.0);
        assert_eq!(e.psnr, f64::INFINITY);
        assert_eq!(e.max_abs, 0.0);
        assert!((e.ssim - 1.0).abs() < 1e-12, "{}", e.ssim);
        assert_eq!(e.silhouette, 0.0);
        // small images take the one-window path
        let s = texture(7, 5);
        assert!((ssim(&s, &s).unwrap() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn constant_offset() {
        let a = image(32, 32, |_, _| [0.2, 0.4, 0.6, 1.0]);
        let b = image(32, 32, |_, _| [0.3, 0.5, 0.7, 1.0]);
        let e = compare(&a, &b).unwrap();
        assert!((e.rmse - 0.1).abs() < 1e-7, "{}", e.rmse);
        assert!((e.psnr - 20.0).abs() < 1e-5, "{}", e.psnr);
        assert!((e.max_abs - 0.1).abs() < 1e-7);
        assert_eq!(e.silhouette, 0.0);
        // flat images: only the luminance term of SSIM remains
        let (ya, yb) = (0.299 * 0.2 + 0.587 * 0.4 + 0.114 * 0.6, 0.299 * 0.3 + 0.587 * 0.5 + 0.114 * 0.7);
        let want = (2.0 * ya * yb + SSIM_C1) / (ya * ya + yb * yb + SSIM_C1);
        assert!((e.ssim - want).abs() < 1e-6, "{} vs {want}", e.ssim);
        // an offset of 0.01 in [0, 1] is 40 dB
        let c = image(32, 32, |_, _| [0.21, 0.41, 0.61, 1.0]);
        assert!((compare(&a, &c).unwrap().psnr - 40.0).abs() < 1e-3);
    }

    #[test]
    fn displayed_values_are_clamped() {
        let a = image(4, 4, |_, _| [1.3, 0.0, -0.2, 1.0]);
        let b = image(4, 4, |_, _| [1.0, 0.0, 0.0, 1.0]);
        assert_eq!(rmse(&a, &b).unwrap(), 0.0);
    }

    #[test]
    fn shifted_silhouettes() {
        // a 20×20 square shifted by 3 pixels: 2·3·20 pixels change coverage
        let sq = |dx: usize| {
            image(64, 64, move |x, y| if (10 + dx..30 + dx).contains(&x) && (20..40).contains(&y) { [1.0; 4] } else { [0.0; 4] })
        };
        assert_eq!(silhouette_error(&sq(0), &sq(3), SILHOUETTE_ALPHA).unwrap(), 120.0 / 4096.0);
        // a disk of radius 20 shifted by d = 4: the symmetric difference is 2(πr² − lens)
        let (r, d) = (20.0f64, 4.0f64);
        let disk = |cx: f64| {
            image(128, 128, move |x, y| if (x as f64 - cx).hypot(y as f64 - 64.0) <= r { [0.8, 0.8, 0.8, 1.0] } else { [0.0; 4] })
        };
        let lens = 2.0 * r * r * (d / (2.0 * r)).acos() - 0.5 * d * (4.0 * r * r - d * d).sqrt();
        let want = 2.0 * (std::f64::consts::PI * r * r - lens) / (128.0 * 128.0);
        let got = silhouette_error(&disk(60.0), &disk(64.0), SILHOUETTE_ALPHA).unwrap();
        assert!((got - want).abs() < 0.05 * want, "{got} vs {want}");
        // partial coverage below the threshold does not count
        let faint = image(8, 8, |_, _| [0.4, 0.4, 0.4, 0.4]);
        let empty = image(8, 8, |_, _| [0.0; 4]);
        assert_eq!(silhouette_error(&faint, &empty, SILHOUETTE_ALPHA).unwrap(), 0.0);
    }

    #[test]
    fn ssim_falls_with_structural_damage() {
        let a = texture(48, 48);
        let noisy = image(48, 48, |x, y| {
            let mut c = a.at(x, y);
            let n = if (x * 7 + y * 13) % 5 < 2 { 0.15 } else { -0.1 };
            c[0] += n;
            c[1] -= n;
            c
        });
        let s = ssim(&a, &noisy).unwrap();
        assert!(s < 0.95 && s > 0.0, "{s}");
        assert!(ssim(&a, &texture(48, 48)).unwrap() > s);
    }

    #[test]
    fn depth_errors() {
        let truth = [1.0, 2.0, f64::NAN, 4.0, 5.0];
        let test = [1.5, 2.0, 3.0, f64::NAN, 3.0];
        let e = depth_error(&test, &truth, 0.5).unwrap();
        assert_eq!((e.both, e.only_test, e.only_truth), (3, 1, 1));
        assert!((e.mean - (1.0 + 0.0 + 4.0) / 3.0).abs() < 1e-12);
        assert_eq!(e.max, 4.0);
        assert_eq!(e.p99, 4.0);
        // percentile by nearest rank: 100 values 0..99 → the 99th is 98
        let t: Vec<f64> = (0..100).map(|i| i as f64).collect();
        let z = vec![0.0; 100];
        assert_eq!(depth_error(&t, &z, 1.0).unwrap().p99, 98.0);
        assert!(depth_error(&[f64::NAN], &[1.0], 1.0).unwrap().mean.is_nan());
        assert!(depth_error(&[1.0], &[1.0, 2.0], 1.0).is_err());
    }

    #[test]
    fn normal_errors() {
        let x = DVec3::X;
        let tilt = |deg: f64| DVec3::new(deg.to_radians().cos(), deg.to_radians().sin(), 0.0) * 3.0;
        let truth = [x, x, x, x, DVec3::NAN];
        let test = [x, tilt(10.0), tilt(90.0), DVec3::ZERO, x];
        let e = normal_error(&test, &truth).unwrap();
        assert_eq!(e.both, 3);
        assert!((e.mean_deg - 100.0 / 3.0).abs() < 1e-9 && (e.max_deg - 90.0).abs() < 1e-9 && (e.p99_deg - 90.0).abs() < 1e-9, "{e:?}");
        // opposite normals are 180° apart; small angles stay accurate
        assert!((angle_deg(x, -x) - 180.0).abs() < 1e-12);
        assert!((angle_deg(x, tilt(1e-6)) - 1e-6).abs() < 1e-15);
        assert!(normal_error(&[x], &[]).is_err());
        assert!(normal_error(&[DVec3::NAN], &[x]).unwrap().mean_deg.is_nan());
    }

    #[test]
    fn rejects_mismatched_sizes() {
        assert!(compare(&texture(10, 10), &texture(10, 11)).is_err());
    }
}
