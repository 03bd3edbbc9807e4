//! Any finite f32 volume — including values near ±FLT_MAX, ±FLT_MAX no-data
//! sentinels, denormals and constant volumes — goes through what `info`
//! computes, the presets and a render (binary and RLE, iso and blend) without
//! a panic: errors are allowed, panics are not.

use proptest::prelude::*;
use shearwarp::classify::presets;
use shearwarp::composite::Mode;
use shearwarp::render::{Method, Renderer, Settings};
use shearwarp::view::Camera;
use shearwarp::warp::Image;
use shearwarp::{Volume, VoxelData};

fn value() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => -2000.0f32..4000.0,
        1 => Just(f32::MAX),
        1 => Just(-f32::MAX),
        1 => Just(1e37f32),
        1 => Just(-3e38f32),
        1 => Just(f32::MIN_POSITIVE),
        1 => Just(1e-45f32),
        1 => Just(0.0f32),
        2 => any::<f32>().prop_filter("finite", |x| x.is_finite()),
    ]
}

/// A volume: random values, or a sentinel frame around ordinary data, or a constant.
fn volume() -> impl Strategy<Value = Volume> {
    let dims = (2usize..7, 2usize..7, 2usize..6);
    (dims, prop::collection::vec(value(), 6 * 6 * 5), 0u8..3, value()).prop_map(|((nx, ny, nz), vals, kind, s)| {
        let n = nx * ny * nz;
        let v: Vec<f32> = match kind {
            0 => vals[..n].to_vec(),
            // a sentinel frame around data in a CT-like range
            1 => (0..n).map(|i| if i % nx == 0 { s } else { vals[i].clamp(-1024.0, 3071.0) }).collect(),
            _ => vec![s; n],
        };
        Volume::new([nx, ny, nz], [1.0, 1.0, 1.0], VoxelData::F32(v)).unwrap()
    })
}

fn exercise(vol: &Volume) {
    // what `info` computes
    let (lo, hi) = vol.value_range();
    let _ = vol.histogram(16);
    let range = presets::data_range(vol);
    assert!(range.lo == lo && range.hi == hi);
    assert!(range.bulk.0 >= lo && range.bulk.1 <= hi);
    let tissues = presets::tissues_for(vol);
    assert!(!tissues.is_empty());
    for t in &tissues {
        assert!(t.threshold.is_finite(), "{t:?}");
    }
    assert!(presets::otsu_threshold(vol).is_finite());
    let _ = presets::generic(lo, hi);
    let _ = presets::generic(hi, lo);
    // renders: errors are fine, panics are not
    let cam = Camera { rotation: shearwarp::NamedView::Anterior.rotation(), zoom: None, size: [16, 16] };
    for method in [Method::Binary, Method::Rle] {
        for mode in [Mode::Iso, Mode::Blend] {
            let settings = Settings { method, mode, threads: 1, ..Settings::default() };
            let Ok(mut r) = Renderer::with_tissues(vol.clone(), &tissues, settings) else { continue };
            let mut img = Image::new(16, 16);
            for i in 0..tissues.len() {
                if r.select_tissue(i).is_ok() {
                    let _ = r.render(&cam, &mut img);
                }
            }
            if r.set_iso(hi).is_ok() {
                let _ = r.render(&cam, &mut img);
            }
            r.set_transfer_function(&presets::generic(lo, hi).tf);
            let _ = r.render(&cam, &mut img);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, ..ProptestConfig::default() })]

    #[test]
    fn no_finite_volume_panics(vol in volume()) {
        exercise(&vol);
    }
}

#[test]
fn the_reported_extremes_do_not_panic() {
    // reported extremes: values of 1e37 and more, ±FLT_MAX sentinels
    for (a, b) in [(0.0, 1e37), (-f32::MAX, f32::MAX), (-f32::MAX, 100.0), (-1000.0, f32::MAX), (3e38, 3.4e38)] {
        let vol =
            Volume::from_fn([6, 5, 4], [1.0; 3], |x, y, z| if (x + y + z) % 3 == 0 { a } else { b - b.abs() * 0.01 * x as f32 }).unwrap();
        exercise(&vol);
    }
}
