//! Inputs are bounded before they are read or allocated: a mesh must be a
//! regular file whose size fits the memory budget, a phantom's voxels are
//! checked against the budget before a byte is allocated; and the smaller
//! input checks (a thin volume named, a huge clip plane explained).

#![cfg(unix)]

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use assert_cmd::Command;
use predicates::prelude::*;

fn sw() -> Command {
    Command::cargo_bin("shearwarp").expect("binary")
}

fn bin() -> PathBuf {
    assert_cmd::cargo::cargo_bin("shearwarp")
}

/// Runs `render --size 32 <flag> <mesh>` and expects a quick exit 2 naming the mesh.
fn refused_quickly(flag: &str, mesh: &Path, why: &str) {
    let t = Instant::now();
    let arg = if flag == "--focus" { format!("mesh:{}", mesh.display()) } else { mesh.display().to_string() };
    let out = dirs_out();
    sw().args(["render", "--size", "32", flag, &arg, "-o"])
        .arg(out.path().join("m.png"))
        .timeout(Duration::from_secs(20))
        .assert()
        .code(2)
        .stderr(predicate::str::contains(mesh.file_name().unwrap().to_str().unwrap()).and(predicate::str::contains(why)));
    assert!(t.elapsed() < Duration::from_secs(10), "{flag} {}: took {:?}", mesh.display(), t.elapsed());
}

fn dirs_out() -> tempfile::TempDir {
    tempfile::tempdir().unwrap()
}

#[test]
fn a_fifo_or_a_device_as_a_mesh_is_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("pipe.obj");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(made.success());
    let zero = dir.path().join("zero.stl");
    std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
    let random = dir.path().join("random.ply");
    std::os::unix::fs::symlink("/dev/urandom", &random).unwrap();
    for flag in ["--mesh", "--clip-mesh", "--focus"] {
        refused_quickly(flag, &fifo, "not a regular file");
        refused_quickly(flag, &zero, "not a regular file");
    }
    refused_quickly("--mesh", &random, "not a regular file");
}

#[test]
fn a_huge_mesh_file_is_refused_by_size_without_reading_it() {
    let dir = tempfile::tempdir().unwrap();
    let big = dir.path().join("big.obj");
    // 1.2 GB of nothing (sparse: no disk used), no line breaks
    std::fs::File::create(&big).unwrap().set_len(1_200_000_000).unwrap();
    let t = Instant::now();
    // under a 2 GB address-space limit reading it whole would fail loudly
    let out = std::process::Command::new("sh")
        .arg("-c")
        .arg("ulimit -v 2000000; exec \"$0\" \"$@\"")
        .arg(bin())
        .args(["render", "--size", "32", "--max-memory", "1G", "--mesh", big.to_str().unwrap(), "-o"])
        .arg(dir.path().join("m.png"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("big.obj") && err.contains("--max-memory"), "{err}");
    assert!(t.elapsed() < Duration::from_secs(10), "took {:?}", t.elapsed());
}

#[test]
fn a_mesh_without_line_breaks_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("one_line.obj");
    std::fs::write(&p, vec![b'v'; 3 << 20]).unwrap();
    refused_quickly("--mesh", &p, "line longer than");
}

#[test]
fn a_huge_phantom_fails_before_allocating() {
    // with 1 GB of budget, 4 GiB of voxels are refused before any is allocated:
    // under a 1.5 GB address-space limit an allocation first would abort
    let out = std::process::Command::new("sh")
        .arg("-c")
        .arg("ulimit -v 1500000; exec \"$0\" \"$@\"")
        .arg(bin())
        .args(["info", "--phantom", "sphere", "--phantom-dims", "1024,1024,1024", "--max-memory", "1G"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("sphere phantom 1024×1024×1024") && err.contains("4.00 GiB"), "{err}");
    // and without --max-memory, the address-space limit is the budget
    let out = std::process::Command::new("sh")
        .arg("-c")
        .arg("ulimit -v 1500000; exec \"$0\" \"$@\"")
        .arg(bin())
        .args(["info", "--phantom", "sphere", "--phantom-dims", "1024,1024,1024"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{out:?}");
}

#[test]
fn a_thin_volume_error_names_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("thin.raw");
    std::fs::write(&p, vec![0u8; 16 * 16]).unwrap();
    sw().args(["render", "--dims", "16,16,1", "--type", "u8", "--raw"])
        .arg(&p)
        .arg("-o")
        .arg(dir.path().join("t.png"))
        .assert()
        .code(2)
        .stderr(predicate::str::contains("thin.raw").and(predicate::str::contains("one voxel thick")));
}

#[test]
fn a_huge_clip_plane_is_explained_not_inf() {
    let dir = tempfile::tempdir().unwrap();
    sw().args(["render", "--size", "32", "--clip-plane", "1e308,1e308,1e308,1e308", "-o"])
        .arg(dir.path().join("c.png"))
        .assert()
        .code(2)
        .stderr(predicate::str::contains("too large").and(predicate::str::contains("inf").not()));
}
