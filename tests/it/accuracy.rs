//! Accuracy against the reference renderer and the analytic truth:
//!
//! * the binary fast rotator at cell size 1 (and every word size, search and
//!   larger cell size) has *exactly* the error of brute force, on every volume
//!   and view of a small matrix, in both modes;
//! * the reference converges as its step shrinks;
//! * the binary iso preview finds the sphere phantom's surface within half a voxel.

use crate::common;

use glam::{DMat3, DVec3};
use shearwarp::accuracy::metrics::{compare, depth_error, rmse};
use shearwarp::accuracy::reference::{Rays, ReferenceOptions, ReferenceRenderer, Scene, fast_path_depth};
use shearwarp::accuracy::truth::{ML_BRACKET_STEP, marschner_lobb_depth, sphere_depth};
use shearwarp::classify::TransferFunction;
use shearwarp::classify::presets;
use shearwarp::composite::Mode;
use shearwarp::data::phantom::{self, SPHERE_ISO, sphere_geometry};
use shearwarp::data::volume::Volume;
use shearwarp::encode::depth::Search;
use shearwarp::render::{Method, Normals, Renderer, Settings, WordSize};
use shearwarp::view::Camera;
use shearwarp::view::NamedView;
use shearwarp::view::standard_views;
use shearwarp::warp::Image;

/// [`common::blobs`] at the spacing these tests use.
fn blobs(dims: [usize; 3], seed: u64) -> Volume {
    common::blobs(dims, seed, [1.0, 0.7, 1.6])
}

/// The small matrix: volumes with a transfer function each.
fn matrix() -> Vec<(&'static str, Volume, TransferFunction)> {
    vec![
        ("sphere", phantom::sphere([30, 30, 30]).unwrap(), presets::generic(SPHERE_ISO, 200.0).tf),
        ("marschner-lobb", phantom::marschner_lobb([25, 25, 25]).unwrap(), presets::generic(0.5, 1.0).tf),
        ("head", phantom::head([40, 40, 36]).unwrap(), presets::ct_tissue("skin").unwrap().tf),
        ("blobs", blobs([22, 19, 27], 99), TransferFunction::ramp(40.0, 160.0, 0.6, [0.9, 0.7, 0.5])),
    ]
}

fn bits(img: &Image) -> Vec<u32> {
    img.data.iter().flatten().map(|x| x.to_bits()).collect()
}

#[test]
fn cell_size_one_has_exactly_the_error_of_brute_force() {
    let size = 48;
    let views = standard_views(NamedView::Anterior.rotation(), 2, 5);
    let opts = ReferenceOptions { step: 0.1, ..Default::default() };
    let mut checked = 0;
    for (name, vol, tf) in matrix() {
        let refr = ReferenceRenderer::new(&vol);
        for mode in [Mode::Iso, Mode::Blend] {
            let base = Settings { mode, threads: 2, ..Settings::default() };
            let mut brute = Renderer::new(vol.clone(), &tf, Settings { method: Method::Brute, ..base }).unwrap();
            let mut fast: Vec<(String, Renderer)> = Vec::new();
            for cell in 1..=4 {
                for word in [WordSize::U32, WordSize::U64] {
                    for search in [Search::Lut, Search::Bitscan] {
                        let s = Settings { method: Method::Binary, cell, word, search, ..base };
                        fast.push((format!("c{cell} {} {}", word.name(), search.name()), Renderer::new(vol.clone(), &tf, s).unwrap()));
                    }
                }
            }
            let scene = Scene::from_renderer(&brute);
            for view in &views {
                let cam = Camera::new(view.rotation, [size, size]);
                let reference = refr.render(&scene, &cam, &opts).unwrap();
                let mut bi = Image::new(size, size);
                brute.render(&cam, &mut bi).unwrap();
                let be = compare(&bi, &reference.image).unwrap();
                let bd = (mode == Mode::Iso).then(|| depth_error(&fast_path_depth(&brute, &cam).unwrap(), &reference.depth, 1.0).unwrap());
                for (label, r) in &mut fast {
                    let mut fi = Image::new(size, size);
                    r.render(&cam, &mut fi).unwrap();
                    let ctx = format!("{name} {} {} {label}", mode.name(), view.name);
                    assert_eq!(bits(&fi), bits(&bi), "{ctx}: image differs from brute force");
                    assert_eq!(compare(&fi, &reference.image).unwrap(), be, "{ctx}: error differs from brute force");
                    if let Some(bd) = bd {
                        let fd = depth_error(&fast_path_depth(r, &cam).unwrap(), &reference.depth, 1.0).unwrap();
                        assert_eq!(fd, bd, "{ctx}: depth error differs from brute force");
                    }
                    checked += 1;
                }
                // the comparison is not vacuous: something is drawn and differs from the reference a little
                assert!(bi.coverage() > 0.01, "{name} {}: empty image", view.name);
                assert!(be.rmse > 0.0 && be.rmse < 0.3, "{name} {} {}: RMSE {}", mode.name(), view.name, be.rmse);
            }
        }
    }
    assert_eq!(checked, 4 * 2 * 9 * 16);
}

#[test]
fn reference_converges_as_its_step_shrinks() {
    let size = 64;
    let cam = Camera::new(standard_views(NamedView::Anterior.rotation(), 1, 3)[7].rotation, [size, size]);
    for (name, vol, tf) in matrix().into_iter().filter(|m| m.0 == "marschner-lobb" || m.0 == "head") {
        let r = Renderer::new(vol.clone(), &tf, Settings { mode: Mode::Blend, ..Settings::default() }).unwrap();
        let scene = Scene::from_renderer(&r);
        let refr = ReferenceRenderer::new(&vol);
        let steps = [0.4, 0.2, 0.1, 0.05, 0.025];
        let imgs: Vec<Image> =
            steps.iter().map(|&step| refr.render(&scene, &cam, &ReferenceOptions { step, ..Default::default() }).unwrap().image).collect();
        let diffs: Vec<f64> = imgs.windows(2).map(|w| rmse(&w[0], &w[1]).unwrap()).collect();
        eprintln!("{name}: RMSE between successive refinements {diffs:?}");
        assert!(diffs.windows(2).all(|d| d[1] < d[0]), "{name}: {diffs:?}");
        assert!(diffs[3] < 0.25 * diffs[0], "{name}: {diffs:?}");
    }
    // iso: the reference's hits converge onto the analytic Marschner–Lobb surface
    let dims = [41, 41, 41];
    let vol = phantom::marschner_lobb(dims).unwrap();
    let tf = TransferFunction::threshold(0.5, [1.0; 3]);
    let r = Renderer::new(vol.clone(), &tf, Settings::default()).unwrap();
    let scene = Scene::from_renderer(&r);
    let truth = marschner_lobb_depth(dims, [1.0; 3], &cam, 0.5, ML_BRACKET_STEP).unwrap();
    let refr = ReferenceRenderer::new(&vol);
    let errs: Vec<f64> = [0.4, 0.1, 0.025]
        .iter()
        .map(|&step| {
            let d = refr.render(&scene, &cam, &ReferenceOptions { step, ..Default::default() }).unwrap().depth;
            let e = depth_error(&d, &truth, 1.0).unwrap();
            (e.mean * e.both as f64 + 10.0 * (e.only_test + e.only_truth) as f64) / e.both as f64
        })
        .collect();
    eprintln!("marschner-lobb iso: reference depth error (mean, misses count 10 voxels) {errs:?}");
    assert!(errs[2] <= errs[0], "{errs:?}");
}

#[test]
fn binary_iso_depth_on_the_sphere_is_within_half_a_voxel() {
    let dims = [64, 64, 64];
    let vol = phantom::sphere(dims).unwrap();
    let (c, radius) = sphere_geometry(dims);
    let c = DVec3::from_array(c);
    let tf = TransferFunction::threshold(SPHERE_ISO, [1.0; 3]);
    let mut r = Renderer::new(vol.clone(), &tf, Settings::default()).unwrap();
    let refr = ReferenceRenderer::new(&vol);
    let scene = Scene::from_renderer(&r);
    let size = 128;
    let mut img = Image::new(size, size);
    let mut views = standard_views(NamedView::Anterior.rotation(), 3, 11);
    views.push(shearwarp::view::View { name: "identity".into(), rotation: DMat3::IDENTITY });
    for view in &views {
        let cam = Camera::new(view.rotation, [size, size]);
        r.render(&cam, &mut img).unwrap();
        let fast = fast_path_depth(&r, &cam).unwrap();
        let truth = sphere_depth(dims, [1.0; 3], &cam).unwrap();
        let e = depth_error(&fast, &truth, 1.0).unwrap();
        let re = depth_error(&refr.render(&scene, &cam, &ReferenceOptions::default()).unwrap().depth, &truth, 1.0).unwrap();
        // along the ray, depth is ill-conditioned where the ray grazes the surface
        // (an error δ across the surface is δ/cos θ along the ray): besides the mean,
        // bound the distance of every hit point to the sphere, and the depth error
        // where the ray meets the surface at cos θ ≥ 0.25
        let rays = Rays::new(&cam, dims, [1.0; 3]).unwrap();
        let (mut worst_dist, mut steep) = (0f64, Vec::new());
        for v in 0..size {
            for u in 0..size {
                let i = v * size + u;
                if !(fast[i].is_finite() && truth[i].is_finite()) {
                    continue;
                }
                let o = rays.origin(u as f64, v as f64);
                let dir = rays.direction();
                worst_dist = worst_dist.max(((o + fast[i] * dir - c).length() - radius).abs());
                let n = (o + truth[i] * dir - c).normalize();
                if n.dot(dir.normalize()).abs() >= 0.25 {
                    steep.push((fast[i] - truth[i]).abs());
                }
            }
        }
        steep.sort_by(f64::total_cmp);
        let p99 = steep[((0.99 * steep.len() as f64).ceil() as usize).clamp(1, steep.len()) - 1];
        eprintln!(
            "{:>9}: depth error mean {:.4} p99 {:.3} (reference: mean {:.4} p99 {:.3}); hit-point distance to the sphere ≤ {:.3}; p99 at cos θ ≥ 0.25: {:.3}",
            view.name, e.mean, e.p99, re.mean, re.p99, worst_dist, p99
        );
        assert!(e.both > 2000, "{}: {e:?}", view.name);
        assert!(e.mean < 0.5, "{}: mean depth error {}", view.name, e.mean);
        assert!(worst_dist < 0.5, "{}: a hit point is {worst_dist} voxels from the surface", view.name);
        assert!(p99 < 0.5, "{}: p99 depth error off the silhouette {p99}", view.name);
        // the silhouettes agree to a thin rim
        assert!((e.only_test + e.only_truth) as f64 / (e.both as f64) < 0.03, "{}: {e:?}", view.name);
        // and the reference itself is far more accurate
        assert!(re.mean < 0.05 && re.p99 < 0.2, "{}: reference {re:?}", view.name);
    }
}

/// Table shading (per-voxel normal codes, a shade table, shades blended in the
/// cell) against the exact gradient at every sample, over the standard views:
/// really different images (the codes are what shades), and a mean error
/// against the reference within a margin of the gradient's. The margin is wide
/// on the noisy blobs, where blending the corners' shades differs most from
/// shading the blended gradient (the price of the speed; `--normals gradient`).
#[test]
fn table_shading_is_about_as_accurate_as_the_exact_gradient() {
    let size = 64;
    let views = standard_views(NamedView::Anterior.rotation(), 2, 5);
    let opts = ReferenceOptions { step: 0.1, ..Default::default() };
    for (name, vol, tf) in matrix() {
        let refr = ReferenceRenderer::new(&vol);
        for mode in [Mode::Iso, Mode::Blend] {
            let base = Settings { mode, threads: 2, method: Method::Binary, ..Settings::default() };
            let mut codes = Renderer::new(vol.clone(), &tf, Settings { normals: Normals::Codes, ..base }).unwrap();
            let mut exact = Renderer::new(vol.clone(), &tf, Settings { normals: Normals::Gradient, ..base }).unwrap();
            let scene = Scene::from_renderer(&exact);
            let (mut ce, mut ee) = (0.0, 0.0);
            for view in &views {
                let cam = Camera::new(view.rotation, [size, size]);
                let reference = refr.render(&scene, &cam, &opts).unwrap();
                let (mut ci, mut ei) = (Image::new(size, size), Image::new(size, size));
                codes.render(&cam, &mut ci).unwrap();
                exact.render(&cam, &mut ei).unwrap();
                let between = rmse(&ci, &ei).unwrap();
                assert!(between > 0.0 && between < 0.1, "{name} {} {}: {between}", mode.name(), view.name);
                ce += compare(&ci, &reference.image).unwrap().rmse / views.len() as f64;
                ee += compare(&ei, &reference.image).unwrap().rmse / views.len() as f64;
            }
            let margin = if name == "blobs" { 1.5 } else { 1.2 };
            println!("{name} {}: mean RMSE codes {ce:.4}, gradient {ee:.4}", mode.name());
            assert!(ce < ee * margin + 0.002, "{name} {}: mean RMSE codes {ce:.4}, gradient {ee:.4}", mode.name());
        }
    }
}
