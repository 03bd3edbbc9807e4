//! The binary rotator under perspective: each perspective ray walks
//! across the mask sheared to the central direction ([`shearwarp::encode::walk`]),
//! and must give its brute force's image bit for bit (every slice of every ray
//! sampled), over random volumes, views, fields of view, eye distances, super
//! cells, threshold codes and word sizes; against the perspective reference it
//! is as accurate as the parallel binary path, and it converges to the
//! parallel image as the eye recedes.

use crate::common;

use common::{bits, blobs};
use glam::{DMat3, EulerRot};
use shearwarp::accuracy::metrics::rmse;
use shearwarp::accuracy::reference::{ReferenceOptions, Scene};
use shearwarp::classify::TransferFunction;
use shearwarp::classify::presets;
use shearwarp::composite::Mode;
use shearwarp::data::volume::Volume;
use shearwarp::render::{Method, Renderer, Settings, WordSize};
use shearwarp::view::{Camera, Projection, rotate_eye};
use shearwarp::warp::Image;

fn try_render(r: &mut Renderer, cam: &Camera) -> Option<Image> {
    let mut img = Image::new(cam.size[0], cam.size[1]);
    r.render(cam, &mut img).ok().map(|_| img)
}

/// A renderer of one transfer function (1-bit mask) or of tissue presets
/// (threshold codes), with `settings`.
fn renderer(vol: &Volume, tissues: bool, s: Settings, proj: Projection) -> Renderer {
    let mut r = if tissues {
        let ts = presets::tissues_for(vol);
        Renderer::with_tissues(vol.clone(), &ts[..ts.len().min(3)], s).unwrap()
    } else {
        Renderer::new(vol.clone(), &TransferFunction::ramp(40.0, 160.0, 0.5, [0.9, 0.7, 0.5]), s).unwrap()
    };
    r.set_projection(proj).unwrap();
    r
}

/// Accelerated binary == brute binary, bit for bit, under perspective: random
/// blob volumes and rotations, fields of view 10–70°, eye distances 1.5–5
/// diagonals, both modes, super cells 1–4, 1-bit masks and threshold codes,
/// u32 and u64 words, the LUT search and the bit scan; and the same image for
/// one thread and two.
#[test]
fn perspective_binary_equals_brute_force_bit_for_bit() {
    let mut rnd = common::uniform(21);
    let mut checked = 0;
    for case in 0..80 {
        let dims = [12 + (rnd() * 14.0) as usize, 10 + (rnd() * 14.0) as usize, 8 + (rnd() * 70.0) as usize];
        let sp = [[1.0, 1.0, 1.0], [1.0, 0.7, 1.6], [0.8, 1.2, 1.0]][case % 3];
        let vol = blobs(dims, 300 + case as u64, sp);
        let rot = DMat3::from_euler(EulerRot::XYZ, rnd() * 7.0, rnd() * 7.0, rnd() * 7.0);
        let proj = Projection::perspective(10.0 + rnd() * 60.0, 1.5 + rnd() * 3.5).unwrap();
        let cam = Camera::new(rot, [48, 40]);
        let mode = if case % 2 == 0 { Mode::Blend } else { Mode::Iso };
        let s = Settings {
            mode,
            threads: 2,
            cell: 1 + case % 4,
            word: if case % 3 == 0 { WordSize::U32 } else { WordSize::U64 },
            search: if case % 5 == 4 { shearwarp::encode::depth::Search::Lut } else { shearwarp::encode::depth::Search::Bitscan },
            ert: if case % 4 == 1 { 1.0 } else { 0.95 },
            ..Settings::default()
        };
        let tissues = case % 3 == 2;
        let mut fast = renderer(&vol, tissues, Settings { method: Method::Binary, ..s }, proj);
        let mut brute = renderer(&vol, tissues, Settings { method: Method::Brute, ..s }, proj);
        let Some(a) = try_render(&mut fast, &cam) else {
            // a view that needs the pyramid split is refused by both
            assert!(try_render(&mut brute, &cam).is_none());
            continue;
        };
        let b = try_render(&mut brute, &cam).unwrap();
        assert!(a.coverage() > 0.0, "case {case}: empty image");
        assert_eq!(bits(&a), bits(&b), "case {case} {s:?}: binary and brute force differ");
        fast.set_settings(Settings { threads: 1, ..fast.settings() }).unwrap();
        assert_eq!(bits(&try_render(&mut fast, &cam).unwrap()), bits(&a), "case {case}: thread count changed the image");
        checked += 1;
    }
    assert!(checked >= 60, "only {checked} views rendered");
}

/// The binary perspective image against the perspective reference ray caster,
/// within the bound the parallel binary image meets against the parallel
/// reference (the same views).
#[test]
fn perspective_binary_matches_the_reference() {
    let (vol, tf, refr) = common::sphere_scene();
    let opts = ReferenceOptions { step: 0.1, ..Default::default() };
    let views = common::three_views();
    let mut report = vec![];
    for mode in [Mode::Blend, Mode::Iso] {
        for (name, rot) in views {
            let cam = Camera::new(rot, [64, 64]);
            let tol = if mode == Mode::Blend { 0.02 } else { 0.05 };
            for proj in [Projection::perspective(40.0, 2.0).unwrap(), Projection::perspective(20.0, 4.0).unwrap(), Projection::Parallel] {
                let s = Settings { mode, threads: 2, method: Method::Binary, ..Settings::default() };
                let mut r = Renderer::new(vol.clone(), &tf, s).unwrap();
                r.set_projection(proj).unwrap();
                let img = try_render(&mut r, &cam).unwrap();
                let want = refr.render_projected(&Scene::from_renderer(&r), &cam, &proj, &opts).unwrap();
                let e = rmse(&img, &want.image).unwrap();
                report.push(format!("{mode:?} {name} {proj:?}: {e:.4}"));
                assert!(img.coverage() > 0.05);
                assert!(e < tol, "{mode:?} {name} {proj:?}: RMSE {e}");
            }
        }
    }
    eprintln!("{}", report.join("\n"));
}

/// As the eye recedes (field of view shrunk to keep the image scale), the
/// binary perspective image converges to the binary parallel one (the RLE
/// path's test, `perspective_converges_to_parallel_as_the_eye_recedes`, on
/// the binary path).
#[test]
fn perspective_binary_converges_to_parallel_as_the_eye_recedes() {
    let vol = common::closed_blobs();
    let size = 64;
    for rot in [rotate_eye(DMat3::IDENTITY, 2, 30.0), DMat3::from_euler(EulerRot::XYZ, 0.3, -0.5, 0.2)] {
        let cam = Camera::new(rot, [size, size]);
        for mode in [Mode::Blend, Mode::Iso] {
            let s = Settings { mode, threads: 2, method: Method::Binary, ..Settings::default() };
            let par = try_render(&mut renderer(&vol, false, s, Projection::Parallel), &cam).unwrap();
            let at = |proj| try_render(&mut renderer(&vol, false, s, proj), &cam).unwrap();
            // iso thresholds samples: a sample that moves by 1e-3 voxel
            // (the eye at 1e4 diagonals) can still flip a hit, so go farther
            common::assert_recedes_to_parallel(&par, &[10.0, 100.0, 1e4, 1e6], at, &format!("{mode:?} {rot:?}"));
        }
    }
}

/// The binary path's iso depth under perspective (`fast_path_depth`) against
/// the perspective reference's: the hit points agree to about a tenth of a
/// voxel on average, as the parallel ones do.
#[test]
fn perspective_binary_iso_depth_matches_the_reference() {
    use shearwarp::accuracy::metrics::depth_error;
    use shearwarp::accuracy::reference::fast_path_depth;
    let (vol, tf, refr) = common::sphere_scene();
    let opts = ReferenceOptions { step: 0.05, ..Default::default() };
    for rot in [DMat3::IDENTITY, rotate_eye(DMat3::IDENTITY, 1, 30.0), DMat3::from_euler(EulerRot::XYZ, 0.4, -0.6, 0.2)] {
        let cam = Camera::new(rot, [96, 96]);
        let mut means = vec![];
        for proj in [Projection::perspective(40.0, 2.0).unwrap(), Projection::Parallel] {
            let s = Settings { mode: Mode::Iso, threads: 2, method: Method::Binary, ..Settings::default() };
            let mut r = Renderer::new(vol.clone(), &tf, s).unwrap();
            r.set_projection(proj).unwrap();
            try_render(&mut r, &cam).unwrap();
            let got = fast_path_depth(&r, &cam).unwrap();
            let want = refr.render_projected(&Scene::from_renderer(&r), &cam, &proj, &opts).unwrap();
            let e = depth_error(&got, &want.depth, 1.0).unwrap();
            eprintln!("{proj:?} {rot:?}: {e:?}");
            assert!(e.both > 500, "{proj:?}: {e:?}");
            // (the 99th percentile is the silhouette's pixels)
            // the 99th percentile is the silhouette's pixels (about 2 voxels, as parallel)
            assert!(e.mean < 0.2 && e.p99 < 2.5, "{proj:?}: {e:?}");
            assert!(e.only_test + e.only_truth < e.both / 20, "{proj:?}: {e:?}");
            means.push(e.mean);
        }
        // perspective (a smaller sphere on screen: more of it silhouette) within twice the parallel mean
        assert!(means[0] < 2.0 * means[1], "{means:?}");
    }
}
