//! Perspective shear-warp: the RLE path and its brute
//! force under perspective plans, against each other, the parallel image as
//! the eye recedes, the perspective reference ray caster, and regression tests
//! for the defects of the public implementations (Virvo).

use crate::common;

use common::{bits, blobs, render, renderer, xorshift};
use glam::{DMat3, EulerRot};
use shearwarp::accuracy::metrics::rmse;
use shearwarp::accuracy::reference::{ReferenceOptions, ReferenceRenderer, Scene};
use shearwarp::classify::TransferFunction;
use shearwarp::classify::presets;
use shearwarp::classify::shading::Shading;
use shearwarp::composite::Mode;
use shearwarp::data::phantom::{self, SPHERE_ISO};
use shearwarp::data::volume::Volume;
use shearwarp::render::{Method, Renderer, Settings};
use shearwarp::view::{Camera, Projection, rotate_eye};
use shearwarp::warp::Image;

/// The accelerated RLE path equals its brute force bit for bit under
/// perspective, over random volumes, rotations, fields of view and eye
/// distances, in both modes, with early termination, and for any thread count.
#[test]
fn perspective_rle_equals_brute_force_bit_for_bit() {
    let mut rnd = common::uniform(5);
    let mut checked = 0;
    for case in 0..24 {
        let dims = [14 + (rnd() * 12.0) as usize, 12 + (rnd() * 12.0) as usize, 10 + (rnd() * 14.0) as usize];
        let sp = [[1.0, 1.0, 1.0], [1.0, 0.7, 1.6], [0.8, 1.2, 1.0]][case % 3];
        let vol = blobs(dims, 100 + case as u64, sp);
        let tf = TransferFunction::ramp(40.0, 160.0, 0.5, [0.9, 0.7, 0.5]);
        let rot = DMat3::from_euler(EulerRot::XYZ, rnd() * 7.0, rnd() * 7.0, rnd() * 7.0);
        let proj = Projection::perspective(15.0 + rnd() * 50.0, 1.2 + rnd() * 3.0).unwrap();
        let cam = Camera::new(rot, [56, 48]);
        let mode = if case % 2 == 0 { Mode::Blend } else { Mode::Iso };
        let mut fast = renderer(&vol, &tf, Method::Rle, mode, proj);
        let mut brute = renderer(&vol, &tf, Method::BruteRle, mode, proj);
        let a = {
            let mut img = Image::new(56, 48);
            match fast.render(&cam, &mut img) {
                Ok(_) => img,
                // a view that needs the pyramid split is refused by both
                Err(_) => {
                    assert!(brute.render(&cam, &mut Image::new(56, 48)).is_err());
                    continue;
                }
            }
        };
        let b = render(&mut brute, &cam);
        assert!(a.coverage() > 0.0, "case {case}: empty image");
        assert_eq!(bits(&a), bits(&b), "case {case}: RLE and brute force differ");
        // one thread renders the same image
        fast.set_settings(Settings { threads: 1, ..fast.settings() }).unwrap();
        assert_eq!(bits(&render(&mut fast, &cam)), bits(&a), "case {case}: thread count changed the image");
        checked += 1;
    }
    assert!(checked >= 16, "only {checked} views rendered");
}

/// As the eye recedes (field of view shrunk to keep the image scale), the
/// perspective image converges to the parallel one.
#[test]
fn perspective_converges_to_parallel_as_the_eye_recedes() {
    let vol = common::closed_blobs();
    let tf = TransferFunction::ramp(40.0, 160.0, 0.5, [0.9, 0.7, 0.5]);
    let size = 64;
    // view along z (no shear) and oblique: in the limit the perspective plan's
    // samples are the parallel plan's
    for rot in [rotate_eye(DMat3::IDENTITY, 2, 30.0), DMat3::from_euler(EulerRot::XYZ, 0.3, -0.5, 0.2)] {
        let cam = Camera::new(rot, [size, size]);
        for mode in [Mode::Blend, Mode::Iso] {
            let par = render(&mut renderer(&vol, &tf, Method::Rle, mode, Projection::Parallel), &cam);
            let at = |proj| render(&mut renderer(&vol, &tf, Method::Rle, mode, proj), &cam);
            common::assert_recedes_to_parallel(&par, &[10.0, 100.0, 1e4], at, &format!("{mode:?} {rot:?}"));
        }
    }
}

/// The perspective RLE image against the perspective reference ray caster
/// (true rays from the eye, fine steps) on the sphere phantom, at 0°, 45° and
/// the main diagonal, beside the parallel error of the same views.
#[test]
fn perspective_rle_matches_the_reference() {
    let (vol, tf, refr) = common::sphere_scene();
    let opts = ReferenceOptions { step: 0.1, ..Default::default() };
    let views = common::three_views();
    let mut report = vec![];
    for mode in [Mode::Blend, Mode::Iso] {
        for (name, rot) in views {
            let cam = Camera::new(rot, [64, 64]);
            for proj in [Projection::perspective(40.0, 2.0).unwrap(), Projection::Parallel] {
                let mut r = renderer(&vol, &tf, Method::Rle, mode, proj);
                let img = render(&mut r, &cam);
                let want = refr.render_projected(&Scene::from_renderer(&r), &cam, &proj, &opts).unwrap();
                let e = rmse(&img, &want.image).unwrap();
                report.push(format!("{mode:?} {name} {}: {e:.4}", if proj.is_perspective() { "perspective" } else { "parallel" }));
                assert!(img.coverage() > 0.05);
                let tol = if mode == Mode::Blend { 0.02 } else { 0.05 };
                assert!(e < tol, "{mode:?} {name} {proj:?}: RMSE {e}");
            }
        }
    }
    eprintln!("{}", report.join("\n"));
}

/// A uniform slab of constant opacity and colour with flat shading, seen
/// head-on: every pixel's opacity is `1 − (1 − α)^(n·r)` for its ray's own
/// spacing ratio `r = 1/cos θ`, and its colour, un-premultiplied, is the
/// voxel colour: premultiplied colour is attenuated once (Virvo's warp
/// blended premultiplied colour by alpha again).
#[test]
fn perspective_slab_is_analytic_and_colour_is_attenuated_once() {
    let dims = [64, 64, 12];
    let vol = Volume::from_fn(dims, [1.0; 3], |_, _, _| 1.0).unwrap();
    let (a0, rgb) = (0.1f64, [0.8f32, 0.5, 0.25]);
    let tf = TransferFunction::new(vec![(0.0, a0 as f32)], vec![(0.0, rgb)]).unwrap();
    let flat = Shading { ambient: 1.0, diffuse: 0.0, specular: 0.0, shininess: 1 };
    let size = 96;
    for method in [Method::Rle, Method::BruteRle] {
        let s = Settings { method, mode: Mode::Blend, ert: 1.0, shading: flat, threads: 2, ..Settings::default() };
        let mut r = Renderer::new(vol.clone(), &tf, s).unwrap();
        let (fov, d) = (90.0f64, 0.6);
        r.set_projection(Projection::perspective(fov, d).unwrap()).unwrap();
        let cam = Camera::new(DMat3::IDENTITY, [size, size]);
        let img = render(&mut r, &cam);
        let f = size as f64 / 2.0 / (fov.to_radians() / 2.0).tan();
        let c = (size as f64 - 1.0) / 2.0;
        for (u, v) in [(c as usize, c as usize), (60, 52), (66, 35), (30, 60)] {
            let px = img.at(u, v);
            let tan = ((u as f64 - c).powi(2) + (v as f64 - c).powi(2)).sqrt() / f;
            let ratio = (1.0 + tan * tan).sqrt();
            let want = 1.0 - (1.0 - a0).powf(dims[2] as f64 * ratio);
            assert!((px[3] as f64 - want).abs() < 2e-3, "{method:?} ({u}, {v}): α {} vs {want}", px[3]);
            for ch in 0..3 {
                assert!((px[ch] / px[3] - rgb[ch]).abs() < 1e-4, "{method:?} ({u}, {v}): colour {px:?}");
            }
        }
    }
}

/// Virvo's parallel loop stopped before the last slice: a volume whose only
/// visible voxels are in the slice farthest from the eye renders them.
#[test]
fn perspective_last_slice_is_composited() {
    let dims = [20, 20, 16];
    // seen from +z (identity rotation): the farthest slice is z = 0
    let vol = Volume::from_fn(dims, [1.0; 3], |_, _, z| if z == 0 { 1.0 } else { 0.0 }).unwrap();
    let tf = TransferFunction::new(vec![(0.0, 0.0), (1.0, 0.5)], vec![(0.0, [1.0; 3])]).unwrap();
    for proj in [Projection::perspective(30.0, 2.0).unwrap(), Projection::Parallel] {
        for method in [Method::Rle, Method::BruteRle] {
            let s = Settings { method, mode: Mode::Blend, ert: 1.0, threads: 1, ..Settings::default() };
            let mut r = Renderer::new(vol.clone(), &tf, s).unwrap();
            r.set_projection(proj).unwrap();
            let img = render(&mut r, &Camera::new(DMat3::IDENTITY, [48, 48]));
            let centre = img.at(24, 24)[3];
            assert!((centre - 0.5).abs() < 0.01, "{proj:?} {method:?}: the last slice gives α {centre}");
        }
    }
}

/// Virvo's perspective compositor never terminated rays (alpha scaled to
/// [0, 1], then tested against 255). Here a ray stops as soon as its opacity
/// reaches the threshold: with `ert` 0.5 in a dense slab every covered pixel
/// ends just past 0.5, where without termination it reaches ~1.
#[test]
fn perspective_early_ray_termination_fires() {
    let vol = Volume::from_fn([24, 24, 24], [1.0; 3], |_, _, _| 1.0).unwrap();
    let tf = TransferFunction::new(vec![(0.0, 0.3)], vec![(0.0, [1.0; 3])]).unwrap();
    let proj = Projection::perspective(40.0, 2.0).unwrap();
    let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, 0.2, 0.3, 0.1), [48, 48]);
    for method in [Method::Rle, Method::BruteRle] {
        let img = |ert: f32| {
            let s = Settings { method, mode: Mode::Blend, ert, threads: 1, ..Settings::default() };
            let mut r = Renderer::new(vol.clone(), &tf, s).unwrap();
            r.set_projection(proj).unwrap();
            render(&mut r, &cam)
        };
        let (stopped, full) = (img(0.5), img(1.0));
        let c = stopped.at(24, 24)[3];
        assert!((0.5..0.75).contains(&c), "{method:?}: α {c} with termination at 0.5");
        assert!(full.at(24, 24)[3] > 0.99);
        // no output pixel passes the threshold by more than one sample
        let inter_max = stopped.data.iter().map(|p| p[3]).fold(0.0f32, f32::max);
        assert!(inter_max < 0.75, "{method:?}: α up to {inter_max}");
    }
}

/// Output pixels whose rays never meet the base plane in front of the eye
/// (a field of view near 180°) are background, not a mirrored image; and
/// the rest of the image is still the volume.
#[test]
fn perspective_wide_field_of_view_corners_are_background() {
    let vol = phantom::sphere([24, 24, 24]).unwrap();
    let tf = presets::generic(SPHERE_ISO, 200.0).tf;
    // the view 40° off the principal axis: the base plane is oblique, so the
    // rays of one side of a 160° field of view never meet it in front of the eye
    let cam = Camera::new(rotate_eye(DMat3::IDENTITY, 1, 40.0), [128, 128]);
    let proj = Projection::perspective(160.0, 1.5).unwrap();
    let mut r = renderer(&vol, &tf, Method::Rle, Mode::Iso, proj);
    let img = render(&mut r, &cam);
    let plan = r.last_plan().unwrap();
    let mut behind = 0;
    for v in 0..128 {
        for u in 0..128 {
            if plan.warp.to_sheared(u as f64, v as f64).is_none() {
                behind += 1;
                assert_eq!(img.at(u, v), [0.0; 4], "({u}, {v}) is behind the eye");
            }
        }
    }
    assert!(behind > 1000, "the test wants pixels behind the eye: {behind}");
    assert!(img.coverage() > 0.0, "the volume is seen");
}

/// Bad projections are errors, not panics (every path renders perspective).
#[test]
fn perspective_errors_are_clear() {
    let vol = phantom::sphere([20, 20, 20]).unwrap();
    let tf = presets::generic(SPHERE_ISO, 200.0).tf;
    let cam = Camera::new(DMat3::IDENTITY, [32, 32]);
    for method in [Method::Binary, Method::Brute] {
        let mut r = renderer(&vol, &tf, method, Mode::Iso, Projection::perspective(40.0, 2.0).unwrap());
        assert!(r.render(&cam, &mut Image::new(32, 32)).unwrap().rays > 0);
    }
    for (fov, d) in
        [(0.0, 2.0), (180.0, 2.0), (-5.0, 2.0), (f64::NAN, 2.0), (40.0, 0.0), (40.0, -1.0), (40.0, f64::NAN), (40.0, f64::INFINITY)]
    {
        assert!(Projection::perspective(fov, d).is_err(), "{fov} {d}");
    }
}

/// The binary rotator under the pyramid split (the eye near or inside the
/// volume, wide fields of view) equals its brute force bit for bit, in both
/// modes, over random views.
#[test]
fn perspective_binary_split_equals_brute_force() {
    let mut rnd = common::uniform(31);
    for case in 0..10 {
        let vol = blobs([30, 26, 22], 500 + case as u64, [1.0, 0.8, 1.2]);
        let tf = TransferFunction::ramp(40.0, 160.0, 0.5, [0.9, 0.7, 0.5]);
        let rot = DMat3::from_euler(EulerRot::XYZ, rnd() * 7.0, rnd() * 7.0, rnd() * 7.0);
        let proj = Projection::perspective(50.0 + rnd() * 70.0, 0.05 + rnd() * 0.6).unwrap();
        let cam = Camera::new(rot, [48, 40]);
        let mode = if case % 2 == 0 { Mode::Iso } else { Mode::Blend };
        let a = render(&mut renderer(&vol, &tf, Method::Binary, mode, proj), &cam);
        let b = render(&mut renderer(&vol, &tf, Method::Brute, mode, proj), &cam);
        assert_eq!(bits(&a), bits(&b), "case {case} {mode:?} {proj:?}: binary and brute force differ");
    }
    // the eye inside the sphere phantom's shell sees it all around
    let vol = phantom::sphere([20, 20, 20]).unwrap();
    let tf = presets::generic(SPHERE_ISO, 200.0).tf;
    let mut r = renderer(&vol, &tf, Method::Binary, Mode::Iso, Projection::perspective(40.0, 0.1).unwrap());
    let img = render(&mut r, &Camera::new(DMat3::IDENTITY, [32, 32]));
    assert!(img.coverage() > 0.5, "coverage {}", img.coverage());
}

/// The eye inside dense tissue (iso: most rays' first sample is already a hit,
/// which the binary rotator answers before walking; others start below the iso
/// value and walk): binary equals brute force bit for bit, over views.
#[test]
fn perspective_binary_eye_in_tissue_equals_brute_force() {
    let vol = Volume::from_fn([28, 24, 26], [1.0; 3], |x, y, z| {
        let (x, y, z) = (x as f32, y as f32, z as f32);
        let d = ((x - 14.0).powi(2) + (y - 12.0).powi(2) + (z - 13.0).powi(2)).sqrt();
        if d < 11.0 { 120.0 + 90.0 * (0.5 * x).sin() * (0.4 * y + 0.3 * z).cos() } else { 0.0 }
    })
    .unwrap();
    let tf = TransferFunction::ramp(40.0, 160.0, 0.5, [0.9, 0.7, 0.5]);
    let mut rnd = common::uniform(47);
    let mut covered = 0.0;
    for case in 0..6 {
        let rot = DMat3::from_euler(EulerRot::XYZ, rnd() * 7.0, rnd() * 7.0, rnd() * 7.0);
        let proj = Projection::perspective(40.0 + rnd() * 60.0, 0.05 + rnd() * 0.1).unwrap();
        let cam = Camera::new(rot, [40, 36]);
        let a = render(&mut renderer(&vol, &tf, Method::Binary, Mode::Iso, proj), &cam);
        let b = render(&mut renderer(&vol, &tf, Method::Brute, Mode::Iso, proj), &cam);
        assert_eq!(bits(&a), bits(&b), "case {case} {proj:?}: binary and brute force differ");
        covered += a.coverage();
    }
    assert!(covered / 6.0 > 0.9, "coverage {}", covered / 6.0);
}

/// One image reused across perspective and parallel frames (the warps clear
/// only what they no longer cover) holds exactly what a fresh image gets.
#[test]
fn perspective_and_parallel_frames_share_an_image_cleanly() {
    let vol = phantom::sphere([30, 30, 30]).unwrap();
    let tf = presets::generic(SPHERE_ISO, 200.0).tf;
    let mut r = renderer(&vol, &tf, Method::Rle, Mode::Blend, Projection::Parallel);
    let mut img = Image::new(64, 64);
    let frames = [
        (Projection::perspective(30.0, 1.5).unwrap(), rotate_eye(DMat3::IDENTITY, 1, 20.0)),
        (Projection::Parallel, rotate_eye(DMat3::IDENTITY, 0, 50.0)),
        (Projection::perspective(60.0, 3.0).unwrap(), rotate_eye(DMat3::IDENTITY, 1, -70.0)),
        (Projection::perspective(20.0, 1.5).unwrap(), rotate_eye(DMat3::IDENTITY, 2, 10.0)),
        (Projection::Parallel, DMat3::IDENTITY),
    ];
    for (proj, rot) in frames {
        r.set_projection(proj).unwrap();
        let cam = Camera::new(rot, [64, 64]);
        r.render(&cam, &mut img).unwrap();
        let fresh = render(&mut r, &cam);
        assert_eq!(bits(&img), bits(&fresh), "{proj:?}");
    }
}

/// Across the principal-axis switch (44.9° and 45.1° about y use different
/// slice stacks) the perspective image hardly changes: no more than the
/// parallel image does across the same switch, and both stay near the reference.
#[test]
fn perspective_has_no_seam_at_the_principal_axis_switch() {
    let vol = phantom::sphere([36, 36, 36]).unwrap();
    let tf = presets::generic(SPHERE_ISO, 200.0).tf;
    let (a, b) = (rotate_eye(DMat3::IDENTITY, 1, 44.9), rotate_eye(DMat3::IDENTITY, 1, 45.1));
    for mode in [Mode::Blend, Mode::Iso] {
        let mut jumps = vec![];
        for proj in [Projection::perspective(40.0, 2.5).unwrap(), Projection::Parallel] {
            let mut r = renderer(&vol, &tf, Method::Rle, mode, proj);
            let ia = render(&mut r, &Camera::new(a, [64, 64]));
            let axis_a = r.last_plan().unwrap().view.axis;
            let ib = render(&mut r, &Camera::new(b, [64, 64]));
            assert_ne!(axis_a, r.last_plan().unwrap().view.axis, "the views straddle the switch");
            jumps.push(rmse(&ia, &ib).unwrap());
        }
        eprintln!("{mode:?}: RMSE across the switch, perspective {:.4}, parallel {:.4}", jumps[0], jumps[1]);
        assert!(jumps[0] < 1.5 * jumps[1] + 0.005, "{mode:?}: {jumps:?}");
    }
}

/// Over random small volumes (down to 2 voxels an axis), fields of view
/// (1°–179°), eye distances (0.05–1000 diagonals, the eye inside included:
/// the pyramid split) and rotations: every frame renders, with no NaN and
/// opacities in [0, 1], and RLE equals brute force bit for bit.
#[test]
fn perspective_random_views_render_or_refuse_cleanly() {
    let mut rnd = common::uniform(99);
    let (mut rendered, mut refused) = (0, 0);
    for case in 0..120 {
        let dims = [2 + (rnd() * 10.0) as usize, 2 + (rnd() * 10.0) as usize, 2 + (rnd() * 10.0) as usize];
        let sp = [0.5 + rnd() as f32, 0.5 + rnd() as f32, 0.5 + rnd() as f32];
        let vol = blobs(dims, case, sp);
        let tf = TransferFunction::ramp(20.0, 160.0, 0.7, [0.9, 0.7, 0.5]);
        let fov = 1.0 + rnd() * 178.0;
        let d = 0.05 * (2e4f64).powf(rnd());
        let proj = Projection::perspective(fov, d).unwrap();
        let rot = DMat3::from_euler(EulerRot::XYZ, rnd() * 7.0, rnd() * 7.0, rnd() * 7.0);
        let cam = Camera::new(rot, [24 + (rnd() * 20.0) as usize, 24]);
        let mode = if case % 2 == 0 { Mode::Blend } else { Mode::Iso };
        let mut imgs = vec![];
        for method in [Method::Rle, Method::BruteRle] {
            let mut r = renderer(&vol, &tf, method, mode, proj);
            let mut img = Image::new(cam.size[0], cam.size[1]);
            match r.render(&cam, &mut img) {
                Ok(_) => imgs.push(img),
                Err(e) => panic!("case {case}: {e}"),
            }
        }
        match imgs.len() {
            0 => refused += 1,
            2 => {
                // (shaded colour may pass 1 with the specular term; opacity may not)
                let ok = |c: &[f32; 4]| c.iter().all(|x| x.is_finite() && *x >= 0.0) && c[3] <= 1.0 + 1e-5;
                let bad = imgs[0].data.iter().find(|c| !ok(c));
                assert!(bad.is_none(), "case {case}: {bad:?} {dims:?} {sp:?} fov {fov} d {d} {mode:?}");
                assert_eq!(bits(&imgs[0]), bits(&imgs[1]), "case {case}: RLE and brute force differ");
                rendered += 1;
            }
            _ => panic!("case {case}: one path rendered, the other refused"),
        }
    }
    assert!(rendered == 120 && refused == 0, "rendered {rendered}, refused {refused}");
}

/// Anisotropic voxels (spacing 1 × 0.7 × 1.6): the perspective RLE image is
/// as close to the perspective reference as the parallel image to the
/// parallel one (geometry and each ray's opacity correction under spacing),
/// with the eye inside too (the split: pyramids along axes of different
/// spacing).
#[test]
fn perspective_anisotropic_spacing_matches_the_reference() {
    let vol = blobs([30, 34, 22], 3, [1.0, 0.7, 1.6]);
    let tf = TransferFunction::ramp(40.0, 160.0, 0.4, [0.9, 0.7, 0.5]);
    let refr = ReferenceRenderer::new(&vol);
    let opts = ReferenceOptions { step: 0.1, ..Default::default() };
    for rot in [DMat3::from_euler(EulerRot::XYZ, 0.4, -0.3, 0.1), rotate_eye(DMat3::IDENTITY, 0, 70.0)] {
        let cam = Camera::new(rot, [64, 64]);
        let mut errs = vec![];
        let projs = [Projection::perspective(50.0, 1.6).unwrap(), Projection::Parallel, Projection::perspective(60.0, 0.15).unwrap()];
        for proj in projs {
            let mut r = renderer(&vol, &tf, Method::Rle, Mode::Blend, proj);
            let img = render(&mut r, &cam);
            let want = refr.render_projected(&Scene::from_renderer(&r), &cam, &proj, &opts).unwrap();
            errs.push(rmse(&img, &want.image).unwrap());
        }
        eprintln!("RMSE perspective {:.4}, parallel {:.4}, the eye inside (split) {:.4}", errs[0], errs[1], errs[2]);
        assert!(errs[0] < 2.0 * errs[1] + 0.002 && errs[0] < 0.03, "{errs:?}");
        // the eye inside: each pyramid's axis has its own spacing and opacity correction
        assert!(errs[2] < 2.0 * errs[1] + 0.01, "{errs:?}");
    }
}

/// Smooth blobs with empty space between them (no noise): what the pyramid
/// split's tests look at from inside.
fn smooth_blobs(dims: [usize; 3]) -> Volume {
    Volume::from_fn(dims, [1.0; 3], |x, y, z| {
        let (x, y, z) = (x as f32, y as f32, z as f32);
        let s = (x / 3.1).sin() * (y / 4.3).sin() * (z / 3.7 + 0.5).sin();
        240.0 * s.max(0.0).powi(2)
    })
    .unwrap()
}

/// Per output pixel, the pyramid of its ray (`None`: the frame is not split).
fn owners(vol: &Volume, cam: &Camera, proj: &Projection) -> Vec<(usize, bool)> {
    let (c, d) = proj.resolve(cam, vol.dims(), vol.spacing()).unwrap().unwrap();
    let rays = shearwarp::view::PerspectiveView::ray_directions(&c, d, vol.dims(), vol.spacing()).unwrap();
    let [w, h] = cam.size;
    (0..w * h).map(|i| rays.owner((i % w) as f64, (i / w) as f64)).collect()
}

/// A pyramid's pixels of an output row are one run: its cone of rays is an
/// intersection of half-spaces and a row's rays are affine in `u`, so a row
/// meets it in one interval, ties included (the owner test's order). The
/// split warp relies on it: it tests ownership only to find a row's run ends
/// (`warp::warp_owned`). Random cameras, fields of view 40–160° and eyes
/// 0.05–1.55 diagonals away, inside the volume and out.
#[test]
fn perspective_pyramid_pixels_of_a_row_are_one_run() {
    let vol = smooth_blobs([48, 44, 40]);
    let mut next = xorshift(0x1234_5678_9ABC_DEF0);
    let mut rnd = move || (next() >> 11) as f64 / (1u64 << 53) as f64;
    let mut crossings = 0;
    for _ in 0..60 {
        let rot = DMat3::from_euler(EulerRot::XYZ, rnd() * 6.3, rnd() * 6.3, rnd() * 6.3);
        let size = 64 + (rnd() * 100.0) as usize;
        let cam = Camera::new(rot, [size, size]);
        let (fov, d) = (40.0 + rnd() * 120.0, 0.05 + rnd() * 1.5);
        let own = owners(&vol, &cam, &Projection::perspective(fov, d).unwrap());
        for v in 0..size {
            let row = &own[v * size..(v + 1) * size];
            // an owner never comes back once another one took over
            let mut seen = vec![row[0]];
            for u in 1..size {
                if row[u] != row[u - 1] {
                    assert!(!seen.contains(&row[u]), "{fov}° at {d}, {rot:?}: row {v} is {:?} again at pixel {u}", row[u]);
                    seen.push(row[u]);
                    crossings += 1;
                }
            }
        }
    }
    assert!(crossings > 500, "rows crossing a pyramid boundary: {crossings}");
}

/// Squared RGBA difference of one pixel.
fn sq(a: [f32; 4], b: [f32; 4]) -> f64 {
    (0..4).map(|c| ((a[c] - b[c]) as f64).powi(2)).sum::<f64>() / 4.0
}

/// No seam where two pyramids of the split meet. With the eye inside the
/// volume (a 45° view puts the x/z boundary down the middle column; an
/// oblique one gives several boundaries), the error against the reference
/// (true perspective rays) on the pixels beside a boundary is no larger than
/// over the whole image, and the step between the two pixels of each
/// boundary pair is the reference's step.
#[test]
fn perspective_pyramid_boundaries_have_no_seam() {
    let vol = smooth_blobs([48, 44, 40]);
    let tf = TransferFunction::ramp(40.0, 160.0, 0.5, [0.9, 0.7, 0.5]);
    let refr = ReferenceRenderer::new(&vol);
    let opts = ReferenceOptions { step: 0.1, ..Default::default() };
    let proj = Projection::perspective(60.0, 0.1).unwrap();
    let size = 128;
    for rot in [rotate_eye(DMat3::IDENTITY, 1, 45.0), DMat3::from_euler(EulerRot::XYZ, 0.4, 0.7, 0.2)] {
        let cam = Camera::new(rot, [size, size]);
        for mode in [Mode::Blend, Mode::Iso] {
            let mut r = renderer(&vol, &tf, Method::Rle, mode, proj);
            let img = render(&mut r, &cam);
            assert!(r.last_plans().len() >= 2, "the frame is split");
            let want = refr.render_projected(&Scene::from_renderer(&r), &cam, &proj, &opts).unwrap().image;
            let own = owners(&vol, &cam, &proj);
            let (mut edge, mut n_edge, mut step_fast, mut step_ref) = (0.0, 0, 0.0, 0.0);
            let mut pairs = 0;
            for v in 0..size {
                for u in 0..size {
                    let i = v * size + u;
                    let beside = [(u + 1 < size).then(|| i + 1), (v + 1 < size).then(|| i + size)];
                    let mut on_edge = false;
                    for j in beside.into_iter().flatten() {
                        if own[j] != own[i] {
                            on_edge = true;
                            pairs += 1;
                            step_fast += sq(img.data[i], img.data[j]).sqrt();
                            step_ref += sq(want.data[i], want.data[j]).sqrt();
                        }
                    }
                    if on_edge || (u > 0 && own[i - 1] != own[i]) || (v > 0 && own[i - size] != own[i]) {
                        edge += sq(img.data[i], want.data[i]);
                        n_edge += 1;
                    }
                }
            }
            assert!(pairs >= size, "{mode:?}: the boundary crosses the image ({pairs} pairs)");
            let (edge, all) = ((edge / n_edge as f64).sqrt(), rmse(&img, &want).unwrap());
            let (sf, sr) = (step_fast / pairs as f64, step_ref / pairs as f64);
            eprintln!("{mode:?}: RMSE on {n_edge} boundary pixels {edge:.4}, overall {all:.4}; step across {sf:.4} (reference {sr:.4})");
            assert!(edge <= 1.5 * all + 0.005, "{mode:?} {rot:?}: boundary {edge} vs overall {all}");
            assert!(sf <= 1.5 * sr + 0.005, "{mode:?} {rot:?}: step across the boundary {sf} vs reference {sr}");
        }
    }
}

/// The eye inside the volume (0.1 and 0.3 diagonals from the centre) and a
/// wide field of view (120°, the eye near): the split image against the
/// reference, in both modes; the same image for any thread count.
#[test]
fn perspective_eye_inside_and_wide_field_of_view_match_the_reference() {
    let vol = smooth_blobs([48, 44, 40]);
    let tf = TransferFunction::ramp(40.0, 160.0, 0.5, [0.9, 0.7, 0.5]);
    let refr = ReferenceRenderer::new(&vol);
    let opts = ReferenceOptions { step: 0.1, ..Default::default() };
    let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, -0.4, 0.3, 0.1), [96, 96]);
    let (mut report, mut worst) = (vec![], 0f64);
    for (fov, d) in [(60.0, 0.1), (60.0, 0.3), (120.0, 0.1), (120.0, 0.8)] {
        let proj = Projection::perspective(fov, d).unwrap();
        for mode in [Mode::Blend, Mode::Iso] {
            let mut r = renderer(&vol, &tf, Method::Rle, mode, proj);
            let img = render(&mut r, &cam);
            // (from 0.8 diagonals every ray into the volume stays within one
            // pyramid's 63.4°, whatever the field of view)
            assert!(d > 0.5 || r.last_plans().len() >= 2, "{fov}° at {d}: split");
            assert!(img.coverage() > if d < 0.5 { 0.3 } else { 0.02 }, "{fov}° at {d}: coverage {}", img.coverage());
            let want = refr.render_projected(&Scene::from_renderer(&r), &cam, &proj, &opts).unwrap().image;
            let e = rmse(&img, &want).unwrap();
            report.push(format!("{fov}° eye {d} {mode:?}: RMSE {e:.4} ({} pyramids)", r.last_plans().len()));
            let tol = if mode == Mode::Blend { 0.04 } else { 0.12 };
            worst = worst.max(e / tol);
            r.set_settings(Settings { threads: 1, ..r.settings() }).unwrap();
            assert_eq!(bits(&render(&mut r, &cam)), bits(&img), "thread count changed the image");
        }
    }
    eprintln!("{}", report.join("\n"));
    assert!(worst < 1.0, "{}", report.join("\n"));
}

/// Across the principal-axis switch with the eye near and inside the volume
/// (44.9° and 45.1° about y), the image changes no more than the reference
/// does between the same two views.
#[test]
fn perspective_principal_axis_switch_near_and_inside_has_no_jump() {
    let vol = smooth_blobs([44, 44, 44]);
    let tf = TransferFunction::ramp(40.0, 160.0, 0.5, [0.9, 0.7, 0.5]);
    let refr = ReferenceRenderer::new(&vol);
    let opts = ReferenceOptions { step: 0.1, ..Default::default() };
    let (a, b) = (rotate_eye(DMat3::IDENTITY, 1, 44.9), rotate_eye(DMat3::IDENTITY, 1, 45.1));
    for d in [0.75, 0.3, 0.1] {
        let proj = Projection::perspective(60.0, d).unwrap();
        for mode in [Mode::Blend, Mode::Iso] {
            let mut r = renderer(&vol, &tf, Method::Rle, mode, proj);
            let (ca, cb) = (Camera::new(a, [80, 80]), Camera::new(b, [80, 80]));
            let ia = render(&mut r, &ca);
            let ib = render(&mut r, &cb);
            let scene = Scene::from_renderer(&r);
            let ra = refr.render_projected(&scene, &ca, &proj, &opts).unwrap().image;
            let rb = refr.render_projected(&scene, &cb, &proj, &opts).unwrap().image;
            let (jump, ref_jump) = (rmse(&ia, &ib).unwrap(), rmse(&ra, &rb).unwrap());
            let err = rmse(&ia, &ra).unwrap();
            eprintln!("eye {d} {mode:?}: jump {jump:.4}, reference jump {ref_jump:.4}, RMSE to the reference {err:.4}");
            assert!(jump <= 1.5 * ref_jump + 0.01, "eye {d} {mode:?}: jump {jump} vs reference {ref_jump}");
        }
    }
}

/// Early ray termination and the last slice under the split: with the eye
/// inside a dense uniform volume and `ert` 0.5, every pixel stops just past
/// 0.5; with the eye inside an empty box whose only visible voxels are its
/// one-voxel walls, every pixel whose ray meets a wall head-on (within ~20°
/// of its pyramid's axis: the wall is the pyramid's last slice) sees it.
#[test]
fn perspective_split_terminates_rays_and_composites_the_last_slices() {
    let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, 0.2, 0.5, 0.1), [48, 48]);
    let proj = Projection::perspective(100.0, 0.1).unwrap();
    let vol = Volume::from_fn([24, 24, 24], [1.0; 3], |_, _, _| 1.0).unwrap();
    let tf = TransferFunction::new(vec![(0.0, 0.3)], vec![(0.0, [1.0; 3])]).unwrap();
    let walls = Volume::from_fn([20, 22, 18], [1.0; 3], |x, y, z| {
        let edge = |a: usize, n: usize| a == 0 || a + 1 == n;
        if edge(x, 20) || edge(y, 22) || edge(z, 18) { 1.0 } else { 0.0 }
    })
    .unwrap();
    let wall_tf = TransferFunction::new(vec![(0.0, 0.0), (1.0, 0.5)], vec![(0.0, [1.0; 3])]).unwrap();
    let (c, d) = proj.resolve(&cam, walls.dims(), walls.spacing()).unwrap().unwrap();
    let rays = shearwarp::view::PerspectiveView::ray_directions(&c, d, walls.dims(), walls.spacing()).unwrap();
    for method in [Method::Rle, Method::BruteRle] {
        let mk = |vol: &Volume, tf: &TransferFunction, ert: f32| {
            let s = Settings { method, mode: Mode::Blend, ert, threads: 2, ..Settings::default() };
            let mut r = Renderer::new(vol.clone(), tf, s).unwrap();
            r.set_projection(proj).unwrap();
            r
        };
        let mut r = mk(&vol, &tf, 0.5);
        let stopped = render(&mut r, &cam);
        assert!(r.last_plans().len() >= 2);
        let (lo, hi) = stopped.data.iter().fold((1f32, 0f32), |m, p| (m.0.min(p[3]), m.1.max(p[3])));
        assert!(lo >= 0.5 && hi < 0.75, "{method:?}: α in [{lo}, {hi}] with termination at 0.5");
        let mut r = mk(&walls, &wall_tf, 1.0);
        let img = render(&mut r, &cam);
        assert!(r.last_plans().len() >= 2);
        let mut head_on = 0;
        for v in 0..48 {
            for u in 0..48 {
                let dir = rays.at(u as f64, v as f64).abs();
                let m = dir.max_element();
                if dir.x + dir.y + dir.z - m <= 0.35 * m {
                    head_on += 1;
                    let a = img.at(u, v)[3];
                    assert!((a - 0.5).abs() < 0.05, "{method:?} ({u}, {v}): the wall gives α {a}");
                }
            }
        }
        assert!(head_on > 50, "{head_on} pixels meet a wall head-on");
    }
}

/// Flying in across the change from one pyramid to the split (the eye
/// distance where a ray into the volume first passes 63.4°): the image
/// changes between the last one-pyramid frame and the first split frame no
/// more than the reference's does between the same two eyes.
#[test]
fn perspective_fly_in_across_the_split_has_no_jump() {
    let vol = smooth_blobs([44, 40, 36]);
    let tf = TransferFunction::ramp(40.0, 160.0, 0.5, [0.9, 0.7, 0.5]);
    let refr = ReferenceRenderer::new(&vol);
    let opts = ReferenceOptions { step: 0.1, ..Default::default() };
    let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, -0.3, 0.4, 0.1), [80, 80]);
    for mode in [Mode::Blend, Mode::Iso] {
        let mut r = renderer(&vol, &tf, Method::Rle, mode, Projection::Parallel);
        let mut last: Option<(f64, Image)> = None;
        let mut crossed = false;
        for i in 0..60 {
            let d = 1.2 * 0.98f64.powi(i);
            let proj = Projection::perspective(60.0, d).unwrap();
            r.set_projection(proj).unwrap();
            let img = render(&mut r, &cam);
            // (the one-pyramid factorization refuses exactly what needs the split)
            let (c, dist) = proj.resolve(&cam, vol.dims(), vol.spacing()).unwrap().unwrap();
            if shearwarp::view::PerspectiveView::new(&c, dist, vol.dims(), vol.spacing()).is_err() {
                let (d0, before) = last.take().expect("the first frame is one pyramid");
                let scene = Scene::from_renderer(&r);
                let p0 = Projection::perspective(60.0, d0).unwrap();
                let ra = refr.render_projected(&scene, &cam, &p0, &opts).unwrap().image;
                let rb = refr.render_projected(&scene, &cam, &proj, &opts).unwrap().image;
                let (jump, ref_jump) = (rmse(&before, &img).unwrap(), rmse(&ra, &rb).unwrap());
                let (ea, eb) = (rmse(&before, &ra).unwrap(), rmse(&img, &rb).unwrap());
                eprintln!("{mode:?}: split from {d:.3} diagonals: jump {jump:.4}, reference {ref_jump:.4}; RMSE {ea:.4} → {eb:.4}");
                assert!(jump <= 1.5 * ref_jump + 0.01, "{mode:?}: jump {jump} vs reference {ref_jump}");
                crossed = true;
                break;
            }
            last = Some((d, img));
        }
        assert!(crossed, "the fly-in never reached the split");
    }
}
