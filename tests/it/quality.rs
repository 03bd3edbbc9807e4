//! The adaptive intermediate image size (Schulze et al.): `q`
//! intermediate pixels per voxel, in both projections. The accelerated RLE
//! path and the binary rotator equal their brute forces at every `q`; `q = 1` is the classic image
//! bit for bit; the image at any `q` stays close to the reference; the intermediate image's
//! pixel count scales with `q²`.

use crate::common;

use common::{bits, blobs, render};
use glam::{DMat3, EulerRot};
use shearwarp::accuracy::metrics::rmse;
use shearwarp::accuracy::reference::{ReferenceOptions, Scene};
use shearwarp::classify::TransferFunction;
use shearwarp::classify::presets;
use shearwarp::composite::Mode;
use shearwarp::data::phantom::{self, SPHERE_ISO};
use shearwarp::data::volume::Volume;
use shearwarp::render::{Method, Renderer, Settings};
use shearwarp::view::{Camera, Projection, rotate_eye};

/// [`common::renderer`] at `q` intermediate pixels per voxel.
fn renderer(vol: &Volume, tf: &TransferFunction, method: Method, mode: Mode, projection: Projection, q: f64) -> Renderer {
    let mut r = common::renderer(vol, tf, method, mode, projection);
    r.set_quality(q).unwrap();
    r
}

/// Accelerated RLE equals its brute force bit for bit at every quality, in
/// both projections (one pyramid and the split) and modes, over random volumes and views, for any thread
/// count; and quality 1 is the default image.
#[test]
fn quality_rle_equals_brute_force_bit_for_bit_in_both_projections() {
    let mut rnd = common::uniform(21);
    let mut checked = 0;
    for case in 0..20 {
        let dims = [14 + (rnd() * 12.0) as usize, 12 + (rnd() * 12.0) as usize, 10 + (rnd() * 14.0) as usize];
        let sp = [[1.0, 1.0, 1.0], [1.0, 0.7, 1.6]][case % 2];
        let vol = blobs(dims, 300 + case as u64, sp);
        let tf = TransferFunction::ramp(40.0, 160.0, 0.5, [0.9, 0.7, 0.5]);
        let rot = DMat3::from_euler(EulerRot::XYZ, rnd() * 7.0, rnd() * 7.0, rnd() * 7.0);
        // parallel, one pyramid, and the split (the eye near or inside)
        let proj = match case % 4 {
            0 => Projection::Parallel,
            3 => Projection::perspective(40.0 + rnd() * 50.0, 0.1 + rnd() * 0.5).unwrap(),
            _ => Projection::perspective(15.0 + rnd() * 40.0, 2.0 + rnd() * 2.0).unwrap(),
        };
        let q = [0.25, 0.5, 0.8, 1.5, 2.0][case % 5];
        let cam = Camera::new(rot, [56, 48]);
        let mode = if case % 2 == 0 { Mode::Blend } else { Mode::Iso };
        // the binary rotator and its brute force too
        let mut bin = renderer(&vol, &tf, Method::Binary, mode, proj, q);
        let mut bin_brute = renderer(&vol, &tf, Method::Brute, mode, proj, q);
        let (x, y) = (render(&mut bin, &cam), render(&mut bin_brute, &cam));
        assert!(x.coverage() > 0.0, "case {case}: empty binary image");
        assert_eq!(bits(&x), bits(&y), "case {case} q {q} {proj:?}: binary and brute force differ");
        let mut fast = renderer(&vol, &tf, Method::Rle, mode, proj, q);
        let mut brute = renderer(&vol, &tf, Method::BruteRle, mode, proj, q);
        let a = render(&mut fast, &cam);
        let b = render(&mut brute, &cam);
        assert!(a.coverage() > 0.0, "case {case}: empty image");
        assert_eq!(bits(&a), bits(&b), "case {case} q {q} {proj:?}: RLE and brute force differ");
        fast.set_settings(Settings { threads: 1, ..fast.settings() }).unwrap();
        assert_eq!(bits(&render(&mut fast, &cam)), bits(&a), "case {case}: thread count changed the image");
        // back to one pixel per voxel: the default image, bit for bit
        fast.set_quality(1.0).unwrap();
        let one = render(&mut fast, &cam);
        let default = render(&mut renderer(&vol, &tf, Method::Rle, mode, proj, 1.0), &cam);
        assert_eq!(bits(&one), bits(&default), "case {case}: quality 1 is not the default image");
        checked += 1;
    }
    assert_eq!(checked, 20);
}

/// The binary rotator's parallel frames at another pixel pitch (`--quality`,
/// Deluxe M) walk rays that do not drift across the mask: each reads the one
/// or two columns per axis its cells sit in (`StillWalk`). They equal the
/// brute force bit for bit over random volumes, views and pitches (0.25–2
/// pixels per voxel), with super cells 1–4, u32/u64 words, LUT and bit scan,
/// the tissue presets' threshold codes, Deluxe I, both modes, early
/// termination on and off, and anisotropic voxels.
#[test]
fn quality_binary_still_walk_equals_brute_force() {
    use shearwarp::encode::depth::Search;
    use shearwarp::render::{Deluxe, WordSize};
    let mut rnd = common::uniform(31);
    let mut checked = 0;
    for case in 0..48 {
        let dims = [6 + (rnd() * 20.0) as usize, 5 + (rnd() * 20.0) as usize, 4 + (rnd() * 44.0) as usize];
        let sp = [[1.0, 1.0, 1.0], [1.0, 0.7, 1.6], [0.8, 1.2, 1.0]][case % 3];
        let vol = blobs(dims, 700 + case as u64, sp);
        let rot = DMat3::from_euler(EulerRot::XYZ, rnd() * 7.0, rnd() * 7.0, rnd() * 7.0);
        let q = 0.25 + rnd() * 1.75;
        let s = Settings {
            mode: if case % 2 == 0 { Mode::Blend } else { Mode::Iso },
            threads: 2,
            cell: 1 + (case / 2) % 4,
            word: if case % 3 == 0 { WordSize::U32 } else { WordSize::U64 },
            search: if case % 5 == 4 { Search::Lut } else { Search::Bitscan },
            ert: if case % 4 == 1 { 0.95 } else { 1.0 },
            deluxe: Deluxe { intermediate: case % 6 == 5, post: false, matched: false },
            ..Settings::default()
        };
        let tissues = case % 5 == 3;
        let tf = common::random_tf(case as u64 * 5 + 3);
        let make = |method| {
            let mut r = if tissues {
                let ts = presets::tissues_for(&vol);
                let n = ts.len().min(3);
                let mut r = Renderer::with_tissues(vol.clone(), &ts[..n], Settings { method, ..s }).unwrap();
                // every tissue in turn: the higher thresholds' codes (3 of a
                // 2-bit code) make the walk's OR of columns a strict superset
                r.select_tissue(case % n).unwrap();
                r
            } else {
                Renderer::new(vol.clone(), &tf, Settings { method, ..s }).unwrap()
            };
            r.set_quality(q).unwrap();
            r
        };
        let cam = Camera::new(rot, [52, 44]);
        let (a, b) = (render(&mut make(Method::Binary), &cam), render(&mut make(Method::Brute), &cam));
        assert_eq!(bits(&a), bits(&b), "case {case} q {q} {s:?}: binary and brute force differ");
        if a.coverage() > 0.0 {
            checked += 1;
        }
    }
    assert!(checked >= 40, "only {checked} non-empty views");
}

/// The image at every quality against the reference ray caster on the
/// sphere phantom, at 0°, 45° and the main diagonal, both projections, where
/// the output magnifies (a 40³ sphere in 128² pixels): the error grows as the
/// grid coarsens and stays bounded, and the fine grid is about as good as one
/// pixel per voxel.
#[test]
fn quality_images_track_the_reference_in_both_projections() {
    let (vol, tf, refr) = common::sphere_scene();
    let opts = ReferenceOptions { step: 0.1, ..Default::default() };
    let views = common::three_views();
    let mut report = vec![];
    for (name, rot) in views {
        let cam = Camera::new(rot, [128, 128]);
        for proj in [Projection::Parallel, Projection::perspective(40.0, 2.0).unwrap()] {
            let want = {
                let r = renderer(&vol, &tf, Method::Rle, Mode::Blend, proj, 1.0);
                refr.render_projected(&Scene::from_renderer(&r), &cam, &proj, &opts).unwrap().image
            };
            let mut errs = vec![];
            for q in [0.25, 0.5, 1.0, 2.0] {
                let mut r = renderer(&vol, &tf, Method::Rle, Mode::Blend, proj, q);
                let img = render(&mut r, &cam);
                let e = rmse(&img, &want).unwrap();
                errs.push((q, e));
                let tol = if q < 0.5 { 0.06 } else { 0.03 };
                assert!(e < tol, "{name} {proj:?} q {q}: RMSE {e}");
            }
            let e = |q: f64| errs.iter().find(|x| x.0 == q).unwrap().1;
            // pre-classified slices blend classified colours between voxels, so a
            // finer grid resamples the same blend (the warp's bilinear did it
            // before): about the same error, not less (matched sampling with
            // post-classification is what removes the blur)
            assert!(e(2.0) <= e(1.0) * 1.5, "{name} {proj:?}: the finer grid is much worse: {errs:?}");
            assert!(e(0.25) >= e(0.5) && e(0.5) >= e(1.0) * 0.98, "{name} {proj:?}: coarser grids are not coarser: {errs:?}");
            report.push(format!("{name} {}: {errs:?}", if proj.is_perspective() { "perspective" } else { "parallel" }));
        }
    }
    eprintln!("{}", report.join("\n"));
}

/// The intermediate image has about `q²` times the pixels of the slices'
/// box, in both projections (the perspective grid at quality 1 is that box;
/// the parallel one is padded for the shear of any view, and a resampled grid
/// holds this view's slices only), and the quality is checked.
#[test]
fn quality_scales_the_intermediate_image_and_is_checked() {
    let vol = phantom::sphere([48, 48, 48]).unwrap();
    let tf = presets::generic(SPHERE_ISO, 200.0).tf;
    let cam = Camera::new(rotate_eye(DMat3::IDENTITY, 1, 30.0), [96, 96]);
    for proj in [Projection::Parallel, Projection::perspective(30.0, 3.0).unwrap()] {
        let mut r = renderer(&vol, &tf, Method::Rle, Mode::Iso, proj, 1.0);
        render(&mut r, &cam);
        let base = r.intermediate().size;
        for q in [0.25, 0.5, 2.0] {
            r.set_quality(q).unwrap();
            render(&mut r, &cam);
            let s = r.intermediate().size;
            for a in 0..2 {
                let want = base[a] as f64 * q;
                if proj.is_perspective() {
                    assert!((s[a] as f64 - want).abs() <= 6.0, "{proj:?} q {q}: {s:?} for {base:?}");
                } else {
                    // at least the volume's 47 cells, at most the padded grid
                    assert!(s[a] as f64 >= 47.0 * q && s[a] as f64 <= want + 6.0, "{proj:?} q {q}: {s:?} for {base:?}");
                }
            }
        }
        for bad in [0.0, 0.2, 2.5, f64::NAN, f64::INFINITY, -1.0] {
            assert!(r.set_quality(bad).is_err(), "quality {bad} accepted");
        }
        assert_eq!(r.quality(), 2.0);
    }
}

/// `--quality Q` on the CLI: renders with the RLE path (the JSON says the
/// quality), and a bad value or the binary rotator is a usage error (exit 2).
#[test]
fn quality_cli_renders_and_rejects_bad_values() {
    use assert_cmd::Command;
    use predicates::prelude::*;
    let dir = tempfile::tempdir().unwrap();
    let sw = || Command::cargo_bin("shearwarp").unwrap();
    let base = ["render", "--phantom", "sphere", "--phantom-dims", "32,32,32", "--size", "64", "--json"];
    let out = sw().args(base).args(["--method", "rle", "--quality", "0.5", "-o"]).arg(dir.path().join("q.png")).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(j["quality"].as_f64(), Some(0.5));
    assert!(j["coverage"].as_f64().unwrap() > 0.1);
    for bad in ["0", "0.1", "3", "nan", "-1", "x"] {
        sw().args(base)
            .args(["--method", "rle", "--quality", bad, "-o"])
            .arg(dir.path().join("bad.png"))
            .assert()
            .code(2)
            .stderr(predicate::str::contains("quality"));
    }
    // the binary rotator (the default) too
    let out = sw().args(base).args(["--quality", "0.5", "-o"]).arg(dir.path().join("b.png")).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    sw().args(["rotate", "--phantom", "sphere", "--phantom-dims", "24,24,24", "--size", "32", "--degrees", "4", "--step-deg", "2"])
        .args(["--method", "rle", "--quality", "1.5", "--json"])
        .assert()
        .success()
        .stdout(predicate::str::contains("\"quality\":1.5"));
}

/// The box footprint of a minified slice ("a box footprint over
/// opacity-weighted colours where it is minified"): at a quarter pixel per
/// voxel a one-voxel-thin slab contributes the same total opacity to the
/// intermediate image wherever it sits between two pixels (one slice thick,
/// so compositing adds no non-linearity) — no voxel falls
/// between them — while the bilinear sample at each pixel's centre misses it
/// at some positions. Both footprints: accelerated equals brute force.
#[test]
fn quality_box_footprint_sees_every_voxel() {
    use shearwarp::render::Footprint;
    let dims = [48, 40, 24];
    let tf = TransferFunction::ramp(40.0, 160.0, 0.3, [0.9, 0.8, 0.7]);
    let cam = Camera::new(DMat3::IDENTITY, [96, 96]);
    let mut totals = vec![];
    for footprint in [Footprint::Box, Footprint::Bilinear] {
        let mut t = vec![];
        for x0 in 20..24 {
            let vol =
                Volume::from_fn(dims, [1.0; 3], |x, y, z| if x == x0 && (4..36).contains(&y) && z == 10 { 200.0 } else { 0.0 }).unwrap();
            let mut sums = vec![];
            for method in [Method::Rle, Method::BruteRle] {
                let s = Settings { method, mode: Mode::Blend, threads: 2, footprint, ..Settings::default() };
                let mut r = Renderer::new(vol.clone(), &tf, s).unwrap();
                r.set_quality(0.25).unwrap();
                let img = render(&mut r, &cam);
                sums.push((r.intermediate().rgba.iter().map(|p| p[3] as f64).sum::<f64>(), bits(&img)));
            }
            assert_eq!(sums[0].1, sums[1].1, "{footprint:?} slab at {x0}: RLE and brute force differ");
            t.push(sums[0].0);
        }
        totals.push(t);
    }
    let spread = |t: &[f64]| t.iter().cloned().fold(f64::MIN, f64::max) / t.iter().cloned().fold(f64::MAX, f64::min);
    eprintln!("total opacity by slab position: box {:?}, bilinear {:?}", totals[0], totals[1]);
    assert!(totals[0].iter().all(|&x| x > 0.0) && spread(&totals[0]) < 1.001, "box: {:?}", totals[0]);
    assert!(totals[1].contains(&0.0) || spread(&totals[1]) > 1.5, "bilinear: {:?}", totals[1]);
}

/// A still `render` never magnifies its intermediate image: by default a
/// zoomed frame is byte for byte the frame rendered with matched sampling
/// (`--deluxe M`), finer than the one-ray-per-voxel frame (`--sampling
/// voxel`, which keeps the steps); a frame that does not magnify is the same
/// either way. Binary and RLE, parallel and perspective.
#[test]
fn still_render_samples_matched_where_the_output_magnifies() {
    use assert_cmd::Command;
    let dir = tempfile::tempdir().unwrap();
    let render = |name: &str, extra: &[&str]| -> (Vec<u8>, serde_json::Value) {
        let png = dir.path().join(format!("{name}.png"));
        let out = Command::cargo_bin("shearwarp")
            .unwrap()
            .args(["render", "--phantom", "head", "--phantom-dims", "24,24,24", "--tissue", "bone", "--json", "-o"])
            .arg(&png)
            .args(extra)
            .output()
            .unwrap();
        assert!(out.status.success(), "{name}: {}", String::from_utf8_lossy(&out.stderr));
        (std::fs::read(&png).unwrap(), serde_json::from_slice(&out.stdout).unwrap())
    };
    for (case, view) in [
        ("binary", &["--size", "192"][..]),
        ("rle", &["--size", "192", "--method", "rle"][..]),
        ("perspective", &["--size", "128", "--method", "rle", "--perspective", "50", "--eye-distance", "0.8"][..]),
    ] {
        let (still, j) = render(&format!("{case}-still"), view);
        let (matched, _) = render(&format!("{case}-matched"), &[view, &["--sampling", "voxel", "--deluxe", "M"]].concat());
        let (voxel, jv) = render(&format!("{case}-voxel"), &[view, &["--sampling", "voxel"]].concat());
        assert_eq!(still, matched, "{case}: the still frame is not the matched frame");
        assert_ne!(still, voxel, "{case}: a magnified frame rendered as one ray per voxel");
        assert!(j["rays"].as_f64().unwrap() > 2.0 * jv["rays"].as_f64().unwrap(), "{case}: {} rays against {}", j["rays"], jv["rays"]);
        assert_eq!(j["sampling"], "matched");
        assert_eq!(jv["sampling"], "voxel");
    }
    // minified: one ray per voxel already covers every output pixel
    let (still, _) = render("small-still", &["--size", "12"]);
    let (voxel, _) = render("small-voxel", &["--size", "12", "--sampling", "voxel"]);
    assert_eq!(still, voxel, "a frame that does not magnify changed");
}
