//! Correctness invariants of the binary fast rotator, as property tests over
//! random volumes, transfer functions and views.

use crate::common;

use common::{random_tf, random_volume};
use glam::{DMat3, EulerRot};
use proptest::prelude::*;
use shearwarp::classify::{Classifier, TransferFunction};
use shearwarp::composite::Mode;
use shearwarp::data::slices::SliceStack;
use shearwarp::data::volume::{Volume, VoxelData};
use shearwarp::encode::depth::{Search, bit_of};
use shearwarp::encode::mask::BinaryMask;
use shearwarp::kernels::{self, CpuLevel};
use shearwarp::render::{Deluxe, Method, Normals, Renderer, Settings, WordSize};
use shearwarp::view::clip::{ClipRegion, Region};
use shearwarp::view::shear::ShearState;
use shearwarp::view::{Camera, Factorization, rotate_eye};
use shearwarp::warp::{Image, Image8};
use std::sync::Arc;

/// `v` as 16-bit integer scans are: every value rounded to the nearest integer
/// and stored as u16, so the renderer packs densities with normal codes.
fn as_u16(v: &Volume) -> Volume {
    let data = v.to_f32().iter().map(|x| x.round() as u16).collect();
    Volume::new(v.dims(), v.spacing(), VoxelData::U16(data)).unwrap()
}

fn render(vol: &Volume, tf: &TransferFunction, s: Settings, cam: &Camera) -> (Image, Vec<[f32; 4]>, Vec<f32>) {
    let mut r = Renderer::new(vol.clone(), tf, s).unwrap();
    let mut img = Image::new(cam.size[0], cam.size[1]);
    r.render(cam, &mut img).unwrap();
    let inter = r.intermediate();
    // the full intermediate grid, transparent outside the valid rectangle
    let [w, h] = inter.size;
    let mut px = Vec::with_capacity(w * h);
    let mut depth = Vec::with_capacity(w * h);
    for q in 0..h {
        for p in 0..w {
            px.push(inter.get(p as isize, q as isize));
            depth.push(inter.depth_at(p, q));
        }
    }
    (img, px, depth)
}

/// A 64-bit linear congruential generator's high bits, from `seed`.
fn lcg(mut seed: u64) -> impl FnMut() -> u64 {
    move || {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        seed >> 11
    }
}

fn same_bits(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases(48)))]

    /// The 8-bit warp writes the f32 warp's pixels rounded, bit for bit, frame
    /// after frame into the same images (so its span clearing is the f32 one's).
    #[test]
    fn eight_bit_frames_are_the_rounded_f32_frames(
        nx in 2usize..20, ny in 2usize..20, nz in 2usize..24, seed in any::<u64>(), tfs in any::<u64>(),
        rx in -3.2f64..3.2, ry in -3.2f64..3.2, step in -1.0f64..1.0, blend in any::<bool>(), rle in any::<bool>(),
    ) {
        let vol = random_volume([nx, ny, nz], seed, [1.0, 0.8, 1.5]);
        let s = Settings {
            mode: if blend { Mode::Blend } else { Mode::Iso },
            method: if rle { Method::Rle } else { Method::Binary },
            threads: 2,
            ..Settings::default()
        };
        let mut r = Renderer::new(vol, &random_tf(tfs), s).unwrap();
        let (mut img, mut img8) = (Image::new(37, 29), Image8::new(37, 29));
        for f in 0..4 {
            let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, rx + f as f64 * step, ry, 0.3), [37, 29]);
            r.render(&cam, &mut img).unwrap();
            r.render(&cam, &mut img8).unwrap();
            prop_assert_eq!(&img8.data, &img.to_rgba8(), "frame {}", f);
            prop_assert_eq!(img8.to_rgb8(), img.to_rgb8());
        }
    }

    /// Lossless skipping: the accelerated image equals brute force sample for sample.
    #[test]
    fn binary_equals_brute_force(
        nx in 2usize..24, ny in 2usize..24, nz in 2usize..40, seed in any::<u64>(), tfs in any::<u64>(),
        rx in -3.2f64..3.2, ry in -3.2f64..3.2, rz in -3.2f64..3.2,
        blend in any::<bool>(), u64w in any::<bool>(), lut in any::<bool>(), aniso in any::<bool>(),
        occupied_rect in any::<bool>(), prefetch in any::<bool>(), codes in any::<bool>(), u16_data in any::<bool>(),
    ) {
        let sp = if aniso { [1.0, 0.7, 2.5] } else { [1.0; 3] };
        // f32 densities, or 16-bit ones (densities and codes packed)
        let vol = random_volume([nx, ny, nz], seed, sp);
        let vol = if u16_data { as_u16(&vol) } else { vol };
        let tf = random_tf(tfs);
        let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, rx, ry, rz), [48, 40]);
        let base = Settings {
            mode: if blend { Mode::Blend } else { Mode::Iso },
            word: if u64w { WordSize::U64 } else { WordSize::U32 },
            search: if lut { Search::Lut } else { Search::Bitscan },
            threads: 2,
            // either shading model: both paths shade with it
            normals: if codes { Normals::Codes } else { Normals::Gradient },
            ..Settings::default()
        };
        // rays inside the occupied mask's rectangle or over the whole volume's,
        // with prefetches or without: same image
        let (bi, bpx, bd) = render(&vol, &tf, Settings { method: Method::Binary, occupied_rect, prefetch, ..base }, &cam);
        let (ri, rpx, rd) = render(&vol, &tf, Settings { method: Method::Brute, ..base }, &cam);
        let flat = |v: &[[f32; 4]]| v.iter().flatten().copied().collect::<Vec<f32>>();
        prop_assert!(same_bits(&flat(&bpx), &flat(&rpx)), "intermediate images differ");
        prop_assert!(same_bits(&bd, &rd), "iso depths differ");
        prop_assert!(same_bits(&flat(&bi.data), &flat(&ri.data)), "final images differ");
    }

    /// Packing densities with normal codes changes where a ray reads, not what:
    /// the same image, intermediate and depths bit for bit as the two arrays apart.
    #[test]
    fn packed_cells_equal_split_cells(
        nx in 2usize..24, ny in 2usize..24, nz in 2usize..40, seed in any::<u64>(), tfs in any::<u64>(),
        rx in -3.2f64..3.2, ry in -3.2f64..3.2, blend in any::<bool>(), brute in any::<bool>(), offset in -3000i32..3000,
        bytes in any::<bool>(),
    ) {
        // integer densities: 16-bit, some negative (CT-like), packed with an
        // offset in two u16 a voxel; or 8-bit, packed in three bytes
        let vol = random_volume([nx, ny, nz], seed, [1.0, 0.8, 1.3]);
        let offset = if bytes { 0 } else { offset };
        let data = match bytes {
            true => VoxelData::U8(vol.to_f32().iter().map(|x| x.round().clamp(0.0, 255.0) as u8).collect()),
            false => VoxelData::I16(vol.to_f32().iter().map(|x| (x.round() as i32 + offset) as i16).collect()),
        };
        let vol = Volume::new(vol.dims(), vol.spacing(), data).unwrap();
        let tf = random_tf(tfs);
        let o = offset as f32;
        let tf = TransferFunction::new(
            tf.opacity.iter().map(|&(d, a)| (d + o, a)).collect(),
            tf.color.iter().map(|&(d, c)| (d + o, c)).collect(),
        ).unwrap();
        let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, rx, ry, 0.3), [48, 40]);
        let base = Settings {
            method: if brute { Method::Brute } else { Method::Binary },
            mode: if blend { Mode::Blend } else { Mode::Iso },
            threads: 2,
            normals: Normals::Codes,
            ..Settings::default()
        };
        let (pi, ppx, pd) = render(&vol, &tf, Settings { pack: true, ..base }, &cam);
        let (si, spx, sd) = render(&vol, &tf, Settings { pack: false, ..base }, &cam);
        let flat = |v: &[[f32; 4]]| v.iter().flatten().copied().collect::<Vec<f32>>();
        prop_assert!(same_bits(&flat(&ppx), &flat(&spx)), "intermediate images differ");
        prop_assert!(same_bits(&pd, &sd), "iso depths differ");
        prop_assert!(same_bits(&flat(&pi.data), &flat(&si.data)), "final images differ");
    }

    /// Conservative mask: no sample with non-zero opacity lies in a cell whose bit is 0.
    #[test]
    fn mask_is_conservative(
        nx in 2usize..20, ny in 2usize..20, nz in 2usize..70, seed in any::<u64>(), tfs in any::<u64>(),
        rx in -3.2f64..3.2, ry in -3.2f64..3.2,
    ) {
        let vol = random_volume([nx, ny, nz], seed, [1.0; 3]);
        let tf = random_tf(tfs);
        let (lo, hi) = vol.value_range();
        let cls = Classifier::new(&tf, lo, hi);
        let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, rx, ry, 0.0), [32, 32]);
        let f = Factorization::new(&cam, vol.dims(), vol.spacing()).unwrap();
        let st = SliceStack::new(&vol, f.axis);
        let mut m = BinaryMask::<u32>::build(&st, |lo, hi| cls.may_be_visible(lo, hi));
        let state = ShearState::from_view(&f);
        m.shear_to(&state);
        let [gw, gh] = m.grid();
        let pad = m.pad() as i32;
        let [cin, cjn] = st.cells();
        for q in 0..gh {
            for p in 0..gw {
                let row = m.row(p, q);
                for k in 0..st.n[2] {
                    let ci = p as i32 - pad + state.floor[0][k];
                    let cj = q as i32 - pad + state.floor[1][k];
                    if ci < 0 || cj < 0 || ci as usize >= cin || cj as usize >= cjn { continue; }
                    let wi = (state.trans[0][k] - state.floor[0][k] as f64) as f32;
                    let wj = (state.trans[1][k] - state.floor[1][k] as f64) as f32;
                    let d = st.bilinear(ci as usize, cj as usize, k, wi, wj);
                    if cls.alpha(d) > 0.0 {
                        prop_assert!(row[k / 32] & bit_of::<u32>(k) != 0, "visible sample at ray ({p},{q}) slice {k} in a clear cell");
                    }
                }
            }
        }
    }

    /// At every CPU level this machine can run (`kernels::all_levels`), the
    /// bit-scan kernels (at `Avx2` the row loop compiled for lzcnt/tzcnt and the
    /// shear kernels for AVX2) and the byte-LUT search give the image of the
    /// plain build's kernels (`CpuLevel::Scalar`, bsr/bsf) bit for bit, for any
    /// word and cell size.
    #[test]
    fn every_cpu_level_renders_like_the_scalar_kernels(
        nx in 2usize..24, ny in 2usize..24, nz in 2usize..90, seed in any::<u64>(), tfs in any::<u64>(),
        rx in -3.2f64..3.2, ry in -3.2f64..3.2, blend in any::<bool>(), u64w in any::<bool>(), cell in 1usize..4,
    ) {
        let vol = random_volume([nx, ny, nz], seed, [1.0; 3]);
        let tf = random_tf(tfs);
        let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, rx, ry, 0.0), [40, 40]);
        let base = Settings {
            mode: if blend { Mode::Blend } else { Mode::Iso },
            word: if u64w { WordSize::U64 } else { WordSize::U32 },
            cell,
            threads: 1,
            ..Settings::default()
        };
        let scalar = render(&vol, &tf, Settings { search: Search::Bitscan, cpu: CpuLevel::Scalar, ..base }, &cam);
        let flat = |v: &[[f32; 4]]| v.iter().flatten().copied().collect::<Vec<f32>>();
        for cpu in kernels::all_levels() {
            for search in [Search::Bitscan, Search::Lut] {
                let other = render(&vol, &tf, Settings { search, cpu, ..base }, &cam);
                let what = format!("{} search at CPU level {}", search.name(), cpu.name());
                prop_assert!(same_bits(&flat(&scalar.1), &flat(&other.1)), "intermediate images differ: {}", what);
                prop_assert!(same_bits(&scalar.2, &other.2), "iso depths differ: {}", what);
                prop_assert!(scalar.0 == other.0, "images differ: {}", what);
            }
        }
    }

    /// At every CPU level this machine can run, the run-length-encoded
    /// traversal (its spans compiled for AVX2 at `Avx2`) composites the
    /// plain build's intermediate image bit for bit: pre- and
    /// post-classified (Deluxe P), iso and blend, with and without ray
    /// limits (a clip box), 8-bit, 16-bit and float volumes.
    #[test]
    fn every_cpu_level_composites_the_runs_like_the_plain_build(
        nx in 2usize..24, ny in 2usize..24, nz in 2usize..30, seed in any::<u64>(), tfs in any::<u64>(),
        rx in -3.2f64..3.2, ry in -3.2f64..3.2, blend in any::<bool>(), post in any::<bool>(), clip in any::<bool>(),
        u16_data in any::<bool>(),
    ) {
        let vol = random_volume([nx, ny, nz], seed, [1.0, 0.8, 1.5]);
        let vol = if u16_data { as_u16(&vol) } else { vol };
        let tf = random_tf(tfs);
        let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, rx, ry, 0.0), [40, 36]);
        let base = Settings {
            method: Method::Rle,
            mode: if blend { Mode::Blend } else { Mode::Iso },
            deluxe: Deluxe { post, ..Deluxe::STANDARD },
            threads: 2,
            ..Settings::default()
        };
        let frame = |cpu: CpuLevel| {
            let mut r = Renderer::new(vol.clone(), &tf, Settings { cpu, ..base }).unwrap();
            if clip {
                let [dx, dy, dz] = vol.dims().map(|d| d as f64);
                let region = ClipRegion::new(Region::Box { lo: [dx * 0.3, -1.0, dz * 0.2], hi: [dx, dy * 0.7, dz] }, vol.spacing()).unwrap();
                r.set_limiter(Some(Arc::new(region)));
            }
            let mut img = Image::new(cam.size[0], cam.size[1]);
            r.render(&cam, &mut img).unwrap();
            let inter = r.intermediate();
            let [w, h] = inter.size;
            let px: Vec<f32> = (0..w * h).flat_map(|i| inter.get((i % w) as isize, (i / w) as isize)).collect();
            (img, px)
        };
        let plain = frame(CpuLevel::Scalar);
        prop_assert!(plain.1.iter().any(|&x| x != 0.0) || plain.0.coverage() == 0.0);
        for cpu in kernels::all_levels() {
            let other = frame(cpu);
            prop_assert!(same_bits(&plain.1, &other.1), "intermediate images differ at CPU level {}", cpu.name());
            prop_assert!(plain.0 == other.0, "images differ at CPU level {}", cpu.name());
        }
    }

    /// Same image for 1 and N threads.
    #[test]
    fn deterministic_across_thread_counts(seed in any::<u64>(), ry in -3.2f64..3.2, blend in any::<bool>()) {
        let vol = random_volume([20, 18, 22], seed, [1.0; 3]);
        let tf = random_tf(seed >> 3);
        let cam = Camera::new(rotate_eye(DMat3::IDENTITY, 1, ry.to_degrees()), [64, 64]);
        let s = Settings { mode: if blend { Mode::Blend } else { Mode::Iso }, ..Settings::default() };
        let a = render(&vol, &tf, Settings { threads: 1, ..s }, &cam).0;
        let b = render(&vol, &tf, Settings { threads: 2, ..s }, &cam).0;
        let c = render(&vol, &tf, Settings { threads: 3, ..s }, &cam).0;
        prop_assert_eq!(&a, &b);
        prop_assert_eq!(&a, &c);
    }
}

/// No drift: thousands of incremental steps in random directions (one-bit
/// rotation steps and multi-bit jumps) end in exactly the mask sheared directly.
#[test]
fn the_cpu_level_is_what_runs_here() {
    // report which kernels the tests above compared on this machine
    eprintln!(
        "CPU level: {} (detected {}, compared: {:?})",
        kernels::level().name(),
        kernels::detected().name(),
        kernels::all_levels().iter().map(|l| l.name()).collect::<Vec<_>>()
    );
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::is_x86_feature_detected as has;
        assert_eq!(kernels::detected().has_avx2(), has!("avx2") && has!("lzcnt") && has!("bmi1"));
    }
    // the one switch: renderers and masks default to the process's level
    assert_eq!(Settings::default().cpu, kernels::level());
    let st = SliceStack::new(&random_volume([6, 5, 7], 3, [1.0; 3]), 2);
    let mut m = BinaryMask::<u64>::build(&st, |_, hi| hi > 60.0);
    assert_eq!(m.cpu_level(), kernels::level());
    // a level above the CPU's is capped
    m.set_cpu_level(CpuLevel::Avx2);
    assert_eq!(m.cpu_level(), kernels::detected());
    m.set_cpu_level(CpuLevel::Scalar);
    assert_eq!(m.cpu_level(), CpuLevel::Scalar);
    // `SHEARWARP_CPU` caps the level (CI's second pass sets `scalar`)
    match std::env::var("SHEARWARP_CPU").ok().as_deref().map(str::trim) {
        Some("scalar") => assert_eq!(kernels::level(), CpuLevel::Scalar),
        None => assert_eq!(kernels::level(), kernels::detected()),
        _ => {}
    }
}

#[test]
fn no_drift_after_thousands_of_random_steps() {
    let vol = random_volume([30, 26, 57], 42, [1.0; 3]);
    let st = SliceStack::new(&vol, 2);
    for word64 in [false, true] {
        let mut rnd = lcg(0x5EED_u64);
        let nk = st.n[2];
        let lim = (nk as i64 - 1) / 2;
        let mut state = ShearState::identity(nk);
        macro_rules! run {
            ($w:ty) => {{
                let mut m = BinaryMask::<$w>::build(&st, |_, hi| hi > 60.0);
                for step in 0..5000 {
                    if rnd() % 10 == 0 {
                        // a jump to a random shear (several bits, or a direct shear)
                        let s = [0, 1].map(|_| (rnd() % 2001) as f64 / 1000.0 - 1.0);
                        // end points on whole voxels, so one-bit steps can continue from here
                        let e = s.map(|x| (x * lim as f64).round());
                        state = ShearState::from_ends(nk, [0, 1].map(|a| [-e[a], e[a]]));
                        m.shear_to(&state);
                    } else {
                        let along = (rnd() & 1) as usize;
                        let dir = if rnd() & 1 == 0 { 1 } else { -1 };
                        if (state.ends[along][1] + dir as f64).abs() > lim as f64 {
                            continue;
                        }
                        state = m.rotate_step(&state, along, dir);
                    }
                    if step % 997 == 0 {
                        let mut d = BinaryMask::<$w>::build(&st, |_, hi| hi > 60.0);
                        d.shear_direct(&state);
                        assert_eq!(m.words(), d.words(), "step {step}");
                    }
                }
                let mut d = BinaryMask::<$w>::build(&st, |_, hi| hi > 60.0);
                d.shear_direct(&state);
                assert_eq!(m.words(), d.words());
                // translations are the closed form of the end points
                for a in 0..2 {
                    for k in 0..nk {
                        let l = (nk - 1) as f64;
                        let closed = (state.ends[a][0] * (l - k as f64) + state.ends[a][1] * k as f64) / l;
                        assert!((state.trans[a][k] - closed).abs() < 1e-9);
                    }
                }
            }};
        }
        if word64 { run!(u64) } else { run!(u32) }
    }
}

/// The shear kernels specialised per column length (1 to 8 words) and the
/// general one (more words): random one-bit steps about both axes and
/// multi-bit jumps end in exactly the mask sheared directly, for every length,
/// at every CPU level the machine can run (the kernels compiled for AVX2 where
/// the CPU has it, and the plain ones), and with multi-bit jumps made of fused
/// two-step passes or of single steps.
#[test]
fn every_column_length_shears_like_the_direct_shear() {
    // u64 columns of 1..=9, 12, 16 and 17 words, u32 columns of 2, 10 and 17 words
    let cases: [(usize, bool); 15] = [
        (700, true),
        (1000, true),
        (1050, true),
        (530, false),
        (40, true),
        (100, true),
        (170, true),
        (230, true),
        (300, true),
        (360, true),
        (420, true),
        (500, true),
        (540, true),
        (40, false),
        (300, false),
    ];
    for (nz, word64) in cases {
        let vol = random_volume([9, 7, nz], nz as u64, [1.0; 3]);
        let st = SliceStack::new(&vol, 2);
        let mut rnd = lcg(0xC0FFEE ^ nz as u64);
        let lim = (nz as i64 - 1) / 2;
        macro_rules! run {
            ($w:ty) => {{
                let mut m = BinaryMask::<$w>::build(&st, |_, hi| hi > 60.0);
                m.set_cpu_level(CpuLevel::Scalar);
                // one mask per level this CPU runs, compared with the scalar one
                let mut levels: Vec<(CpuLevel, BinaryMask<$w>)> = kernels::all_levels()
                    .into_iter()
                    .map(|l| {
                        let mut c = m.clone();
                        c.set_cpu_level(l);
                        (l, c)
                    })
                    .collect();
                let mut single = m.clone();
                single.set_fused(false);
                single.set_cpu_level(kernels::detected());
                let mut state = ShearState::identity(nz);
                for step in 0..240 {
                    if step % 40 == 39 {
                        // a few bits at once along both axes
                        let e = [0, 1].map(|a| (state.ends[a][1] + (rnd() % 7) as f64 - 3.0).clamp(-(lim as f64), lim as f64));
                        state = ShearState::from_ends(nz, [0, 1].map(|a| [-e[a], e[a]]));
                        m.shear_to(&state);
                        for (_, c) in levels.iter_mut() {
                            c.shear_to(&state);
                        }
                        single.shear_to(&state);
                    } else {
                        let along = (rnd() & 1) as usize;
                        let dir = if rnd() % 3 == 0 { -1 } else { 1 };
                        if (state.ends[along][1] + dir as f64).abs() > lim as f64 {
                            continue;
                        }
                        for (_, c) in levels.iter_mut() {
                            c.rotate_step(&state, along, dir);
                        }
                        single.rotate_step(&state, along, dir);
                        state = m.rotate_step(&state, along, dir);
                    }
                    if step % 10 == 0 {
                        for (l, c) in &levels {
                            assert_eq!(m.words(), c.words(), "{} and scalar kernels, depth {nz}, step {step}", l.name());
                        }
                        assert_eq!(m.words(), single.words(), "fused and single steps, depth {nz}, step {step}");
                    }
                }
                let mut d = BinaryMask::<$w>::build(&st, |_, hi| hi > 60.0);
                d.shear_direct(&state);
                assert_eq!(m.words(), d.words(), "depth {nz}, {} bits", <$w>::BITS);
                for (l, c) in &levels {
                    assert_eq!(c.words(), d.words(), "{} kernels, depth {nz}, {} bits", l.name(), <$w>::BITS);
                }
            }};
        }
        if word64 { run!(u64) } else { run!(u32) }
    }
}

/// A full 360° turn about each eye axis in small increments: every frame's mask
/// (reached incrementally, switching principal axes on the way) equals the mask
/// sheared directly to that frame's state.
#[test]
fn full_turn_about_each_axis_has_no_drift() {
    let vol = random_volume([24, 20, 28], 7, [1.0, 1.0, 1.5]);
    for axis in 0..3 {
        let stacks: Vec<SliceStack> = (0..3).map(|a| SliceStack::new(&vol, a)).collect();
        let mut masks: Vec<BinaryMask<u64>> = stacks.iter().map(|s| BinaryMask::build(s, |_, hi| hi > 60.0)).collect();
        let base = DMat3::from_euler(EulerRot::XYZ, 0.3, 0.2, 0.1);
        let steps = 720;
        for f in 0..=steps {
            let cam = Camera::new(rotate_eye(base, axis, 360.0 * f as f64 / steps as f64), [32, 32]);
            let fac = Factorization::new(&cam, vol.dims(), vol.spacing()).unwrap();
            let state = ShearState::from_view(&fac);
            masks[fac.axis].shear_to(&state);
            if f % 60 == 0 || f == steps {
                let mut d = BinaryMask::<u64>::build(&stacks[fac.axis], |_, hi| hi > 60.0);
                d.shear_direct(&state);
                assert_eq!(masks[fac.axis].words(), d.words(), "axis {axis} frame {f}");
            }
        }
    }
}

/// Principal-axis switches are seamless: across a full turn of an off-centre
/// blob the rendered object's centroid moves smoothly (no jump at the switches)
/// and its area does not drop (no gaps or holes).
#[test]
fn principal_axis_switches_are_seamless() {
    let n = 40;
    let vol = Volume::from_fn([n, n, n], [1.0; 3], |x, y, z| {
        let d = ((x as f32 - 26.0).powi(2) + (y as f32 - 17.0).powi(2) + (z as f32 - 20.0).powi(2)).sqrt();
        (100.0 + 25.0 * (7.0 - d)).clamp(0.0, 200.0)
    })
    .unwrap();
    let tf = TransferFunction::threshold(100.0, [1.0; 3]);
    let mut r = Renderer::new(vol, &tf, Settings::default()).unwrap();
    let mut img = Image::new(128, 128);
    let mut prev: Option<(f64, f64, f64)> = None;
    let mut axes = std::collections::BTreeSet::new();
    for f in 0..=360 {
        let cam = Camera::new(rotate_eye(DMat3::from_rotation_x(0.4), 1, f as f64), [128, 128]);
        let st = r.render(&cam, &mut img).unwrap();
        axes.insert(st.axis);
        let (mut a, mut cx, mut cy) = (0.0, 0.0, 0.0);
        for y in 0..128 {
            for x in 0..128 {
                let w = img.at(x, y)[3] as f64;
                a += w;
                cx += w * x as f64;
                cy += w * y as f64;
            }
        }
        let (cx, cy) = (cx / a, cy / a);
        if let Some((pa, px, py)) = prev {
            assert!(((a - pa) / pa).abs() < 0.08, "area jumped at {f}°: {pa} → {a}");
            assert!((cx - px).hypot(cy - py) < 1.2, "centroid jumped at {f}°");
        }
        prev = Some((a, cx, cy));
    }
    assert!(axes.len() >= 2, "the turn should cross principal-axis switches");
}

/// Case count: `PROPTEST_CASES` when set (for long soak runs), else `default`.
fn cases(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}
