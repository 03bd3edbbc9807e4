//! Criterion benches of the run-length-encoded pre-classified path against the
//! binary fast rotator and the brute-force references, on the head phantom at
//! 128³ and 256³ with the CT presets, single-threaded:
//!
//! - `preprocess_{n}`: building one axis's acceleration structure for a
//!   classification — the binary path's cell codes + packed mask (skin iso
//!   threshold) against the RLE encoding (skin iso and bone blend transfer
//!   functions). The memory of both (all three axes) is printed once per size.
//! - `frame_{iso,blend}_{n}`: one 512² frame of a rotation (1° per iteration,
//!   so the per-view tables are rebuilt every frame) with `binary`, `rle`,
//!   `brute` (post-classified reference) and `brute-rle` (pre-classified
//!   reference); iso uses the skin preset, blend the bone preset.
//!
//! Run: `cargo bench --bench rle`.

use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use glam::DMat3;
use shearwarp::classify::Classifier;
use shearwarp::classify::presets::{ct_tissue, ct_tissues};
use shearwarp::composite::Mode;
use shearwarp::data::phantom;
use shearwarp::data::slices::SliceStack;
use shearwarp::encode::mask::{BinaryMask, CellCodes};
use shearwarp::encode::rle::{Preclass, RleVolume};
use shearwarp::render::{Method, Renderer, Settings};
use shearwarp::view::{Camera, rotate_eye};
use shearwarp::warp::Image;

fn cam(deg: f64) -> Camera {
    let anterior = DMat3::from_cols_array(&[-1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0]);
    Camera::new(rotate_eye(anterior, 1, deg), [512, 512])
}

fn benches(c: &mut Criterion) {
    // single-threaded, also for the rayon code inside the builders
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("pool");
    for n in [128usize, 256] {
        let vol = phantom::head([n, n, n]).expect("phantom");
        let (lo, hi) = vol.value_range();
        let skin = ct_tissue("skin").expect("preset");
        let bone = ct_tissue("bone").expect("preset");
        let stack = SliceStack::new(&vol, 2);
        let skin_iso = Preclass::new(&Classifier::new(&skin.iso_tf(), lo, hi), vol.spacing());
        let bone_blend = Preclass::new(&Classifier::new(&bone.tf, lo, hi), vol.spacing());

        let mut g = c.benchmark_group(format!("preprocess_{n}"));
        g.sample_size(10);
        g.bench_function("mask_skin_iso", |b| {
            b.iter(|| one.install(|| BinaryMask::<u64>::from_codes(&CellCodes::binary(&stack, |_, h| h >= skin.threshold), 1)))
        });
        g.bench_function("rle_skin_iso", |b| b.iter(|| one.install(|| RleVolume::encode(&stack, &skin_iso))));
        g.bench_function("rle_bone_blend", |b| b.iter(|| one.install(|| RleVolume::encode(&stack, &bone_blend))));
        g.finish();

        // memory of all three axes
        for (mode, tissue) in [(Mode::Iso, "skin"), (Mode::Blend, "bone")] {
            let bytes = |method| {
                let s = Settings { method, mode, threads: 1, ..Settings::default() };
                let mut r = Renderer::with_tissues(vol.clone(), &ct_tissues(), s).expect("renderer");
                r.select_tissue_named(tissue).expect("tissue");
                r.prepare_all_axes();
                r.mask_bytes() + r.rle_bytes()
            };
            eprintln!(
                "memory {n}³ {} {tissue}: binary mask {:.1} MB, rle {:.1} MB (three axes)",
                mode.name(),
                bytes(Method::Binary) as f64 / 1e6,
                bytes(Method::Rle) as f64 / 1e6
            );
        }

        for (mode, tissue) in [(Mode::Iso, "skin"), (Mode::Blend, "bone")] {
            let mut g = c.benchmark_group(format!("frame_{}_{n}", mode.name()));
            g.sample_size(10);
            for method in [Method::Binary, Method::Rle, Method::Brute, Method::BruteRle] {
                let s = Settings { method, mode, threads: 1, ..Settings::default() };
                let mut r = Renderer::with_tissues(vol.clone(), &ct_tissues(), s).expect("renderer");
                r.select_tissue_named(tissue).expect("tissue");
                r.prepare_all_axes();
                let mut img = Image::new(512, 512);
                let mut deg = 0.0;
                g.bench_function(BenchmarkId::from_parameter(method.name()), |b| {
                    b.iter(|| {
                        deg += 1.0;
                        r.render(&cam(deg % 360.0), &mut img).expect("render")
                    })
                });
            }
            g.finish();
        }
    }
}

criterion_group! {
    name = rle;
    config = Criterion::default().without_plots().measurement_time(Duration::from_secs(2)).warm_up_time(Duration::from_millis(500)).sample_size(10);
    targets = benches
}
criterion_main!(rle);
