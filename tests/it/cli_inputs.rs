//! Command-line checks: the thread cap, NaN / zero / negative
//! arguments (exit 2, never a panic or exit 1), warnings instead of silent
//! black images, one error line per missing file, orientation in `info` and
//! `--orientation`, and ±FLT_MAX sentinels.

use assert_cmd::Command;
use predicates::prelude::*;

fn sw() -> Command {
    Command::cargo_bin("shearwarp").expect("binary")
}

const SMALL: [&str; 4] = ["--phantom-dims", "24,24,20", "--size", "32"];

#[test]
fn the_thread_count_is_capped() {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let too_many = (8 * cores + 1).to_string();
    for cmd in ["render", "rotate", "bench"] {
        let t = std::time::Instant::now();
        sw().args([cmd, "--threads", &too_many])
            .args(SMALL)
            .assert()
            .code(2)
            .stderr(predicate::str::contains("--threads").and(predicate::str::contains("8 per core")));
        assert!(t.elapsed().as_secs() < 5, "{cmd}: the refusal took {:?}", t.elapsed());
    }
    sw().args(["render", "--threads", "100000"]).args(SMALL).assert().code(2);
    let dir = tempfile::tempdir().unwrap();
    sw().args(["render", "--threads", &(8 * cores).to_string(), "-q", "-o"]).arg(dir.path().join("a.png")).args(SMALL).assert().success();
}

#[test]
fn nan_zero_and_negative_arguments_exit_2() {
    let bad: &[&[&str]] = &[
        &["render", "--iso", "nan"],
        &["render", "--iso", "inf"],
        &["render", "--zoom", "0"],
        &["render", "--zoom", "-1"],
        &["render", "--zoom", "nan"],
        &["render", "--ert", "nan"],
        &["render", "--ert", "0"],
        &["render", "--size", "0"],
        &["render", "--cell", "0"],
        &["render", "--spacing", "0,1,1"],
        &["render", "--spacing", "nan,1,1"],
        &["render", "--spacing", "-1,1,1"],
        &["render", "--rotate", "nan,0,0"],
        &["render", "--threads", "-1"],
        &["rotate", "--step-deg", "0"],
        &["rotate", "--step-deg", "-2"],
        &["rotate", "--step-deg", "nan"],
        &["rotate", "--degrees", "0"],
        &["rotate", "--degrees", "nan"],
        &["rotate", "--degrees", "-90"],
        &["info", "--bins", "0"],
        &["render", "--orientation", "XYZ"],
        &["render", "--orientation", "RLS"],
    ];
    for args in bad {
        let o = sw().args(*args).args(SMALL).arg("-q").output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: exit {:?}: {err}", o.status.code());
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}

#[test]
fn an_iso_outside_the_data_warns_and_says_so_in_json() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("empty.png");
    // the phantom's densities lie in about −1000 … 2200
    let o = sw().args(["render", "--iso", "100000", "--json", "-o"]).arg(&png).args(SMALL).output().unwrap();
    assert!(o.status.success(), "the image is what was asked for: exit 0");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("warning") && err.contains("above the data's largest value"), "{err}");
    assert!(err.contains("nothing is visible"), "{err}");
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["coverage"], 0.0);
    assert_eq!(j["warnings"].as_array().unwrap().len(), 2, "{j}");
    // below the data: the whole box is opaque
    let o = sw().args(["render", "--iso", "-5000", "--json", "-o"]).arg(&png).args(SMALL).output().unwrap();
    assert!(o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("at or below the data's smallest value"));
    // an ordinary render has no warnings
    let o = sw().args(["render", "--json", "-o"]).arg(&png).args(SMALL).output().unwrap();
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["warnings"], serde_json::json!([]), "{j}");
    assert!(!String::from_utf8_lossy(&o.stderr).contains("warning"));
    // rotate reports them too
    let o = sw().args(["rotate", "--iso", "100000", "--degrees", "2", "--json"]).args(SMALL).output().unwrap();
    assert!(o.status.success());
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(!j["warnings"].as_array().unwrap().is_empty(), "{j}");
}

#[test]
fn a_one_slice_volume_is_refused_not_drawn_black() {
    let dir = tempfile::tempdir().unwrap();
    let raw = dir.path().join("slice.raw");
    std::fs::write(&raw, vec![200u8; 16 * 16]).unwrap();
    sw().args(["render", "--raw"])
        .arg(&raw)
        .args(["--dims", "16,16,1", "--type", "u8", "-o"])
        .arg(dir.path().join("x.png"))
        .assert()
        .code(2)
        .stderr(predicate::str::contains("one voxel thick along z"));
    // info still describes it
    sw().args(["info", "--raw"]).arg(&raw).args(["--dims", "16,16,1", "--type", "u8"]).assert().success();
}

#[test]
fn a_missing_file_is_one_clear_line() {
    let o = sw().args(["info", "/no/such/scan.nrrd"]).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.matches("No such file").count(), 1, "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
}

#[test]
fn info_prints_orientation_and_origin() {
    let o = sw().args(["info", "--phantom-dims", "20,20,20"]).output().unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("orientation RAS") && out.contains("origin"), "{out}");
    // raw data carry none; --orientation sets it, a mirrored code is reversed
    let dir = tempfile::tempdir().unwrap();
    let raw = dir.path().join("v.raw");
    std::fs::write(&raw, (0..4 * 3 * 2).map(|i| i as u8).collect::<Vec<_>>()).unwrap();
    let base = ["info", "--dims", "4,3,2", "--type", "u8", "--raw"];
    let o = sw().args(base).arg(&raw).output().unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("orientation unknown") && out.contains("--orientation"), "{out}");
    let o = sw().args(base).arg(&raw).args(["--orientation", "LPS", "--json"]).output().unwrap();
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["orientation"], "LPS");
    assert_eq!(j["orientation_source"], "--orientation");
    assert_eq!(j["origin_ras"], serde_json::json!([0.0, 0.0, 0.0]));
    let o = sw().args(base).arg(&raw).args(["--orientation", "LAS", "--json"]).output().unwrap();
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!((&j["orientation"], &j["stored_orientation"], &j["reversed_axis"]), (&"RAS".into(), &"LAS".into(), &"x".into()), "{j}");
    // x reversed: the new voxel 0 is the file's voxel 3, 3 mm toward the patient's left (RAS x = −3)
    assert_eq!(j["origin_ras"], serde_json::json!([-3.0, 0.0, 0.0]));
}

#[test]
fn flt_max_sentinels_are_reported_and_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let raw = dir.path().join("sentinel.raw");
    // 16³ CT-like values with a -FLT_MAX no-data border along x = 0
    let v: Vec<u8> = (0..16 * 16 * 16)
        .flat_map(|i: usize| {
            let (x, y) = (i % 16, (i / 16) % 16);
            let d = if x == 0 {
                -f32::MAX
            } else if (4..12).contains(&x) && (4..12).contains(&y) {
                700.0
            } else {
                -1000.0
            };
            d.to_le_bytes()
        })
        .collect();
    std::fs::write(&raw, v).unwrap();
    let spec = ["--dims", "16,16,16", "--type", "f32"];
    let o = sw().args(["info", "--raw"]).arg(&raw).args(spec).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("sentinel") && out.contains("CT"), "{out}");
    for extra in [&["--tissue", "bone"][..], &["--mode", "blend"], &["--method", "rle"], &["--iso", "3e38"]] {
        let o = sw()
            .args(["render", "--size", "32", "-q", "--raw"])
            .arg(&raw)
            .args(spec)
            .args(extra)
            .arg("-o")
            .arg(dir.path().join("s.png"))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!err.contains("panicked") && o.status.code() != Some(101), "{extra:?}: {err}");
        assert!(matches!(o.status.code(), Some(0) | Some(2)), "{extra:?}: {:?} {err}", o.status.code());
    }
}

#[test]
fn long_animations_keep_at_most_200_frames() {
    let dir = tempfile::tempdir().unwrap();
    let gif = dir.path().join("t.gif");
    sw().args(["rotate", "--phantom-dims", "16,16,16", "--size", "16", "--degrees", "360", "--step-deg", "0.5", "--gif"])
        .arg(&gif)
        .assert()
        .success()
        .stderr(predicate::str::contains("keeps every 4th of the 720 frames (180 frames)"));
    let frames = image::codecs::gif::GifDecoder::new(std::io::BufReader::new(std::fs::File::open(&gif).unwrap())).unwrap();
    use image::AnimationDecoder;
    assert_eq!(frames.into_frames().count(), 180);
}

#[test]
fn a_truncated_nifti_header_is_plain_words() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("short.nii");
    let mut h = vec![0u8; 200];
    h[0..4].copy_from_slice(&348i32.to_le_bytes());
    std::fs::write(&p, &h).unwrap();
    let o = sw().arg("info").arg(&p).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("short.nii") && err.contains("ends inside the 348-byte header"), "{err}");
    assert!(!err.contains("Io(") && !err.contains("kind:"), "Rust debug text: {err}");
}
