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
use shearwarp::render::{Method, Renderer, Settings, WordSize};
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

/// A tissue switch changes no mask: the shear state and words stay the same,
/// and the factorization is untouched.
#[test]
fn tissue_switch_is_constant_time_and_keeps_the_mask() {
    let vol = random_volume([40, 40, 40], 3);
    let mut r = Renderer::with_tissues(vol, &tissues(), Settings::default()).unwrap();
    let cam = Camera::new(rotate_eye(DMat3::IDENTITY, 1, 20.0), [64, 64]);
    render_with(&mut r, &cam);
    let bytes = r.mask_bytes();
    let t = std::time::Instant::now();
    for i in 0..3000 {
        r.select_tissue(i % 3).unwrap();
    }
    let per = t.elapsed().as_secs_f64() / 3000.0;
    assert!(per < 1e-4, "a switch took {per} s");
    assert_eq!(r.mask_bytes(), bytes);
    // and the next frame builds nothing
    let st = {
        let mut img = Image::new(64, 64);
        r.render(&cam, &mut img).unwrap()
    };
    assert!(st.build_ms < 5.0);
    assert_eq!(st.shear_steps + st.shear_direct, 0, "no re-shear after a switch");
    let _ = Factorization::new(&cam, [40, 40, 40], [1.0; 3]).unwrap();
}

/// Case count: `PROPTEST_CASES` when set (for long soak runs), else `default`.
fn cases(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}
