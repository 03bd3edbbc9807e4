//! What each skip buys, side by side in one run (head phantom 128×128×113, 512²,
//! one thread): the mask's empty-space skipping (binary vs brute force), early
//! ray termination (ert 0.99 vs 1.0), skipping an unchanged frame, and the limit
//! of a shear step — its words against a memcpy of the same bytes; rays cast
//! only inside the occupied mask's rectangle against the whole volume's; the RLE
//! path's per-view tables reused when nothing changed against rebuilt; the
//! binary path's bit-scan kernels (at every CPU level: lzcnt, plain bsr; LUT);
//! the binary row's prefetches against none; shading by normal code and table
//! against the exact gradient; densities packed with the normal codes against
//! the two arrays apart; the shear's kernels compiled for AVX2 against plain;
//! a frame for a window warped to 8 bits against warped to f32 and rounded.
//! Run: `cargo bench --bench skips`.

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::measurement::WallTime;
use criterion::{BenchmarkGroup, Criterion, SamplingMode, criterion_group, criterion_main};
use glam::DMat3;
use shearwarp::classify::presets::ct_tissues;
use shearwarp::classify::shading::Shading;
use shearwarp::classify::{Classifier, TransferFunction};
use shearwarp::composite::Mode;
use shearwarp::data::phantom;
use shearwarp::data::slices::SliceStack;
use shearwarp::data::volume::{Volume, VoxelData};
use shearwarp::encode::depth::Search;
use shearwarp::encode::mask::{BinaryMask, CellCodes};
use shearwarp::encode::rle::{Preclass, ViewTables};
use shearwarp::render::Target;
use shearwarp::render::{Method, Normals, Renderer, Settings};
use shearwarp::view::shear::ShearState;
use shearwarp::view::{Camera, rotate_eye};
use shearwarp::warp::{Canvas, Image, Image8, Texel};

fn cam(deg: f64) -> Camera {
    let anterior = DMat3::from_cols_array(&[-1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0]);
    Camera::new(rotate_eye(anterior, 1, deg), [512, 512])
}

/// A one-thread renderer of the 128×128×113 head phantom at `tissue`, every axis built.
fn renderer(s: Settings, tissue: &str) -> Renderer {
    renderer_of(phantom::head([128, 128, 113]).expect("phantom"), s, tissue)
}

/// [`renderer`] for volume `vol`.
fn renderer_of(vol: Volume, s: Settings, tissue: &str) -> Renderer {
    let mut r = Renderer::with_tissues(vol, &ct_tissues(), Settings { threads: 1, ..s }).expect("renderer");
    r.select_tissue_named(tissue).expect("tissue");
    r.prepare_all_axes();
    r
}

/// Benches `r` turning 1° per iteration (so every frame renders) into a 512² image.
/// Every sample turns through the same views (flat sampling: the same number of
/// frames per sample, each sample starting from the same view, which is
/// rendered untimed first), so samples differ by noise, not by what they show.
fn bench_turn(g: &mut BenchmarkGroup<'_, WallTime>, name: impl Into<String>, r: Renderer) {
    bench_turn_into(g, name, r, Image::new(512, 512), |_| ());
}

/// [`bench_turn`] into image `img` (f32 or 8-bit), with `show(img)` after every frame.
fn bench_turn_into<T: Texel>(
    g: &mut BenchmarkGroup<'_, WallTime>,
    name: impl Into<String>,
    mut r: Renderer,
    mut img: Canvas<T>,
    mut show: impl FnMut(&Canvas<T>),
) where
    Canvas<T>: Target,
{
    g.sampling_mode(SamplingMode::Flat);
    g.bench_function(name.into(), |b| {
        b.iter_custom(|frames| {
            r.render(&cam(0.0), &mut img).expect("render");
            let t = Instant::now();
            for f in 1..=frames {
                black_box(r.render(&cam((f % 360) as f64), &mut img).expect("render"));
                show(&img);
            }
            t.elapsed()
        })
    });
}

fn skips(c: &mut Criterion) {
    // a frame for a window (0RGB words, as `shearwarp view` hands softbuffer):
    // the f32 warp and a rounding pass over the whole image, against the warp
    // rounding to 8 bits as it writes and a byte shuffle
    let mut g = c.benchmark_group("display_frame_iso_skin");
    let mut words: Vec<u32> = Vec::with_capacity(512 * 512);
    bench_turn_into(&mut g, "f32_then_round", renderer(Settings::default(), "skin"), Image::new(512, 512), |img| {
        img.to_0rgb(&mut words);
        black_box(&words);
    });
    bench_turn_into(&mut g, "warp_to_u8", renderer(Settings::default(), "skin"), Image8::new(512, 512), |img| {
        img.to_0rgb(&mut words);
        black_box(&words);
    });
    g.finish();
    // empty-space skipping through the mask
    for (mode, tissue) in [(Mode::Iso, "skin"), (Mode::Blend, "bone")] {
        let mut g = c.benchmark_group(format!("mask_skipping_{}", mode.name()));
        for method in [Method::Binary, Method::Brute] {
            let r = renderer(Settings { mode, method, ..Settings::default() }, tissue);
            bench_turn(&mut g, method.name(), r);
        }
        g.finish();
    }
    // early ray termination
    let mut g = c.benchmark_group("early_ray_termination_blend_skin");
    for ert in [0.99f32, 1.0] {
        let r = renderer(Settings { mode: Mode::Blend, ert, ..Settings::default() }, "skin");
        bench_turn(&mut g, format!("ert_{ert}"), r);
    }
    g.finish();
    // an unchanged frame renders nothing
    let mut g = c.benchmark_group("unchanged_frame");
    let mut r = renderer(Settings::default(), "skin");
    let mut img = Image::new(512, 512);
    g.bench_function("same_view_skipped", |b| b.iter(|| r.render(&cam(30.0), &mut img).expect("render")));
    let mut other = Image::new(512, 512);
    g.bench_function("same_view_rendered", |b| {
        b.iter(|| {
            // alternate the target image so the frame must be rendered
            std::mem::swap(&mut img, &mut other);
            r.render(&cam(30.0), &mut img).expect("render")
        })
    });
    g.finish();
    // rays only inside the occupied mask's bounding rectangle, against the whole
    // sheared volume's rectangle (bone occupies a small part of the head)
    let mut g = c.benchmark_group("occupied_rect_iso_bone");
    for (name, occupied_rect) in [("occupied_rect", true), ("volume_rect", false)] {
        let r = renderer(Settings { occupied_rect, ..Settings::default() }, "bone");
        bench_turn(&mut g, name, r);
    }
    g.finish();
    // the RLE path's per-view tables: reused when classification, spacing ratio,
    // light and material are unchanged, rebuilt when the light moves
    let vol = phantom::head([64, 64, 64]).expect("phantom");
    let (lo, hi) = vol.value_range();
    let tf = shearwarp::classify::presets::ct_tissue("bone").expect("bone").tf;
    let pre = Preclass::new(&Classifier::new(&tf, lo, hi), vol.spacing());
    let mut tables = ViewTables::default();
    let mut g = c.benchmark_group("rle_view_tables");
    let light = [0.0f32, 0.6, 0.8];
    g.bench_function("unchanged_reused", |b| b.iter(|| tables.update(&pre, 1.2, black_box(light), Shading::default())));
    let mut t = 0.0f32;
    g.bench_function("light_moved_rebuilt", |b| {
        b.iter(|| {
            t += 0.01;
            tables.update(&pre, 1.2, [t.sin() * 0.6, 0.0, t.cos() * 0.6], Shading::default())
        })
    });
    g.finish();
    // the depth search kernels of the binary path, whole frames
    let mut g = c.benchmark_group("bitscan_kernels_iso_skin");
    // (bit scan at every CPU level this machine runs: lzcnt/tzcnt against bsr/bsf)
    for cpu in shearwarp::kernels::all_levels() {
        let r = renderer(Settings { search: Search::Bitscan, cpu, ..Settings::default() }, "skin");
        bench_turn(&mut g, format!("bitscan-{}", cpu.name()), r);
    }
    bench_turn(&mut g, "lut", renderer(Settings { search: Search::Lut, ..Settings::default() }, "skin"));
    g.finish();
    // the binary row's prefetches (the voxel rows of each ray's first candidate,
    // while a group of rays is bit-scanned) against none; on a 256×256×225 head,
    // whose f32 slice stack (59 MB) is far beyond the caches
    let head256 = phantom::head([256, 256, 225]).expect("phantom");
    let mut g = c.benchmark_group("prefetch_iso_skin_256");
    for (name, prefetch) in [("prefetch", true), ("no_prefetch", false)] {
        bench_turn(&mut g, name, renderer_of(head256.clone(), Settings { prefetch, ..Settings::default() }, "skin"));
    }
    g.finish();
    // shading by normal code and shade table against the exact gradient at
    // every hit, on the same 256×256×225 head (same mask, same walks)
    let mut g = c.benchmark_group("normals_iso_skin_256");
    for normals in [Normals::Codes, Normals::Gradient] {
        bench_turn(&mut g, normals.name(), renderer_of(head256.clone(), Settings { normals, ..Settings::default() }, "skin"));
    }
    g.finish();
    // densities and normal codes packed into one u32 per voxel (a hit reads both
    // from the same lines) against the f32 stack and the u16 codes apart, on the
    // same head rounded to 16-bit integers as CT scans are
    let rounded = head256.to_f32().iter().map(|v| v.round() as i16).collect();
    let head16 = Volume::new(head256.dims(), head256.spacing(), VoxelData::I16(rounded)).expect("volume");
    let mut g = c.benchmark_group("packed_cells_iso_skin_256");
    for (name, pack) in [("packed", true), ("apart", false)] {
        bench_turn(&mut g, name, renderer_of(head16.clone(), Settings { pack, ..Settings::default() }, "skin"));
    }
    g.finish();
    // the same on a real scan, when SHEARWARP_DATA holds VolPack's brainsmall.den:
    // upsampled 2× (256×256×168, u8), iso 26, the 1-bit mask
    if let Some(den) = std::env::var_os("SHEARWARP_DATA").map(|d| std::path::Path::new(&d).join("brainsmall.den")).filter(|p| p.exists()) {
        let vol = shearwarp::data::io::den::load_den(&den).expect("brainsmall.den");
        let up2 = vol.resampled(vol.dims().map(|n| 2 * n)).expect("upsample");
        let tf = TransferFunction::threshold(26.0, [0.9, 0.85, 0.8]);
        let mut g = c.benchmark_group("packed_cells_iso_brainsmall_up2");
        for (name, pack) in [("packed", true), ("apart", false)] {
            let mut r = Renderer::new(up2.clone(), &tf, Settings { pack, threads: 1, ..Settings::default() }).expect("renderer");
            r.prepare_all_axes();
            bench_turn(&mut g, name, r);
        }
        g.finish();
    }
    // the limit of a shear step: its words against a memcpy of the same bytes
    // (and the step's kernels compiled for AVX2 against the plain build's)
    let stack = SliceStack::new(&head256, 2);
    let codes = CellCodes::binary(&stack, |_, hi| hi >= -500.0);
    let mut m = BinaryMask::<u64>::from_codes(&codes, 1);
    let mut st = ShearState::identity(225);
    st = m.rotate_step(&st, 0, 1);
    let mut plain = m.clone();
    plain.set_cpu_level(shearwarp::kernels::CpuLevel::Scalar);
    let plain_st = st.clone();
    let w = m.shear_to(&st.rotated(0, 1)).words.max(1);
    let bytes = (w * 8) as usize;
    let (src, mut dst) = (vec![1u8; bytes], vec![0u8; bytes]);
    let mut g = c.benchmark_group(format!("shear_step_vs_memcpy_256_{bytes}_bytes"));
    // one thread for both, so the comparison is per core
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("pool");
    // one-bit steps back and forth within ±40 bits, so the state stays valid
    let steps = |g: &mut BenchmarkGroup<'_, WallTime>, name: &str, m: &mut BinaryMask<u64>, mut st: ShearState| {
        let (mut dir, mut pos) = (1, 2i32);
        g.bench_function(name, |b| {
            b.iter(|| {
                if pos.abs() >= 40 {
                    dir = -dir;
                }
                pos += dir;
                st = pool.install(|| m.rotate_step(&st, 0, dir));
            })
        });
    };
    steps(&mut g, "shear_step", &mut m, st);
    g.bench_function("memcpy", |b| b.iter(|| dst.copy_from_slice(black_box(&src))));
    steps(&mut g, "shear_step_plain", &mut plain, plain_st);
    g.finish();
    // two steps in one pass (each slice moves −2..=2) against two single steps,
    // for the 1-bit mask and the tissue presets' 4-bit codes (16 words a column)
    let tissue = CellCodes::thresholds(&stack, &[-500.0, -100.0, 40.0, 300.0]).expect("codes");
    for (bits, codes) in [(1, &codes), (tissue.nb, &tissue)] {
        let mut g = c.benchmark_group(format!("shear_two_steps_256_{bits}bit"));
        for (name, fused) in [("fused", true), ("single", false)] {
            let mut m = BinaryMask::<u64>::from_codes(codes, 1);
            m.set_fused(fused);
            let (mut st, mut dir, mut pos) = (ShearState::identity(225), 2, 0i32);
            g.bench_function(name, |b| {
                b.iter(|| {
                    if pos.abs() >= 40 {
                        dir = -dir;
                    }
                    pos += dir;
                    st = st.rotated(0, dir);
                    pool.install(|| m.shear_to(&st))
                })
            });
        }
        g.finish();
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().without_plots().measurement_time(Duration::from_secs(2)).warm_up_time(Duration::from_millis(500)).sample_size(20);
    targets = skips
}
criterion_main!(benches);
