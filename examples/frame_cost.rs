//! A fixed rotation workload for instruction counting with callgrind:
//! `valgrind --tool=callgrind target/release/examples/frame_cost [iso|blend] [frames] [n]`.
//! Builds the head phantom and its masks first, then renders `frames` frames
//! 1° apart single-threaded, so the counts of the frame stages are repeatable.

use glam::DMat3;
use shearwarp::classify::presets::ct_tissues;
use shearwarp::composite::Mode;
use shearwarp::data::phantom;
use shearwarp::render::{Renderer, Settings};
use shearwarp::view::{Camera, rotate_eye};
use shearwarp::warp::Image;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let mode = if args.get(1).map(String::as_str) == Some("blend") { Mode::Blend } else { Mode::Iso };
    let frames: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(20);
    let n: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(128);
    let vol = phantom::head([n, n, n * 113 / 128]).expect("phantom");
    let mut r = Renderer::with_tissues(vol, &ct_tissues(), Settings { mode, threads: 1, ..Settings::default() }).expect("renderer");
    if mode == Mode::Blend {
        r.select_tissue_named("bone").expect("bone");
    }
    r.prepare_all_axes();
    let anterior = DMat3::from_cols_array(&[-1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0]);
    let mut img = Image::new(512, 512);
    let mut total = [0.0; 3];
    for f in 0..frames {
        let cam = Camera::new(rotate_eye(anterior, 1, 10.0 + f as f64), [512, 512]);
        let s = r.render(&cam, &mut img).expect("render");
        total[0] += s.shear_ms;
        total[1] += s.render_ms;
        total[2] += s.warp_ms;
    }
    let k = frames as f64;
    println!(
        "per frame: shear {:.3} ms, render {:.3} ms, warp {:.3} ms, coverage {:.3}",
        total[0] / k,
        total[1] / k,
        total[2] / k,
        img.coverage()
    );
}
