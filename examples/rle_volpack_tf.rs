//! The RLE path on VolPack's comparison cases (benches/scripts/volpack/README.md):
//! the same transfer functions, early termination and rotation, single-threaded.
//!
//! `cargo run --release --example rle_volpack_tf -- FILE.den [SIZE] [FRAMES] [METHOD] [opaque|ramp]`
//!
//! - opaque: `α = clamp((d − 24)/4, 0, 1)`;
//! - ramp: `α = 0.3·clamp((d − 24)/231, 0, 1)` with voxels of `α ≤ 0.05` dropped
//!   (VolPack's minimum voxel opacity);
//! - both white, composited as transfer functions (blend mode: pre-classified for
//!   `rle`, opacity corrected for the sample spacing as VolPack does);
//! - both stop a pixel at opacity 0.95 (VolPack's maximum ray opacity) and rotate
//!   about the vertical axis from VolPack's identity view in 1° steps.
//!
//! Prints one line per case with the per-frame medians (shade table, compositing,
//! warp, total) and the encoding's size.

use std::path::Path;

use glam::DMat3;
use shearwarp::classify::TransferFunction;
use shearwarp::composite::Mode;
use shearwarp::data::io::{LoadOptions, load};
use shearwarp::render::{Method, Renderer, Settings};
use shearwarp::view::{Camera, rotate_eye};
use shearwarp::warp::Image;

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).ok_or("usage: rle_volpack_tf FILE.den [SIZE] [FRAMES] [rle|binary|brute-rle]")?;
    let size: usize = args.get(2).map_or(Ok(512), |s| s.parse())?;
    let frames: usize = args.get(3).map_or(Ok(90), |s| s.parse())?;
    let method = match args.get(4).map(String::as_str) {
        None | Some("rle") => Method::Rle,
        Some("binary") => Method::Binary,
        Some("brute-rle") => Method::BruteRle,
        Some("all") => Method::Rle,
        Some(m) => return Err(format!("unknown method {m}").into()),
    };
    let vol = load(Path::new(path), &LoadOptions::default())?;
    // the 0.05 cut-off of the ramp: 0.3·(d − 24)/231 = 0.05 at d = 24 + 231/6
    let cut = 24.0 + 231.0 / 6.0;
    let white = [1.0f32; 3];
    let cases = [
        ("opaque", Mode::Blend, TransferFunction::new(vec![(24.0, 0.0), (28.0, 1.0)], vec![(0.0, white)])?),
        ("ramp", Mode::Blend, TransferFunction::new(vec![(cut, 0.0), (cut, 0.05), (255.0, 0.3)], vec![(0.0, white)])?),
    ];
    let only = args.get(5);
    for (name, mode, tf) in cases {
        if only.is_some_and(|o| o != name) {
            continue;
        }
        let s = Settings { method, mode, ert: 0.95, threads: 1, ..Settings::default() };
        let mut r = Renderer::new(vol.clone(), &tf, s)?;
        let build = r.prepare_all_axes();
        let mut img = Image::new(size, size);
        let (mut shear, mut render, mut warp, mut total) = (vec![], vec![], vec![], vec![]);
        for f in 0..frames {
            let cam = Camera::new(rotate_eye(DMat3::IDENTITY, 1, f as f64), [size, size]);
            let st = r.render(&cam, &mut img)?;
            shear.push(st.shear_ms);
            render.push(st.render_ms);
            warp.push(st.warp_ms);
            total.push(st.frame_ms());
        }
        println!(
            "{name:6} {} {size}² {frames} frames: shear {:.3} ms, render {:.3} ms, warp {:.3} ms, frame {:.3} ms (median); build {build:.0} ms; rle {:.1} MB",
            method.name(),
            median(&mut shear),
            median(&mut render),
            median(&mut warp),
            median(&mut total),
            r.rle_bytes() as f64 / 1e6
        );
    }
    Ok(())
}
