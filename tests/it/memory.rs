//! Memory checks: every structure is reported, the prediction made
//! before building matches what is built, a budget that cannot hold a view
//! fails with a clear error before anything is allocated, other axes are
//! freed to make room, and `--max-memory` works from the command line.

use assert_cmd::Command;
use glam::DMat3;
use predicates::prelude::*;
use shearwarp::classify::presets;
use shearwarp::render::{Method, estimate_axis};
use shearwarp::{Camera, Error, Image, Renderer, Settings, Volume};

fn volume() -> Volume {
    Volume::from_fn([40, 36, 30], [1.0, 1.0, 1.2], |x, y, z| {
        let d = ((x as f32 - 20.0).powi(2) + (y as f32 - 18.0).powi(2) + (z as f32 - 15.0).powi(2)).sqrt();
        ((14.0 - d) * 40.0).clamp(0.0, 255.0).round()
    })
    .unwrap()
    .window_u8(0.0, 255.0)
    .unwrap()
}

fn renderer(method: Method) -> Renderer {
    let v = volume();
    let tissues = presets::tissues_for(&v);
    Renderer::with_tissues(v, &tissues, Settings { method, threads: 2, ..Settings::default() }).unwrap()
}

/// The code width of the renderer's tissue mask.
fn bits(r: &Renderer) -> u32 {
    shearwarp::encode::depth::code_width_for(r.tissues().map_or(1, |t| t.0.len())).unwrap()
}

/// Cameras whose principal axis is x, y and z.
fn along(axis: usize) -> Camera {
    let r = match axis {
        0 => DMat3::from_rotation_y(std::f64::consts::FRAC_PI_2 - 0.1),
        1 => DMat3::from_rotation_x(std::f64::consts::FRAC_PI_2 - 0.1),
        _ => DMat3::from_rotation_y(0.1),
    };
    Camera::new(r, [48, 48])
}

#[test]
fn the_prediction_matches_what_a_frame_builds() {
    for method in [Method::Binary, Method::Brute, Method::Rle] {
        for axis in 0..3 {
            let mut r = renderer(method);
            let before = r.memory();
            assert_eq!(before.total(), before.volume, "{method:?}: nothing but the volume before the first frame");
            assert_eq!(before.volume, 40 * 36 * 30);
            let est = estimate_axis(&r.volume().unwrap(), &r.settings(), bits(&r), axis);
            let mut img = Image::new(48, 48);
            let st = r.render(&along(axis), &mut img).unwrap();
            assert_eq!(st.axis, axis);
            let m = r.memory();
            assert_eq!(m.stacks, est.stacks, "{method:?} axis {axis}");
            assert_eq!(m.normals, est.normals, "{method:?} axis {axis}");
            assert_eq!(m.cell_codes, est.cell_codes, "{method:?} axis {axis}");
            assert_eq!(m.intermediate, est.intermediate, "{method:?} axis {axis}");
            for a in 0..3 {
                // the mask's prediction is an upper bound, tight within 10 %
                assert!(
                    m.masks[a] <= est.masks[a] && est.masks[a] as f64 <= 1.1 * m.masks[a] as f64,
                    "{method:?} {:?} {:?}",
                    m.masks,
                    est.masks
                );
            }
            assert_eq!((0..3).filter(|&a| m.axis_total(a) > 0).collect::<Vec<_>>(), [axis], "only the view's axis is built");
            if method == Method::Rle {
                assert!(m.rle[axis] > 0);
            }
            assert_eq!(m.total(), m.volume + m.axis_total(axis) + m.intermediate);
        }
    }
}

#[test]
fn the_prediction_holds_for_super_cells() {
    for cell in [2, 3, 8] {
        let mut r = renderer(Method::Binary);
        r.set_settings(Settings { cell, ..r.settings() }).unwrap();
        let est = estimate_axis(&r.volume().unwrap(), &r.settings(), bits(&r), 1);
        r.render(&along(1), &mut Image::new(48, 48)).unwrap();
        let m = r.memory();
        assert_eq!(m.cell_codes, est.cell_codes, "cell {cell}");
        assert!(m.masks[1] <= est.masks[1] && est.masks[1] as f64 <= 1.1 * m.masks[1] as f64, "cell {cell}: {:?} {:?}", m.masks, est.masks);
    }
}

#[test]
fn a_budget_too_small_fails_before_allocating() {
    let mut r = renderer(Method::Binary);
    let volume_bytes = r.memory().volume;
    r.set_memory_budget(Some(volume_bytes + 1000));
    let mut img = Image::new(48, 48);
    let e = r.render(&along(2), &mut img).unwrap_err();
    assert!(matches!(e, Error::Memory { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(msg.contains("memory budget") && msg.contains("along z"), "{msg}");
    assert_eq!(r.memory().total(), volume_bytes, "nothing was allocated");
    // a budget that holds the view renders it, the same image as no budget
    let need = volume_bytes + estimate_axis(&r.volume().unwrap(), &r.settings(), bits(&r), 2).total() - volume_bytes;
    r.set_memory_budget(Some(need));
    r.render(&along(2), &mut img).unwrap();
    let mut free = renderer(Method::Binary);
    let mut img2 = Image::new(48, 48);
    free.render(&along(2), &mut img2).unwrap();
    assert_eq!(img, img2);
}

#[test]
fn other_axes_are_freed_to_fit_the_budget() {
    let mut r = renderer(Method::Binary);
    let one = (0..3).map(|a| estimate_axis(&r.volume().unwrap(), &r.settings(), bits(&r), a).total()).max().unwrap();
    // room for the volume and one axis, not two
    r.set_memory_budget(Some(one + 1000));
    let mut img = Image::new(48, 48);
    for axis in [0, 2, 1, 0] {
        r.render(&along(axis), &mut img).unwrap();
        let m = r.memory();
        assert!(m.total() <= one + 1000);
        assert!(m.axis_total(axis) > 0);
        for a in (0..3).filter(|&a| a != axis) {
            assert_eq!(m.axis_total(a), 0, "axis {a} freed while rendering along {axis}");
        }
    }
    // a prefetch never evicts: with room for one axis it builds nothing more
    assert!(!r.prefetch_axis(2).unwrap());
    assert!(r.memory().axis_total(0) > 0 && r.memory().axis_total(2) == 0);
    // with room for all three it builds them
    r.set_memory_budget(Some(3 * one));
    assert!(r.prefetch_axis(2).unwrap() && r.prefetch_axis(1).unwrap());
    assert!((0..3).all(|a| r.memory().axis_total(a) > 0));
    // with no budget all three stay
    let mut r = renderer(Method::Binary);
    for axis in 0..3 {
        r.render(&along(axis), &mut img).unwrap();
    }
    assert!((0..3).all(|a| r.memory().axis_total(a) > 0));
}

fn sw() -> Command {
    Command::cargo_bin("shearwarp").expect("binary")
}

#[test]
fn max_memory_on_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("a.png");
    let small = ["--phantom-dims", "64,64,48", "--size", "64"];
    // the volume alone (64·64·48 i16 = 384 KiB) does not fit: a usage error
    sw().args(["render", "--max-memory", "100k", "-o"]).arg(&out).args(small).assert().code(2).stderr(
        predicate::str::contains("--max-memory").and(predicate::str::contains("384.0 KiB")).and(predicate::str::contains("panicked").not()),
    );
    // the volume fits, its structures do not: a clear error naming the budget
    sw().args(["render", "--max-memory", "1M", "-o"])
        .arg(&out)
        .args(small)
        .assert()
        .failure()
        .stderr(predicate::str::contains("memory budget of 1.0 MiB").and(predicate::str::contains("panicked").not()));
    assert!(!out.exists());
    // enough: renders, and the JSON reports every structure within the budget
    let o = sw().args(["render", "--max-memory", "64M", "--json", "-o"]).arg(&out).args(small).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let m = &j["memory"];
    // the binary path let go of the volume: its packed cells hold the voxels
    // (2 bytes each) beside their 2-byte normal codes
    assert_eq!(m["volume"], 0);
    assert_eq!(m["normals"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).sum::<u64>(), 64 * 64 * 48 * 4);
    assert_eq!(m["budget"], 64 << 20);
    let total = m["total"].as_u64().unwrap();
    assert!(total > 64 * 64 * 48 * 4 && total <= 64 << 20);
    for k in ["stacks", "normals", "cell_codes", "masks", "rle"] {
        assert_eq!(m[k].as_array().unwrap().len(), 3, "{k}");
    }
    assert!(j["first_frame_ms"].as_f64().unwrap() >= j["load_ms"].as_f64().unwrap());
    // bad values are usage errors
    for bad in ["0", "lots", "5X", "-1G"] {
        sw().args(["render", "--max-memory", bad, "-o"]).arg(&out).args(small).assert().code(2);
    }
    // every command that loads a volume takes it
    let den = dir.path().join("x.den");
    for cmd in [&["rotate"][..], &["info"], &["bench"], &["export", "-o", den.to_str().unwrap()]] {
        sw().args(cmd)
            .args(["--max-memory", "100k", "--phantom-dims", "64,64,48"])
            .assert()
            .code(2)
            .stderr(predicate::str::contains("over the memory budget of 100.0 KiB (--max-memory)"));
    }
}

#[test]
fn the_binary_path_of_an_integer_scan_holds_no_f32_stack_and_renders_the_same() {
    let mut img = Image::new(48, 48);
    let mut reference = Image::new(48, 48);
    for axis in 0..3 {
        let mut r = renderer(Method::Binary);
        r.render(&along(axis), &mut img).unwrap();
        let m = r.memory();
        assert_eq!(m.stacks, [0; 3], "no f32 stack on the binary path of an integer scan");
        // the u8 densities packed with 2-byte codes, and no volume beside them
        assert_eq!(m.normals[axis], 3 * 40 * 36 * 30);
        assert_eq!(m.volume, 0);
        // the volume comes back, voxel for voxel
        assert_eq!(*r.volume().unwrap(), volume(), "axis {axis}");
        // the layout with the f32 stack and the codes apart gives the same image
        let mut apart = renderer(Method::Binary);
        apart.set_settings(Settings { pack: false, ..apart.settings() }).unwrap();
        apart.render(&along(axis), &mut reference).unwrap();
        assert!(apart.memory().stacks[axis] > 0);
        assert_eq!(img, reference, "axis {axis}");
        // other paths bring the stack in when they need it, and back
        r.set_settings(Settings { method: Method::Brute, ..r.settings() }).unwrap();
        r.render(&along(axis), &mut reference).unwrap();
        assert!(r.memory().stacks[axis] > 0);
        r.set_settings(Settings { method: Method::Binary, ..r.settings() }).unwrap();
        let mut again = Image::new(48, 48);
        r.render(&along(axis), &mut again).unwrap();
        assert_eq!(again, img);
        // a new classification re-codes the cells from the packed densities
        let mut r = renderer(Method::Binary);
        r.render(&along(axis), &mut img).unwrap();
        r.set_iso(140.0).unwrap();
        r.render(&along(axis), &mut img).unwrap();
        let mut fresh = renderer(Method::Binary);
        fresh.set_settings(Settings { pack: false, ..fresh.settings() }).unwrap();
        fresh.set_iso(140.0).unwrap();
        fresh.render(&along(axis), &mut reference).unwrap();
        assert_eq!(img, reference, "axis {axis}, iso 140");
        assert_eq!(r.memory().stacks, [0; 3]);
    }
}

#[test]
fn a_volume_shared_outside_the_renderer_is_kept() {
    for axis in 0..3 {
        let v = volume();
        let tissues = presets::tissues_for(&v);
        // the caller keeps a handle of the voxels: the renderer cannot free them, so it keeps its own
        let mut r = Renderer::with_tissues(v.clone(), &tissues, Settings { threads: 2, ..Settings::default() }).unwrap();
        let mut img = Image::new(48, 48);
        r.render(&along(axis), &mut img).unwrap();
        let m = r.memory();
        assert_eq!(m.volume, 40 * 36 * 30, "axis {axis}");
        assert_eq!(m.normals[axis], 3 * 40 * 36 * 30, "axis {axis}");
        let mut alone = renderer(Method::Binary);
        let mut img2 = Image::new(48, 48);
        alone.render(&along(axis), &mut img2).unwrap();
        assert_eq!(img, img2, "axis {axis}");
        // a renderer that let go of its volume builds the other axes and paths from its packed cells
        for (a, method) in [(0, Method::Binary), (1, Method::Rle), (2, Method::Binary), (axis, Method::Brute)] {
            alone.set_settings(Settings { method, ..alone.settings() }).unwrap();
            r.set_settings(Settings { method, ..r.settings() }).unwrap();
            alone.render(&along(a), &mut img2).unwrap();
            r.render(&along(a), &mut img).unwrap();
            assert_eq!(img, img2, "axis {axis} then {a} {method:?}");
        }
        assert_eq!(*alone.volume().unwrap(), v);
    }
}
