//! `shearwarp bench` with its whole default matrix: every variant, both
//! modes, on a small phantom with few views, runs to the end (the BCC grid's
//! iso depth included).

use assert_cmd::Command;

#[test]
fn the_whole_default_matrix_runs() {
    let mut c = Command::cargo_bin("shearwarp").unwrap();
    c.args(["bench", "--phantom", "head", "--phantom-dims", "24,24,22", "--size", "32", "--random-views", "0"]);
    c.args(["--reps", "1", "--rounds", "1", "--warmup", "1", "--ref-step", "0.25", "--quiet", "--json"]);
    let out = c.assert().success();
    let json: serde_json::Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
    let records = json["records"].as_array().unwrap();
    let names = |mode: &str| {
        let mut v: Vec<&str> = records.iter().filter(|r| r["mode"] == mode).map(|r| r["variant"].as_str().unwrap()).collect();
        v.dedup();
        v
    };
    let (iso, blend) = (names("iso"), names("blend"));
    for name in ["rle", "rle-bcc", "rle-bcc-deluxe-I", "rle-bcc-deluxe-I,M,P", "rle-reuse", "brute", "binary-c1-u64-bitscan"] {
        assert!(
            iso.contains(&name) || name.contains(',') && iso.iter().any(|n| n.starts_with("rle-bcc-deluxe-I")),
            "iso lacks {name}: {iso:?}"
        );
        assert!(
            blend.contains(&name) || name.contains(',') && blend.iter().any(|n| n.starts_with("rle-bcc-deluxe-I")),
            "blend lacks {name}: {blend:?}"
        );
    }
    assert!(iso.len() >= 20, "iso variants: {iso:?}");
    for r in records {
        assert!(r["error"]["rmse"].as_f64().unwrap().is_finite(), "{r}");
    }
}
