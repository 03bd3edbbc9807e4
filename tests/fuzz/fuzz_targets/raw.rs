//! libFuzzer target: the first bytes (up to a NUL) are the JSON sidecar, the
//! rest the raw voxels; the loader must return, never panic.
#![no_main]

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;
use shearwarp::data::io::{LoadOptions, load};

fuzz_target!(|data: &[u8]| {
    let split = data.iter().position(|&b| b == 0).unwrap_or(data.len());
    let (sidecar, voxels) = (&data[..split], data.get(split + 1..).unwrap_or(&[]));
    common::write("f.raw.json", sidecar);
    let p = common::write("f.raw", voxels);
    let _ = load(&p, &LoadOptions::default());
});
