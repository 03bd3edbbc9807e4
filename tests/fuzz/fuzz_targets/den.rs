//! libFuzzer target: arbitrary bytes as a Den file; the loader must return, never panic.
#![no_main]

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;
use shearwarp::data::io::{Format, LoadOptions, load};

fuzz_target!(|data: &[u8]| {
    let p = common::write("f.den", data);
    let _ = load(
        &p,
        &LoadOptions {
            format: Some(Format::Den),
            raw: None,
        },
    );
});
