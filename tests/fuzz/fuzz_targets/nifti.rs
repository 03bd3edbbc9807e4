//! libFuzzer target: arbitrary bytes as a Nifti file; the loader must return, never panic.
#![no_main]

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;
use shearwarp::data::io::{Format, LoadOptions, load};

fuzz_target!(|data: &[u8]| {
    let p = common::write("f.nii", data);
    let _ = load(
        &p,
        &LoadOptions {
            format: Some(Format::Nifti),
            raw: None,
        },
    );
});
