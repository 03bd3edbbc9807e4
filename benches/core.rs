//! Criterion benches of the binary fast rotator's stages on the head phantom:
//! mask build, one incremental shear step, and one rendered frame (iso and
//! blend), at 128³ and 256³, comparing u32 with u64 words and the byte-LUT search
//! with the hardware bit scan, plus the depth search alone over random rows
//! and its code comparator (SWAR against the bit-plane reference).
//! Run: `cargo bench --bench core`.

use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use glam::DMat3;
use shearwarp::classify::presets::{ct_tissue, ct_tissues};
use shearwarp::composite::Mode;
use shearwarp::data::phantom;
use shearwarp::data::slices::SliceStack;
use shearwarp::encode::depth::{Matcher, Search, SetBits};
use shearwarp::encode::mask::{BinaryMask, CellCodes};
use shearwarp::render::{Method, Renderer, Settings, WordSize};
use shearwarp::view::shear::ShearState;
use shearwarp::view::{Camera, rotate_eye};
use shearwarp::warp::Image;

fn cam(deg: f64) -> Camera {
    let anterior = DMat3::from_cols_array(&[-1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0]);
    Camera::new(rotate_eye(anterior, 1, deg), [512, 512])
}

/// The depth search alone: every match of 4096 random 256-slice rows (4 u64
/// words, about one slot in 8 matching), front to back, for 1-, 2- and 4-bit
/// codes. What each ray's walk pays to find its candidate slices.
fn depth_search(c: &mut Criterion) {
    let mut x = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    let rows: Vec<[u64; 4]> = (0..4096).map(|_| [0; 4].map(|_| next() & next() & next())).collect();
    let mut g = c.benchmark_group("depth_search");
    for nb in [1u32, 2, 4] {
        let m = Matcher::new(nb, 1 << (nb - 1));
        g.bench_function(BenchmarkId::new("bitscan", nb), |b| {
            b.iter(|| rows.iter().map(|r| SetBits::with_matcher(&r[..], true, Search::Bitscan, &m).sum::<usize>()).sum::<usize>())
        });
    }
    // the comparator alone, side by side: the SWAR carry test the searches use
    // against the bit-plane loop it replaced (kept as the reference kernel)
    for nb in [2u32, 4] {
        let m = Matcher::new(nb, 1 << (nb - 1));
        g.bench_function(BenchmarkId::new("hits-swar", nb), |b| {
            b.iter(|| rows.iter().flatten().fold(0u64, |a, &w| a ^ m.hits(std::hint::black_box(w))))
        });
        g.bench_function(BenchmarkId::new("hits-planes", nb), |b| {
            b.iter(|| rows.iter().flatten().fold(0u64, |a, &w| a ^ m.hits_planes(std::hint::black_box(w))))
        });
    }
    g.finish();
}

fn benches(c: &mut Criterion) {
    depth_search(c);
    for n in [128usize, 256] {
        let vol = phantom::head([n, n, n]).expect("phantom");
        let skin = ct_tissue("skin").expect("preset");
        let stack = SliceStack::new(&vol, 2);

        let mut g = c.benchmark_group(format!("mask_build_{n}"));
        g.bench_function("u32", |b| b.iter(|| BinaryMask::<u32>::build(&stack, |_, hi| hi >= skin.threshold)));
        g.bench_function("u64", |b| b.iter(|| BinaryMask::<u64>::build(&stack, |_, hi| hi >= skin.threshold)));
        g.finish();

        // tissue switch (a table change) against rebuilding the mask for the new tissue
        let mut g = c.benchmark_group(format!("tissue_switch_{n}"));
        let tissues = ct_tissues();
        let mut r = Renderer::with_tissues(vol.clone(), &tissues, Settings::default()).expect("renderer");
        r.prepare_all_axes();
        let mut i = 0;
        g.bench_function("switch", |b| {
            b.iter(|| {
                i = (i + 1) % tissues.len();
                r.select_tissue(i).expect("tissue")
            })
        });
        g.bench_function("rebuild_mask", |b| {
            b.iter(|| {
                i = (i + 1) % tissues.len();
                let t = tissues[i].threshold;
                BinaryMask::<u64>::from_codes(&CellCodes::binary(&stack, |_, hi| hi >= t), 1)
            })
        });
        g.finish();

        // one shear step per super-cell size (the step moves s voxels)
        let mut g = c.benchmark_group(format!("shear_step_cell_{n}"));
        let codes = CellCodes::thresholds(&stack, &tissues.iter().map(|t| t.threshold).collect::<Vec<_>>()).expect("codes");
        for s in 1..=4usize {
            let mut m = BinaryMask::<u64>::from_codes(&codes, s);
            let mut st = ShearState::identity(n);
            let (mut dir, mut pos) = (1, 0i32);
            g.bench_function(BenchmarkId::from_parameter(s), |b| {
                b.iter(|| {
                    if pos.abs() >= 40 / s as i32 {
                        dir = -dir;
                    }
                    pos += dir;
                    st = m.rotate_step(&st, 0, dir);
                })
            });
        }
        g.finish();

        let mut g = c.benchmark_group(format!("shear_step_{n}"));
        macro_rules! step {
            ($w:ty, $name:expr) => {{
                let mut m = BinaryMask::<$w>::build(&stack, |_, hi| hi >= skin.threshold);
                let mut s = ShearState::identity(n);
                let mut dir = 1;
                let mut pos = 0i32;
                g.bench_function($name, |b| {
                    b.iter(|| {
                        // oscillate within ±20 bits so the state stays valid
                        if pos.abs() >= 20 {
                            dir = -dir;
                        }
                        pos += dir;
                        s = m.rotate_step(&s, 0, dir);
                    })
                });
            }};
        }
        step!(u32, "u32");
        step!(u64, "u64");
        g.finish();

        for mode in [Mode::Iso, Mode::Blend] {
            let mut g = c.benchmark_group(format!("frame_{}_{n}", mode.name()));
            g.sample_size(20);
            for (word, search) in [
                (WordSize::U32, Search::Lut),
                (WordSize::U32, Search::Bitscan),
                (WordSize::U64, Search::Lut),
                (WordSize::U64, Search::Bitscan),
            ] {
                let s = Settings { method: Method::Binary, mode, word, search, threads: 1, ..Settings::default() };
                let tf = if mode == Mode::Iso { skin.iso_tf() } else { ct_tissue("bone").expect("preset").tf };
                let mut r = Renderer::new(vol.clone(), &tf, s).expect("renderer");
                r.prepare_all_axes();
                let mut img = Image::new(512, 512);
                let mut deg = 0.0;
                g.bench_function(BenchmarkId::new(word.name(), search.name()), |b| {
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
    name = core;
    config = Criterion::default().without_plots().measurement_time(Duration::from_secs(2)).warm_up_time(Duration::from_millis(500)).sample_size(20);
    targets = benches
}
criterion_main!(core);
