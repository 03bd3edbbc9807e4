//! Tissue invariants: super cells lose nothing, n-bit threshold codes match
//! masks built from scratch for each threshold (also after any sequence of
//! shears), and tissue switches need no rebuild.

use glam::{DMat3, EulerRot};
use proptest::prelude::*;
use shearwarp::classify::TransferFunction;
use shearwarp::classify::presets::Tissue;
use shearwarp::composite::Mode;
use shearwarp::data::slices::SliceStack;
use shearwarp::data::volume::{Volume, VoxelData};
use shearwarp::encode::depth::{Matcher, Search, SetBits};
use shearwarp::encode::mask::{BinaryMask, CellCodes};
use shearwarp::render::{Focus, Method, Renderer, Settings, WordSize};
use shearwarp::view::clip::Region;
use shearwarp::view::shear::ShearState;
use shearwarp::view::{Camera, Factorization, rotate_eye};
use shearwarp::warp::Image;

fn random_volume(dims: [usize; 3], seed: u64) -> Volume {
    let n = dims[0] * dims[1] * dims[2];
    let mut data = vec![0f32; n];
    let mut s = seed | 1;
    // a few random boxes of different densities plus sparse noise
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    for _ in 0..5 {
        let lo: Vec<usize> = (0..3).map(|a| (next() as usize) % dims[a]).collect();
        let hi: Vec<usize> = (0..3).map(|a| (lo[a] + 1 + (next() as usize) % dims[a]).min(dims[a])).collect();
        let v = (next() % 300) as f32;
        for z in lo[2]..hi[2] {
            for y in lo[1]..hi[1] {
                for x in lo[0]..hi[0] {
                    let i = x + dims[0] * (y + dims[1] * z);
                    data[i] = data[i].max(v);
                }
            }
        }
    }
    for v in data.iter_mut() {
        if next() % 23 == 0 {
            *v = (next() % 300) as f32;
        }
    }
    Volume::new(dims, [1.0; 3], VoxelData::F32(data)).unwrap()
}

fn tissues() -> Vec<Tissue> {
    [(60.0, "a"), (130.0, "b"), (210.0, "c")]
        .into_iter()
        .map(|(t, name)| Tissue {
            name,
            threshold: t,
            rgb: [0.8, 0.7, 0.6],
            tf: TransferFunction::new(vec![(t, 0.0), (t + 30.0, 0.5), (300.0, 0.9)], vec![(t, [0.9, 0.5, 0.3]), (300.0, [0.3, 0.5, 0.9])])
                .unwrap(),
        })
        .collect()
}

fn render_with(r: &mut Renderer, cam: &Camera) -> Image {
    let mut img = Image::new(cam.size[0], cam.size[1]);
    r.render(cam, &mut img).unwrap();
    img
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases(24)))]

    /// A preset's own one-bit mask renders the code mask's image bit for
    /// bit, through a rotation with tissue switches and prefetches: random
    /// volumes, two to four presets (2- and 4-bit codes), cell sizes, word
    /// sizes, thread counts, iso and blend.
    #[test]
    fn a_presets_own_mask_renders_the_code_masks_image(
        seed in any::<u64>(), n in 2usize..=4, cell in 1usize..5, u32w in any::<bool>(), threads in 1usize..=3,
        blend in any::<bool>(), rx in -3.2f64..3.2, step in -9.0f64..9.0,
    ) {
        let vol = random_volume([23, 18, 29], seed);
        let mut ts = tissues();
        if n == 4 {
            let mut top = ts[2].clone();
            (top.name, top.threshold) = ("d", 260.0);
            top.tf = TransferFunction::threshold(260.0, [0.4, 0.6, 0.8]);
            ts.push(top);
        }
        ts.truncate(n);
        let s = Settings {
            cell,
            word: if u32w { WordSize::U32 } else { WordSize::U64 },
            threads,
            mode: if blend { Mode::Blend } else { Mode::Iso },
            ..Settings::default()
        };
        let mut own = Renderer::with_tissues(vol.clone(), &ts, s).unwrap();
        let mut coded = Renderer::with_tissues(vol, &ts, s).unwrap();
        coded.set_preset_masks(false);
        let mut served = 0;
        for f in 0..16 {
            let cam = Camera::new(rotate_eye(DMat3::from_rotation_x(rx), 1, f as f64 * step), [40, 36]);
            if f % 5 == 4 {
                for r in [&mut own, &mut coded] {
                    r.select_tissue((f / 5) % n).unwrap();
                }
            }
            if f % 5 == 1 {
                let axis = Factorization::new(&cam, own.dims(), own.spacing()).unwrap().axis;
                own.prefetch_axis(axis).unwrap();
            }
            let (mut a, mut b) = (Image::new(40, 36), Image::new(40, 36));
            let st = own.render(&cam, &mut a).unwrap();
            prop_assert!(!coded.render(&cam, &mut b).unwrap().preset_mask);
            served += st.preset_mask as usize;
            let diff = a.data.iter().zip(&b.data).filter(|(x, y)| x != y).count();
            prop_assert_eq!(diff, 0, "frame {}: {} pixels differ (preset mask: {})", f, diff, st.preset_mask);
        }
        prop_assert!(served >= 4, "the preset's own mask served {} frames", served);
    }

    /// For every cell size 1..=8, at every CPU level, the image is identical to
    /// cell size 1 (and to brute force).
    #[test]
    fn super_cells_lose_nothing(
        nx in 2usize..30, ny in 2usize..30, nz in 2usize..40, seed in any::<u64>(),
        rx in -3.2f64..3.2, ry in -3.2f64..3.2, blend in any::<bool>(), u32w in any::<bool>(), lut in any::<bool>(),
    ) {
        let vol = random_volume([nx, ny, nz], seed);
        let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, rx, ry, 0.3), [40, 40]);
        let base = Settings {
            mode: if blend { Mode::Blend } else { Mode::Iso },
            word: if u32w { WordSize::U32 } else { WordSize::U64 },
            search: if lut { Search::Lut } else { Search::Bitscan },
            threads: 1,
            ..Settings::default()
        };
        let mut brute = Renderer::with_tissues(vol.clone(), &tissues(), Settings { method: Method::Brute, ..base }).unwrap();
        brute.select_tissue(1).unwrap();
        let want = render_with(&mut brute, &cam);
        let mut r = Renderer::with_tissues(vol, &tissues(), base).unwrap();
        r.select_tissue(1).unwrap();
        // at every CPU level this machine runs (the code masks' lzcnt and AVX2
        // kernels against the plain ones, via brute force)
        for cpu in shearwarp::kernels::all_levels() {
            for s in 1..=8 {
                r.set_settings(Settings { cell: s, cpu, ..base }).unwrap();
                let got = render_with(&mut r, &cam);
                let diff = got.data.iter().zip(&want.data).filter(|(a, b)| a != b).count();
                prop_assert_eq!(diff, 0, "cell size {} at CPU level {}: {} pixels differ", s, cpu.name(), diff);
            }
        }
    }

    /// The code mask, searched for "code ≥ c", visits exactly the slices of the
    /// binary mask built from scratch for threshold c alone — after a random
    /// sequence of incremental shears, for every cell size.
    #[test]
    fn code_masks_match_threshold_masks(
        nx in 2usize..24, ny in 2usize..24, nz in 2usize..70, seed in any::<u64>(), steps in 0usize..40, cell in 1usize..5,
    ) {
        let vol = random_volume([nx, ny, nz], seed);
        let st = SliceStack::new(&vol, 2);
        let ts = [60.0f32, 130.0, 210.0];
        let codes = CellCodes::thresholds(&st, &ts).unwrap();
        prop_assert_eq!(codes.nb, 2);
        let mut cm = BinaryMask::<u64>::from_codes(&codes, cell);
        let mut bms: Vec<BinaryMask<u32>> = ts.iter().map(|&t| BinaryMask::from_codes(&CellCodes::binary(&st, |_, hi| hi >= t), cell)).collect();
        let mut state = ShearState::identity(nz);
        let lim = ((nz as f64 - 1.0) / 2.0).floor();
        let mut s = seed;
        for _ in 0..steps {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let along = (s >> 40) as usize & 1;
            let dir = if (s >> 50) & 1 == 0 { 1 } else { -1 };
            if (state.ends[along][1] + (dir * cell as i32) as f64).abs() > lim {
                continue;
            }
            state = cm.rotate_step(&state, along, dir);
            for b in bms.iter_mut() {
                b.shear_to(&state);
            }
        }
        let [gw, gh] = cm.grid();
        for (c, b) in bms.iter().enumerate() {
            let m = Matcher::new(2, c as u32 + 1);
            for q in 0..gh {
                for p in 0..gw {
                    for asc in [true, false] {
                        for search in [Search::Lut, Search::Bitscan] {
                            let got: Vec<usize> = SetBits::with_matcher(cm.row(p, q), asc, search, &m).collect();
                            let want: Vec<usize> = SetBits::new(b.row(p, q), asc, search).collect();
                            prop_assert_eq!(got, want);
                        }
                    }
                }
            }
        }
    }

    /// Rendering each threshold through the shared code mask equals rendering it
    /// with a renderer that built a 1-bit mask for that threshold alone, at a view
    /// reached through other views first.
    #[test]
    fn code_renders_equal_single_threshold_renders(seed in any::<u64>(), ry in -3.2f64..3.2, cell in 1usize..4, blend in any::<bool>()) {
        let vol = random_volume([22, 19, 27], seed);
        let s = Settings { cell, mode: if blend { Mode::Blend } else { Mode::Iso }, threads: 2, ..Settings::default() };
        let mut coded = Renderer::with_tissues(vol.clone(), &tissues(), s).unwrap();
        // wander through some views first (incremental shears, axis switches)
        for d in 0..20 {
            let cam = Camera::new(rotate_eye(DMat3::from_rotation_x(0.3), 1, d as f64 * 7.0), [36, 36]);
            render_with(&mut coded, &cam);
        }
        let cam = Camera::new(rotate_eye(DMat3::from_rotation_x(0.3), 1, ry.to_degrees()), [36, 36]);
        for (i, t) in tissues().iter().enumerate() {
            coded.select_tissue(i).unwrap();
            let a = render_with(&mut coded, &cam);
            let tf = if blend { t.tf.clone() } else { t.iso_tf() };
            let mut single = Renderer::new(vol.clone(), &tf, s).unwrap();
            single.set_iso(t.threshold).unwrap();
            let b = render_with(&mut single, &cam);
            let diff = a.data.iter().zip(&b.data).filter(|(x, y)| x != y).count();
            prop_assert_eq!(diff, 0, "tissue {}: {} pixels differ", t.name, diff);
        }
    }
}

/// A tissue switch changes no mask: the masks' words stay the same, and
/// the frame after it builds nothing. It reads the presets' code mask (the
/// new preset's own one-bit mask is not built yet), so it shears only that
/// mask to the view; with the preset masks off, where the code mask served
/// every frame, it shears nothing.
#[test]
fn tissue_switch_is_constant_time_and_keeps_the_mask() {
    for preset_masks in [true, false] {
        let vol = random_volume([40, 40, 40], 3);
        let mut r = Renderer::with_tissues(vol, &tissues(), Settings::default()).unwrap();
        r.set_preset_masks(preset_masks);
        let cam = Camera::new(rotate_eye(DMat3::IDENTITY, 1, 20.0), [64, 64]);
        let mut img = Image::new(64, 64);
        assert_eq!(r.render(&cam, &mut img).unwrap().preset_mask, preset_masks);
        let bytes = r.mask_bytes();
        let t = std::time::Instant::now();
        for i in 0..3000 {
            r.select_tissue(i % 3).unwrap();
        }
        let per = t.elapsed().as_secs_f64() / 3000.0;
        assert!(per < 1e-4, "a switch took {per} s");
        assert_eq!(r.mask_bytes(), bytes);
        // and the next frame builds nothing
        let st = r.render(&cam, &mut img).unwrap();
        assert!(!st.preset_mask);
        assert!(st.build_ms < 5.0, "the next frame built for {} ms", st.build_ms);
        if !preset_masks {
            assert_eq!(st.shear_steps + st.shear_direct, 0, "no re-shear after a switch");
        }
        let _ = Factorization::new(&cam, [40, 40, 40], [1.0; 3]).unwrap();
    }
}

/// The life of a preset's own one-bit mask: built with the code mask, read
/// by its preset's frames; after a switch the frames read the code mask
/// until [`Renderer::prefetch_axis`] builds the new preset's (at the code
/// mask's shear: its first frame shears incrementally); a focus region,
/// which needs two presets' codes, reads the code mask.
#[test]
fn a_presets_own_mask_serves_its_frames_until_a_switch() {
    let vol = random_volume([30, 34, 38], 11);
    let mut r = Renderer::with_tissues(vol, &tissues(), Settings::default()).unwrap();
    let mut img = Image::new(64, 64);
    let mut frame = |r: &mut Renderer, deg: f64| r.render(&Camera::new(rotate_eye(DMat3::IDENTITY, 1, deg), [64, 64]), &mut img).unwrap();
    assert!(frame(&mut r, 10.0).preset_mask, "built with the code mask");
    assert!(frame(&mut r, 11.0).preset_mask);
    r.select_tissue(2).unwrap();
    let st = frame(&mut r, 12.0);
    assert!(!st.preset_mask && st.build_ms < 5.0, "after a switch: the code mask, no build ({st:?})");
    assert!(r.preset_mask_pending(st.axis));
    assert!(r.prefetch_axis(st.axis).unwrap());
    assert!(!r.preset_mask_pending(st.axis));
    let st = frame(&mut r, 13.0);
    assert!(st.preset_mask, "after the prefetch: the preset's own mask");
    assert_eq!(st.shear_direct, 0, "built at the code mask's shear");
    r.set_focus(Some(Focus::new(Region::Sphere { centre: [15.0, 17.0, 19.0], radius: 6.0 }, "a"))).unwrap();
    assert!(!frame(&mut r, 14.0).preset_mask, "a focus region reads the code mask");
    r.set_focus(None).unwrap();
    assert!(frame(&mut r, 15.0).preset_mask);
}

/// Case count: `PROPTEST_CASES` when set (for long soak runs), else `default`.
fn cases(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}
