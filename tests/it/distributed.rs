//! `--distributed` under `mpirun` (feature `mpi`; Open MPI's `mpirun` on the
//! PATH): with 1–4 ranks, oversubscribed, the iso image is the single
//! process's byte for byte and the blended image within 1/255 and the same
//! every run, for a raw file and an uncompressed NRRD each rank reads its
//! own brick of and for a phantom rank 0 scatters; `bench` times the
//! variants a distributed frame runs and names the others; `--json` reports every rank; a rank that cannot
//! read its brick ends the job with one error from rank 0 and no output.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use shearwarp::data::io::save_raw;
use shearwarp::data::volume::{Volume, VoxelData};

use crate::common::random_volume;

fn bin() -> PathBuf {
    assert_cmd::cargo::cargo_bin("shearwarp")
}

/// `shearwarp ARGS` under `mpirun -np n` (a time limit: a hang fails).
fn mpirun(n: usize, args: &[&str]) -> Output {
    let mut c = Command::new("timeout");
    c.args(["300", "mpirun", "--oversubscribe", "-np", &n.to_string()]);
    // (as root Open MPI wants to be told)
    if std::env::var("USER").as_deref() == Ok("root") || Command::new("id").arg("-u").output().is_ok_and(|o| o.stdout == b"0\n") {
        c.arg("--allow-run-as-root");
    }
    c.arg(bin()).args(args).arg("--distributed");
    c.output().expect("mpirun runs (Open MPI's mpirun on the PATH)")
}

fn single(args: &[&str]) -> Output {
    Command::new(bin()).args(args).args(["--sampling", "voxel"]).output().expect("shearwarp runs")
}

fn ok(o: &Output, what: &str) {
    assert!(o.status.success(), "{what}: {}\n{}", o.status, String::from_utf8_lossy(&o.stderr));
}

fn pixels(p: &Path) -> Vec<u8> {
    image::open(p).unwrap_or_else(|e| panic!("{}: {e}", p.display())).to_rgba8().into_raw()
}

/// A random 8-bit volume with its sidecar, in `dir`.
fn raw_volume(dir: &Path, dims: [usize; 3], seed: u64) -> PathBuf {
    let v = random_volume(dims, seed, [1.0, 0.9, 1.2]);
    let v = Volume::new(dims, v.spacing(), VoxelData::U8(v.to_f32().iter().map(|x| x.round().clamp(0.0, 255.0) as u8).collect())).unwrap();
    let path = dir.join(format!("v{seed}.raw"));
    save_raw(&v, &path).unwrap();
    path
}

#[test]
fn iso_images_equal_one_process_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let raw = raw_volume(dir.path(), [45, 38, 52], 11);
    let raw = raw.to_str().unwrap();
    // (file, cell, tissue, view)
    let cases: [(&str, &str, &str, &str); 4] =
        [(raw, "1", "low", "20,35,0"), (raw, "3", "mid", "-70,10,15"), (raw, "2", "high", "5,-120,0"), ("", "2", "bone", "80,20,0")];
    for (i, (file, cell, tissue, rot)) in cases.iter().enumerate() {
        let mut args = vec!["render", "--cell", cell, "--tissue", tissue, "--rotate", rot, "--size", "160"];
        if !file.is_empty() {
            args.push(file);
        }
        let one = dir.path().join(format!("one{i}.png"));
        ok(&single(&[&args[..], &["-o", one.to_str().unwrap()]].concat()), "one process");
        for n in 1..=4 {
            let out = dir.path().join(format!("d{i}-{n}.png"));
            ok(&mpirun(n, &[&args[..], &["-o", out.to_str().unwrap()]].concat()), &format!("{n} ranks"));
            assert!(std::fs::read(&one).unwrap() == std::fs::read(&out).unwrap(), "case {i}: {n} ranks differ from one process");
        }
        assert!(pixels(&one).chunks(4).filter(|p| p[..3] != [0, 0, 0]).count() > 500, "case {i} shows little");
    }
}

#[test]
fn blended_images_are_within_one_level_and_repeat() {
    let dir = tempfile::tempdir().unwrap();
    let raw = raw_volume(dir.path(), [40, 44, 36], 5);
    let raw = raw.to_str().unwrap();
    for (method, rot) in [("rle", "10,-50,0"), ("binary", "60,20,10")] {
        let args =
            ["render", raw, "--mode", "blend", "--method", method, "--tissue", "mid", "--rotate", rot, "--size", "160", "--ert", "1"];
        let one = dir.path().join(format!("one-{method}.png"));
        ok(&single(&[&args[..], &["-o", one.to_str().unwrap()]].concat()), "one process");
        let a = pixels(&one);
        for n in [2, 3, 4] {
            let out = dir.path().join(format!("d-{method}-{n}.png"));
            let again = dir.path().join(format!("e-{method}-{n}.png"));
            ok(&mpirun(n, &[&args[..], &["-o", out.to_str().unwrap()]].concat()), &format!("{n} ranks"));
            ok(&mpirun(n, &[&args[..], &["-o", again.to_str().unwrap()]].concat()), &format!("{n} ranks again"));
            let b = pixels(&out);
            let worst = a.iter().zip(&b).map(|(x, y)| x.abs_diff(*y)).max().unwrap();
            assert!(worst <= 1, "{method}, {n} ranks: a channel {worst}/255 off");
            assert!(b == pixels(&again), "{method}, {n} ranks: two runs differ");
        }
        assert!(a.chunks(4).filter(|p| p[..3] != [0, 0, 0]).count() > 500, "{method} shows little");
    }
}

#[test]
fn json_reports_every_rank() {
    let dir = tempfile::tempdir().unwrap();
    let raw = raw_volume(dir.path(), [30, 30, 30], 3);
    let out = dir.path().join("j.png");
    let o = mpirun(3, &["render", raw.to_str().unwrap(), "--size", "96", "--json", "-o", out.to_str().unwrap()]);
    ok(&o, "3 ranks");
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    assert_eq!(j["ranks"], 3);
    let ranks = j["per_rank"].as_array().unwrap();
    assert_eq!(ranks.len(), 3);
    for (i, r) in ranks.iter().enumerate() {
        assert_eq!(r["rank"], i);
        assert!(r["render_ms"].as_f64().unwrap() >= 0.0 && r["peak_rss_bytes"].as_u64().unwrap() > 0);
        // rank 0 receives the others' partial images, they send theirs
        let key = if i == 0 { "received_bytes_per_frame" } else { "sent_bytes_per_frame" };
        assert!(r[key].as_f64().unwrap() > 16.0, "rank {i}: {r}");
    }
}

#[test]
fn a_rank_that_cannot_read_its_brick_ends_the_job_with_one_error() {
    let dir = tempfile::tempdir().unwrap();
    let raw = raw_volume(dir.path(), [32, 32, 40], 9);
    // the last slices are gone: only the bricks at the end of the file fail
    let bytes = std::fs::read(&raw).unwrap();
    std::fs::write(&raw, &bytes[..32 * 32 * 30]).unwrap();
    let out = dir.path().join("never.png");
    let o = mpirun(4, &["render", raw.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    let ours: Vec<&str> = err.lines().filter(|l| l.starts_with("error: ")).collect();
    assert_eq!(ours.len(), 1, "{err}");
    assert!(ours[0].contains("truncated") && ours[0].contains(raw.to_str().unwrap()) && ours[0].contains("rank "), "{err}");
    assert!(!out.exists(), "an output was written");
    // over the memory budget: the same, naming it
    let o = mpirun(2, &["render", raw.to_str().unwrap(), "--max-memory", "1k", "-o", out.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("memory budget"), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!out.exists(), "an output was written");
}

#[test]
fn bench_times_the_binary_and_rle_variants_on_every_rank() {
    let dir = tempfile::tempdir().unwrap();
    let raw = raw_volume(dir.path(), [36, 40, 33], 7);
    let json = dir.path().join("bench.json");
    let args = [
        "bench",
        raw.to_str().unwrap(),
        "--only",
        "binary-c1-u64-bitscan,rle,binary-c1-u64-bitscan-q2",
        "--size",
        "64",
        "--reps",
        "2",
        "--rounds",
        "1",
        "--random-views",
        "0",
        "--quiet",
        "--json",
        "--json-out",
        json.to_str().unwrap(),
    ];
    let o = mpirun(3, &args);
    ok(&o, "3 ranks");
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON report");
    assert_eq!(j, serde_json::from_slice::<serde_json::Value>(&std::fs::read(&json).unwrap()).unwrap(), "--json-out differs");
    assert_eq!(j["ranks"], 3);
    let views = j["views"].as_array().unwrap().len();
    let rows = j["records"].as_array().unwrap();
    let names: Vec<String> = rows.iter().map(|r| format!("{} {}", r["mode"].as_str().unwrap(), r["variant"].as_str().unwrap())).collect();
    assert_eq!(names, ["iso binary-c1-u64-bitscan", "iso rle", "blend binary-c1-u64-bitscan", "blend rle"]);
    for r in rows {
        assert_eq!(r["frames"], 2 * views);
        assert!(r["frame_ms_median"].as_f64().unwrap() > 0.0, "{r}");
        let ranks = r["per_rank"].as_array().unwrap();
        assert_eq!(ranks.len(), 3);
        for (i, x) in ranks.iter().enumerate() {
            assert_eq!(x["rank"], i);
            let key = if i == 0 { "received_bytes_per_frame" } else { "sent_bytes_per_frame" };
            assert!(x[key].as_f64().unwrap() > 16.0 && x["peak_rss_bytes"].as_u64().unwrap() > 0, "rank {i}: {x}");
        }
    }
    // the variants a distributed frame does not run are named, with the reason
    let skipped = j["skipped"].as_array().unwrap();
    assert_eq!(skipped.len(), 2, "{skipped:?}");
    assert!(skipped.iter().all(|s| s["variant"] == "binary-c1-u64-bitscan-q2" && s["reason"].as_str().unwrap().contains("quality 1")));
    // the table names them too; a selection of none of them is refused before any rank reads
    let o = mpirun(2, &args[..args.len() - 3]);
    ok(&o, "2 ranks, the table");
    let table = String::from_utf8_lossy(&o.stdout);
    assert!(table.contains("| blend | rle |") && table.contains("binary-c1-u64-bitscan-q2"), "{table}");
    let o = mpirun(2, &["bench", raw.to_str().unwrap(), "--only", "brute", "--quiet"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("no binary or RLE variant"), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn an_uncompressed_nrrd_is_read_brick_by_brick_as_one_process_reads_it() {
    let dir = tempfile::tempdir().unwrap();
    let dims = [41, 36, 30];
    let v = random_volume(dims, 23, [1.0; 3]);
    // 16-bit big-endian voxels in a mirrored patient frame (x is reversed on load)
    let mut bytes = format!(
        "NRRD0004\ntype: ushort\ndimension: 3\nsizes: {} {} {}\nendian: big\nencoding: raw\n\
         space: right-anterior-superior\nspace directions: (-0.8,0,0) (0,0.8,0) (0,0,1.6)\nspace origin: (5,-3,40)\n\n",
        dims[0], dims[1], dims[2]
    )
    .into_bytes();
    v.to_f32().iter().for_each(|x| bytes.extend((x.round().clamp(0.0, 255.0) as u16 * 9).to_be_bytes()));
    let path = dir.path().join("ct.nrrd");
    std::fs::write(&path, bytes).unwrap();
    let file = path.to_str().unwrap();
    for (i, (view, tissue)) in [("anterior", "low"), ("left", "high")].into_iter().enumerate() {
        // (linear: a one-process still of these thick slices would take the cubic)
        let args =
            ["render", file, "--view", view, "--rotate", "10,25,0", "--tissue", tissue, "--size", "128", "--reconstruction", "linear"];
        let one = dir.path().join(format!("one{i}.png"));
        ok(&single(&[&args[..], &["-o", one.to_str().unwrap()]].concat()), "one process");
        for n in [2, 4] {
            let out = dir.path().join(format!("d{i}-{n}.png"));
            let o = mpirun(n, &[&args[..], &["-o", out.to_str().unwrap(), "--json"]].concat());
            ok(&o, &format!("{n} ranks"));
            assert!(std::fs::read(&one).unwrap() == std::fs::read(&out).unwrap(), "{view}: {n} ranks differ from one process");
            // every rank read its own brick from the file
            let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
            assert!(j["per_rank"].as_array().unwrap().iter().all(|r| r["read"] == "seek"), "{j}");
        }
        assert!(pixels(&one).chunks(4).filter(|p| p[..3] != [0, 0, 0]).count() > 300, "{view} shows little");
    }
}

#[test]
fn frames_it_does_not_render_are_usage_errors() {
    let dir = tempfile::tempdir().unwrap();
    let raw = raw_volume(dir.path(), [20, 18, 16], 5);
    let out = dir.path().join("x.png");
    for (extra, says) in [
        (&["--perspective", "40"][..], "parallel projections only"),
        (&["--clip-plane", "1,0,0,8"][..], "clip planes"),
        (&["--reconstruction", "cubic"][..], "linearly only"),
    ] {
        // (refused before MPI starts: one process shows it)
        let o = Command::new(bin())
            .args(["render", raw.to_str().unwrap(), "--distributed", "-o", out.to_str().unwrap()])
            .args(extra)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {}", String::from_utf8_lossy(&o.stderr));
        assert!(String::from_utf8_lossy(&o.stderr).contains(says), "{extra:?}: {}", String::from_utf8_lossy(&o.stderr));
        assert!(!out.exists(), "{extra:?} wrote an image");
    }
}
