//! The README's commands and code, checked so they cannot break unseen.
//!
//! Convention: every line of a ```` ```sh ```` block of README.md that starts
//! with `shearwarp ` or `cargo run --release -- ` is a command of the tool; it
//! runs here, in order, in one temporary directory (so a file one command
//! writes is there for the next), with flags appended or lowered that keep it
//! small (`--size 64`, fewer `--degrees`, a small bench). Comments (` # …`) and
//! `\` line continuations are understood. Placeholder scans are made or found:
//! `scan.nrrd` is a small synthetic CT written here, `brain.nii.gz` is
//! `$SHEARWARP_DATA/head-mri-ch2.nii.gz` (its commands are skipped when
//! `SHEARWARP_DATA` is not set). `view` is skipped (it needs a window), and so
//! is every other line of those blocks (`cargo test`, `cargo bench`, scripts).
//! Each command must exit 0 and write the outputs it names (`-o`, `--gif`,
//! `--apng`, `--frames-dir`, `--csv`, `--json-out`, `--plot`).
//!
//! The README's Rust block must be `examples/quickstart.rs`, which `cargo test`
//! compiles.

use std::path::{Path, PathBuf};
use std::time::Duration;

use assert_cmd::Command;

fn readme() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md");
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()))
}

/// The contents of every fenced block of `lang` in `text`, in order.
fn blocks(text: &str, lang: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut current: Option<String> = None;
    for line in text.lines() {
        let fence = line.trim_start();
        match &mut current {
            None if fence.starts_with("```") && fence[3..].trim() == lang => current = Some(String::new()),
            Some(block) if fence.starts_with("```") => {
                out.push(std::mem::take(block));
                current = None;
            }
            Some(block) => {
                block.push_str(line);
                block.push('\n');
            }
            None => {}
        }
    }
    assert!(current.is_none(), "README.md: a ```{lang} block is not closed");
    out
}

/// One command line of a shell block: continuations joined, the comment gone.
fn shell_lines(block: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut pending = String::new();
    for line in block.lines() {
        let line = line.trim();
        if let Some(head) = line.strip_suffix('\\') {
            pending.push_str(head.trim_end());
            pending.push(' ');
            continue;
        }
        pending.push_str(line);
        let joined = std::mem::take(&mut pending);
        let code = match joined.find(" #") {
            Some(i) => &joined[..i],
            None => joined.as_str(),
        };
        let code = code.trim();
        if !code.is_empty() && !code.starts_with('#') {
            out.push(code.to_string());
        }
    }
    out
}

/// The tool's arguments of a README line, or `None` for a line that is not a
/// `shearwarp` command.
fn tool_args(line: &str) -> Option<Vec<String>> {
    let rest = line.strip_prefix("shearwarp ").or_else(|| line.strip_prefix("cargo run --release -- "))?;
    Some(rest.split_whitespace().map(str::to_string).collect())
}

/// Sets `flag` to `value`: replaces the value where the flag is given, else
/// appends both.
fn set_flag(args: &mut Vec<String>, flag: &str, value: &str) {
    match args.iter().position(|a| a == flag) {
        Some(i) if i + 1 < args.len() => args[i + 1] = value.to_string(),
        _ => args.extend([flag.to_string(), value.to_string()]),
    }
}

/// Adds `flag value` unless the flag is given already.
fn default_flag(args: &mut Vec<String>, flag: &str, value: &str) {
    if !args.iter().any(|a| a == flag) {
        args.extend([flag.to_string(), value.to_string()]);
    }
}

/// Makes a README command small: the same subcommand and options, less work.
fn shrink(args: &mut Vec<String>, reads_a_file: bool) {
    match args[0].as_str() {
        "render" => set_flag(args, "--size", "64"),
        "rotate" => {
            set_flag(args, "--size", "64");
            set_flag(args, "--degrees", "10");
        }
        "bench" => {
            set_flag(args, "--size", "32");
            // a suite picks its own volumes
            if !reads_a_file && !args.iter().any(|a| a == "--suite") {
                set_flag(args, "--phantom-dims", "24,24,24");
            }
            set_flag(args, "--reps", "1");
            set_flag(args, "--rounds", "1");
            set_flag(args, "--random-views", "0");
            default_flag(args, "--ref-step", "0.25");
            if !args.iter().any(|a| a == "--quiet" || a == "-q") {
                args.push("--quiet".into());
            }
        }
        _ => {}
    }
}

/// The files a command says it writes.
fn declared_outputs(args: &[String]) -> Vec<String> {
    const FLAGS: [&str; 8] = ["-o", "--output", "--gif", "--apng", "--frames-dir", "--csv", "--json-out", "--plot"];
    args.windows(2).filter(|w| FLAGS.contains(&w[0].as_str())).map(|w| w[1].clone()).collect()
}

/// A small CT-like NRRD (Hounsfield units, anisotropic voxels): air, a soft
/// tissue ball with a skin-dense rim and a bone ball inside.
fn write_ct_nrrd(path: &Path) {
    let dims = [32usize, 32, 24];
    let spacing = [1.0f64, 1.0, 1.5];
    let mut bytes = Vec::with_capacity(dims.iter().product::<usize>() * 2);
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                let c = |i: usize, v: usize| (v as f64 - (dims[i] as f64 - 1.0) / 2.0) * spacing[i];
                let (dx, dy, dz) = (c(0, x), c(1, y), c(2, z));
                let r = (dx * dx + dy * dy + dz * dz).sqrt();
                let hu: i16 = if r < 5.0 {
                    800
                } else if r < 12.0 {
                    40
                } else if r < 13.0 {
                    -300
                } else {
                    -1000
                };
                bytes.extend_from_slice(&hu.to_le_bytes());
            }
        }
    }
    let header = format!(
        "NRRD0004\ntype: short\ndimension: 3\nsizes: {} {} {}\nspacings: {} {} {}\nendian: little\nencoding: raw\n\n",
        dims[0], dims[1], dims[2], spacing[0], spacing[1], spacing[2]
    );
    let mut file = header.into_bytes();
    file.extend_from_slice(&bytes);
    std::fs::write(path, file).unwrap();
}

/// The placeholder scans of the README: name → where the test gets one.
/// `None` when it cannot (the commands naming it are skipped).
fn provide_scans(dir: &Path) -> Vec<(&'static str, Option<PathBuf>)> {
    write_ct_nrrd(&dir.join("scan.nrrd"));
    let data = std::env::var_os("SHEARWARP_DATA").map(PathBuf::from);
    let mri = data.map(|d| d.join("head-mri-ch2.nii.gz")).filter(|p| p.is_file());
    if let Some(mri) = &mri {
        std::fs::copy(mri, dir.join("brain.nii.gz")).unwrap();
    }
    vec![("scan.nrrd", Some(dir.join("scan.nrrd"))), ("brain.nii.gz", mri)]
}

#[test]
fn readme_cli_commands_run() {
    let text = readme();
    let dir = tempfile::tempdir().unwrap();
    let scans = provide_scans(dir.path());

    let (mut ran, mut skipped, mut failures) = (Vec::new(), Vec::new(), Vec::new());
    for line in blocks(&text, "sh").iter().flat_map(|b| shell_lines(b)) {
        let Some(mut args) = tool_args(&line) else {
            skipped.push(format!("{line}  (not a shearwarp command)"));
            continue;
        };
        if args[0] == "view" {
            skipped.push(format!("{line}  (needs a window)"));
            continue;
        }
        let named: Vec<_> = scans.iter().filter(|(name, _)| args.iter().any(|a| a == name)).collect();
        if let Some((name, _)) = named.iter().find(|(_, path)| path.is_none()) {
            skipped.push(format!("{line}  ({name}: set SHEARWARP_DATA)"));
            continue;
        }
        shrink(&mut args, !named.is_empty());
        let run = Command::cargo_bin("shearwarp")
            .unwrap()
            .current_dir(dir.path())
            .args(&args)
            .timeout(Duration::from_secs(600))
            .output()
            .unwrap();
        let shown = format!("shearwarp {}", args.join(" "));
        if !run.status.success() {
            let stderr = String::from_utf8_lossy(&run.stderr);
            let tail: Vec<&str> = stderr.lines().rev().take(3).collect();
            failures.push(format!("{shown}\n    exit {:?}: {}", run.status.code(), tail.into_iter().rev().collect::<Vec<_>>().join(" / ")));
            continue;
        }
        for out in declared_outputs(&args) {
            if !dir.path().join(&out).exists() {
                failures.push(format!("{shown}\n    exit 0 but wrote no {out}"));
            }
        }
        ran.push((args[0].clone(), shown));
    }

    println!("ran {} README commands:", ran.len());
    for (_, shown) in &ran {
        println!("  {shown}");
    }
    println!("skipped {}:", skipped.len());
    for s in &skipped {
        println!("  {s}");
    }
    assert!(failures.is_empty(), "{} README command(s) failed:\n{}", failures.len(), failures.join("\n"));
    for sub in ["render", "rotate", "info", "export", "bench"] {
        assert!(ran.iter().any(|(s, _)| s == sub), "the README runs no `shearwarp {sub}` command");
    }
    assert!(ran.len() >= 15, "only {} README commands ran: did the sh blocks move?", ran.len());
}

#[test]
fn readme_rust_block_is_the_quickstart_example() {
    let text = readme();
    let rust = blocks(&text, "rust");
    assert_eq!(rust.len(), 1, "README.md should hold one ```rust block, examples/quickstart.rs");
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/quickstart.rs");
    let example = std::fs::read_to_string(&path).unwrap();
    assert!(
        rust[0].trim() == example.trim(),
        "README.md's Rust block differs from examples/quickstart.rs: copy the example into the README"
    );
}

#[test]
fn readme_parsing_understands_the_conventions() {
    let block = "shearwarp render -o a.png   # a comment\n# only a comment\nshearwarp render \\\n    --size 512 -o b.png\ncargo bench\n";
    let lines = shell_lines(block);
    assert_eq!(lines, ["shearwarp render -o a.png", "shearwarp render --size 512 -o b.png", "cargo bench"]);
    let mut args = tool_args(&lines[1]).unwrap();
    shrink(&mut args, false);
    assert_eq!(args, ["render", "--size", "64", "-o", "b.png"]);
    assert_eq!(declared_outputs(&args), ["b.png"]);
    assert_eq!(tool_args("cargo run --release -- rotate --degrees 360").unwrap(), ["rotate", "--degrees", "360"]);
    assert!(tool_args("cargo test --release").is_none());
}
