//! Outputs are never lost and never reported written when they were not:
//! every file goes to a temporary beside the target and replaces it by
//! rename only when complete, so a full device, a file-size limit or a
//! SIGTERM leaves the previous file as it was and no temporary behind; a
//! device or `-` is written in place, every error checked (exit 2, the path
//! named); the image type comes from the extension.

#![cfg(unix)]

use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

use assert_cmd::Command;
use predicates::prelude::*;

fn sw() -> Command {
    Command::cargo_bin("shearwarp").expect("binary")
}

fn bin() -> PathBuf {
    assert_cmd::cargo::cargo_bin("shearwarp")
}

/// The temporaries an output left in `dir`.
fn temps(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).filter(|n| n.ends_with(".tmp")).collect()
}

/// Runs the binary with `args` under `ulimit -f blocks` (512-byte blocks).
fn under_file_limit(blocks: u64, args: &[&str]) -> std::process::Output {
    std::process::Command::new("sh")
        .arg("-c")
        .arg(format!("ulimit -f {blocks}; exec \"$0\" \"$@\""))
        .arg(bin())
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn a_full_device_is_a_write_error_at_every_size() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("link.png");
    std::os::unix::fs::symlink("/dev/full", &link).unwrap();
    for size in ["1", "64", "512"] {
        sw().args(["render", "--size", size, "-o", "/dev/full"])
            .assert()
            .code(2)
            .stderr(predicate::str::contains("/dev/full").and(predicate::str::contains("No space left")));
    }
    // through a link: the device is written (and fails), the link stays
    sw().args(["render", "--size", "64", "-o"]).arg(&link).assert().code(2).stderr(predicate::str::contains("link.png"));
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
    for flag in ["--gif", "--apng"] {
        sw().args(["rotate", "--size", "32", "--degrees", "2", "--step-deg", "1", "--quiet", flag, "/dev/full"])
            .assert()
            .code(2)
            .stderr(predicate::str::contains("/dev/full").and(predicate::str::contains("No space left")));
    }
    let svg = dir.path().join("plot.svg");
    std::os::unix::fs::symlink("/dev/full", &svg).unwrap();
    sw().args(["bench", "--phantom", "sphere", "--phantom-dims", "16,16,16", "--size", "24", "--random-views", "0"])
        .args(["--reps", "1", "--rounds", "1", "--only", "brute", "--ref-step", "0.25", "--quiet", "--plot"])
        .arg(&svg)
        .assert()
        .code(2)
        .stderr(predicate::str::contains("plot.svg"));
    assert!(temps(dir.path()).is_empty());
}

#[test]
fn a_good_file_survives_a_file_size_limit() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("head.png");
    sw().args(["render", "--size", "64", "-o"]).arg(&png).assert().success();
    let good = std::fs::read(&png).unwrap();
    // 8 blocks (4 KiB): a 512-pixel render does not fit
    let out = under_file_limit(8, &["render", "--size", "512", "-o", png.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("head.png") && err.contains("File too large"), "{err}");
    assert_eq!(std::fs::read(&png).unwrap(), good, "the previous PNG changed");
    // the same for export's .den
    let den = dir.path().join("scan.den");
    sw().args(["export", "--phantom-dims", "8,8,8", "-o"]).arg(&den).assert().success();
    let good = std::fs::read(&den).unwrap();
    let out = under_file_limit(8, &["export", "--phantom-dims", "64,64,64", "-o", den.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    assert!(String::from_utf8_lossy(&out.stderr).contains("scan.den"));
    assert_eq!(std::fs::read(&den).unwrap(), good, "the previous .den changed");
    assert!(temps(dir.path()).is_empty(), "{:?}", temps(dir.path()));
}

#[test]
fn sigterm_during_a_long_rotate_leaves_the_previous_gif() {
    let dir = tempfile::tempdir().unwrap();
    let gif = dir.path().join("turn.gif");
    sw().args(["rotate", "--size", "32", "--degrees", "4", "--quiet", "--gif"]).arg(&gif).assert().success();
    let good = std::fs::read(&gif).unwrap();
    let child = std::process::Command::new(bin())
        .args(["rotate", "--size", "384", "--degrees", "360", "--quiet", "--gif"])
        .arg(&gif)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // wait until the GIF is being written (its temporary exists), or a while
    let start = Instant::now();
    while temps(dir.path()).is_empty() && start.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(20));
    }
    let writing = !temps(dir.path()).is_empty();
    let kill = std::process::Command::new("kill").args(["-TERM", &child.id().to_string()]).status().unwrap();
    assert!(kill.success());
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(143), "{out:?}");
    assert!(String::from_utf8_lossy(&out.stderr).contains("interrupted"));
    assert_eq!(std::fs::read(&gif).unwrap(), good, "the previous GIF changed");
    assert!(temps(dir.path()).is_empty(), "a temporary was left: {:?}", temps(dir.path()));
    assert!(writing, "the GIF was never being written when the signal came");
}

#[test]
fn two_writers_to_one_path_each_leave_a_complete_file() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("same.png");
    let spawn = |size: &str| {
        std::process::Command::new(bin())
            .args(["render", "--size", size, "-o"])
            .arg(&png)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap()
    };
    for _ in 0..3 {
        let (mut a, mut b) = (spawn("300"), spawn("301"));
        assert!(a.wait().unwrap().success() && b.wait().unwrap().success());
        let img = image::open(&png).expect("a complete PNG");
        assert!([300, 301].contains(&img.width()), "{}", img.width());
    }
    assert!(temps(dir.path()).is_empty());
}

#[test]
fn the_image_type_comes_from_the_extension() {
    let dir = tempfile::tempdir().unwrap();
    for bad in ["x.jpg", "noext"] {
        let p = dir.path().join(bad);
        sw().args(["render", "--size", "32", "-o"])
            .arg(&p)
            .assert()
            .code(2)
            .stderr(predicate::str::contains(bad).and(predicate::str::contains(".png, .gif, .apng")));
        assert!(!p.exists());
    }
    for (name, magic) in [("a.png", &b"\x89PNG"[..]), ("a.gif", b"GIF8"), ("a.apng", b"\x89PNG")] {
        let p = dir.path().join(name);
        sw().args(["render", "--size", "32", "-o"]).arg(&p).assert().success();
        assert!(std::fs::read(&p).unwrap().starts_with(magic), "{name}");
    }
    let apng = std::fs::read(dir.path().join("a.apng")).unwrap();
    assert!(apng.windows(4).any(|w| w == b"acTL"), "an APNG has an animation control chunk");
    // `-`: a PNG on standard output (the report stays on standard error)
    let out = sw().args(["render", "--size", "32", "-o", "-"]).assert().success();
    assert!(out.get_output().stdout.starts_with(b"\x89PNG"));
    image::load_from_memory(&out.get_output().stdout).expect("a whole PNG");
}

#[test]
fn a_frames_directory_csv_and_json_are_written_whole() {
    let dir = tempfile::tempdir().unwrap();
    let frames = dir.path().join("frames");
    sw().args(["rotate", "--size", "32", "--degrees", "3", "--step-deg", "1", "--quiet", "--frames-dir"]).arg(&frames).assert().success();
    let n = std::fs::read_dir(&frames).unwrap().count();
    assert_eq!(n, 3);
    assert!(temps(&frames).is_empty());
    let (csv, json) = (dir.path().join("b.csv"), dir.path().join("b.json"));
    sw().args(["bench", "--phantom", "sphere", "--phantom-dims", "16,16,16", "--size", "24", "--random-views", "0"])
        .args(["--reps", "1", "--rounds", "1", "--only", "brute", "--ref-step", "0.25", "--quiet", "--csv"])
        .arg(&csv)
        .arg("--json-out")
        .arg(&json)
        .assert()
        .success();
    assert!(std::fs::read_to_string(&csv).unwrap().starts_with("volume,"));
    let _: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!(temps(dir.path()).is_empty());
}

#[test]
fn a_report_to_a_full_stdout_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let full = || std::fs::OpenOptions::new().write(true).open("/dev/full").unwrap();
    let render = std::process::Command::new(bin())
        .args(["render", "--size", "32", "--json", "-o"])
        .arg(dir.path().join("r.png"))
        .stdout(full())
        .output()
        .unwrap();
    assert_eq!(render.status.code(), Some(2), "{render:?}");
    assert!(String::from_utf8_lossy(&render.stderr).contains("standard output"));
    let bench = std::process::Command::new(bin())
        .args(["bench", "--phantom", "sphere", "--phantom-dims", "16,16,16", "--size", "24", "--random-views", "0"])
        .args(["--reps", "1", "--rounds", "1", "--only", "brute", "--ref-step", "0.25", "--quiet", "--json"])
        .stdout(full())
        .output()
        .unwrap();
    assert_eq!(bench.status.code(), Some(2), "{bench:?}");
    assert!(String::from_utf8_lossy(&bench.stderr).contains("standard output"));
}
