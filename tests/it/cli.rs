//! The command-line tool as a user runs it: help, renders, real files, errors
//! and their exit codes.

use assert_cmd::Command;
use predicates::prelude::*;

fn sw() -> Command {
    Command::cargo_bin("shearwarp").expect("binary")
}

#[test]
fn help_lists_commands_and_examples() {
    sw().arg("--help")
        .assert()
        .success()
        .stdout(predicate::str::contains("render").and(predicate::str::contains("rotate")).and(predicate::str::contains("Examples")));
    for c in ["render", "rotate", "info"] {
        sw().args([c, "--help"]).assert().success().stdout(predicate::str::contains("--phantom"));
    }
}

#[test]
fn render_writes_a_non_blank_png() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("head.png");
    sw().args(["render", "--phantom-dims", "48,48,42", "--size", "96", "-o"])
        .arg(&out)
        .arg("--json")
        .assert()
        .success()
        .stdout(predicate::str::contains("\"coverage\""));
    let img = image::open(&out).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (96, 96));
    let lit = img.pixels().filter(|p| p.0.iter().any(|&c| c > 20)).count();
    assert!(lit > 500, "only {lit} lit pixels");
}

/// The frames `rotate` writes (`--frames-dir`, `--gif`, `--apng`) are stills
/// where the output magnifies: frame 0 is `render`'s image of the same view;
/// with `--sampling voxel` it is the timed frame (one ray per voxel), which
/// differs.
#[test]
fn rotate_writes_the_stills_render_draws() {
    let dir = tempfile::tempdir().unwrap();
    let (frames, voxel, still) = (dir.path().join("f"), dir.path().join("v"), dir.path().join("r.png"));
    let view = ["--phantom-dims", "40,40,36", "--size", "160", "--quiet"];
    sw().args(["rotate", "--degrees", "2", "--step-deg", "1", "--frames-dir"]).arg(&frames).args(view).assert().success();
    sw().args(["rotate", "--degrees", "2", "--step-deg", "1", "--sampling", "voxel", "--frames-dir"])
        .arg(&voxel)
        .args(view)
        .assert()
        .success();
    sw().args(["render", "-o"]).arg(&still).args(view).assert().success();
    let png = |p: &std::path::Path| image::open(p).unwrap().to_rgb8();
    assert!(png(&frames.join("frame_00000.png")) == png(&still), "a written frame is not render's still");
    assert!(png(&voxel.join("frame_00000.png")) != png(&still), "the view does not magnify: no test of matched sampling");
    assert_eq!(std::fs::read_dir(&frames).unwrap().count(), 2);
}

#[test]
fn rotate_json_has_the_promised_fields() {
    let out = sw().args(["rotate", "--phantom-dims", "40,40,36", "--size", "64", "--degrees", "10", "--json"]).output().unwrap();
    assert!(out.status.success());
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for k in ["frames", "degrees", "shear_ms_median", "render_ms_median", "warp_ms_median", "frame_ms_median", "fps", "degrees_per_second"]
    {
        assert!(j[k].is_number(), "missing {k}: {j}");
    }
    assert!(j["frames"].as_u64().unwrap() >= 1);
}

/// `--cell auto` (the default): a rotation of tissue presets (two-bit codes)
/// over more than 256 slices takes super cells of 2, a one-bit mask of the
/// same volume cell size 1, and a still frame 1; the frames are those of
/// cell size 1, byte for byte.
#[test]
fn rotate_takes_the_cell_size_of_its_depth_rows() {
    let dir = tempfile::tempdir().unwrap();
    let run = |args: &[&str], gif: &str| -> serde_json::Value {
        let out = sw()
            .args([
                "rotate",
                "--phantom-dims",
                "24,20,300",
                "--view",
                "anterior",
                "--size",
                "48",
                "--degrees",
                "4",
                "--step-deg",
                "2",
                "--json",
            ])
            .args(args)
            .arg("--gif")
            .arg(dir.path().join(gif))
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_slice(&out.stdout).unwrap()
    };
    assert_eq!(run(&["--tissue", "bone"], "auto.gif")["cell"], 2);
    assert_eq!(run(&["--tissue", "bone", "--cell", "1"], "one.gif")["cell"], 1);
    assert_eq!(run(&["--iso", "300"], "iso.gif")["cell"], 1);
    let read = |f: &str| std::fs::read(dir.path().join(f)).unwrap();
    assert!(read("auto.gif") == read("one.gif"), "super cells changed the frames");
    let out = sw()
        .args(["render", "--phantom-dims", "24,20,300", "--tissue", "bone", "--size", "32", "--json", "-o"])
        .arg(dir.path().join("r.png"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(j["cell"], 1, "{j}");
    sw().args(["rotate", "--cell", "9"]).assert().code(2).stderr(predicate::str::contains("must be auto or 1..=8"));
}

#[test]
fn rotate_cycles_tissues_and_writes_animations() {
    let dir = tempfile::tempdir().unwrap();
    let gif = dir.path().join("t.gif");
    let apng = dir.path().join("t.png");
    sw().args(["rotate", "--phantom-dims", "32,32,28", "--size", "48", "--degrees", "12", "--cell", "2", "--cycle-tissues", "2", "--gif"])
        .arg(&gif)
        .arg("--apng")
        .arg(&apng)
        .arg("--json")
        .assert()
        .success()
        .stdout(predicate::str::contains("\"tissue_switches\""));
    assert!(std::fs::metadata(&gif).unwrap().len() > 100);
    let png = std::fs::read(&apng).unwrap();
    assert!(png.windows(4).any(|w| w == b"acTL"), "APNG has no animation control chunk");
}

#[test]
fn bad_input_is_a_clear_error_with_exit_code_2() {
    let dir = tempfile::tempdir().unwrap();
    let short = dir.path().join("short.raw");
    std::fs::write(&short, vec![0u8; 100]).unwrap();
    sw().args(["render", "--raw"])
        .arg(&short)
        .args(["--dims", "10,10,10", "--type", "u8"])
        .assert()
        .code(2)
        .stderr(predicate::str::contains("short.raw"));
    sw().args(["render", "/no/such/file.nrrd"]).assert().code(2).stderr(predicate::str::contains("/no/such/file.nrrd"));
    sw().args(["render", "--tissue", "liver"]).assert().code(2).stderr(predicate::str::contains("unknown tissue"));
    sw().args(["render", "--cell", "0"]).assert().code(2);
    sw().args(["render", "--dims", "0,1,1", "--raw", "x"]).assert().code(2);
    let garbage = dir.path().join("garbage.nrrd");
    std::fs::write(&garbage, b"NRRD0004\ntype: short\ndimension: 3\nsizes: 100000 100000 100000\nencoding: raw\n\n").unwrap();
    sw().arg("info").arg(&garbage).assert().code(2).stderr(predicate::str::contains("garbage.nrrd"));
}

#[test]
fn closed_stdout_is_not_a_panic() {
    // `shearwarp info | head -1` must not panic when head closes the pipe
    let mut child = std::process::Command::new(assert_cmd::cargo::cargo_bin("shearwarp"))
        .args(["info", "--phantom-dims", "20,20,20", "--bins", "4000"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    assert!(!String::from_utf8_lossy(&out.stderr).contains("panicked"), "{}", String::from_utf8_lossy(&out.stderr));
}

/// Every real sample scan renders (needs `SHEARWARP_DATA`; CI sets it).
#[test]
fn real_scans_render() {
    let Ok(dir) = std::env::var("SHEARWARP_DATA") else {
        eprintln!("SHEARWARP_DATA unset: real-scan CLI test skipped");
        return;
    };
    let dir = std::path::PathBuf::from(dir);
    let out = tempfile::tempdir().unwrap();
    for (f, tissue) in
        [("brainsmall.den", "low"), ("chest-ct-lung1.nrrd", "bone"), ("head-mri-ch2.nii.gz", "low"), ("dicom-brain-pd", "mid")]
    {
        let png = out.path().join(format!("{f}.png"));
        let o = sw().arg("render").arg(dir.join(f)).args(["--tissue", tissue, "--size", "128", "--json", "-o"]).arg(&png).output().unwrap();
        assert!(o.status.success(), "{f}: {}", String::from_utf8_lossy(&o.stderr));
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert!(j["coverage"].as_f64().unwrap() > 0.02, "{f} renders almost nothing: {j}");
    }
}

#[test]
fn export_writes_a_den_that_loads_back_windowed_and_resampled() {
    let dir = tempfile::tempdir().unwrap();
    let den = dir.path().join("head.den");
    // the head phantom in HU, window of 10 HU per step, anisotropic spacing made cubic
    let out = sw()
        .args(["export", "--phantom-dims", "40,40,20", "--spacing", "1,1,2", "--window", "-1000,1550", "--max-dim", "40", "--json", "-o"])
        .arg(&den)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // z: 19 gaps of 2 = 38 units, at the 1-unit voxel of x (39 gaps over 40 voxels) → 39 voxels
    assert_eq!(j["dims"], serde_json::json!([40, 40, 39]), "{j}");
    assert_eq!(j["units_per_step"].as_f64(), Some(10.0));
    let vol = shearwarp::data::io::load(&den, &shearwarp::data::io::LoadOptions::default()).unwrap();
    assert_eq!(vol.dims(), [40, 40, 39]);
    assert_eq!(vol.data().voxel_type(), shearwarp::data::volume::VoxelType::U8);
    let (lo, hi) = vol.value_range();
    assert_eq!(lo, 0.0, "air maps to 0");
    assert!(hi > 100.0, "bone maps high, got {hi}");
    // the exported file renders like any .den
    sw().args(["render", "--size", "48", "--iso", "50", "-o"]).arg(dir.path().join("d.png")).arg(&den).assert().success();
    // bad requests: clear usage errors, no file written
    for bad in [vec!["--window", "5,1"], vec!["--out-dims", "40000,2,2"], vec!["--max-dim", "1"], vec!["--window", "nan,1"]] {
        let bad_out = dir.path().join("bad.den");
        sw().arg("export").args(&bad).arg("-o").arg(&bad_out).assert().code(2).stderr(predicate::str::contains("error"));
        assert!(!bad_out.exists());
    }
    sw().args(["export", "-o"]).arg(dir.path().join("x.png")).assert().code(2).stderr(predicate::str::contains(".den"));
}

#[test]
fn opacity_curve_sets_the_blend_transfer_function() {
    let dir = tempfile::tempdir().unwrap();
    let render = |curve: &str, name: &str| {
        let out = dir.path().join(name);
        sw().args(["render", "--phantom-dims", "40,40,36", "--size", "64", "--mode", "blend", "--method", "rle"])
            .arg(format!("--opacity={curve}"))
            .arg("-o")
            .arg(&out)
            .assert()
            .success();
        image::open(&out).unwrap().to_rgb8()
    };
    // skin-and-up ramp shows the head; a curve that starts above every density shows nothing
    let head = render("-500:0,0:0.5", "a.png");
    assert!(head.pixels().filter(|p| p.0.iter().any(|&c| c > 20)).count() > 300);
    let none = render("5000:0,5001:1", "b.png");
    assert!(none.pixels().all(|p| p.0 == [0, 0, 0]));
    // iso mode, bad curves and --iso together are usage errors
    sw().args(["render", "--opacity", "1:0,2:1"]).assert().code(2).stderr(predicate::str::contains("--mode blend"));
    for bad in ["5:0,1:1", "5:0,6:2", "nan:0", "1", "1:x"] {
        sw().args(["render", "--mode", "blend"]).arg(format!("--opacity={bad}")).assert().code(2);
    }
    sw().args(["render", "--mode", "blend", "--opacity", "1:0", "--iso", "3"]).assert().code(2);
}

/// `SHEARWARP_CPU` is the one switch of the kernels' CPU level: reports name the
/// level, `scalar` runs the plain kernels with the same image, and a name that
/// is no level is a usage error.
#[test]
fn shearwarp_cpu_caps_the_level_and_reports_it() {
    let json = |c: &mut Command| -> serde_json::Value {
        let out = c.output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_slice(&out.stdout).unwrap()
    };
    // unset: the detected level
    let info = json(sw().env_remove("SHEARWARP_CPU").args(["info", "--phantom-dims", "20,20,20", "--json"]));
    assert!(["scalar", "avx2"].contains(&info["cpu"].as_str().unwrap()), "{info}");
    assert_eq!(info["cpu"], info["cpu_detected"]);
    // scalar: every report says so
    let info = json(sw().env("SHEARWARP_CPU", "scalar").args(["info", "--phantom-dims", "20,20,20", "--json"]));
    assert_eq!(info["cpu"], "scalar", "{info}");
    let rot = json(sw().env("SHEARWARP_CPU", "scalar").args([
        "rotate",
        "--phantom-dims",
        "32,32,28",
        "--size",
        "48",
        "--degrees",
        "6",
        "--json",
    ]));
    assert_eq!(rot["cpu"], "scalar", "{rot}");
    // the same image at the plain kernels as at the detected level
    let dir = tempfile::tempdir().unwrap();
    let mut pngs = Vec::new();
    for (name, cpu) in [("native.png", None), ("scalar.png", Some("scalar"))] {
        let out = dir.path().join(name);
        let mut c = sw();
        match cpu {
            Some(l) => c.env("SHEARWARP_CPU", l),
            None => c.env_remove("SHEARWARP_CPU"),
        };
        let j = json(c.args(["render", "--phantom-dims", "40,40,36", "--size", "64", "--rotate", "10,25,0", "--json", "-o"]).arg(&out));
        assert_eq!(j["cpu"], cpu.unwrap_or(info["cpu_detected"].as_str().unwrap()), "{j}");
        pngs.push(image::open(&out).unwrap().to_rgb8());
    }
    assert!(pngs[0] == pngs[1], "the scalar kernels render a different image");
    // a name that is no level: exit 2, naming the variable and the value
    sw().env("SHEARWARP_CPU", "sse9")
        .args(["render", "--phantom-dims", "20,20,20", "--size", "16", "--json", "-o"])
        .arg(dir.path().join("x.png"))
        .assert()
        .code(2)
        .stderr(predicate::str::contains("SHEARWARP_CPU").and(predicate::str::contains("sse9")));
    sw().env("SHEARWARP_CPU", "sse9").args(["info", "--phantom-dims", "20,20,20"]).assert().code(2);
}

#[test]
fn perspective_renders_with_rle_and_binary_and_bad_input_is_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("persp.png");
    for method in ["rle", "binary", "brute"] {
        let o = sw()
            .args(["render", "--phantom-dims", "40,40,36", "--size", "64", "--method", method])
            .args(["--perspective", "40", "--eye-distance", "1.5", "--json", "-o"])
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{method}: {}", String::from_utf8_lossy(&o.stderr));
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(j["projection"]["fov_deg"], 40.0);
        assert!(j["coverage"].as_f64().unwrap() > 0.05, "{method}: {j}");
        // rotate too, through the 45° principal-axis switch
        let o = sw()
            .args(["rotate", "--phantom-dims", "40,40,36", "--size", "48", "--method", method, "--mode", "blend", "--perspective", "30"])
            .args(["--degrees", "90", "--step-deg", "15", "--json"])
            .output()
            .unwrap();
        assert!(o.status.success(), "{method}: {}", String::from_utf8_lossy(&o.stderr));
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(j["projection"]["eye_distance"], 2.0);
        // the eye inside the volume: the pyramid split
        let o = sw()
            .args(["render", "--phantom-dims", "40,40,36", "--size", "48", "--method", method, "--perspective", "60"])
            .args(["--eye-distance", "0.1", "--json", "-o"])
            .arg(dir.path().join("inside.png"))
            .output()
            .unwrap();
        assert!(o.status.success(), "{method}: {}", String::from_utf8_lossy(&o.stderr));
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert!(j["coverage"].as_f64().unwrap() > 0.5, "{method}: {j}");
    }
    for (args, msg) in [
        (vec!["--perspective", "0", "--method", "rle"], "0 < FOV < 180"),
        (vec!["--perspective", "180", "--method", "rle"], "0 < FOV < 180"),
        (vec!["--perspective", "NaN", "--method", "rle"], "0 < FOV < 180"),
        (vec!["--perspective", "40", "--eye-distance", "0", "--method", "rle"], "--eye-distance"),
        (vec!["--perspective", "40", "--eye-distance", "inf", "--method", "rle"], "--eye-distance"),
        (vec!["--eye-distance", "2", "--method", "rle"], "--perspective"),
    ] {
        sw().args(["render", "--phantom-dims", "24,24,20", "--size", "32", "-o"])
            .arg(dir.path().join("x.png"))
            .args(&args)
            .assert()
            .code(2)
            .stderr(predicate::str::contains(msg).and(predicate::str::contains("panicked").not()));
    }
}
