//! libFuzzer target: arbitrary bytes as the one slice of a DICOM series
//! directory; the loader must return, never panic.
#![no_main]

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;
use shearwarp::data::io::{Format, LoadOptions, load};

fuzz_target!(|data: &[u8]| {
    let p = common::write("a.dcm", data);
    let dir = p.parent().expect("the scratch directory");
    let _ = load(
        dir,
        &LoadOptions {
            format: Some(Format::Dicom),
            raw: None,
        },
    );
});
