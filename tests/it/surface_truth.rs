//! Truth for surfaces: the analytic phantoms sampled at any spacing, their
//! first-hit depth and normal per pixel, and the metrics against them.
//!
//! * every analytic shape's normal is the gradient of its density (finite
//!   differences of the continuous density and of the sampled volume);
//! * the truth's hits lie on the surface, first along each ray, with the
//!   surface's normal, in both projections and at any spacing;
//! * a phantom sampled at another spacing keeps its physical shape: the
//!   volume's spacing is the sampling's, and its rendering covers the same
//!   pixels as the isotropic one;
//! * the metrics give known numbers on a known pair;
//! * the linear reconstruction's error on the ball stays within the margins
//!   measured for it (a guard for the numbers the bench reports);
//! * `--phantom-spacing` and `bench --suite surfaces` on the command line.

use assert_cmd::Command;
use glam::{DMat3, DVec3};
use predicates::prelude::*;
use proptest::prelude::*;

use shearwarp::accuracy::metrics::{SurfaceError, angle_deg, depth_error, normal_error, surface_error};
use shearwarp::accuracy::reference::{Rays, ReferenceRenderer, fast_path_depth, fast_path_normals};
use shearwarp::accuracy::truth::{SurfaceTruth, surface_truth};
use shearwarp::classify::presets;
use shearwarp::composite::Mode;
use shearwarp::data::phantom::Phantom;
use shearwarp::data::shapes::{AnalyticPhantom, Shape};
use shearwarp::render::{Method, Normals, Renderer, Settings};
use shearwarp::view::{Camera, NamedView, Projection, rotate_eye, standard_views};
use shearwarp::warp::Image;

fn cases(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// The phantoms with an analytic surface, at sizes small enough for many cases.
const SMALL: [(Phantom, [usize; 3]); 4] = [
    (Phantom::Sphere, [48, 48, 48]),
    (Phantom::MarschnerLobb, [41, 41, 41]),
    (Phantom::Ellipsoid, [48, 48, 48]),
    (Phantom::Torus, [48, 48, 48]),
];

/// Spacings the tests sample at: isotropic, thick slices, clinical thick slices, uneven.
const SPACINGS: [[f64; 3]; 4] = [[1.0, 1.0, 1.0], [1.0, 1.0, 3.0], [0.6, 0.6, 5.0], [1.7, 0.8, 1.25]];

fn analytic(p: Phantom, dims: [usize; 3], spacing: Option<[f64; 3]>) -> AnalyticPhantom {
    p.analytic(dims, spacing).unwrap().unwrap()
}

/// Central differences of `f` at `p` with step `h`.
fn fd(f: impl Fn(DVec3) -> f64, p: DVec3, h: f64) -> DVec3 {
    DVec3::new(
        f(p + DVec3::X * h) - f(p - DVec3::X * h),
        f(p + DVec3::Y * h) - f(p - DVec3::Y * h),
        f(p + DVec3::Z * h) - f(p - DVec3::Z * h),
    ) / (2.0 * h)
}

/// The ray parameter `t` of a truth depth: `t` itself for parallel rays,
/// else solved from the (affine in `t`) depth of the ray's points.
fn ray_t(rays: &Rays, o: DVec3, d: DVec3, depth: f64, perspective: bool) -> f64 {
    if !perspective {
        return depth;
    }
    let (a, b) = (rays.depth_of(o), rays.depth_of(o + d));
    (depth - a) / (b - a)
}

#[test]
fn analytic_normals_are_the_gradient_of_the_density() {
    for (p, dims) in SMALL {
        let a = analytic(p, dims, None);
        let shape = a.shape;
        let half = DVec3::from_array(dims.map(|n| (n - 1) as f64 / 2.0));
        let mut next = {
            let mut s = 0x9E37_79B9u64 + dims[0] as u64;
            move || {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
            }
        };
        let mut near_surface = 0;
        for _ in 0..4000 {
            let q = DVec3::new(next(), next(), next()) * half;
            let v = shape.density(q);
            // (the ball's ramp has kinks where it clamps: not a gradient there)
            if matches!(shape, Shape::Ball { .. }) && !(1e-3..200.0 - 1e-3).contains(&v) {
                continue;
            }
            let g = shape.gradient(q);
            let f = fd(|x| shape.density(x), q, 1e-5);
            assert!((g - f).length() <= 1e-5 * (1.0 + g.length()), "{p:?} at {q}: {g} vs {f}");
            assert!(g.length() <= shape.lipschitz() * (1.0 + 1e-9), "{p:?}: the Lipschitz bound");
            near_surface += ((v - shape.iso() as f64).abs() < 0.2 * shape.iso() as f64) as usize;
        }
        assert!(near_surface > 50, "{p:?}: {near_surface} points near the surface");
    }
}

/// The sampled volume's central differences point where the analytic
/// normal does, near the surface (the smooth shapes, sampled finely).
#[test]
fn sampled_central_differences_follow_the_analytic_normal() {
    for p in [Phantom::Sphere, Phantom::Ellipsoid, Phantom::Torus] {
        let a = analytic(p, [48, 48, 48], Some([0.5, 0.5, 0.5]));
        let vol = a.build().unwrap();
        let [nx, ny, nz] = vol.dims();
        let (mut n, mut worst) = (0, 0f64);
        for k in 1..nz - 1 {
            for j in 1..ny - 1 {
                for i in 1..nx - 1 {
                    let v = vol.get(i, j, k) as f64;
                    if (v - 100.0).abs() > 20.0 {
                        continue;
                    }
                    let c = DVec3::new(
                        (vol.get(i + 1, j, k) - vol.get(i - 1, j, k)) as f64,
                        (vol.get(i, j + 1, k) - vol.get(i, j - 1, k)) as f64,
                        (vol.get(i, j, k + 1) - vol.get(i, j, k - 1)) as f64,
                    );
                    let g = a.shape.gradient(a.grid.position(i, j, k));
                    worst = worst.max(angle_deg(c, g));
                    n += 1;
                }
            }
        }
        assert!(n > 1000, "{p:?}: {n}");
        assert!(worst < 2.0, "{p:?}: {worst}°");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases(24)))]

    /// Every hit of the truth lies on the iso-surface (or on the box face
    /// the ray enters through, already inside, with no normal), nothing
    /// along the ray before it reaches iso, and its normal is the surface's.
    #[test]
    fn truth_hits_lie_on_the_surface_first_along_each_ray(
        which in 0usize..4,
        sp in 0usize..4,
        rx in -180.0f64..180.0,
        ry in -90.0f64..90.0,
        persp in prop::option::of((25.0f64..70.0, 1.2f64..3.0)),
    ) {
        let (p, dims) = SMALL[which];
        let a = analytic(p, dims, Some(SPACINGS[sp]));
        let spacing = a.grid.spacing_f32();
        let cam = Camera { rotation: rotate_eye(rotate_eye(DMat3::IDENTITY, 0, rx), 1, ry), zoom: None, size: [36, 32] };
        let proj = match persp {
            Some((fov, d)) => Projection::perspective(fov, d).unwrap(),
            None => Projection::Parallel,
        };
        let iso = a.shape.iso() as f64;
        let t = surface_truth(&a, spacing, &cam, &proj, iso, 1.0).unwrap();
        let rays = Rays::with_projection(&cam, &proj, a.grid.dims, spacing).unwrap();
        let f = |v: DVec3| a.shape.density(a.grid.to_physical(v));
        let mut hits = 0;
        for v in 0..32 {
            for u in 0..36 {
                let i = v * 36 + u;
                if t.depth[i].is_nan() {
                    prop_assert!(t.normal[i].is_nan());
                    continue;
                }
                let (o, d) = rays.ray(u as f64, v as f64);
                let th = ray_t(&rays, o, d, t.depth[i], persp.is_some());
                let x = o + th * d;
                let (t0, _) = rays.clip_ray(o, d).unwrap();
                if t.normal[i].is_nan() {
                    // the box face, entered inside
                    prop_assert!(f(x) >= iso - 1e-9 && (th - t0).abs() < 1e-6 * (1.0 + th.abs()), "pixel ({u},{v})");
                    continue;
                }
                prop_assert!((f(x) - iso).abs() < 1e-6 * (1.0 + iso), "pixel ({u},{v}): {} vs {iso}", f(x));
                for s in 0..64 {
                    let ts = t0 + (th - t0) * s as f64 / 64.0;
                    prop_assert!(f(o + ts * d) < iso + 1e-9, "pixel ({u},{v}): iso reached before the hit");
                }
                let g = a.shape.gradient(a.grid.to_physical(x));
                prop_assert!(angle_deg(t.normal[i], -g) < 1e-6, "pixel ({u},{v})");
                prop_assert!((t.normal[i].length() - 1.0).abs() < 1e-12);
                hits += 1;
            }
        }
        prop_assert!(hits > 0 || p == Phantom::MarschnerLobb);
    }
}

#[test]
fn the_closed_form_and_the_march_agree() {
    // the ball and the ellipsoid intersect in closed form at their own iso value,
    // and by the march at any other: at the iso value ± 1e-9 the two must meet
    for p in [Phantom::Sphere, Phantom::Ellipsoid] {
        for sp in SPACINGS {
            let a = analytic(p, [48, 48, 48], Some(sp));
            let cam = Camera { rotation: rotate_eye(rotate_eye(DMat3::IDENTITY, 0, 30.0), 1, 50.0), zoom: None, size: [40, 40] };
            let proj = Projection::Parallel;
            let iso = a.shape.iso() as f64;
            let exact = surface_truth(&a, a.grid.spacing_f32(), &cam, &proj, iso, 1.0).unwrap();
            let marched = surface_truth(&a, a.grid.spacing_f32(), &cam, &proj, iso + 1e-9, 1.0).unwrap();
            let e = depth_error(&marched.depth, &exact.depth, 1.0).unwrap();
            assert_eq!((e.only_test, e.only_truth), (0, 0), "{p:?} {sp:?}");
            assert!(e.max < 1e-6, "{p:?} {sp:?}: {e:?}");
            assert!(normal_error(&marched.normal, &exact.normal).unwrap().max_deg < 1e-4);
        }
    }
}

#[test]
fn a_phantom_sampled_at_another_spacing_keeps_its_physical_shape() {
    for (p, dims) in SMALL {
        let iso = analytic(p, dims, None);
        let extent = dims.map(|n| (n - 1) as f64);
        let extent = if p == Phantom::MarschnerLobb { [extent[0]; 3] } else { extent };
        let zoom = 2.0;
        let cam = |deg: f64| Camera { rotation: rotate_eye(NamedView::Anterior.rotation(), 1, deg), zoom: Some(zoom), size: [120, 120] };
        let render = |vol: shearwarp::Volume, c: &Camera| {
            let tf = presets::generic(iso.shape.iso(), 200.0).tf;
            let mut r = Renderer::new(vol, &tf, Settings { mode: Mode::Iso, threads: 2, ..Settings::default() }).unwrap();
            r.set_iso(iso.shape.iso()).unwrap();
            let mut img = Image::new(120, 120);
            r.render(c, &mut img).unwrap();
            img
        };
        let reference = p.build(dims).unwrap();
        for s in SPACINGS {
            let a = analytic(p, dims, Some(s));
            let vol = p.build_sampled(dims, Some(s)).unwrap();
            assert_eq!(vol.spacing(), s.map(|x| x as f32), "{p:?} {s:?}");
            assert_eq!(vol.dims(), a.grid.dims);
            for ax in 0..3 {
                let covered = (vol.dims()[ax] - 1) as f64 * s[ax];
                assert!(covered <= extent[ax] + 1e-9 && covered > extent[ax] - s[ax], "{p:?} {s:?} axis {ax}: {covered} of {}", extent[ax]);
            }
            // voxel values are the shape's at their physical positions
            let [nx, ny, nz] = vol.dims();
            for (i, j, k) in [(0, 0, 0), (nx / 2, ny / 3, nz / 2), (nx - 1, ny / 2, nz - 1)] {
                let want = a.shape.density(a.grid.position(i, j, k)) as f32;
                assert_eq!(vol.get(i, j, k), want);
            }
            if p == Phantom::MarschnerLobb {
                continue; // (its surface meets the box: the box's coverage moves with the sampling)
            }
            // the rendered silhouette: the same pixels, up to a slice's worth at the edges
            let slack = (s.iter().copied().fold(0.0, f64::max) * zoom).ceil() as i64 + 2;
            for deg in [0.0, 35.0, 90.0] {
                let c = cam(deg);
                let (x, y) = (render(reference.clone(), &c), render(vol.clone(), &c));
                let bbox = |img: &Image| {
                    let mut b = [i64::MAX, i64::MAX, i64::MIN, i64::MIN];
                    for v in 0..120 {
                        for u in 0..120 {
                            if img.at(u, v)[3] > 0.5 {
                                b = [b[0].min(u as i64), b[1].min(v as i64), b[2].max(u as i64), b[3].max(v as i64)];
                            }
                        }
                    }
                    b
                };
                let (bx, by) = (bbox(&x), bbox(&y));
                assert!(bx[0] < bx[2], "{p:?}: nothing rendered");
                for e in 0..4 {
                    assert!((bx[e] - by[e]).abs() <= slack, "{p:?} {s:?} at {deg}°: {bx:?} vs {by:?}");
                }
                // and the truth of both samplings is one surface
                let t0 = surface_truth(&iso, reference.spacing(), &c, &Projection::Parallel, iso.shape.iso() as f64, 1.0).unwrap();
                let t1 = surface_truth(&a, vol.spacing(), &c, &Projection::Parallel, a.shape.iso() as f64, 1.0).unwrap();
                let e = depth_error(&t1.depth, &t0.depth, 1.0).unwrap();
                assert!(e.max < 1e-9 && e.only_test + e.only_truth == 0, "{p:?} {s:?}: {e:?}");
            }
        }
    }
}

#[test]
fn the_metrics_give_known_numbers_on_a_known_pair() {
    // a 10×10 plane at depth 0 facing +z; the tested image: 50 pixels 0.3 voxel
    // off, 20 normals tilted 4°, 5 tilted 30°, one pixel missed, one extra
    let n = 100;
    let mut truth = SurfaceTruth { depth: vec![0.0; n], normal: vec![DVec3::Z; n] };
    truth.depth[99] = f64::NAN;
    truth.normal[99] = DVec3::NAN;
    let mut depth = vec![0.0; n];
    let mut normal = vec![DVec3::Z; n];
    let tilt = |deg: f64| DVec3::new(deg.to_radians().sin(), 0.0, deg.to_radians().cos());
    for (i, d) in depth.iter_mut().enumerate().take(50) {
        *d = if i % 2 == 0 { 0.6 } else { -0.6 };
    }
    for v in normal.iter_mut().skip(50).take(20) {
        *v = tilt(4.0) * 2.5;
    }
    for v in normal.iter_mut().skip(70).take(5) {
        *v = tilt(30.0);
    }
    depth[0] = f64::NAN;
    normal[0] = DVec3::NAN;
    depth[99] = 1.0;
    normal[99] = DVec3::Z;
    // depths in mm, unit 2 mm: 0.3 voxel
    let e = surface_error(&depth, &normal, &truth, 2.0).unwrap();
    assert_eq!((e.depth.both, e.depth.only_test, e.depth.only_truth), (98, 1, 1));
    assert!((e.depth.mean - 49.0 * 0.3 / 98.0).abs() < 1e-12, "{:?}", e.depth);
    assert!((e.depth.max - 0.3).abs() < 1e-12 && (e.depth.p99 - 0.3).abs() < 1e-12);
    assert_eq!(e.normal.both, 98);
    assert!((e.normal.mean_deg - (20.0 * 4.0 + 5.0 * 30.0) / 98.0).abs() < 1e-9, "{:?}", e.normal);
    // the 99th percentile by nearest rank of 98 values: the 98th, the largest
    assert!((e.normal.p99_deg - 30.0).abs() < 1e-9 && (e.normal.max_deg - 30.0).abs() < 1e-9);
    // against itself: nothing
    let z = surface_error(&truth.depth, &truth.normal, &truth, 1.0).unwrap();
    assert_eq!((z.depth.max, z.normal.max_deg), (0.0, 0.0));
}

/// Pooled mean and worst view's p99 of the depth (voxels) and normal (°)
/// error of `settings` on `vol` against `a` over the standard views.
fn linear_errors(a: &AnalyticPhantom, vol: &shearwarp::Volume, settings: Settings, size: usize) -> [f64; 4] {
    let tf = presets::generic(a.shape.iso(), 200.0).tf;
    let mut r = Renderer::new(vol.clone(), &tf, settings).unwrap();
    r.set_iso(a.shape.iso()).unwrap();
    let model = ReferenceRenderer::new(vol);
    let unit = vol.spacing().iter().fold(f32::MAX, |x, &y| x.min(y)) as f64;
    let (mut dsum, mut dn, mut dp99, mut nsum, mut nn, mut np99) = (0.0, 0, 0f64, 0.0, 0, 0f64);
    for view in standard_views(NamedView::Anterior.rotation(), 0, 1) {
        let cam = Camera { rotation: view.rotation, zoom: None, size: [size, size] };
        let mut img = Image::new(size, size);
        r.render(&cam, &mut img).unwrap();
        let t = surface_truth(a, vol.spacing(), &cam, &Projection::Parallel, a.shape.iso() as f64, 1.0).unwrap();
        let e = surface_error(&fast_path_depth(&r, &cam).unwrap(), &fast_path_normals(&r, &cam, &model).unwrap(), &t, unit).unwrap();
        dsum += e.depth.mean * e.depth.both as f64;
        dn += e.depth.both;
        dp99 = dp99.max(e.depth.p99);
        nsum += e.normal.mean_deg * e.normal.both as f64;
        nn += e.normal.both;
        np99 = np99.max(e.normal.p99_deg);
    }
    [dsum / dn as f64, dp99, nsum / nn as f64, np99]
}

/// The linear reconstruction's error on the ball, isotropic and with slices
/// three times thicker, stays within ±20 % of what was measured for it at
/// 128² over the seven standard views: depth in voxels (mean, worst view's
/// p99), normal in degrees (mean, worst view's p99), with normal codes and
/// with the exact gradient.
#[test]
fn the_linear_ball_stays_within_measured_margins() {
    let base = Settings { method: Method::Binary, mode: Mode::Iso, threads: 2, ..Settings::default() };
    for (spacing, normals, measured) in [
        (None, Normals::Codes, [0.0579, 2.079, 0.300, 2.481]),
        (None, Normals::Gradient, [0.0579, 2.079, 0.0634, 2.293]),
        (Some([1.0, 1.0, 3.0]), Normals::Codes, [0.155, 3.501, 0.410, 4.771]),
        (Some([1.0, 1.0, 3.0]), Normals::Gradient, [0.155, 3.501, 0.208, 4.532]),
    ] {
        let a = analytic(Phantom::Sphere, [128; 3], spacing);
        let vol = Phantom::Sphere.build_sampled([128; 3], spacing).unwrap();
        let got = linear_errors(&a, &vol, Settings { normals, ..base }, 128);
        for i in 0..4 {
            assert!(
                got[i] >= 0.8 * measured[i] && got[i] <= 1.2 * measured[i],
                "ball {spacing:?} {normals:?}: {got:?}, measured {measured:?} (depth mean, p99 in voxels; normal mean, p99 in degrees)"
            );
        }
    }
}

fn shearwarp() -> Command {
    Command::cargo_bin("shearwarp").unwrap()
}

#[test]
fn phantom_spacing_on_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("thick.png");
    shearwarp()
        .args(["render", "--phantom", "ellipsoid", "--phantom-spacing", "0.6,0.6,5", "--iso", "100", "--size", "48", "-q", "-o"])
        .arg(&out)
        .assert()
        .success()
        .stderr(predicate::str::contains("212×212×26"));
    assert!(out.exists());
    shearwarp()
        .args(["info", "--phantom", "torus", "--phantom-spacing", "1,1,3"])
        .assert()
        .success()
        .stdout(predicate::str::contains("128 × 128 × 43").and(predicate::str::contains("1 × 1 × 3")));
    // a phantom without an analytic shape, a bad spacing, one too fine: usage errors naming them
    shearwarp()
        .args(["render", "--phantom", "head", "--phantom-spacing", "1,1,3", "-o"])
        .arg(&out)
        .assert()
        .code(2)
        .stderr(predicate::str::contains("--phantom-spacing").and(predicate::str::contains("head")));
    for bad in ["1,0,3", "1,1", "a,1,1", "1,1,inf"] {
        shearwarp().args(["render", "--phantom", "sphere", "--phantom-spacing", bad, "-o"]).arg(&out).assert().code(2);
    }
    shearwarp()
        .args(["rotate", "--phantom", "sphere", "--phantom-spacing", "0.001,0.001,0.001", "--degrees", "1"])
        .assert()
        .code(2)
        .stderr(predicate::str::contains("phantom spacing"));
}

/// `bench --suite surfaces --json` at `size` px, one frame a view, with `args`: its report.
fn suite_json(size: &str, args: &[&std::ffi::OsStr]) -> serde_json::Value {
    let out = shearwarp()
        .args(["bench", "--suite", "surfaces", "--size", size, "--reps", "1", "--rounds", "1", "--random-views", "0", "--json", "--quiet"])
        .args(args)
        .assert()
        .success();
    serde_json::from_slice(&out.get_output().stdout).unwrap()
}

#[test]
fn the_surfaces_suite_reports_depth_and_normal_error_per_case() {
    let json = suite_json("24", &["--only", "binary-c1-u64-bitscan", "--ref-step", "0.5"].map(std::ffi::OsStr::new));
    let table = json["table"].as_array().unwrap();
    assert_eq!(table.len(), 5);
    let cases: Vec<&str> = table.iter().map(|r| r["case"].as_str().unwrap()).collect();
    assert_eq!(cases, ["ball 128³", "ball 1×1×3", "marschner-lobb 41³", "marschner-lobb 1×1×3", "ellipsoid 0.6×0.6×5"]);
    let sp: Vec<f64> = table[4]["spacing"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert!((sp[0] - 0.6).abs() < 1e-6 && (sp[1] - 0.6).abs() < 1e-6 && sp[2] == 5.0, "{sp:?}");
    for r in table {
        assert_eq!(r["reconstruction"], "linear");
        for k in ["depth_mean", "depth_p99", "normal_deg_mean", "normal_deg_p99", "frame_ms"] {
            assert!(r[k].as_f64().is_some_and(|v| v >= 0.0), "{k}: {r}");
        }
    }
    for case in json["cases"].as_array().unwrap() {
        for s in case["summary"].as_array().unwrap() {
            assert_eq!(s["reconstruction"], "linear");
            assert!(
                s["depth_p99"].as_f64().is_some() && s["normal_deg_mean"].as_f64().is_some() && s["normal_deg_p99"].as_f64().is_some(),
                "{s}"
            );
        }
    }
    // the suite picks its volumes
    shearwarp()
        .args(["bench", "--suite", "surfaces", "--phantom-spacing", "1,1,1"])
        .assert()
        .code(2)
        .stderr(predicate::str::contains("--suite"));
}

/// `--suite surfaces --perspective` adds the perspective rows of its variants
/// (with depth and normal error against the perspective truth), and `--plot`
/// draws a panel per case against the error `--plot-error` names.
#[test]
fn the_surfaces_suite_measures_perspective_and_plots_either_error() {
    let dir = tempfile::tempdir().unwrap();
    let plot = dir.path().join("suite.svg");
    let mut args =
        ["--only", "binary-c1-u64-bitscan,binary-persp", "--perspective", "40", "--ref-step", "0.5", "--plot-error", "normal", "--plot"]
            .map(std::ffi::OsStr::new)
            .to_vec();
    args.push(plot.as_os_str());
    let json = suite_json("24", &args);
    let table = json["table"].as_array().unwrap();
    let persp: Vec<&serde_json::Value> = table.iter().filter(|r| r["variant"] == "binary-persp").collect();
    assert_eq!(persp.len(), 5, "{table:?}");
    for r in persp {
        assert!(r["normal_deg_mean"].as_f64().is_some() && r["depth_p99"].as_f64().is_some(), "{r}");
    }
    // one panel per case
    let svg = std::fs::read_to_string(&plot).unwrap();
    assert_eq!(svg.matches("frame time vs normal error").count(), 5, "{svg}");
    // by default the suite's perspective rows are its own variants'
    let json = suite_json("16", &["--perspective", "40", "--ref-step", "1"].map(std::ffi::OsStr::new));
    let mut variants: Vec<String> = json["table"].as_array().unwrap().iter().map(|r| r["variant"].as_str().unwrap().to_string()).collect();
    variants.sort();
    variants.dedup();
    assert_eq!(variants, ["binary-c1-u64-bitscan", "binary-persp", "rle", "rle-persp"]);
}

/// The 64³ ball, its volume and an iso renderer of it (gradient normals,
/// two threads) under `proj`.
fn ball_in(proj: Projection) -> (AnalyticPhantom, shearwarp::Volume, Renderer) {
    let a = analytic(Phantom::Sphere, [64; 3], None);
    let vol = Phantom::Sphere.build([64; 3]).unwrap();
    let tf = presets::generic(a.shape.iso(), 200.0).tf;
    let mut r =
        Renderer::new(vol.clone(), &tf, Settings { mode: Mode::Iso, normals: Normals::Gradient, threads: 2, ..Settings::default() })
            .unwrap();
    r.set_iso(a.shape.iso()).unwrap();
    r.set_projection(proj).unwrap();
    (a, vol, r)
}

/// The depth and normal error of `r`'s last frame (`cam` under `proj`) on
/// the ball `a` against its perspective truth.
fn ball_error(a: &AnalyticPhantom, vol: &shearwarp::Volume, r: &Renderer, cam: &Camera, proj: &Projection) -> SurfaceError {
    let t = surface_truth(a, vol.spacing(), cam, proj, a.shape.iso() as f64, shearwarp::render::NEAR_SLICES).unwrap();
    surface_error(&fast_path_depth(r, cam).unwrap(), &fast_path_normals(r, cam, &ReferenceRenderer::new(vol)).unwrap(), &t, 1.0).unwrap()
}

/// A perspective frame is measured against the perspective truth: the ball's
/// depth error stays small and its normals close.
#[test]
fn perspective_truth_matches_the_ball() {
    let proj = Projection::perspective(40.0, 1.5).unwrap();
    let (a, vol, mut r) = ball_in(proj);
    let cam = Camera { rotation: rotate_eye(NamedView::Anterior.rotation(), 1, 30.0), zoom: None, size: [96, 96] };
    r.render(&cam, &mut Image::new(96, 96)).unwrap();
    let e = ball_error(&a, &vol, &r, &cam, &proj);
    assert!(e.depth.both > 1000 && e.depth.only_test + e.depth.only_truth < 40, "{e:?}");
    assert!(e.depth.mean < 0.2 && e.depth.p99 < 3.0 && e.normal.mean_deg < 0.5 && e.normal.p99_deg < 6.0, "{e:?}");
}

/// A perspective frame split into pyramids (the eye near the volume) is
/// measured against the perspective truth as well, each pixel in the
/// pyramid that owns it, once the renderer keeps the pyramids' depths; without
/// them the depth is refused with a reason, not made up.
#[test]
fn a_split_perspective_frame_is_measured_against_the_truth() {
    let proj = Projection::perspective(60.0, 0.6).unwrap();
    let (a, vol, mut r) = ball_in(proj);
    let cam = Camera { rotation: rotate_eye(rotate_eye(NamedView::Anterior.rotation(), 0, 35.26), 1, 45.0), zoom: None, size: [96, 96] };
    let mut img = Image::new(96, 96);
    r.render(&cam, &mut img).unwrap();
    assert!(r.last_plans().len() > 1, "the frame was not split");
    let why = fast_path_depth(&r, &cam).unwrap_err().to_string();
    assert!(why.contains("set_keep_depths"), "{why}");
    r.set_keep_depths(true);
    // (into another image: a frame identical to the last one into the same image is skipped)
    r.render(&cam, &mut Image::new(96, 96)).unwrap();
    let e = ball_error(&a, &vol, &r, &cam, &proj);
    assert!(e.depth.both > 1000 && e.depth.only_test + e.depth.only_truth < 60, "{e:?}");
    // (measured: depth mean 0.04, p99 0.66 voxels; normal mean 0.11°, p99 1.6°)
    assert!(e.depth.mean < 0.1 && e.depth.p99 < 1.5 && e.normal.mean_deg < 0.3 && e.normal.p99_deg < 4.0, "{e:?}");
}

/// `render` reconstructs a thick-slice scan (slices at least 1.5× as far
/// apart as its pixels) by the cubic unless told otherwise, where the method
/// and mode render it; an isotropic scan, `rotate`, an explicit
/// `--reconstruction`, and the RLE path stay linear.
#[test]
fn render_takes_the_cubic_for_thick_slices() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("r.png");
    let recon = |args: &[&str]| -> String {
        let o = shearwarp().args(args).args(["--size", "48", "-q", "--json", "-o"]).arg(&out).output().unwrap();
        assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        j["reconstruction"].as_str().unwrap_or_else(|| panic!("{args:?}: no reconstruction in {j}")).to_string()
    };
    let thick = ["render", "--phantom", "ellipsoid", "--phantom-spacing", "0.6,0.6,5", "--iso", "100"];
    assert_eq!(recon(&thick), "cubic");
    assert_eq!(recon(&[&thick[..], &["--reconstruction", "linear"]].concat()), "linear");
    assert_eq!(recon(&[&thick[..], &["--method", "rle"]].concat()), "cubic");
    assert_eq!(recon(&[&thick[..], &["--method", "rle", "--deluxe", "P", "--mode", "blend"]].concat()), "cubic");
    assert_eq!(recon(&[&thick[..], &["--method", "rle", "--deluxe", "I"]].concat()), "linear");
    assert_eq!(recon(&[&thick[..], &["--method", "rle", "--grid", "bcc"]].concat()), "linear");
    assert_eq!(recon(&["render", "--phantom", "ellipsoid", "--phantom-spacing", "1,1,1.4", "--iso", "100"]), "linear");
    assert_eq!(recon(&["render", "--phantom", "sphere", "--iso", "100"]), "linear");
}
