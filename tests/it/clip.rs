//! Clipping planes ([`shearwarp::view::clip`]) on every path, against analytic truth.
//!
//! - The sphere phantom cut by a plane through its centre: every intermediate
//!   pixel whose ray meets the ball's support only in the removed half is
//!   background (blend and iso; binary, brute, RLE parallel and perspective),
//!   and the binary path's iso depth is the plane or the sphere, whichever the
//!   ray meets first on the kept side, within 0.5 voxel of the first kept
//!   slice (the plane quantized to slices, as the limits are).
//! - Accelerated equals brute force with the same planes, bit for bit, over
//!   random volumes, views and planes (binary vs brute parallel; RLE vs
//!   brute-RLE parallel and perspective).
//! - A plane keeping everything is the unclipped frame bit for bit; one
//!   keeping nothing is an empty frame.
//! - Zero / NaN normals are errors, in the library and on the command line.

use crate::common;

use std::sync::Arc;

use assert_cmd::Command;
use glam::{DMat3, DVec3, EulerRot};
use predicates::prelude::*;
use proptest::prelude::*;
use shearwarp::Volume;
use shearwarp::classify::TransferFunction;
use shearwarp::composite::Mode;
use shearwarp::data::phantom::{SPHERE_ISO, sphere, sphere_geometry};
use shearwarp::render::{Method, Renderer, Settings};
use shearwarp::view::clip::{ClipPlane, ClipPlanes, ClipRegion, Keep, Region};
use shearwarp::view::plan::FramePlan;
use shearwarp::view::plan::{Limiter, RayLimits};
use shearwarp::view::{Camera, Projection};
use shearwarp::warp::Image;

use common::shell_volume as volume;

fn tf() -> TransferFunction {
    TransferFunction::ramp(40.0, 180.0, 0.7, [0.9, 0.7, 0.5])
}

fn settings(method: Method, mode: Mode, ert: f32) -> Settings {
    Settings { method, mode, ert, threads: 2, ..Settings::default() }
}

/// A renderer with `planes` (none: no limiter) and its projection.
fn renderer(vol: &Volume, s: Settings, iso: f32, planes: Option<&[ClipPlane]>, persp: Option<(f64, f64)>) -> Renderer {
    let mut r = Renderer::new(vol.clone(), &tf(), s).unwrap();
    if s.mode == Mode::Iso {
        r.set_iso(iso).unwrap();
    }
    if let Some((fov, d)) = persp {
        r.set_projection(Projection::perspective(fov, d).unwrap()).unwrap();
    }
    if let Some(pl) = planes {
        r.set_limiter(Some(Arc::new(ClipPlanes::new(pl, vol.spacing()).unwrap())));
    }
    r
}

/// One frame: the final image and the intermediate image, or `None` for a
/// view the projection refuses (a perspective eye too near the volume).
#[allow(clippy::type_complexity)]
fn try_frame(
    vol: &Volume,
    s: Settings,
    rot: DMat3,
    planes: Option<&[ClipPlane]>,
    persp: Option<(f64, f64)>,
    size: usize,
) -> Option<(Image, Vec<[f32; 4]>)> {
    let mut r = renderer(vol, s, 90.0, planes, persp);
    let mut img = Image::new(size, size);
    r.render(&Camera::new(rot, [size, size]), &mut img).ok()?;
    Some((img, r.intermediate().rgba.clone()))
}

/// The voxel position of pixel `(p, q)`'s sample in slice `k`, as the traversals sample it.
fn sample(plan: &FramePlan, k: usize, p: usize, q: usize) -> DVec3 {
    let (ci, wi) = plan.cell_of(k, 0, p);
    let (cj, wj) = plan.cell_of(k, 1, q);
    let mut v = [0.0; 3];
    v[plan.view.perm[0]] = ci as f64 + wi as f64;
    v[plan.view.perm[1]] = cj as f64 + wj as f64;
    v[plan.view.perm[2]] = k as f64;
    DVec3::from_array(v)
}

/// 0°, 45° about y, the cube diagonal, and an oblique view.
fn views() -> Vec<DMat3> {
    vec![
        DMat3::IDENTITY,
        DMat3::from_rotation_y(45f64.to_radians()),
        DMat3::from_euler(EulerRot::XYZ, 35.264f64.to_radians(), 45f64.to_radians(), 0.0),
        DMat3::from_euler(EulerRot::XYZ, 0.4, -0.9, 0.2),
    ]
}

fn cut_normals() -> Vec<DVec3> {
    vec![DVec3::X, DVec3::new(0.6, -0.3, 0.74).normalize(), DVec3::new(-0.2, 0.9, -0.5).normalize()]
}

#[test]
fn clip_sphere_rays_in_the_removed_half_only_are_background() {
    let dims = [44, 44, 44];
    let vol = sphere(dims).unwrap();
    let (c, radius) = sphere_geometry(dims);
    let c = DVec3::from_array(c);
    // density is nonzero within R + 4 of the centre; a sample reads its
    // in-slice cell, √2 further at most
    let support = radius + 4.0 + 1.5;
    let cases: [(Method, Option<(f64, f64)>); 4] =
        [(Method::Binary, None), (Method::Brute, None), (Method::Rle, None), (Method::Rle, Some((40.0, 1.5)))];
    for n in cut_normals() {
        let planes = [ClipPlane::new(n.to_array(), 0.0).unwrap()];
        for rot in views() {
            for (method, persp) in cases {
                for mode in [Mode::Blend, Mode::Iso] {
                    let mut r = renderer(&vol, settings(method, mode, 0.99), SPHERE_ISO, Some(&planes), persp);
                    let mut img = Image::new(64, 64);
                    r.render(&Camera::new(rot, [64, 64]), &mut img).unwrap();
                    let plan = r.last_plan().unwrap();
                    let inter = r.intermediate();
                    let [w, h] = plan.grid.size;
                    let (mut removed, mut kept) = (0, 0);
                    for q in 0..h {
                        for p in 0..w {
                            let signed: Vec<(f64, f64)> =
                                plan.front_to_back().map(|k| sample(plan, k, p, q) - c).map(|x| (x.length(), x.dot(n))).collect();
                            let px = inter.get(p as isize, q as isize);
                            if signed.iter().all(|&(r, s)| r > support || s > 1e-3) {
                                assert_eq!(px, [0.0; 4], "{method:?} {persp:?} {mode:?} n {n} pixel ({p}, {q}) shows the removed half");
                                removed += 1;
                            } else if signed.iter().any(|&(r, s)| r < radius - 2.0 && s < -1e-3) {
                                assert!(px[3] > 0.0, "{method:?} {persp:?} {mode:?} n {n} pixel ({p}, {q}) misses the kept half");
                                kept += 1;
                            }
                        }
                    }
                    assert!(removed > 50 && kept > 50, "{removed} removed and {kept} kept pixels checked");
                }
            }
        }
    }
}

/// The slices `[ka, kb]`, within the given `(ka, kb)`, in which the ray
/// `x0 + k·dx` is inside the box `[lo, hi]`: the slab intersection (`ka > kb`:
/// never).
fn slab(x0: DVec3, dx: DVec3, lo: DVec3, hi: DVec3, (mut ka, mut kb): (f64, f64)) -> (f64, f64) {
    for a in 0..3 {
        if dx[a].abs() < 1e-12 {
            if x0[a] < lo[a] || x0[a] > hi[a] {
                return (1.0, 0.0);
            }
        } else {
            let (s, t) = ((lo[a] - x0[a]) / dx[a], (hi[a] - x0[a]) / dx[a]);
            ka = ka.max(s.min(t));
            kb = kb.min(s.max(t));
        }
    }
    (ka, kb)
}

/// The first hit, in (fractional) slices, of the ray `x0 + k·dx` walking
/// `ascending` (or not) on the ball of radius `radius` about `c`, over the
/// slices `[ka, kb]` the plane keeps; `None` for none.
fn first_hit(x0: DVec3, dx: DVec3, c: DVec3, radius: f64, ka: f64, kb: f64, ascending: bool) -> Option<f64> {
    // |x0 − c + k dx|² = R²
    let o = x0 - c;
    let (a, b, cc) = (dx.dot(dx), 2.0 * o.dot(dx), o.dot(o) - radius * radius);
    let disc = b * b - 4.0 * a * cc;
    if disc <= 0.0 {
        return None;
    }
    let (e0, e1) = ((-b - disc.sqrt()) / (2.0 * a), (-b + disc.sqrt()) / (2.0 * a));
    let (lo, hi) = (e0.max(ka), e1.min(kb));
    (lo <= hi).then_some(if ascending { lo } else { hi })
}

#[test]
fn clip_sphere_iso_depth_is_the_plane_or_the_sphere() {
    let dims = [44, 44, 44];
    let vol = sphere(dims).unwrap();
    let (c, radius) = sphere_geometry(dims);
    let c = DVec3::from_array(c);
    let mut plane_hits = 0;
    for n in cut_normals() {
        let planes = [ClipPlane::new(n.to_array(), 0.0).unwrap()];
        for rot in views() {
            let mut r = renderer(&vol, settings(Method::Binary, Mode::Iso, 0.99), SPHERE_ISO, Some(&planes), None);
            let mut img = Image::new(64, 64);
            r.render(&Camera::new(rot, [64, 64]), &mut img).unwrap();
            let plan = r.last_plan().unwrap();
            let inter = r.intermediate();
            let last = plan.slices() - 1;
            let [w, h] = plan.grid.size;
            let (mut checked, mut on_plane, mut worst, mut worst_exact) = (0, 0, 0f64, 0f64);
            for q in 0..h {
                for p in 0..w {
                    let x0 = sample(plan, 0, p, q);
                    let dx = sample(plan, 1, p, q) - x0;
                    // the plane n·(x − c) ≤ 0 along the ray: affine in k
                    let (g0, g1) = (n.dot(x0 - c), n.dot(dx));
                    let (ka, kb) = if g1.abs() < 1e-12 {
                        if g0 <= 0.0 { (0.0, last as f64) } else { (1.0, 0.0) }
                    } else if g1 > 0.0 {
                        (0.0, (-g0 / g1).min(last as f64))
                    } else {
                        ((-g0 / g1).max(0.0), last as f64)
                    };
                    // the rays well inside the ball, whose kept chord is more than
                    // two slices long (no grazing rays, no slivers)
                    let closest = (x0 - c).reject_from(dx).length();
                    let (Some(exact), Some(far)) = (
                        first_hit(x0, dx, c, radius, ka, kb, plan.view.ascending),
                        first_hit(x0, dx, c, radius, ka, kb, !plan.view.ascending),
                    ) else {
                        continue;
                    };
                    if closest > radius - 2.0 || (far - exact).abs() < 2.0 {
                        continue;
                    }
                    // the plane quantized to the first kept slice, as the limits are
                    // (a sample on the plane, to rounding, may go either way)
                    let quant = first_hit(x0, dx, c, radius, (ka - 1e-6).ceil(), (kb + 1e-6).floor(), plan.view.ascending).unwrap();
                    let d = inter.depth_at(p, q) as f64;
                    assert!(d.is_finite(), "n {n}: pixel ({p}, {q}) has no hit, want slice {exact:.2}");
                    let err = (d - quant).abs() * dx.length();
                    worst = worst.max(err);
                    worst_exact = worst_exact.max((d - exact).abs() * dx.length());
                    assert!(
                        err <= 0.5,
                        "n {n}: pixel ({p}, {q}) hits slice {d:.3}, want {quant:.3} (exact {exact:.3}): {err:.3} voxels off"
                    );
                    checked += 1;
                    let on = (exact - ka).abs() < 1e-9 || (exact - kb).abs() < 1e-9;
                    on_plane += on as usize;
                }
            }
            assert!(checked > 200, "{checked} pixels checked");
            plane_hits += on_plane;
            // the quantization to slices costs at most one slice step more
            assert!(worst_exact <= 0.5 + 3f64.sqrt(), "n {n}: worst {worst_exact} voxels from the exact surface");
            eprintln!(
                "n {n}: {checked} pixels ({on_plane} on the plane), worst {worst:.3} voxels, {worst_exact:.3} from the unquantized plane"
            );
        }
    }
    assert!(plane_hits > 1000, "only {plane_hits} hits on the plane checked");
}

fn cases(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases(24)))]

    /// Accelerated paths equal their brute-force references, bit for bit, under
    /// the same clip planes (perspective from 0.05 diagonals on: the eye inside,
    /// the pyramid split, each pyramid's plan limited by the planes).
    #[test]
    fn clip_accelerated_equals_brute_force(
        nx in 6usize..20, ny in 6usize..20, nz in 6usize..20, seed in any::<u64>(),
        rx in -3.2f64..3.2, ry in -3.2f64..3.2, rz in -3.2f64..3.2, blend in any::<bool>(),
        planes in prop::collection::vec(((-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0), -6.0f64..6.0), 1..4),
        fov in 20.0f64..70.0, dist in 0.05f64..3.0,
    ) {
        let planes: Vec<ClipPlane> = planes.into_iter().filter_map(|((a, b, c), d)| ClipPlane::new([a, b, c], d).ok()).collect();
        prop_assume!(!planes.is_empty());
        let vol = volume([nx, ny, nz], seed);
        let rot = DMat3::from_euler(EulerRot::XYZ, rx, ry, rz);
        let mode = if blend { Mode::Blend } else { Mode::Iso };
        let fast = try_frame(&vol, settings(Method::Binary, mode, 0.95), rot, Some(&planes), None, 40).unwrap();
        let brute = try_frame(&vol, settings(Method::Brute, mode, 0.95), rot, Some(&planes), None, 40).unwrap();
        prop_assert!(fast == brute, "binary vs brute");
        for persp in [None, Some((fov, dist))] {
            let rle = try_frame(&vol, settings(Method::Rle, mode, 1.0), rot, Some(&planes), persp, 40);
            let brute_rle = try_frame(&vol, settings(Method::BruteRle, mode, 1.0), rot, Some(&planes), persp, 40);
            prop_assert!(rle.is_some() || persp.is_some(), "a parallel view failed");
            prop_assert!(rle == brute_rle, "rle vs brute-rle {:?}", persp);
        }
    }
}

/// Every method in parallel projection, and the RLE paths in perspective
/// (`(fov, eye distance)`): the cases of the keep-all / keep-nothing tests.
const EVERY_PATH: [(Method, Option<(f64, f64)>); 6] = [
    (Method::Binary, None),
    (Method::Brute, None),
    (Method::Rle, None),
    (Method::BruteRle, None),
    (Method::Rle, Some((40.0, 1.5))),
    (Method::BruteRle, Some((40.0, 1.5))),
];

#[test]
fn clip_keeping_everything_changes_nothing_and_keeping_nothing_leaves_nothing() {
    let vol = volume([19, 21, 17], 4);
    let all = [ClipPlane::new([0.3, -0.8, 0.5], 1e6).unwrap(), ClipPlane::new([0.0, 0.0, 1.0], 1e3).unwrap()];
    let none = [ClipPlane::new([0.0, 0.0, 1.0], 1e3).unwrap(), ClipPlane::new([-0.7, 0.1, 0.2], -1e3).unwrap()];
    for rot in views() {
        for (method, persp) in EVERY_PATH {
            for mode in [Mode::Iso, Mode::Blend] {
                let s = settings(method, mode, 0.95);
                let open = try_frame(&vol, s, rot, None, persp, 48).unwrap();
                assert!(open.0.coverage() > 0.05);
                assert_eq!(try_frame(&vol, s, rot, Some(&all), persp, 48).unwrap(), open, "{method:?} {persp:?} {mode:?}");
                let (img, inter) = try_frame(&vol, s, rot, Some(&none), persp, 48).unwrap();
                assert!(img.data.iter().all(|p| *p == [0.0; 4]), "{method:?} {persp:?} {mode:?}: clipped away, yet visible");
                assert!(inter.iter().all(|p| *p == [0.0; 4]));
            }
        }
    }
}

#[test]
fn clip_zero_or_nan_normals_are_errors() {
    for n in [[0.0; 3], [f64::NAN, 0.0, 1.0], [1.0, f64::INFINITY, 0.0]] {
        let e = ClipPlane::new(n, 0.0).unwrap_err().to_string();
        assert!(e.contains("normal"), "{e}");
    }
    assert!(ClipPlanes::new(&[ClipPlane { normal: [0.0; 3], offset: 1.0 }], [1.0; 3]).is_err());
}

#[test]
fn clip_cli_renders_and_rejects_bad_planes_with_exit_code_2() {
    let dir = tempfile::tempdir().unwrap();
    let sw = || Command::cargo_bin("shearwarp").unwrap();
    let base = ["render", "--phantom", "sphere", "--phantom-dims", "40,40,40", "--size", "64", "--json"];
    let out = dir.path().join("whole.png");
    let whole = sw().args(base).arg("-o").arg(&out).output().unwrap();
    assert!(whole.status.success());
    let cov = |o: &std::process::Output| -> f64 {
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        j["coverage"].as_f64().unwrap()
    };
    // half the sphere (seen from the front: x is across the image) covers about
    // half the pixels: the plane x = 19.5 in voxel indices is the centre of 40³
    let half = sw().args(base).args(["--clip-plane", "1,0,0,19.5", "-o"]).arg(dir.path().join("half.png")).output().unwrap();
    assert!(half.status.success(), "{}", String::from_utf8_lossy(&half.stderr));
    let ratio = cov(&half) / cov(&whole);
    assert!((0.4..0.6).contains(&ratio), "half the sphere covers {ratio} of the whole");
    // repeatable: two opposite half-spaces keep a slab
    let slab = sw()
        .args(base)
        .args(["--clip-plane", "1,0,0,22.5", "--clip-plane", "-1,0,0,-16.5", "-o"])
        .arg(dir.path().join("slab.png"))
        .output()
        .unwrap();
    assert!(slab.status.success() && cov(&slab) < 0.3 * cov(&whole));
    // voxel coordinates: the plane x = 19.5 and its mirror keep complementary halves
    // (each about half), and the plane x = 0 (the volume's first voxel column) keeps almost nothing
    let other = sw().args(base).args(["--clip-plane", "-1,0,0,-19.5", "-o"]).arg(dir.path().join("other.png")).output().unwrap();
    let r2 = cov(&other) / cov(&whole);
    assert!((0.4..0.6).contains(&r2) && (ratio + r2 - 1.0).abs() < 0.1, "complementary halves cover {ratio} and {r2}");
    let edge = sw().args(base).args(["--clip-plane", "1,0,0,0", "-o"]).arg(dir.path().join("edge.png")).output().unwrap();
    assert!(edge.status.success() && cov(&edge) < 0.02 * cov(&whole), "the plane x = 0 keeps {}", cov(&edge) / cov(&whole));
    for bad in ["0,0,0,1", "nan,0,1,0", "1,0,0", "1,0,0,x", "1,0,0,inf"] {
        sw().args(base)
            .args(["--clip-plane", bad, "-o"])
            .arg(dir.path().join("bad.png"))
            .assert()
            .code(2)
            .stderr(predicate::str::contains("clip-plane"));
    }
    let seven: Vec<&str> = (0..7).flat_map(|_| ["--clip-plane", "1,0,0,0"]).collect();
    sw().args(base).args(&seven).arg("-o").arg(dir.path().join("bad.png")).assert().code(2).stderr(predicate::str::contains("at most 6"));
    // rotate takes it too
    sw().args([
        "rotate",
        "--phantom",
        "sphere",
        "--phantom-dims",
        "32,32,32",
        "--size",
        "32",
        "--degrees",
        "4",
        "--step-deg",
        "2",
        "--clip-plane",
        "0,1,0,0",
        "--json",
    ])
    .assert()
    .success();
}

/// In blend mode the two halves of a plane-clipped volume composite to the
/// unclipped image: per intermediate pixel, the half toward the
/// viewer "over" the other equals the whole volume's composite (early
/// termination off: it would stop the whole ray before the far half), in
/// both projections, on the RLE path and the binary rotator's blend, over
/// random planes and views.
#[test]
fn clip_halves_composite_to_the_unclipped_image() {
    let vol = volume([30, 26, 22], 5);
    let mut rnd = common::uniform(77);
    let mut checked = 0;
    for case in 0..12 {
        let rot = DMat3::from_euler(EulerRot::XYZ, rnd() * 7.0, rnd() * 7.0, rnd() * 7.0);
        let n = [rnd() - 0.5, rnd() - 0.5, rnd() - 0.5];
        let d = (rnd() - 0.5) * 6.0 + 0.37;
        let persp = if case % 2 == 0 { None } else { Some((30.0, 2.5)) };
        for method in [Method::Rle, Method::Binary] {
            let s = settings(method, Mode::Blend, 1.0);
            let front = [ClipPlane::new(n, d).unwrap()];
            let back = [ClipPlane::new(n.map(|x| -x), -d).unwrap()];
            let frames: Vec<Option<(Renderer, Image)>> = [None, Some(&front[..]), Some(&back[..])]
                .into_iter()
                .map(|pl| {
                    let mut r = renderer(&vol, s, 90.0, pl, persp);
                    let mut img = Image::new(48, 48);
                    r.render(&Camera::new(rot, [48, 48]), &mut img).ok().map(|_| (r, img))
                })
                .collect();
            let [Some((whole, _)), Some((a, _)), Some((b, _))] = &frames[..] else {
                // a path that does not render this projection (yet) refuses all three
                assert!(frames.iter().all(|f| f.is_none()), "case {case} {method:?}: some frames rendered, some did not");
                continue;
            };
            let (iw, ia, ib) = (whole.intermediate(), a.intermediate(), b.intermediate());
            assert_eq!(iw.size, ia.size);
            let px = |i: &shearwarp::composite::Intermediate, p: usize, q: usize| -> [f32; 4] {
                match i.valid {
                    Some(r) if (r.p0..=r.p1).contains(&p) && (r.q0..=r.q1).contains(&q) => i.rgba[q * i.size[0] + p],
                    _ => [0.0; 4],
                }
            };
            // which half is toward the viewer: compare each order, keep the better
            let mut worst = [0f32; 2];
            for q in 0..iw.size[1] {
                for p in 0..iw.size[0] {
                    let (w, x, y) = (px(iw, p, q), px(ia, p, q), px(ib, p, q));
                    for (o, (f, g)) in [(x, y), (y, x)].into_iter().enumerate() {
                        let t = 1.0 - f[3];
                        let e = (0..4).map(|c| (f[c] + t * g[c] - w[c]).abs()).fold(0.0, f32::max);
                        worst[o] = worst[o].max(e);
                    }
                }
            }
            let err = worst[0].min(worst[1]);
            assert!(iw.rgba.iter().any(|c| c[3] > 0.1), "case {case}: nothing composited");
            assert!(err < 1e-5, "case {case} {method:?} {persp:?}: halves differ from the whole by {err} (orders {worst:?})");
            checked += 1;
        }
    }
    assert!(checked >= 12, "only {checked} cases rendered");
}

/// A convex clip box on the sphere phantom (`--clip-box`, keep inside): the
/// binary path's iso depth is the analytic CSG depth of sphere ∩ box — the
/// first point of the ray inside both — within 0.5 voxel of the box quantized
/// to the first kept slice (as the limits are), and within one slice step
/// more of the exact box face; rays that miss sphere ∩ box are background.
#[test]
fn clip_box_on_the_sphere_is_the_analytic_csg_depth() {
    let dims = [44, 44, 44];
    let vol = sphere(dims).unwrap();
    let (c, radius) = sphere_geometry(dims);
    let c = DVec3::from_array(c);
    // a box over one corner of the ball: three faces cut it
    let (lo, hi) = (c - DVec3::new(25.0, 6.0, 25.0), c + DVec3::new(5.5, 25.0, 4.0));
    let region = ClipRegion::new(Region::Box { lo: lo.to_array(), hi: hi.to_array() }, vol.spacing()).unwrap();
    let (mut face_hits, mut missed) = (0, 0);
    for rot in views() {
        let mut r = renderer(&vol, settings(Method::Binary, Mode::Iso, 0.99), SPHERE_ISO, None, None);
        r.set_limiter(Some(Arc::new(region.clone())));
        let mut img = Image::new(64, 64);
        r.render(&Camera::new(rot, [64, 64]), &mut img).unwrap();
        let plan = r.last_plan().unwrap();
        let inter = r.intermediate();
        let last = plan.slices() - 1;
        let [w, h] = plan.grid.size;
        let mut checked = 0;
        for q in 0..h {
            for p in 0..w {
                let x0 = sample(plan, 0, p, q);
                let dx = sample(plan, 1, p, q) - x0;
                // the box along the ray: the slab intersection, in slices
                let (ka, kb) = slab(x0, dx, lo, hi, (0.0, last as f64));
                let d = inter.depth_at(p, q) as f64;
                let (Some(exact), Some(far)) =
                    (first_hit(x0, dx, c, radius, ka, kb, plan.view.ascending), first_hit(x0, dx, c, radius, ka, kb, !plan.view.ascending))
                else {
                    // no point of the ray inside both, by a margin: background
                    if ka > kb + 1.0 || first_hit(x0, dx, c, radius + 2.0, ka - 1.0, kb + 1.0, true).is_none() {
                        assert!(!d.is_finite(), "pixel ({p}, {q}) hits slice {d} outside sphere ∩ box");
                        missed += 1;
                    }
                    continue;
                };
                // well inside: no grazing rays, no slivers of the box
                let closest = (x0 - c).reject_from(dx).length();
                if closest > radius - 2.0 || (far - exact).abs() < 2.0 {
                    continue;
                }
                let quant = first_hit(x0, dx, c, radius, (ka - 1e-6).ceil(), (kb + 1e-6).floor(), plan.view.ascending).unwrap();
                assert!(d.is_finite(), "pixel ({p}, {q}) has no hit, want slice {exact:.2}");
                let err = (d - quant).abs() * dx.length();
                assert!(err <= 0.5, "pixel ({p}, {q}) hits slice {d:.3}, want {quant:.3} (exact {exact:.3}): {err:.3} voxels off");
                assert!((d - exact).abs() * dx.length() <= 0.5 + 3f64.sqrt(), "pixel ({p}, {q}): {d:.3} vs the exact {exact:.3}");
                checked += 1;
                face_hits += ((exact - ka).abs() < 1e-9 || (exact - kb).abs() < 1e-9) as usize;
            }
        }
        assert!(checked > 100, "{checked} pixels checked");
    }
    assert!(face_hits > 200 && missed > 200, "{face_hits} hits on the box faces, {missed} background pixels checked");
}

/// The convex clip regions on the command line: a box and a sphere render
/// (and a box keeping everything is the unclipped frame), inside and
/// outside; bad regions are usage errors naming the problem.
#[test]
fn clip_box_and_sphere_on_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = |n: &str| dir.path().join(n);
    let run = |extra: &[&str], name: &str| {
        let mut args = vec!["render", "--phantom", "sphere", "--phantom-dims", "32,32,32", "--size", "64", "--quiet", "-o"];
        let o = out(name);
        args.push(o.to_str().unwrap());
        args.extend_from_slice(extra);
        Command::cargo_bin("shearwarp").unwrap().args(&args).assert()
    };
    run(&[], "plain.png").success();
    run(&["--clip-box", "-5,-5,-5,40,40,40"], "all.png").success();
    run(&["--clip-box", "0,0,0,15.5,31,31"], "half.png").success();
    run(&["--clip-sphere", "16,16,16,9"], "ball.png").success();
    let px = |n: &str| image::open(out(n)).unwrap().to_rgb8().into_raw();
    assert_eq!(px("plain.png"), px("all.png"));
    assert_ne!(px("plain.png"), px("half.png"));
    assert_ne!(px("plain.png"), px("ball.png"));
    // the outside kept: the box over the half x ≤ 15.5 cut out is the other half;
    // a box over everything cut out leaves nothing, one missing the volume changes nothing
    run(&["--clip-box", "0,0,0,15.5,31,31", "--clip-keep", "outside"], "out_half.png").success();
    run(&["--clip-box", "-5,-5,-5,40,40,40", "--clip-keep", "outside"], "out_all.png").success();
    run(&["--clip-box", "40,40,40,50,50,50", "--clip-keep", "outside"], "out_none.png").success();
    // (a ball at the left edge: one inside the sphere phantom's shell would not show)
    run(&["--clip-sphere", "0,16,16,14", "--clip-keep", "outside"], "out_ball.png").success();
    assert_ne!(px("plain.png"), px("out_half.png"));
    assert_ne!(px("half.png"), px("out_half.png"));
    assert!(px("out_all.png").iter().all(|&c| c == 0), "a box over everything cut out leaves something");
    assert_eq!(px("plain.png"), px("out_none.png"));
    assert_ne!(px("plain.png"), px("out_ball.png"));
    run(&["--clip-box", "5,0,0,1,31,31"], "x.png").failure().code(2).stderr(predicate::str::contains("below its second"));
    run(&["--clip-sphere", "1,2,3,-4"], "x.png").failure().code(2).stderr(predicate::str::contains("radius"));
    run(&["--clip-sphere", "1,2,nan,4"], "x.png").failure().code(2);
    run(&["--clip-box", "0,0,0,1,1,1", "--clip-sphere", "1,2,3,4"], "x.png").failure().code(2).stderr(predicate::str::contains("one of"));
}

/// One frame with `limiter` (none: no limiter): the final image and the
/// intermediate image, or `None` for a view the projection refuses.
fn try_frame_with(
    vol: &Volume,
    s: Settings,
    rot: DMat3,
    limiter: Option<Arc<dyn Limiter>>,
    persp: Option<(f64, f64)>,
    size: usize,
) -> Option<(Image, Vec<[f32; 4]>)> {
    let mut r = renderer(vol, s, 90.0, None, persp);
    r.set_limiter(limiter);
    let mut img = Image::new(size, size);
    r.render(&Camera::new(rot, [size, size]), &mut img).ok()?;
    Some((img, r.intermediate().rgba.clone()))
}

/// The limits of `limiter` on `plan`, normalized as the plan holds them.
fn limits_of(plan: &FramePlan, limiter: &dyn Limiter) -> RayLimits {
    let mut l = RayLimits::open(plan.grid.size, plan.slices());
    limiter.limit(plan, &mut l);
    l.normalize();
    l
}

/// An outside region keeps exactly the slices its inside version does not
/// (its limits are the complement within each ray's `[k0, k1]`), every hole
/// strictly inside its interval, on the renderer's own plans (parallel and
/// perspective); chained after a plane, the complement within the plane's
/// interval.
#[test]
fn clip_outside_limits_are_the_complement_of_the_inside() {
    let vol = volume([30, 26, 22], 3);
    let regions = [
        Region::Box { lo: [8.0, 6.5, 4.0], hi: [20.0, 18.0, 15.5] },
        Region::Sphere { centre: [14.0, 12.0, 11.0], radius: 7.5 },
        Region::Box { lo: [-3.0, 10.0, -3.0], hi: [40.0, 14.0, 40.0] },
    ];
    let plane = ClipPlanes::new(&[ClipPlane::new([0.4, 0.1, -0.7], 2.0).unwrap()], vol.spacing()).unwrap();
    let mut holes = 0;
    for rot in views() {
        for persp in [None, Some((40.0, 1.5))] {
            let mut r = renderer(&vol, settings(Method::Rle, Mode::Blend, 1.0), 90.0, None, persp);
            let mut img = Image::new(48, 48);
            r.render(&Camera::new(rot, [48, 48]), &mut img).unwrap();
            let plan = r.last_plan().unwrap().clone();
            for region in regions {
                let inside = ClipRegion::new(region, vol.spacing()).unwrap();
                let outside = inside.clone().keeping(Keep::Outside);
                let chained = shearwarp::view::clip::Limiters::new(vec![Arc::new(plane.clone()), Arc::new(outside.clone())]).unwrap();
                let (li, lo, lp, lc) =
                    (limits_of(&plan, &inside), limits_of(&plan, &outside), limits_of(&plan, &plane), limits_of(&plan, &chained));
                holes += lo.has_holes() as usize;
                let [w, h] = plan.grid.size;
                for q in 0..h {
                    for p in 0..w {
                        let ([a, b], [h0, h1]) = (lo.get(p, q), lo.hole(p, q));
                        assert!(h0 > h1 || (a < h0 && h1 < b), "{region:?} ({p}, {q}): hole {h0}..{h1} in {a}..{b}");
                        for k in 0..plan.slices() {
                            assert_eq!(lo.keeps(p, q, k), !li.keeps(p, q, k), "{region:?} {persp:?} ({p}, {q}) slice {k}");
                            assert_eq!(lc.keeps(p, q, k), lp.keeps(p, q, k) && !li.keeps(p, q, k), "chained ({p}, {q}) slice {k}");
                        }
                    }
                }
            }
        }
    }
    assert!(holes >= 16, "only {holes} frames with holes");
}

/// Cutting out a box over the whole volume leaves an empty frame; cutting out
/// one that misses it is the plain frame bit for bit (every path, both
/// projections, iso and blend).
#[test]
fn clip_outside_everything_leaves_nothing_and_outside_nothing_changes_nothing() {
    let vol = volume([19, 21, 17], 4);
    let sp = vol.spacing();
    let all: Arc<dyn Limiter> = Arc::new(ClipRegion::new(Region::Box { lo: [-2.0; 3], hi: [30.0; 3] }, sp).unwrap().keeping(Keep::Outside));
    let none: Arc<dyn Limiter> =
        Arc::new(ClipRegion::new(Region::Box { lo: [25.0; 3], hi: [30.0; 3] }, sp).unwrap().keeping(Keep::Outside));
    for rot in views() {
        for (method, persp) in EVERY_PATH {
            for mode in [Mode::Iso, Mode::Blend] {
                let s = settings(method, mode, 0.95);
                let open = try_frame_with(&vol, s, rot, None, persp, 48).unwrap();
                assert!(open.0.coverage() > 0.05);
                assert_eq!(try_frame_with(&vol, s, rot, Some(none.clone()), persp, 48).unwrap(), open, "{method:?} {persp:?} {mode:?}");
                let (img, inter) = try_frame_with(&vol, s, rot, Some(all.clone()), persp, 48).unwrap();
                assert!(img.data.iter().all(|p| *p == [0.0; 4]), "{method:?} {persp:?} {mode:?}: cut out, yet visible");
                assert!(inter.iter().all(|p| *p == [0.0; 4]));
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases(24)))]

    /// Accelerated paths equal their brute-force references, bit for bit,
    /// with a region whose outside is kept (a hole in the rays), alone or
    /// after a plane (ERT off; binary vs brute and RLE vs brute-RLE, both
    /// projections; with Deluxe I's midpoints on some cases).
    #[test]
    fn clip_outside_accelerated_equals_brute_force(
        nx in 6usize..20, ny in 6usize..20, nz in 6usize..20, seed in any::<u64>(),
        rx in -3.2f64..3.2, ry in -3.2f64..3.2, rz in -3.2f64..3.2, blend in any::<bool>(),
        c in (0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0), e in (0.1f64..0.6, 0.1f64..0.6, 0.1f64..0.6),
        ball in any::<bool>(), with_plane in any::<bool>(), half in any::<bool>(),
        fov in 20.0f64..70.0, dist in 0.05f64..3.0,
    ) {
        let vol = volume([nx, ny, nz], seed);
        let n = [nx, ny, nz].map(|x| x as f64);
        let centre = [c.0 * n[0], c.1 * n[1], c.2 * n[2]];
        let region = if ball {
            Region::Sphere { centre, radius: e.0 * n[0].min(n[1]).min(n[2]) }
        } else {
            let e = [e.0 * n[0], e.1 * n[1], e.2 * n[2]];
            Region::Box { lo: [0, 1, 2].map(|a| centre[a] - e[a]), hi: [0, 1, 2].map(|a| centre[a] + e[a]) }
        };
        let out: Arc<dyn Limiter> = Arc::new(ClipRegion::new(region, vol.spacing()).unwrap().keeping(Keep::Outside));
        let limiter: Arc<dyn Limiter> = if with_plane {
            let plane = ClipPlanes::new(&[ClipPlane::new([0.3, -0.6, 0.2], 0.5).unwrap()], vol.spacing()).unwrap();
            Arc::new(shearwarp::view::clip::Limiters::new(vec![Arc::new(plane), out]).unwrap())
        } else {
            out
        };
        let rot = DMat3::from_euler(EulerRot::XYZ, rx, ry, rz);
        let mode = if blend { Mode::Blend } else { Mode::Iso };
        let s = |method| {
            let mut s = settings(method, mode, 1.0);
            s.deluxe.intermediate = half;
            s
        };
        for persp in [None, Some((fov, dist))] {
            let fast = try_frame_with(&vol, s(Method::Binary), rot, Some(limiter.clone()), persp, 40);
            let brute = try_frame_with(&vol, s(Method::Brute), rot, Some(limiter.clone()), persp, 40);
            prop_assert!(fast.is_some() || persp.is_some(), "a parallel view failed");
            prop_assert!(fast == brute, "binary vs brute {:?}", persp);
            let rle = try_frame_with(&vol, s(Method::Rle), rot, Some(limiter.clone()), persp, 40);
            let brute_rle = try_frame_with(&vol, s(Method::BruteRle), rot, Some(limiter.clone()), persp, 40);
            prop_assert!(rle.is_some() || persp.is_some(), "a parallel view failed");
            prop_assert!(rle == brute_rle, "rle vs brute-rle {:?}", persp);
        }
    }
}

/// The first hit (fractional slices) of ray `x0 + k·dx` on the ball, walking
/// `ascending` (or not), over the kept pieces `pieces` (slice intervals, in
/// index order), front piece first.
fn first_hit_in(x0: DVec3, dx: DVec3, c: DVec3, radius: f64, pieces: &[[f64; 2]], ascending: bool) -> Option<(f64, [f64; 2])> {
    let mut order: Vec<[f64; 2]> = pieces.iter().copied().filter(|[a, b]| a <= b).collect();
    if !ascending {
        order.reverse();
    }
    order.into_iter().find_map(|[a, b]| first_hit(x0, dx, c, radius, a, b, ascending).map(|k| (k, [a, b])))
}

/// A box cut *out* of the sphere phantom (`--clip-box --clip-keep outside`):
/// the binary path's iso depth is the analytic CSG depth of sphere minus box
/// — the first point of the ray in the ball and not in the box — within 0.5
/// voxel of the box quantized to the slices its samples fall in (as the
/// limits are), and within one slice step more of the exact box face; rays
/// whose chord through the ball lies inside the box are background. The
/// mirror of `clip_box_on_the_sphere_is_the_analytic_csg_depth`.
#[test]
fn clip_box_cut_out_of_the_sphere_is_the_analytic_csg_depth() {
    let dims = [44, 44, 44];
    let vol = sphere(dims).unwrap();
    let (c, radius) = sphere_geometry(dims);
    let c = DVec3::from_array(c);
    // the same box over one corner of the ball, cut out
    let (lo, hi) = (c - DVec3::new(25.0, 6.0, 25.0), c + DVec3::new(5.5, 25.0, 4.0));
    let region = ClipRegion::new(Region::Box { lo: lo.to_array(), hi: hi.to_array() }, vol.spacing()).unwrap().keeping(Keep::Outside);
    let (mut face_hits, mut missed, mut total) = (0, 0, 0);
    for rot in views() {
        for method in [Method::Binary, Method::Brute] {
            let mut r = renderer(&vol, settings(method, Mode::Iso, 0.99), SPHERE_ISO, None, None);
            r.set_limiter(Some(Arc::new(region.clone())));
            let mut img = Image::new(64, 64);
            r.render(&Camera::new(rot, [64, 64]), &mut img).unwrap();
            let plan = r.last_plan().unwrap();
            let inter = r.intermediate();
            let last = plan.slices() as f64 - 1.0;
            let asc = plan.view.ascending;
            let [w, h] = plan.grid.size;
            let mut checked = 0;
            for q in 0..h {
                for p in 0..w {
                    let x0 = sample(plan, 0, p, q);
                    let dx = sample(plan, 1, p, q) - x0;
                    // the box along the ray: the slab intersection, in slices
                    let (ka, kb) = slab(x0, dx, lo, hi, (f64::NEG_INFINITY, f64::INFINITY));
                    let d = inter.depth_at(p, q) as f64;
                    // the kept pieces: exact, and quantized to the slices whose samples leave the box
                    let (exact_pieces, quant_pieces) = if ka > kb {
                        (vec![[0.0, last]], vec![[0.0, last]])
                    } else {
                        let (qa, qb) = ((ka - 1e-6).ceil(), (kb + 1e-6).floor());
                        (vec![[0.0, ka.min(last)], [kb.max(0.0), last]], vec![[0.0, (qa - 1.0).min(last)], [(qb + 1.0).max(0.0), last]])
                    };
                    let Some((exact, piece)) = first_hit_in(x0, dx, c, radius, &exact_pieces, asc) else {
                        // no point of the ray in the ball outside the box, by a margin: background
                        let in_box = |k: f64| ka + 1.0 < k && k < kb - 1.0;
                        let chord =
                            first_hit(x0, dx, c, radius + 2.0, 0.0, last, true).zip(first_hit(x0, dx, c, radius + 2.0, 0.0, last, false));
                        if chord.is_none_or(|(a, b)| in_box(a) && in_box(b)) {
                            assert!(!d.is_finite(), "{method:?} pixel ({p}, {q}) hits slice {d} outside sphere − box");
                            missed += 1;
                        }
                        continue;
                    };
                    // well inside: no grazing rays, no slivers of the kept pieces
                    let far = first_hit(x0, dx, c, radius, piece[0], piece[1], !asc).unwrap();
                    let closest = (x0 - c).reject_from(dx).length();
                    if closest > radius - 2.0 || (far - exact).abs() < 2.0 {
                        continue;
                    }
                    let Some((quant, _)) = first_hit_in(x0, dx, c, radius, &quant_pieces, asc) else { continue };
                    assert!(d.is_finite(), "{method:?} pixel ({p}, {q}) has no hit, want slice {exact:.2}");
                    let err = (d - quant).abs() * dx.length();
                    assert!(
                        err <= 0.5,
                        "{method:?} pixel ({p}, {q}) hits slice {d:.3}, want {quant:.3} (exact {exact:.3}): {err:.3} voxels off"
                    );
                    assert!((d - exact).abs() * dx.length() <= 0.5 + 3f64.sqrt(), "pixel ({p}, {q}): {d:.3} vs the exact {exact:.3}");
                    checked += 1;
                    face_hits += ((exact - ka).abs() < 1e-9 || (exact - kb).abs() < 1e-9) as usize;
                }
            }
            assert!(checked > 100, "{checked} pixels checked");
            total += checked;
        }
    }
    eprintln!("{total} pixels checked, {face_hits} on the box faces, {missed} background");
    assert!(face_hits > 200 && missed > 50, "{face_hits} hits on the box faces, {missed} background pixels checked");
}

/// The convex mesh of a region: a cuboid for a box, a fine UV sphere for a ball.
fn mesh_of(region: Region) -> shearwarp::geometry::ConvexMesh {
    use shearwarp::geometry::{ConvexMesh, Mesh};
    let m = match region {
        Region::Box { lo, hi } => Mesh::cuboid(DVec3::from_array(lo), DVec3::from_array(hi)).unwrap(),
        Region::Sphere { centre, radius } => Mesh::sphere(DVec3::from_array(centre), radius, 96).unwrap(),
    };
    ConvexMesh::new(&m).unwrap()
}

/// Whether pixel `(p, q)` is within `r` pixels of the silhouette of the
/// region whose inside limits are `li`: its interval is at most two slices
/// long, or some pixel within `r` is empty where it is not (or the reverse).
fn near_silhouette(li: &RayLimits, grid: [usize; 2], p: usize, q: usize, r: i64) -> bool {
    let len = |p: usize, q: usize| {
        let [a, b] = li.get(p, q);
        if a > b { 0 } else { b - a + 1 }
    };
    let n = len(p, q);
    if (1..=2).contains(&n) {
        return true;
    }
    (-r..=r).any(|dq| {
        (-r..=r).any(|dp| {
            let (x, y) = (p as i64 + dp, q as i64 + dq);
            x >= 0 && y >= 0 && x < grid[0] as i64 && y < grid[1] as i64 && (len(x as usize, y as usize) == 0) != (n == 0)
        })
    })
}

/// The regions the mesh tests clip the sphere phantom (44³) with.
fn mesh_regions(c: DVec3) -> [Region; 3] {
    [
        Region::Box { lo: (c - DVec3::new(25.0, 6.0, 25.0)).to_array(), hi: (c + DVec3::new(5.5, 25.0, 4.0)).to_array() },
        Region::Box { lo: (c - DVec3::new(7.3, 9.1, 30.0)).to_array(), hi: (c + DVec3::new(8.2, 6.6, 30.0)).to_array() },
        Region::Sphere { centre: (c + DVec3::new(6.0, -5.0, 7.0)).to_array(), radius: 11.0 },
    ]
}

/// A renderer of the sphere phantom in binary iso mode (`persp`: perspective)
/// and its camera for `rot`.
fn sphere_renderer(vol: &Volume, rot: DMat3, persp: Option<(f64, f64)>) -> (Renderer, Camera) {
    let r = renderer(vol, settings(Method::Binary, Mode::Iso, 0.99), SPHERE_ISO, None, persp);
    (r, Camera::new(rot, [64, 64]))
}

/// A convex mesh clips like the analytic region of the same shape (a box, a
/// ball), inside and outside kept, in both projections: per ray on the
/// output image, the kept slices are the same or differ by one slice at an
/// end of the interval (the faces are rasterized and interpolated between
/// output pixels), but for fewer than 1 in 1000 rays and the silhouette
/// (rays whose analytic interval is at most two slices long, or whose
/// neighbour's is empty while theirs is not, or the reverse).
#[test]
fn clip_mesh_limits_match_the_analytic_region() {
    use shearwarp::geometry::{MeshClip, Projector};
    let dims = [44, 44, 44];
    let vol = sphere(dims).unwrap();
    let c = DVec3::from_array(sphere_geometry(dims).0);
    let (mut rays, mut off_by_one, mut silhouette, mut worse) = (0usize, 0usize, 0usize, 0usize);
    for rot in views() {
        for persp in [None, Some((40.0, 2.0))] {
            let (mut r, cam) = sphere_renderer(&vol, rot, persp);
            let mut img = Image::new(64, 64);
            r.render(&cam, &mut img).unwrap();
            let plan = r.last_plan().unwrap().clone();
            let proj = Projector::new(&cam, &r.projection(), dims, vol.spacing()).unwrap();
            for region in mesh_regions(c) {
                for keep in [Keep::Inside, Keep::Outside] {
                    let exact = ClipRegion::new(region, vol.spacing()).unwrap().keeping(keep);
                    let mesh = MeshClip::new(&mesh_of(region), proj, keep).unwrap();
                    let (le, lm) = (limits_of(&plan, &exact), limits_of(&plan, &mesh));
                    // the analytic inside interval's length, per pixel
                    let li = limits_of(&plan, &ClipRegion::new(region, vol.spacing()).unwrap());
                    let [w, h] = plan.grid.size;
                    for q in 0..h {
                        for p in 0..w {
                            // (a ray off the output image: the faces were not drawn there)
                            let [a, b] = plan.intermediate_to_sheared(p as f64, q as f64);
                            let Some([u, v]) = plan.warp.to_output(a, b) else { continue };
                            if !(0.0..=63.0).contains(&u) || !(0.0..=63.0).contains(&v) {
                                continue;
                            }
                            let diff: Vec<usize> = (0..plan.slices()).filter(|&k| le.keeps(p, q, k) != lm.keeps(p, q, k)).collect();
                            rays += 1;
                            if diff.is_empty() {
                                continue;
                            }
                            if near_silhouette(&li, [w, h], p, q, 1) {
                                silhouette += 1;
                                continue;
                            }
                            // within one slice of each end of the inside interval
                            let [a, b] = li.get(p, q);
                            let near_end = |k: usize| k.abs_diff(a as usize) <= 1 || k.abs_diff(b as usize) <= 1;
                            if diff.len() <= 2 && diff.iter().all(|&k| near_end(k)) {
                                off_by_one += 1;
                            } else {
                                eprintln!("{region:?} {keep:?} {persp:?} pixel ({p}, {q}): slices {diff:?} differ (inside {a}..={b})");
                                worse += 1;
                            }
                        }
                    }
                }
            }
        }
    }
    eprintln!("{rays} rays: {off_by_one} off by one slice at an end, {worse} by more, {silhouette} differ on the silhouette");
    assert!(
        off_by_one * 10 < rays && silhouette * 20 < rays && worse * 1000 < rays,
        "{off_by_one} off by one, {worse} by more, {silhouette} on the silhouette of {rays}"
    );
}

/// The sphere phantom clipped by a convex mesh renders the iso depth of the
/// analytic region of the same shape (binary iso, inside and outside kept,
/// both projections), away from the region's silhouette (two pixels): 98%
/// of the pixels within 0.5 voxel, fewer than 1 in 1000 more than a slice
/// step and 0.5 voxel off; coverage differs on at most 10% of the pixels.
#[test]
fn clip_mesh_iso_depth_is_the_analytic_regions() {
    use shearwarp::geometry::{MeshClip, Projector};
    let dims = [44, 44, 44];
    let vol = sphere(dims).unwrap();
    let c = DVec3::from_array(sphere_geometry(dims).0);
    let (mut both, mut close, mut worst, mut far) = (0usize, 0usize, 0f64, 0usize);
    for rot in views() {
        for persp in [None, Some((40.0, 2.0))] {
            for region in mesh_regions(c) {
                for keep in [Keep::Inside, Keep::Outside] {
                    let (mut re, cam) = sphere_renderer(&vol, rot, persp);
                    let (mut rm, _) = sphere_renderer(&vol, rot, persp);
                    let proj = Projector::new(&cam, &rm.projection(), dims, vol.spacing()).unwrap();
                    re.set_limiter(Some(Arc::new(ClipRegion::new(region, vol.spacing()).unwrap().keeping(keep))));
                    rm.set_limiter(Some(Arc::new(MeshClip::new(&mesh_of(region), proj, keep).unwrap())));
                    let mut img = Image::new(64, 64);
                    if re.render(&cam, &mut img).is_err() {
                        // (a projection the binary path does not render refuses both)
                        assert!(rm.render(&cam, &mut img).is_err());
                        continue;
                    }
                    rm.render(&cam, &mut img).unwrap();
                    let plan = re.last_plan().unwrap();
                    let (ie, im) = (re.intermediate(), rm.intermediate());
                    let [w, h] = plan.grid.size;
                    let li = limits_of(plan, &ClipRegion::new(region, vol.spacing()).unwrap());
                    let (mut covered, mut differ) = (0usize, 0usize);
                    for q in 0..h {
                        for p in 0..w {
                            let (de, dm) = (ie.depth_at(p, q) as f64, im.depth_at(p, q) as f64);
                            covered += de.is_finite() as usize;
                            if near_silhouette(&li, [w, h], p, q, 2) {
                                continue;
                            }
                            if de.is_finite() != dm.is_finite() {
                                differ += 1;
                                continue;
                            }
                            if !de.is_finite() {
                                continue;
                            }
                            let step = (sample(plan, 1, p, q) - sample(plan, 0, p, q)).length();
                            let err = (de - dm).abs() * step;
                            worst = worst.max(err);
                            both += 1;
                            close += (err <= 0.5) as usize;
                            if err > 0.5 + step {
                                far += 1;
                                eprintln!("{region:?} {keep:?} {persp:?} pixel ({p}, {q}): {dm:.3} vs {de:.3}");
                            }
                        }
                    }
                    assert!(
                        differ * 10 <= covered.max(10),
                        "{region:?} {keep:?} {persp:?}: {differ} of {covered} pixels differ in coverage"
                    );
                }
            }
        }
    }
    eprintln!("{both} pixels: {close} within 0.5 voxel, {far} further than a slice and 0.5, worst {worst:.3}");
    // (the few further off: a limit one slice apart exactly where the
    // phantom's surface meets the clip face, which moves the hit to the far
    // side of the cut)
    assert!(both > 10_000 && close as f64 >= 0.98 * both as f64 && far * 1000 < both, "{close} of {both} within 0.5 voxel, {far} far");
}

/// `--clip-mesh` on the command line: a closed convex mesh clips (a cube
/// as large as the volume keeps everything inside and nothing outside);
/// an open or a non-convex mesh, and two outside regions, are usage errors.
#[test]
fn clip_mesh_on_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = |n: &str| dir.path().join(n);
    let obj = |name: &str, v: &[[f64; 3]], f: &[[usize; 3]]| {
        let mut s = String::new();
        for p in v {
            s += &format!("v {} {} {}\n", p[0], p[1], p[2]);
        }
        for t in f {
            s += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
        }
        std::fs::write(out(name), s).unwrap();
        out(name).to_str().unwrap().to_string()
    };
    let cube = |lo: f64, hi: f64| {
        let m = shearwarp::geometry::Mesh::cuboid(DVec3::splat(lo), DVec3::splat(hi)).unwrap();
        (m.vertices.iter().map(|v| v.to_array()).collect::<Vec<_>>(), m.triangles.iter().map(|t| t.map(|i| i as usize)).collect::<Vec<_>>())
    };
    let (v, f) = cube(-0.5, 0.5);
    let unit = obj("cube.obj", &v, &f);
    let open = obj("open.obj", &v, &f[..10]);
    let mut dented = v.clone();
    dented[7] = [0.2, 0.2, 0.2];
    let dent = obj("dent.obj", &dented, &f);
    let run = |extra: &[&str], name: &str| {
        let mut args = vec!["render", "--phantom", "sphere", "--phantom-dims", "32,32,32", "--size", "64", "--quiet", "-o"];
        let o = out(name);
        args.push(o.to_str().unwrap());
        args.extend_from_slice(extra);
        Command::cargo_bin("shearwarp").unwrap().args(&args).assert()
    };
    run(&[], "plain.png").success();
    // the unit cube scaled to 40 voxels about the volume centre covers it all
    let all = ["--clip-mesh", &unit, "--mesh-scale", "40", "--mesh-translate", "15.5,15.5,15.5"];
    run(&all, "all.png").success();
    run(&[&all[..], &["--clip-keep", "outside"]].concat(), "none.png").success();
    // a corner cut out
    let corner = ["--clip-mesh", &unit, "--mesh-scale", "16", "--mesh-translate", "8,8,24", "--clip-keep", "outside"];
    run(&corner, "corner.png").success();
    let px = |n: &str| image::open(out(n)).unwrap().to_rgb8().into_raw();
    assert_eq!(px("plain.png"), px("all.png"));
    assert!(px("none.png").iter().all(|&c| c == 0));
    assert_ne!(px("plain.png"), px("corner.png"));
    run(&["--clip-mesh", &open], "x.png").failure().code(2).stderr(predicate::str::contains("not closed"));
    run(&["--clip-mesh", &dent, "--mesh-scale", "10"], "x.png").failure().code(2).stderr(predicate::str::contains("not convex"));
    run(&[&corner[..], &["--clip-box", "0,0,0,10,10,10"]].concat(), "x.png")
        .failure()
        .code(2)
        .stderr(predicate::str::contains("at most one region may keep its outside"));
}
