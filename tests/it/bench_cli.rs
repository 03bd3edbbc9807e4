//! `shearwarp bench` end to end: a tiny matrix writes its Markdown, JSON, CSV
//! and plots; bad arguments are usage errors.

use assert_cmd::Command;
use predicates::prelude::*;

fn bench(only: &str) -> Command {
    let mut c = Command::cargo_bin("shearwarp").unwrap();
    c.args(["bench", "--phantom", "sphere", "--phantom-dims", "20,20,20", "--size", "32", "--random-views", "1"]);
    c.args(["--reps", "1", "--rounds", "1", "--only", only, "--ref-step", "0.2", "--quiet"]);
    c
}

fn tiny() -> Command {
    bench("binary-c1-u64-bitscan,binary-c1-u64-bitscan-noert,c2-u32-lut,brute")
}

#[test]
fn a_tiny_matrix_writes_every_output() {
    let dir = tempfile::tempdir().unwrap();
    let (csv, svg, png) = (dir.path().join("b.csv"), dir.path().join("b.svg"), dir.path().join("b.png"));
    let out = tiny().arg("--csv").arg(&csv).arg("--plot").arg(&svg).arg("--plot").arg(&png).arg("--json").assert().success();
    let json: serde_json::Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
    // 8 views × (3 iso variants + 4 blend variants: the no-ERT twin is blend's alone)
    assert_eq!(json["records"].as_array().unwrap().len(), 8 * 7);
    assert_eq!(json["summary"].as_array().unwrap().len(), 7);
    assert_eq!(json["views"].as_array().unwrap().len(), 8);
    // the CPU level the kernels ran at
    assert!(["scalar", "avx2"].contains(&json["cpu"].as_str().unwrap()), "cpu: {}", json["cpu"]);
    for r in json["records"].as_array().unwrap() {
        assert!(r["frame_ms"].as_f64().unwrap() >= 0.0);
        assert!(r["error"]["rmse"].as_f64().unwrap() < 0.2, "{r}");
        if r["mode"] == "iso" {
            assert_eq!(r["depth_truth"], "analytic");
        }
    }
    // every binary variant (with the same early ray termination) has exactly brute force's error
    let rs = json["records"].as_array().unwrap();
    for r in rs.iter().filter(|r| !r["variant"].as_str().unwrap().ends_with("noert")) {
        let brute = rs.iter().find(|b| b["variant"] == "brute" && b["view"] == r["view"] && b["mode"] == r["mode"]).unwrap();
        assert_eq!(r["error"], brute["error"], "{} {}", r["variant"], r["view"]);
    }
    // each mode has a Pareto front
    for mode in ["iso", "blend"] {
        assert!(json["summary"].as_array().unwrap().iter().any(|s| s["mode"] == mode && s["pareto"] == true));
    }
    let csv = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(csv.lines().count(), 1 + 8 * 7);
    assert!(csv.starts_with("volume,dims,mode,variant,view,"));
    assert!(std::fs::read_to_string(&svg).unwrap().contains("<svg"));
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (1000, 640));
}

#[test]
fn rle_is_in_the_matrix_and_matches_its_brute_force() {
    let out = bench("rle,brute-rle").arg("--json").assert().success();
    let json: serde_json::Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
    let rs = json["records"].as_array().unwrap();
    assert_eq!(rs.len(), 8 * 2 * 2, "8 views x 2 modes x (rle, brute-rle): the exact name \"rle\" picks only rle");
    for r in rs.iter().filter(|r| r["variant"] == "rle") {
        let b = rs.iter().find(|b| b["variant"] == "brute-rle" && b["view"] == r["view"] && b["mode"] == r["mode"]).unwrap();
        let (e, eb) = (r["error"]["rmse"].as_f64().unwrap(), b["error"]["rmse"].as_f64().unwrap());
        assert!(e < 0.2 && (e - eb).abs() < 1e-3, "rle {e} vs brute-rle {eb} at {} {}", r["view"], r["mode"]);
    }
}

#[test]
fn markdown_by_default() {
    tiny().args(["--modes", "iso"]).assert().success().stdout(
        predicate::str::contains("| variant | frame ms |")
            .and(predicate::str::contains("| brute |"))
            .and(predicate::str::contains("vs analytic")),
    );
}

#[test]
fn bad_arguments_are_usage_errors() {
    tiny().args(["--plot", "x.gif"]).assert().code(2).stderr(predicate::str::contains(".svg or .png"));
    tiny()
        .args(["--modes", "blend", "--plot-error", "normal", "--plot", "x.png"])
        .assert()
        .code(2)
        .stderr(predicate::str::contains("iso mode"));
    bench("nothing-like-this").assert().code(2).stderr(predicate::str::contains("matches no variant"));
    tiny().args(["--ref-step", "0"]).assert().code(2).stderr(predicate::str::contains("--ref-step"));
    tiny().args(["--reps", "0"]).assert().code(2);
    tiny().args(["--tissue", "bone"]).assert().code(2).stderr(predicate::str::contains("unknown tissue"));
}

/// `bench --perspective` takes lists of fields of view and eye distances:
/// each projection's variants (named with their field of view and distance)
/// sit in the same table as the parallel ones, each accelerated path equals its
/// brute force, and every view a path cannot render is listed with the reason
/// instead of failing the run.
#[test]
fn perspective_lists_are_measured_or_listed_as_skipped() {
    let out = bench("rle,persp").args(["--perspective", "40", "--eye-distance", "3,0.1", "--modes", "blend", "--json"]).assert().success();
    let json: serde_json::Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
    let rs = json["records"].as_array().unwrap();
    let skipped = json["skipped"].as_array().unwrap();
    let views = json["views"].as_array().unwrap().len();
    // every variant and view: measured or skipped, never both, never neither
    for v in ["rle", "binary-persp", "brute-persp", "rle-persp", "brute-rle-persp"] {
        for d in ["3", "0.1"] {
            let name = if v == "rle" { v.to_string() } else { format!("{v}-f40-d{d}") };
            let n = rs.iter().filter(|r| r["variant"] == name.as_str()).count();
            let k = skipped.iter().filter(|r| r["variant"] == name.as_str()).count();
            assert_eq!(n + k, views, "{name}: {n} records, {k} skipped");
            for s in skipped.iter().filter(|r| r["variant"] == name.as_str()) {
                assert!(!s["reason"].as_str().unwrap().is_empty());
            }
        }
    }
    // the RLE path renders the eye 3 diagonals away at every view, as its brute force does
    let persp: Vec<&serde_json::Value> = rs.iter().filter(|r| r["variant"] == "rle-persp-f40-d3").collect();
    assert_eq!(persp.len(), views);
    for r in persp {
        assert!(r["error"]["rmse"].as_f64().unwrap() < 0.1, "{r}");
        let b = rs.iter().find(|b| b["variant"] == "brute-rle-persp-f40-d3" && b["view"] == r["view"]).unwrap();
        assert_eq!(r["error"], b["error"], "{}", r["view"]);
    }
    // the Markdown report names the perspective / parallel ratio
    bench("rle,rle-persp")
        .args(["--perspective", "40", "--eye-distance", "3", "--modes", "blend"])
        .assert()
        .success()
        .stdout(predicate::str::contains("Perspective / parallel frame time").and(predicate::str::contains("rle-persp ")));
    // bad lists are usage errors
    bench("rle").args(["--perspective", "40,200"]).assert().code(2);
    bench("rle").args(["--perspective", "40", "--eye-distance", "3,-1"]).assert().code(2);
}

/// `bench --peers`: a peer that cannot run here is listed as skipped at every
/// view with the reason (the run still succeeds); where VTK or VolPack is
/// installed its frames are measured against the same reference as
/// shearwarp's rows (same views, same model: a matched frame is close, a
/// shifted or mirrored one would not be); VolPack's perspective is listed as
/// skipped; bad uses are usage errors.
#[test]
fn peers_are_measured_beside_the_variants_or_listed_as_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let den = dir.path().join("sphere.den");
    Command::cargo_bin("shearwarp")
        .unwrap()
        .args(["export", "--phantom", "sphere", "--phantom-dims", "24,24,24", "-o"])
        .arg(&den)
        .assert()
        .success();
    let peers = |list: &str, fake: bool| {
        let mut c = Command::cargo_bin("shearwarp").unwrap();
        c.args(["bench", "--size", "48", "--random-views", "1", "--reps", "1", "--rounds", "1", "--ref-step", "0.2", "--quiet"]);
        // (the ball's surface, inside the volume: at a lower threshold the box's faces cut it, where
        // the peers shade with a zero normal and the reference with the one-sided gradient)
        c.args(["--modes", "blend", "--only", "rle", "--peers", list, "--iso", "127", "--json", "--den"]).arg(&den);
        c.arg("--peer-dir").arg(dir.path().join("frames"));
        if fake {
            c.env("SHEARWARP_VTK_HARNESS", "/nonexistent/harness.py").env("SHEARWARP_VOLPACK_HARNESS", "/nonexistent/harness");
        }
        c
    };
    let out = peers("vtk,volpack", true).assert().success();
    let json: serde_json::Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
    let views = json["views"].as_array().unwrap().len();
    for (peer, why) in [("vtk", "vtk harness"), ("volpack", "volpack harness")] {
        let skipped: Vec<&serde_json::Value> = json["skipped"].as_array().unwrap().iter().filter(|s| s["variant"] == peer).collect();
        assert_eq!(skipped.len(), views);
        assert!(skipped.iter().all(|s| s["reason"].as_str().unwrap().contains(why)), "{skipped:?}");
    }
    assert!(json["records"].as_array().unwrap().iter().any(|r| r["variant"] == "rle"));

    let vtk = std::process::Command::new("python3").args(["-c", "import vtk"]).output().is_ok_and(|o| o.status.success());
    let volpack = std::path::Path::new("/usr/include/volpack.h").exists();
    for (peer, here) in [("vtk", vtk), ("volpack", volpack)] {
        if !here {
            eprintln!("{peer} is not installed: the measured half of this test did not run for it");
            continue;
        }
        let out = peers(peer, false).args(["--perspective", "40"]).assert().success();
        let json: serde_json::Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
        let rs: Vec<&serde_json::Value> = json["records"].as_array().unwrap().iter().filter(|r| r["variant"] == peer).collect();
        assert_eq!(rs.len(), views, "{}", json["skipped"]);
        for r in rs {
            // the same views and model: a matched frame, not a shifted or mirrored one
            assert!(r["error"]["rmse"].as_f64().unwrap() < 0.08 && r["error"]["ssim"].as_f64().unwrap() > 0.8, "{r}");
            assert!(r["frame_ms"].as_f64().unwrap() > 0.0);
        }
        let persp = format!("{peer}-persp");
        let measured = json["records"].as_array().unwrap().iter().filter(|r| r["variant"] == persp.as_str()).count();
        let skipped = json["skipped"].as_array().unwrap().iter().filter(|r| r["variant"] == persp.as_str()).count();
        assert_eq!((measured, skipped), if peer == "vtk" { (views, 0) } else { (0, views) }, "{persp}");
    }

    // peers need blend mode and a .den volume
    let mut c = Command::cargo_bin("shearwarp").unwrap();
    c.args(["bench", "--phantom", "sphere", "--phantom-dims", "20,20,20", "--peers", "vtk", "--quiet"]);
    c.assert().code(2).stderr(predicate::str::contains(".den"));
    let mut c = Command::cargo_bin("shearwarp").unwrap();
    c.args(["bench", "--modes", "iso", "--peers", "vtk", "--quiet", "--den"]).arg(&den);
    c.assert().code(2).stderr(predicate::str::contains("blend"));
}
