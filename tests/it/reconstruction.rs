//! The cubic reconstruction between slices: its kernel, and the reference
//! renderer under it.
//!
//! * the cell bound is conservative: whenever the Catmull–Rom cubic over four
//!   bilinear slices reaches an iso value inside a cell, the bound says it can;
//! * the crossing on a cubic segment is its first point at or above iso;
//! * along the slice axis the cubic reproduces linear and quadratic densities
//!   exactly and misses a cubic one by exactly its known third-order term;
//!   the normal's gradient (the B-spline smoothing's) is exact on linear and
//!   quadratic densities;
//! * the cubic reference on the thick-slice ball and ellipsoid stays within
//!   the depth and normal margins measured for it, with at most half the
//!   linear reference's normal error; the linear reference is unchanged;
//! * the binary path under the cubic equals its brute force bit for bit over
//!   random volumes, views (parallel and perspective), spacings, super cells,
//!   words, searches and tissue codes;
//! * the binary path's cubic on the ball (isotropic and 1×1×3) stays within
//!   the depth and normal goals, with margins;
//! * the RLE paths' normal codes under the cubic (the B-spline gradient at
//!   each voxel) follow the thick-slice ellipsoid at half the central
//!   differences' angle error, and the RLE frames' shading (pre-classified
//!   and Deluxe P) follows its analytic shading at half the error, no worse
//!   on the ball.

use glam::DVec3;
use proptest::prelude::*;

use crate::common;
use shearwarp::accuracy::metrics::{DepthError, NormalError, depth_error, normal_error};
use shearwarp::accuracy::reference::{ReferenceOptions, ReferenceRenderer, Scene, fast_path_depth, fast_path_normals};
use shearwarp::accuracy::truth::surface_truth;
use shearwarp::classify::presets::Tissue;
use shearwarp::classify::shading::Shading;
use shearwarp::classify::{Classifier, TransferFunction};
use shearwarp::composite::Mode;
use shearwarp::data::normals::{cubic_voxel_normal, decode_normal, voxel_normal};
use shearwarp::data::phantom::Phantom;
use shearwarp::data::slices::SliceStack;
use shearwarp::data::volume::{Volume, VoxelData};
use shearwarp::encode::depth::Search;
use shearwarp::kernels::Reconstruction;
use shearwarp::kernels::reconstruct::{self, catmull_rom, cell_may_reach, crossing, eval, lower_bound, upper_bound};
use shearwarp::render::{Method, Normals, Renderer, Settings, WordSize};
use shearwarp::view::{Camera, NamedView, Projection, standard_views};
use shearwarp::warp::Image;

fn cases(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

fn lerp(a: f64, b: f64, t: f64) -> f64 {
    a + (b - a) * t
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases(2000)))]

    /// Four slices of 2×2 in-plane corners (a cell and the slices before and
    /// after it), a point in the cell and an iso value: when the reconstruction
    /// at the point reaches iso, the bound from the inner slices' maximum and
    /// the outer slices' minimum says the cell may reach it; and every value
    /// lies between the lower and the upper bound, and within
    /// `1.125·max − 0.125·min` of all sixteen corners.
    #[test]
    fn the_cell_bound_is_conservative(
        corners in prop::array::uniform4(prop::array::uniform4(-1000.0f64..1000.0)),
        spread in prop::sample::select(vec![1e-3, 1.0, 100.0, 1000.0]),
        fx in 0.0f64..=1.0, fy in 0.0f64..=1.0, t in 0.0f64..=1.0,
        iso in -1200.0f64..1200.0,
    ) {
        let s = spread / 1000.0;
        let c: Vec<[f64; 4]> = corners.iter().map(|k| k.map(|v| v * s)).collect();
        let slice = |k: &[f64; 4]| lerp(lerp(k[0], k[1], fx), lerp(k[2], k[3], fx), fy);
        let p = [slice(&c[0]), slice(&c[1]), slice(&c[2]), slice(&c[3])];
        let value = eval(p, t);
        let max = |r: &[[f64; 4]]| r.iter().flatten().fold(f64::NEG_INFINITY, |a, &b| a.max(b));
        let min = |r: &[[f64; 4]]| r.iter().flatten().fold(f64::INFINITY, |a, &b| a.min(b));
        let outer = [c[0], c[3]];
        let (inner_max, inner_min) = (max(&c[1..3]), min(&c[1..3]));
        let (outer_max, outer_min) = (max(&outer), min(&outer));
        let eps = 1e-9 * (1.0 + value.abs());
        prop_assert!(value <= upper_bound(inner_max, outer_min) + eps, "{value} > {}", upper_bound(inner_max, outer_min));
        prop_assert!(value >= lower_bound(inner_min, outer_max) - eps);
        let (all_max, all_min) = (max(&c), min(&c));
        prop_assert!(value <= 1.125 * all_max - 0.125 * all_min + eps);
        if value >= iso {
            prop_assert!(cell_may_reach(inner_max + eps, outer_min, iso));
        }
        let (lo, hi) = reconstruct::widened(all_min, all_max);
        prop_assert!(value >= lo - eps && value <= hi + eps);
    }

    /// The crossing is where the cubic first reaches iso: at or above iso
    /// there, below iso at every sampled point before it, and found whenever
    /// a sample of the segment reaches iso.
    #[test]
    fn the_crossing_is_the_first_point_at_iso(
        p in prop::array::uniform4(-10.0f64..10.0),
        iso in -12.0f64..12.0,
    ) {
        const N: usize = 2000;
        let first = (0..=N).map(|i| i as f64 / N as f64).find(|&t| eval(p, t) >= iso);
        match crossing(p, iso) {
            None => prop_assert!(first.is_none(), "missed a crossing at {first:?}"),
            Some(t) => {
                // (bisection brackets the crossing to 2⁻¹², the secant places it inside)
                const H: f64 = 1.0 / 4096.0;
                prop_assert!((0.0..=1.0).contains(&t));
                prop_assert!((0..=64).any(|i| eval(p, (t + H * i as f64 / 64.0).min(1.0)) >= iso - 1e-3), "nothing at iso within 2⁻¹² after {t}");
                if let Some(f) = first {
                    prop_assert!(t <= f + H, "crossing {t} after the sampled {f}");
                }
                // nothing before it reaches iso (up to the sampling and the bracket)
                let before = (0..N).map(|i| i as f64 / N as f64 * t).take_while(|&s| s < t - H);
                for s in before {
                    prop_assert!(eval(p, s) < iso + 1e-9, "f({s}) = {} ≥ {iso} before {t}", eval(p, s));
                }
            }
        }
    }
}

/// A volume of `f(x, y, z)` at unit spacing, and its cubic reference.
fn field(dims: [usize; 3], f: impl Fn(f64, f64, f64) -> f64) -> ReferenceRenderer {
    let v = Volume::from_fn(dims, [1.0, 1.0, 1.0], |x, y, z| f(x as f64, y as f64, z as f64) as f32).unwrap();
    ReferenceRenderer::new(&v)
}

#[test]
fn the_cubic_reproduces_what_its_order_promises() {
    let dims = [5, 4, 12];
    let mut s = 0x2545_F491u64;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    // small integer coefficients keep the f32 voxels exact
    let linear = |x: f64, y: f64, z: f64| 2.0 * x - 3.0 * y + 5.0 * z - 7.0;
    let quadratic = |x: f64, y: f64, z: f64| x - y + 3.0 * z * z - 4.0 * z + 1.0;
    let cubic = |x: f64, y: f64, z: f64| 2.0 * x + y + z * z * z;
    let (rl, rq, rc) = (field(dims, linear), field(dims, quadratic), field(dims, cubic));
    for _ in 0..500 {
        // points whose four slices lie inside the volume (no border repeat)
        let p = DVec3::new(next() * 4.0, next() * 3.0, 1.0 + next() * 8.0);
        let (z0, t) = (p.z.floor(), p.z - p.z.floor());
        let l = rl.density_cubic(p);
        assert!((l - linear(p.x, p.y, p.z)).abs() < 1e-9, "linear at {p}: {l}");
        let q = rq.density_cubic(p);
        assert!((q - quadratic(p.x, p.y, p.z)).abs() < 1e-9, "quadratic at {p}: {q}");
        // the gradient is exact for both (x and y: central differences, exact on these)
        let g = rq.gradient_cubic(p);
        assert!((g - DVec3::new(1.0, -1.0, 6.0 * p.z - 4.0)).length() < 1e-9, "quadratic gradient at {p}: {g}");
        assert!((rl.gradient_cubic(p) - DVec3::new(2.0, -3.0, 5.0)).length() < 1e-9);
        // a cubic is missed by exactly the kernel's third-order term t(1 − t)(1 − 2t)
        let c = rc.density_cubic(p);
        let want = cubic(p.x, p.y, p.z) + t * (1.0 - t) * (1.0 - 2.0 * t);
        assert!((c - want).abs() < 1e-6, "cubic at {p} (slice {z0}): {c} vs {want}");
        // the normal's gradient along z is the derivative of the B-spline
        // smoothing of the slices, which maps z³ to z³ + z
        let gz = rc.gradient_cubic(p).z;
        assert!((gz - (3.0 * p.z * p.z + 1.0)).abs() < 1e-6, "d/dz at {p}: {gz}");
    }
    // the weights interpolate: on a slice the cubic is the slice
    for z in 1..10 {
        let p = DVec3::new(1.5, 2.25, z as f64);
        assert!((rc.density_cubic(p) - rc.density(p)).abs() < 1e-9);
    }
    assert_eq!(catmull_rom(0.0), [0.0, 1.0, 0.0, 0.0]);
}

/// Depth and normal errors over several views: both means weighted by the
/// pixels compared, the largest p99 of each.
#[derive(Default)]
struct ViewErrors {
    dsum: f64,
    dn: usize,
    dp99: f64,
    nsum: f64,
    nn: usize,
    np99: f64,
}

impl ViewErrors {
    fn add(&mut self, d: &DepthError, n: &NormalError) {
        self.dsum += d.mean * d.both as f64;
        self.dn += d.both;
        self.dp99 = self.dp99.max(d.p99);
        self.nsum += n.mean_deg * n.both as f64;
        self.nn += n.both;
        self.np99 = self.np99.max(n.p99_deg);
    }

    /// `[depth mean, depth p99, normal mean °, normal p99 °]`.
    fn summary(&self) -> [f64; 4] {
        [self.dsum / self.dn as f64, self.dp99, self.nsum / self.nn as f64, self.np99]
    }
}

/// Depth (voxels of the finest spacing: pooled mean, worst view's p99) and
/// normal error (degrees: pooled mean, worst view's p99) of the reference
/// against the analytic surface over the seven standard views at `size`².
fn reference_errors(phantom: Phantom, dims: [usize; 3], spacing: [f64; 3], recon: Reconstruction, size: usize) -> [f64; 4] {
    let a = phantom.analytic(dims, Some(spacing)).unwrap().unwrap();
    let vol = phantom.build_sampled(dims, Some(spacing)).unwrap();
    let iso = a.shape.iso();
    let unit = vol.spacing().iter().fold(f32::MAX, |m, &s| m.min(s)) as f64;
    let model = ReferenceRenderer::new(&vol);
    let (lo, hi) = vol.value_range();
    let cls = Classifier::new(&TransferFunction::threshold(iso, [0.9, 0.8, 0.7]), lo, hi);
    let scene = Scene::new(Mode::Iso, &cls, iso, Shading::default());
    let opts = ReferenceOptions { reconstruction: recon, threads: 2, ..Default::default() };
    let mut errors = ViewErrors::default();
    for v in standard_views(NamedView::Anterior.rotation(), 0, 1) {
        let cam = Camera { rotation: v.rotation, zoom: None, size: [size, size] };
        let img = model.render(&scene, &cam, &opts).unwrap();
        let t = surface_truth(&a, vol.spacing(), &cam, &Projection::Parallel, iso as f64, opts.near).unwrap();
        let d = depth_error(&img.depth, &t.depth, unit).unwrap();
        let n = normal_error(&img.normal, &t.normal).unwrap();
        errors.add(&d, &n);
    }
    errors.summary()
}

/// The reference's error on the thick-slice ball (1×1×3) and ellipsoid
/// (0.6×0.6×5) at 128² over the seven standard views, linear and cubic,
/// within ±20 % of what was measured (a guard for the numbers the bench
/// reports); the cubic's normal error at most half the linear's and within
/// 1.5° mean and 6° p99, its depth mean and p99 no worse.
#[test]
fn the_cubic_reference_stays_within_measured_margins() {
    let cases = [
        (Phantom::Sphere, [1.0, 1.0, 3.0], [0.02439, 0.1751, 0.08992, 0.8449], [0.008043, 0.1175, 0.03006, 0.2506]),
        (Phantom::Ellipsoid, [0.6, 0.6, 5.0], [0.3259, 3.369, 3.432, 11.01], [0.2657, 3.250, 0.8596, 3.595]),
    ];
    let got: Vec<([f64; 4], [f64; 4])> = cases
        .iter()
        .map(|&(phantom, spacing, _, _)| {
            let l = reference_errors(phantom, [128; 3], spacing, Reconstruction::Linear, 128);
            let c = reference_errors(phantom, [128; 3], spacing, Reconstruction::Cubic, 128);
            eprintln!("{phantom:?} {spacing:?}: linear {l:?} cubic {c:?}");
            (l, c)
        })
        .collect();
    for ((phantom, spacing, linear, cubic), (l, c)) in cases.into_iter().zip(got) {
        for (got, measured, name) in [(l, linear, "linear"), (c, cubic, "cubic")] {
            for i in 0..4 {
                assert!(
                    got[i] >= 0.8 * measured[i] && got[i] <= 1.2 * measured[i],
                    "{phantom:?} {spacing:?} {name}: {got:?}, measured {measured:?} (depth mean, p99 in voxels; normal mean, p99 in degrees)"
                );
            }
        }
        assert!(c[2] <= 0.5 * l[2] && c[3] <= 0.5 * l[3], "{phantom:?}: normal error cubic {c:?} vs linear {l:?}");
        assert!(c[2] <= 1.5 && c[3] <= 6.0, "{phantom:?}: normal error cubic {c:?}");
        assert!(c[0] <= l[0] && c[1] <= l[1], "{phantom:?}: depth cubic {c:?} vs linear {l:?}");
    }
}

/// `bench --reconstruction linear,cubic`: the suite's reference rows name
/// the last (cubic) and carry its depth and normal error; the binary
/// variant runs once per reconstruction, the RLE path only linear.
/// `render` takes the option, on the RLE path too (with Deluxe P); Deluxe I
/// and the BCC grid refuse the cubic with a usage error (exit code 2).
#[test]
fn bench_and_render_take_the_reconstruction() {
    let out = assert_cmd::Command::cargo_bin("shearwarp")
        .unwrap()
        .args(["bench", "--suite", "surfaces", "--size", "24", "--reps", "1", "--rounds", "1", "--random-views", "0"])
        .args(["--only", "binary-c1-u64-bitscan,rle", "--ref-step", "0.5", "--reconstruction", "linear,cubic", "--json", "--quiet"])
        .assert()
        .success();
    let json: serde_json::Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
    let refs = json["reference"].as_array().unwrap();
    assert_eq!(refs.len(), 5);
    for r in refs {
        assert_eq!(r["variant"], "reference");
        assert_eq!(r["reconstruction"], "cubic");
        for k in ["depth_mean", "depth_p99", "normal_deg_mean", "normal_deg_p99"] {
            assert!(r[k].as_f64().is_some_and(|v| v >= 0.0), "{k}: {r}");
        }
    }
    let rows: Vec<(String, String)> = json["table"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| (r["variant"].as_str().unwrap().to_string(), r["reconstruction"].as_str().unwrap().to_string()))
        .collect();
    for (v, rec) in [("binary-c1-u64-bitscan", "linear"), ("binary-c1-u64-bitscan-cubic", "cubic"), ("rle", "linear")] {
        assert_eq!(rows.iter().filter(|(a, b)| a == v && b == rec).count(), 5, "{v} {rec}: {rows:?}");
    }
    assert!(!rows.iter().any(|(v, _)| v == "rle-cubic"), "{rows:?}");
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("cubic.png");
    assert_cmd::Command::cargo_bin("shearwarp")
        .unwrap()
        .args(["render", "--phantom", "sphere", "--phantom-dims", "24,24,24", "--size", "32", "--reconstruction", "cubic", "-q", "-o"])
        .arg(&png)
        .assert()
        .success();
    assert!(png.exists());
    let rle = dir.path().join("rle.png");
    let out = assert_cmd::Command::cargo_bin("shearwarp")
        .unwrap()
        .args(["render", "--phantom", "head", "--phantom-dims", "48,48,42", "--size", "48", "--method", "rle", "--deluxe", "P"])
        .args(["--reconstruction", "cubic", "--json", "-o"])
        .arg(&rle)
        .assert()
        .success();
    let json: serde_json::Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
    // (a still frame adds matched sampling: MP)
    assert_eq!(
        (json["method"].as_str(), json["deluxe"].as_str(), json["reconstruction"].as_str()),
        (Some("rle"), Some("MP"), Some("cubic"))
    );
    assert!(json["coverage"].as_f64().unwrap() > 0.05, "{json}");
    for bad in [
        &["--deluxe", "I"][..],
        &["--method", "rle", "--deluxe", "I"],
        &["--method", "rle", "--deluxe", "I,P"],
        &["--method", "rle", "--grid", "bcc"],
    ] {
        let out = assert_cmd::Command::cargo_bin("shearwarp")
            .unwrap()
            .args(["render", "--phantom", "sphere", "--phantom-dims", "24,24,24", "--size", "32", "--reconstruction", "cubic", "-q", "-o"])
            .arg(dir.path().join("refused.png"))
            .args(bad)
            .assert()
            .code(2);
        let err = String::from_utf8_lossy(&out.get_output().stderr).to_string();
        assert!(err.contains("cubic") && !err.contains("panicked"), "{bad:?}: {err}");
    }
}

/// `v` stored as 16-bit integers (rounded), as 8/16-bit scans are.
fn as_u16(v: &Volume) -> Volume {
    let data = v.to_f32().iter().map(|x| x.round().clamp(0.0, 65535.0) as u16).collect();
    Volume::new(v.dims(), v.spacing(), VoxelData::U16(data)).unwrap()
}

/// Three tissue presets at ascending thresholds (2-bit cell codes).
fn tissues() -> Vec<Tissue> {
    [(60.0, "a"), (130.0, "b"), (210.0, "c")]
        .into_iter()
        .map(|(t, name)| Tissue {
            name,
            threshold: t,
            rgb: [0.8, 0.7, 0.6],
            tf: TransferFunction::new(vec![(t, 0.0), (t + 30.0, 0.5), (300.0, 0.9)], vec![(t, [0.9, 0.5, 0.3]), (300.0, [0.3, 0.5, 0.9])])
                .unwrap(),
        })
        .collect()
}

/// The intermediate image, its depths and the final image of one frame, as bits.
fn frame_bits(r: &mut Renderer, cam: &Camera) -> (Vec<u32>, Vec<u32>, Vec<u32>) {
    let mut img = Image::new(cam.size[0], cam.size[1]);
    r.render(cam, &mut img).unwrap();
    let inter = r.intermediate();
    let [w, h] = inter.size;
    let (mut px, mut depth) = (vec![], vec![]);
    for q in 0..h {
        for p in 0..w {
            px.extend(inter.get(p as isize, q as isize).map(f32::to_bits));
            depth.push(inter.depth_at(p, q).to_bits());
        }
    }
    (px, depth, img.data.iter().flatten().map(|x| x.to_bits()).collect())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases(40)))]

    /// Lossless skipping under the cubic, its first crossing shaded by its
    /// gradient or the linear hit at its crossing shaded by its normal codes:
    /// the binary path (every cell size
    /// 1–4, word and search, one transfer function or tissue codes, f32 or
    /// 16-bit voxels) renders brute force's intermediate image, depths and
    /// final image bit for bit, at spacings that put the volume's z along
    /// the slices or in them, in parallel and perspective views.
    #[test]
    fn cubic_binary_equals_brute_force(
        nx in 3usize..22, ny in 3usize..22, nz in 3usize..30, seed in any::<u64>(), tfs in any::<u64>(),
        rx in -3.2f64..3.2, ry in -3.2f64..3.2, rz in -3.2f64..3.2,
        spacing in prop::sample::select(vec![[1.0f32, 1.0, 1.0], [1.0, 1.0, 3.0], [0.6, 0.6, 5.0], [3.0, 1.0, 1.0], [1.0, 2.5, 0.7]]),
        cell in 1usize..=4, u64w in any::<bool>(), lut in any::<bool>(), coded in any::<bool>(), tissue in 0usize..3,
        u16_data in any::<bool>(), perspective in prop::option::of(0.4f64..3.0), quality in prop::option::of(0.5f64..2.0),
        codes in any::<bool>(),
    ) {
        let vol = common::random_volume([nx, ny, nz], seed, spacing);
        let vol = if u16_data { as_u16(&vol) } else { vol };
        let cam = Camera::new(glam::DMat3::from_euler(glam::EulerRot::XYZ, rx, ry, rz), [40, 36]);
        let base = Settings {
            mode: Mode::Iso,
            reconstruction: Reconstruction::Cubic,
            normals: if codes { Normals::Codes } else { Normals::Gradient },
            word: if u64w { WordSize::U64 } else { WordSize::U32 },
            search: if lut { Search::Lut } else { Search::Bitscan },
            cell,
            threads: 2,
            ..Settings::default()
        };
        let projection = match perspective {
            Some(d) => Projection::perspective(50.0, d).unwrap(),
            None => Projection::Parallel,
        };
        let make = |method| {
            let s = Settings { method, ..base };
            let mut r = if coded {
                let mut r = Renderer::with_tissues(vol.clone(), &tissues(), s).unwrap();
                r.select_tissue(tissue).unwrap();
                r
            } else {
                Renderer::new(vol.clone(), &common::random_tf(tfs), s).unwrap()
            };
            r.set_projection(projection).unwrap();
            if let Some(q) = quality {
                r.set_quality(q).unwrap();
            }
            r
        };
        let want = frame_bits(&mut make(Method::Brute), &cam);
        let got = frame_bits(&mut make(Method::Binary), &cam);
        prop_assert!(got.0 == want.0, "intermediate images differ");
        prop_assert!(got.1 == want.1, "iso depths differ");
        prop_assert!(got.2 == want.2, "final images differ");
    }
}

/// Depth (voxels of the finest spacing: pooled mean, worst view's p99) and
/// normal error (degrees: pooled mean, worst view's p99) of the binary
/// path against the analytic surface over the seven standard views at `size`².
fn binary_errors(phantom: Phantom, dims: [usize; 3], spacing: Option<[f64; 3]>, recon: Reconstruction, size: usize) -> [f64; 4] {
    // a still frame under the cubic shades by its gradient (`render`'s choice)
    let normals = if recon == Reconstruction::Cubic { Normals::Gradient } else { Normals::Codes };
    binary_errors_with(phantom, dims, spacing, Settings { reconstruction: recon, normals, ..Settings::default() }, true, size)
}

/// [`binary_errors`] with `base`'s reconstruction and normals, as a still
/// frame (`matched` sampling) or a preview.
fn binary_errors_with(
    phantom: Phantom,
    dims: [usize; 3],
    spacing: Option<[f64; 3]>,
    base: Settings,
    matched: bool,
    size: usize,
) -> [f64; 4] {
    let a = phantom.analytic(dims, spacing).unwrap().unwrap();
    let vol = phantom.build_sampled(dims, spacing).unwrap();
    let iso = a.shape.iso();
    let unit = vol.spacing().iter().fold(f32::MAX, |m, &s| m.min(s)) as f64;
    let model = ReferenceRenderer::new(&vol);
    let tf = TransferFunction::threshold(iso, [0.9, 0.8, 0.7]);
    // matched sampling (a still frame): the intermediate image is not magnified, so the
    // errors are the reconstruction's, not the warp's interpolation of depths
    let deluxe = shearwarp::Deluxe { matched, ..Default::default() };
    let s = Settings { mode: Mode::Iso, deluxe, threads: 2, ..base };
    let mut r = Renderer::new(vol.clone(), &tf, s).unwrap();
    r.set_iso(iso).unwrap();
    let mut errors = ViewErrors::default();
    for v in standard_views(NamedView::Anterior.rotation(), 0, 1) {
        let cam = Camera { rotation: v.rotation, zoom: None, size: [size, size] };
        let mut img = Image::new(size, size);
        r.render(&cam, &mut img).unwrap();
        let t = surface_truth(&a, vol.spacing(), &cam, &Projection::Parallel, iso as f64, 0.0).unwrap();
        let d = depth_error(&fast_path_depth(&r, &cam).unwrap(), &t.depth, unit).unwrap();
        let n = normal_error(&fast_path_normals(&r, &cam, &model).unwrap(), &t.normal).unwrap();
        errors.add(&d, &n);
    }
    errors.summary()
}

/// The binary path's cubic on the ball, isotropic (64³) and at 1×1×3, over
/// the seven standard views at 128² with matched sampling, with margins over
/// what was measured: the normal error well within the goals (mean ≤ 1.5°,
/// p99 ≤ 6°) and on the thick slices a mean at most half the linear's (the
/// p99 of both is set by grazing pixels at the silhouette: no worse); the
/// depth error mean within 0.1 voxel, its p99 at most 15 % over the linear's.
#[test]
fn the_binary_cubic_ball_meets_the_goals() {
    for spacing in [None, Some([1.0, 1.0, 3.0])] {
        let l = binary_errors(Phantom::Sphere, [64; 3], spacing, Reconstruction::Linear, 128);
        let c = binary_errors(Phantom::Sphere, [64; 3], spacing, Reconstruction::Cubic, 128);
        eprintln!("ball {spacing:?}: linear {l:?} cubic {c:?} (depth mean, p99 in voxels; normal mean, p99 in degrees)");
        assert!(c[2] <= 0.2 && c[3] <= 3.0, "{spacing:?}: normal error cubic {c:?}");
        assert!(c[0] <= 0.06, "{spacing:?}: depth mean cubic {c:?}");
        assert!(c[1] <= 1.15 * l[1], "{spacing:?}: depth p99 cubic {c:?} vs linear {l:?}");
        assert!(c[2] <= 0.5 * l[2] && c[3] <= 1.1 * l[3], "{spacing:?}: normal error cubic {c:?} vs linear {l:?}");
    }
}

/// The preview of the cubic (its crossing at the linear samples' hit,
/// shaded by its normal codes; one ray per voxel, magnified by the warp) on
/// the ellipsoid at 0.6×0.6×5, over the seven standard views at 128², with
/// margins over what was measured: the normal error mean within the goal
/// (≤ 1.5°) and at most half the linear preview's, the depth error no worse
/// than the linear preview's (the warp's magnification sets both previews'
/// p99, the reason still frames take matched sampling).
#[test]
fn the_cubic_preview_follows_thick_slice_surfaces() {
    let run = |reconstruction| {
        let s = Settings { reconstruction, normals: Normals::Codes, ..Settings::default() };
        binary_errors_with(Phantom::Ellipsoid, [96; 3], Some([0.6, 0.6, 5.0]), s, false, 128)
    };
    let (l, c) = (run(Reconstruction::Linear), run(Reconstruction::Cubic));
    eprintln!("ellipsoid 0.6×0.6×5 preview: linear {l:?} cubic {c:?} (depth mean, p99 in voxels; normal mean, p99 in degrees)");
    assert!(c[2] <= 1.5 && c[2] <= 0.5 * l[2], "normal error mean: cubic {c:?} vs linear {l:?}");
    assert!(c[3] <= l[3], "normal error p99: cubic {c:?} vs linear {l:?}");
    assert!(c[0] <= 1.02 * l[0] && c[1] <= 1.02 * l[1], "depth error: cubic {c:?} vs linear {l:?}");
}

/// The normal codes the RLE paths store under each reconstruction, against
/// the analytic surface: over the voxels next to it (a neighbour along some
/// axis on the other side of iso), the angle (degrees) between each voxel's
/// decoded code and the analytic normal at the voxel — `[mean, p99]` for the
/// central differences ([`voxel_normal`]) and for the cubic's B-spline
/// gradient ([`cubic_voxel_normal`]), and how many voxels.
fn voxel_code_errors(phantom: Phantom, dims: [usize; 3], spacing: [f64; 3]) -> ([f64; 2], [f64; 2], usize) {
    let a = phantom.analytic(dims, Some(spacing)).unwrap().unwrap();
    let vol = phantom.build_sampled(dims, Some(spacing)).unwrap();
    let iso = a.shape.iso();
    let d = vol.dims();
    let inv = vol.spacing().map(|s| 1.0 / s);
    let v = vol.to_f32();
    let at = |x: usize, y: usize, z: usize| v[x + d[0] * (y + d[1] * z)];
    let stack = SliceStack::new(&vol, 2);
    let p = stack.perm();
    let (mut linear, mut cubic) = (vec![], vec![]);
    for z in 0..d[2] {
        for y in 0..d[1] {
            for x in 0..d[0] {
                let inside = at(x, y, z) >= iso;
                let c = [x, y, z];
                let next = (0..3).any(|ax| {
                    [c[ax].wrapping_sub(1), c[ax] + 1].into_iter().filter(|&u| u < d[ax]).any(|u| {
                        let mut q = c;
                        q[ax] = u;
                        (at(q[0], q[1], q[2]) >= iso) != inside
                    })
                });
                let truth = a.shape.gradient(a.grid.to_physical(DVec3::new(x as f64, y as f64, z as f64)));
                if !next || truth.length() <= 0.0 {
                    continue;
                }
                let truth = truth.normalize();
                let s = p.map(|ax| c[ax]);
                let angle = |code: u16| {
                    decode_normal(code).map_or(90.0, |n| {
                        let n = DVec3::new(n[0] as f64, n[1] as f64, n[2] as f64);
                        n.dot(truth).abs().min(1.0).acos().to_degrees()
                    })
                };
                linear.push(angle(voxel_normal(&stack, s[0], s[1], s[2], inv)));
                cubic.push(angle(cubic_voxel_normal(&stack, s[0], s[1], s[2], inv)));
            }
        }
    }
    let summary = |e: &mut Vec<f64>| {
        e.sort_by(f64::total_cmp);
        [e.iter().sum::<f64>() / e.len() as f64, e[(e.len() * 99 / 100).min(e.len() - 1)]]
    };
    let n = linear.len();
    (summary(&mut linear), summary(&mut cubic), n)
}

/// The RLE paths' normal codes under the cubic on thick slices, at the
/// voxels next to the surface (128 mm boxes, margins over what was
/// measured): on the ellipsoid at 0.6×0.6×5 the cubic codes' mean and p99
/// angle error are at most half the central differences' (measured 1.78°
/// and 5.16° against 4.40° and 11.6°); on the ball at 1×1×3, whose linear
/// ramp central differences follow well, the mean is lower and the p99 at
/// most half (0.78° and 2.89° against 0.94° and 6.30°); on the isotropic
/// ball the two are alike (0.48° mean: the codes' quantization).
#[test]
fn the_cubic_voxel_codes_follow_thick_slice_surfaces() {
    // (phantom, spacing, the most the cubic's mean and p99 may be of the linear's, the cubic's measured mean and p99)
    let cases = [
        (Phantom::Ellipsoid, [0.6, 0.6, 5.0], [0.5, 0.5], [1.778, 5.158]),
        (Phantom::Sphere, [1.0, 1.0, 3.0], [0.9, 0.5], [0.7773, 2.889]),
        (Phantom::Sphere, [1.0, 1.0, 1.0], [1.01, 1.01], [0.4753, 0.9391]),
    ];
    for (phantom, spacing, ratio, measured) in cases {
        let (l, c, n) = voxel_code_errors(phantom, [128; 3], spacing);
        eprintln!("{phantom:?} {spacing:?}: {n} voxels, central differences {l:?}, cubic {c:?} (mean, p99 in degrees)");
        assert!(n > 10_000, "{phantom:?} {spacing:?}: {n} voxels");
        for i in 0..2 {
            assert!(c[i] <= ratio[i] * l[i], "{phantom:?} {spacing:?}: cubic {c:?} vs central differences {l:?}");
            assert!(c[i] <= 1.2 * measured[i], "{phantom:?} {spacing:?}: cubic {c:?}, measured {measured:?}");
        }
    }
}

/// The RLE path's iso frames under the cubic, pre-classified and with
/// Deluxe P, against the analytic surface's shading
/// ([`rle_shading_errors`], margins over what was measured): on the
/// ellipsoid at 0.6×0.6×5 the error's mean and p99 are at most half the
/// linear codes' (P: measured 0.0088 and 0.033 of the iso colour against
/// 0.028 and 0.107); on the ball at 1×1×3 and isotropic no worse.
#[test]
fn the_rle_cubic_shading_follows_thick_slice_surfaces() {
    let cases =
        [(Phantom::Ellipsoid, [0.6, 0.6, 5.0], 0.5), (Phantom::Sphere, [1.0, 1.0, 3.0], 1.02), (Phantom::Sphere, [1.0, 1.0, 1.0], 1.02)];
    for (phantom, spacing, ratio) in cases {
        for post in [true, false] {
            let deluxe = shearwarp::Deluxe { post, ..Default::default() };
            let run = |reconstruction| {
                let s = Settings { method: Method::Rle, reconstruction, deluxe, ..Settings::default() };
                rle_shading_errors(phantom, [128; 3], spacing, s, 128)
            };
            let (l, c) = (run(Reconstruction::Linear), run(Reconstruction::Cubic));
            eprintln!("RLE {} {phantom:?} {spacing:?}: shading error linear {l:?}, cubic {c:?} (mean, p99)", deluxe.label());
            assert!(
                c[0] <= ratio * l[0] && c[1] <= ratio * l[1],
                "{} {phantom:?} {spacing:?}: cubic {c:?} vs linear {l:?}",
                deluxe.label()
            );
        }
    }
}

/// The shading error of the RLE path's iso frames against the analytic
/// surface: over the seven standard views at `size`², the pixels whose
/// truth normal faces the view (`|n·l| ≥ 0.3`) and which the frame covers,
/// the difference between the frame's green channel and the analytic
/// normal's shade — `[mean, p99]`, in units of the iso colour's green.
fn rle_shading_errors(phantom: Phantom, dims: [usize; 3], spacing: [f64; 3], settings: Settings, size: usize) -> [f64; 2] {
    let a = phantom.analytic(dims, Some(spacing)).unwrap().unwrap();
    let vol = phantom.build_sampled(dims, Some(spacing)).unwrap();
    let iso = a.shape.iso();
    let rgb = [0.9, 0.8, 0.7];
    let tf = TransferFunction::threshold(iso, rgb);
    let s = Settings { mode: Mode::Iso, threads: 2, ..settings };
    let mut r = Renderer::new(vol.clone(), &tf, s).unwrap();
    r.set_iso(iso).unwrap();
    let mut e = vec![];
    for v in standard_views(NamedView::Anterior.rotation(), 0, 1) {
        let cam = Camera { rotation: v.rotation, zoom: None, size: [size, size] };
        let mut img = Image::new(size, size);
        r.render(&cam, &mut img).unwrap();
        let t = surface_truth(&a, vol.spacing(), &cam, &Projection::Parallel, iso as f64, 0.0).unwrap();
        let light = cam.rotation.row(2);
        for (px, n) in img.data.iter().zip(&t.normal) {
            let ndl = n.dot(light).abs();
            if n.is_nan() || ndl < 0.3 || px[3] < 0.999 {
                continue;
            }
            let want = s.shading.shade(rgb, ndl as f32);
            e.push(((px[1] - want[1]) / rgb[1]).abs() as f64);
        }
    }
    e.sort_by(f64::total_cmp);
    [e.iter().sum::<f64>() / e.len() as f64, e[e.len() * 99 / 100]]
}

/// A scaled frame (an intermediate grid coarser than the voxels) whose ray
/// samples a slice exactly on its first voxel row: the binary path's
/// occupied rectangle keeps that ray, so it equals brute force under either
/// reconstruction (this volume and view once lost one hit pixel).
#[test]
fn scaled_frames_keep_the_rays_on_a_voxel_line() {
    let vol = common::random_volume([15, 3, 18], 2789997283212598668, [1.0, 1.0, 1.0]);
    let cam = Camera::new(glam::DMat3::from_euler(glam::EulerRot::XYZ, 0.8880360042846189, 0.0, 2.813609941067683), [40, 36]);
    for reconstruction in [Reconstruction::Linear, Reconstruction::Cubic] {
        for normals in [Normals::Codes, Normals::Gradient] {
            let s = Settings { mode: Mode::Iso, reconstruction, normals, word: WordSize::U32, threads: 2, ..Settings::default() };
            let make = |method| {
                let mut r = Renderer::new(vol.clone(), &common::random_tf(1230050938176927570), Settings { method, ..s }).unwrap();
                r.set_quality(0.5052158061691725).unwrap();
                r
            };
            let (want, got) = (frame_bits(&mut make(Method::Brute), &cam), frame_bits(&mut make(Method::Binary), &cam));
            assert!(want.1.iter().any(|d| !f32::from_bits(*d).is_nan()), "no hit");
            assert!(got == want, "{reconstruction:?} {normals:?}: binary and brute force differ");
        }
    }
}

/// `rotate` takes the cubic for a thick-slice volume unless told otherwise
/// (its preview: normal codes), and linear for an isotropic one; its JSON
/// says which.
#[test]
fn rotate_takes_the_cubic_on_thick_slices() {
    let run = |extra: &[&str]| {
        let out = assert_cmd::Command::cargo_bin("shearwarp")
            .unwrap()
            .args(["rotate", "--phantom", "sphere", "--phantom-dims", "24,24,24", "--size", "32", "--degrees", "3", "--json"])
            .args(extra)
            .assert()
            .success();
        let json: serde_json::Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
        (json["reconstruction"].as_str().unwrap().to_string(), json["normals"].as_str().unwrap().to_string())
    };
    assert_eq!(run(&["--phantom-spacing", "1,1,3"]), ("cubic".to_string(), "codes".to_string()));
    assert_eq!(run(&["--phantom-spacing", "1,1,3", "--reconstruction", "linear"]).0, "linear");
    assert_eq!(run(&[]).0, "linear");
    assert_eq!(run(&["--phantom-spacing", "1,1,3", "--normals", "gradient"]), ("cubic".to_string(), "gradient".to_string()));
}

/// `render --method rle` of a thick-slice volume in iso mode takes the
/// post-classified sampler (Deluxe P) unless --deluxe is given: its still is
/// `--deluxe P,M`'s, and nearer the ray-cast iso surface (`--method brute`)
/// than the pre-classified still, whose slices draw as bands. An isotropic
/// volume, blend mode and an explicit --deluxe keep pre-classification.
#[test]
fn render_rle_takes_post_classification_on_thick_slices() {
    let dir = tempfile::tempdir().unwrap();
    let render = |extra: &[&str], name: &str| {
        let path = dir.path().join(name);
        let out = assert_cmd::Command::cargo_bin("shearwarp")
            .unwrap()
            .args(["render", "--phantom", "sphere", "--phantom-dims", "48,48,48", "--size", "96", "--json", "-o"])
            .arg(&path)
            .args(extra)
            .assert()
            .success();
        let json: serde_json::Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
        (json["deluxe"].as_str().unwrap().to_string(), image::open(&path).unwrap().to_rgb8())
    };
    let thick = ["--phantom-spacing", "1,1,3"];
    let (label, default) = render(&[&thick[..], &["--method", "rle"]].concat(), "default.png");
    assert_eq!(label, "MP");
    let (_, post) = render(&[&thick[..], &["--method", "rle", "--deluxe", "P,M"]].concat(), "post.png");
    assert!(default == post, "the default still is not --deluxe P,M's");
    let (label, pre) = render(&[&thick[..], &["--method", "rle", "--deluxe", "S"]].concat(), "pre.png");
    assert_eq!(label, "M");
    let (_, surface) = render(&[&thick[..], &["--method", "brute"]].concat(), "brute.png");
    let off = |a: &image::RgbImage| a.as_raw().iter().zip(surface.as_raw()).map(|(&x, &y)| (x as f64 - y as f64).abs()).sum::<f64>();
    assert!(off(&default) < 0.5 * off(&pre), "post {} against pre {}", off(&default), off(&pre));
    assert_eq!(render(&["--method", "rle"], "iso.png").0, "M");
    assert_eq!(render(&[&thick[..], &["--method", "rle", "--mode", "blend"]].concat(), "blend.png").0, "M");
}
