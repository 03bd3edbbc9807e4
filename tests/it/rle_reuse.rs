//! Shear-Warp Deluxe's re-use of RLE runs (Sweeney & Mueller §3.1;
//! `Settings::rle_reuse`): one encoding serves the x and z axes, z read
//! through the mirrored permutation (y, x, z) and a pointer table over x's
//! scanlines (or x through one over z's). The image equals the separate encodings' to float rounding, the
//! accelerated path equals its brute force bit for bit, the RLE memory is at
//! least 30 % smaller on the head, the shared encoding is built once, and a
//! classification change re-encodes (no stale pointer table).

use crate::common;

use common::{blobs, uniform};
use glam::DMat3;
use shearwarp::accuracy::reference::fast_path_depth;
use shearwarp::classify::TransferFunction;
use shearwarp::classify::presets::ct_tissues;
use shearwarp::composite::Mode;
use shearwarp::data::phantom;
use shearwarp::data::slices::SliceStack;
use shearwarp::data::volume::Volume;
use shearwarp::encode::rle::{Preclass, RleVolume};
use shearwarp::kernels::Reconstruction;
use shearwarp::render::{Method, Renderer, Settings};
use shearwarp::view::{Camera, Factorization, Projection, permutation, reuse_permutation, rotate_eye};
use shearwarp::warp::Image;

const TOL: f32 = 1e-5;

fn frame(r: &mut Renderer, cam: &Camera) -> Image {
    let mut img = Image::new(cam.size[0], cam.size[1]);
    r.render(cam, &mut img).unwrap();
    img
}

fn max_diff(a: &Image, b: &Image) -> f32 {
    assert_eq!(a.data.len(), b.data.len());
    a.data.iter().zip(&b.data).flat_map(|(x, y)| (0..4).map(move |c| (x[c] - y[c]).abs())).fold(0.0, f32::max)
}

fn bits(img: &Image) -> Vec<u32> {
    img.data.iter().flatten().map(|x| x.to_bits()).collect()
}

/// The intermediate image's pixels (row-major over its grid).
fn intermediate(r: &Renderer) -> Vec<u32> {
    let inter = r.intermediate();
    let [w, h] = inter.size;
    (0..h).flat_map(|q| (0..w).map(move |p| (p, q))).flat_map(|(p, q)| inter.get(p as isize, q as isize)).map(f32::to_bits).collect()
}

/// Views covering every principal axis in both slice orders (asserted):
/// the six axis-aligned ones, and random ones until each (axis, order) has an
/// oblique view too.
fn views(dims: [usize; 3], sp: [f32; 3], seed: u64) -> Vec<DMat3> {
    let id = DMat3::IDENTITY;
    let mut v = vec![
        id,
        rotate_eye(id, 1, 180.0),
        rotate_eye(id, 1, 90.0),
        rotate_eye(id, 1, -90.0),
        rotate_eye(id, 0, 90.0),
        rotate_eye(id, 0, -90.0),
    ];
    let mut rnd = uniform(seed);
    let mut seen = [[false; 2]; 3];
    for _ in 0..400 {
        let r = DMat3::from_euler(glam::EulerRot::XYZ, rnd() * 6.3, rnd() * 6.3, rnd() * 6.3);
        let f = Factorization::new(&Camera::new(r, [8, 8]), dims, sp).unwrap();
        if !seen[f.axis][f.ascending as usize] {
            seen[f.axis][f.ascending as usize] = true;
            v.push(r);
        }
    }
    assert!(seen.iter().flatten().all(|&s| s), "views cover every axis and order");
    v
}

fn tf(seed: u64) -> TransferFunction {
    match seed % 2 {
        0 => TransferFunction::ramp(30.0, 150.0, 0.6, [0.9, 0.7, 0.5]),
        _ => TransferFunction::new(vec![(40.0, 0.0), (60.0, 0.8), (90.0, 0.1)], vec![(0.0, [1.0, 0.3, 0.2]), (250.0, [0.2, 0.4, 1.0])])
            .unwrap(),
    }
}

/// With reuse the images equal the separate encodings' within 1e-5 per
/// channel, over random volumes (anisotropic too) and views of every axis in
/// both slice orders, blend and iso, early termination off, with the cubic
/// reconstruction's normal codes too (a voxel's code is the same from every
/// axis's stack); the z views really read the mirrored permutation, and the
/// iso depth follows it.
#[test]
fn reuse_equals_separate_encodings_deluxe() {
    for (seed, dims, sp, reconstruction) in [
        (3u64, [19, 23, 17], [1.0f32; 3], Reconstruction::Linear),
        (11, [16, 13, 26], [1.0, 0.7, 1.6], Reconstruction::Linear),
        (29, [9, 31, 12], [0.8, 1.0, 1.3], Reconstruction::Linear),
        (11, [16, 13, 26], [0.7, 0.7, 2.5], Reconstruction::Cubic),
    ] {
        let vol = blobs(dims, seed, sp);
        for mode in [Mode::Blend, Mode::Iso] {
            let base = Settings { method: Method::Rle, mode, ert: 1.0, threads: 2, reconstruction, ..Settings::default() };
            let t = tf(seed);
            let mut sep = Renderer::new(vol.clone(), &t, base).unwrap();
            let mut reu = Renderer::new(vol.clone(), &t, Settings { rle_reuse: true, ..base }).unwrap();
            if mode == Mode::Iso {
                sep.set_iso(70.0).unwrap();
                reu.set_iso(70.0).unwrap();
            }
            for r in views(dims, sp, seed) {
                let cam = Camera::new(r, [44, 36]);
                let (a, b) = (frame(&mut sep, &cam), frame(&mut reu, &cam));
                let f = reu.last_factorization().unwrap().clone();
                assert_eq!(f.perm, reuse_permutation(f.axis));
                assert_eq!(sep.last_factorization().unwrap().perm, permutation(f.axis));
                let d = max_diff(&a, &b);
                assert!(d <= TOL, "seed {seed} {mode:?} axis {} ascending {}: images differ by {d}", f.axis, f.ascending);
                if mode == Mode::Iso {
                    let (da, db) = (fast_path_depth(&sep, &cam).unwrap(), fast_path_depth(&reu, &cam).unwrap());
                    for (x, y) in da.iter().zip(&db) {
                        assert!(x.is_nan() == y.is_nan() && (x.is_nan() || (x - y).abs() < 1e-4), "iso depth {x} vs {y}");
                    }
                }
            }
        }
    }
}

/// Under perspective the reuse falls back to the separate encodings (cyclic
/// permutations): the same image bit for bit, the same encodings.
#[test]
fn reuse_falls_back_under_perspective() {
    let (dims, sp) = ([18, 22, 15], [1.0, 0.9, 1.2]);
    let vol = blobs(dims, 5, sp);
    let base = Settings { method: Method::Rle, mode: Mode::Blend, ert: 1.0, threads: 2, ..Settings::default() };
    let mut sep = Renderer::new(vol.clone(), &tf(0), base).unwrap();
    let mut reu = Renderer::new(vol.clone(), &tf(0), Settings { rle_reuse: true, ..base }).unwrap();
    for r in [&mut sep, &mut reu] {
        r.set_projection(Projection::perspective(40.0, 2.0).unwrap()).unwrap();
    }
    for r in views(dims, sp, 5).into_iter().take(6) {
        let cam = Camera::new(r, [40, 40]);
        let (a, b) = (frame(&mut sep, &cam), frame(&mut reu, &cam));
        assert_eq!(bits(&a), bits(&b));
        let f = reu.last_factorization().unwrap();
        assert_eq!(f.perm, permutation(f.axis));
    }
    assert_eq!(sep.rle_axis_bytes(), reu.rle_axis_bytes());
    assert_eq!(reu.rle_cache().encodings_built(), 3);
}

/// With reuse the RLE path equals its brute force (which reads the mirrored
/// stack) bit for bit, intermediate and final images, early termination off.
#[test]
fn reuse_accelerated_equals_brute_bit_for_bit() {
    for (seed, dims, sp) in [(7u64, [17, 21, 14], [1.0f32; 3]), (13, [12, 10, 25], [1.0, 0.6, 1.8])] {
        let vol = blobs(dims, seed, sp);
        for mode in [Mode::Blend, Mode::Iso] {
            let base = Settings { mode, ert: 1.0, threads: 2, rle_reuse: true, ..Settings::default() };
            let mut acc = Renderer::new(vol.clone(), &tf(seed), Settings { method: Method::Rle, ..base }).unwrap();
            let mut bru = Renderer::new(vol.clone(), &tf(seed), Settings { method: Method::BruteRle, ..base }).unwrap();
            for r in views(dims, sp, seed + 1) {
                let cam = Camera::new(r, [40, 34]);
                let (a, b) = (frame(&mut acc, &cam), frame(&mut bru, &cam));
                assert_eq!(bru.last_factorization().unwrap().perm, acc.last_factorization().unwrap().perm);
                assert!(intermediate(&acc) == intermediate(&bru), "seed {seed} {mode:?}: intermediate images differ");
                assert!(bits(&a) == bits(&b), "seed {seed} {mode:?}: final images differ by {}", max_diff(&a, &b));
            }
        }
    }
}

/// The pointer table over x's scanlines is exactly the encoding of the
/// mirrored z stack: the same runs and voxels per scanline, in both
/// directions (z built from x and x built from z), sharing the data.
#[test]
fn transposed_encoding_is_the_mirrored_axis_encoding_reuse() {
    let vol: Volume = blobs([14, 11, 9], 21, [1.0, 0.8, 1.3]);
    let cls = shearwarp::classify::Classifier::new(&tf(1), 0.0, 260.0);
    let pre = Preclass::new(&cls, vol.spacing());
    let z = SliceStack::try_permuted(&vol, reuse_permutation(2)).unwrap();
    let y = SliceStack::try_permuted(&vol, reuse_permutation(0)).unwrap();
    assert_eq!((z.perm(), y.perm()), ([1, 0, 2], [1, 2, 0]));
    let (ez, ey) = (RleVolume::encode(&z, &pre), RleVolume::encode(&y, &pre));
    for (direct, other) in [(&ey, &ez), (&ez, &ey)] {
        let t = other.transposed();
        assert!(t.is_transposed() && t.shares_scanlines(other) && !direct.shares_scanlines(other));
        assert_eq!((t.axis, t.n, t.perm), (direct.axis, direct.n, direct.perm));
        for k in 0..t.n[2] {
            for j in 0..t.n[1] {
                assert_eq!(t.scanline_runs(j, k), direct.scanline_runs(j, k));
                assert!(t.stored_scanline(j, k).eq(direct.stored_scanline(j, k)));
            }
        }
        assert_eq!(t.bytes(), t.table_bytes() + direct.shared_bytes());
        // its own tables: a pointer and an extent per scanline, a box per slice
        assert_eq!(t.table_bytes(), t.n[1] * t.n[2] * 8 + t.n[2] * 16);
    }
}

/// The mirrored permutation factorizes to the same rays: every sheared point
/// maps to the same voxel point and the same image pixel as the cyclic
/// permutation's (transposed); bad permutations are an error.
#[test]
fn mirrored_factorization_same_rays_deluxe() {
    let (dims, sp) = ([20, 30, 40], [1.0f32, 1.5, 0.7]);
    let cam = Camera::new(rotate_eye(rotate_eye(DMat3::IDENTITY, 0, 20.0), 1, 15.0), [64, 48]);
    let cyc = Factorization::new(&cam, dims, sp).unwrap();
    assert_eq!(cyc.axis, 2);
    let mir = Factorization::with_permutations(&cam, dims, sp, [0, 1, 2].map(reuse_permutation)).unwrap();
    assert_eq!((mir.axis, mir.perm, mir.ascending, mir.n), (2, [1, 0, 2], cyc.ascending, [cyc.n[1], cyc.n[0], cyc.n[2]]));
    assert_eq!(mir.shear, [cyc.shear[1], cyc.shear[0]]);
    assert!((mir.sample_spacing - cyc.sample_spacing).abs() < 1e-12);
    for (a, b, k) in [(3.25, 7.5, 4.0), (0.0, 0.0, 0.0), (11.0, 2.5, 19.5)] {
        let (p, q) = (cyc.sheared_to_voxel(a, b, k), mir.sheared_to_voxel(b, a, k));
        assert!((0..3).all(|c| (p[c] - q[c]).abs() < 1e-9), "{p:?} vs {q:?}");
        let px = |f: &Factorization, a: f64, b: f64| [0, 1].map(|r| f.warp_m[r][0] * a + f.warp_m[r][1] * b + f.warp_t[r]);
        let (u, v) = (px(&cyc, a, b), px(&mir, b, a));
        assert!((u[0] - v[0]).abs() < 1e-9 && (u[1] - v[1]).abs() < 1e-9);
    }
    // the same headlight in object space
    let light = |f: &Factorization| {
        let mut l = [0.0; 3];
        for c in 0..3 {
            l[f.perm[c]] = f.grad_to_eye_z[c] / f.grad_scale[c];
        }
        l
    };
    assert_eq!(light(&cyc), light(&mir));
    for bad in [[[1, 2, 0], [0, 1, 2], [0, 1, 2]], [[1, 2, 0], [0, 0, 1], [0, 1, 2]], [[1, 2, 0], [2, 0, 1], [0, 1, 3]]] {
        assert!(Factorization::with_permutations(&cam, dims, sp, bad).is_err(), "{bad:?}");
    }
}

/// On the head phantom, with all three axes prepared, reuse holds at least
/// 30 % less RLE memory (blend and iso), builds two encodings instead of three,
/// and x and z share theirs.
#[test]
fn reuse_memory_deluxe_head() {
    let vol = phantom::head([128, 128, 113]).unwrap();
    for mode in [Mode::Blend, Mode::Iso] {
        let s = Settings { method: Method::Rle, mode, threads: 2, ..Settings::default() };
        let mut sep = Renderer::with_tissues(vol.clone(), &ct_tissues(), s).unwrap();
        let mut reu = Renderer::with_tissues(vol.clone(), &ct_tissues(), Settings { rle_reuse: true, ..s }).unwrap();
        sep.prepare_all_axes();
        reu.prepare_all_axes();
        let (a, b) = (sep.rle_bytes(), reu.rle_bytes());
        assert!(
            b as f64 <= 0.7 * a as f64,
            "{mode:?}: {b} bytes with reuse vs {a} without ({:.1} % less)",
            100.0 * (1.0 - b as f64 / a as f64)
        );
        assert_eq!(reu.memory().rle.iter().sum::<u64>(), b as u64);
        assert_eq!((sep.rle_cache().encodings_built(), reu.rle_cache().encodings_built()), (3, 2));
        let c = reu.rle_cache();
        assert!(c.axis(0).unwrap().shares_scanlines(c.axis(2).unwrap()));
        assert!(!c.axis(1).unwrap().shares_scanlines(c.axis(2).unwrap()));
        eprintln!("{mode:?}: RLE bytes {a} → {b} ({:.1} % less)", 100.0 * (1.0 - b as f64 / a as f64));
    }
}

/// A tissue or transfer-function change after the shared encoding served y
/// and z re-encodes both from the new classification (no stale pointer
/// table): every frame equals a fresh renderer's; switching reuse off and on
/// mid-run too.
#[test]
fn reuse_after_classification_change_reencodes() {
    let vol = phantom::head([64, 64, 56]).unwrap();
    let s = Settings { method: Method::Rle, mode: Mode::Blend, ert: 1.0, threads: 2, rle_reuse: true, ..Settings::default() };
    let mut r = Renderer::with_tissues(vol.clone(), &ct_tissues(), s).unwrap();
    let id = DMat3::IDENTITY;
    let cams = [id, rotate_eye(id, 0, 80.0), rotate_eye(id, 1, 85.0), rotate_eye(id, 0, -75.0)].map(|m| Camera::new(m, [48, 48]));
    let fresh = |tissue: usize, settings: Settings, cam: &Camera| {
        let mut f = Renderer::with_tissues(vol.clone(), &ct_tissues(), settings).unwrap();
        f.select_tissue(tissue).unwrap();
        frame(&mut f, cam)
    };
    for tissue in [0, 2, 1] {
        r.select_tissue(tissue).unwrap();
        for cam in &cams {
            let img = frame(&mut r, cam);
            let want = fresh(tissue, s, cam);
            assert!(max_diff(&img, &want) <= TOL, "tissue {tissue}: differs from a fresh renderer by {}", max_diff(&img, &want));
        }
        assert_eq!(r.rle_cache().encodings_built(), 2);
    }
    // reuse off: y gets its own cyclic encoding; on again: the pointer table back
    for reuse in [false, true] {
        r.set_settings(Settings { rle_reuse: reuse, ..s }).unwrap();
        for cam in &cams {
            let img = frame(&mut r, cam);
            let want = fresh(1, Settings { rle_reuse: reuse, ..s }, cam);
            assert!(max_diff(&img, &want) <= TOL, "reuse {reuse}: differs from a fresh renderer by {}", max_diff(&img, &want));
        }
    }
    // a new transfer function
    let t = TransferFunction::ramp(-300.0, 400.0, 0.5, [0.8, 0.8, 0.6]);
    r.set_transfer_function(&t);
    for cam in &cams {
        let img = frame(&mut r, cam);
        let mut f = Renderer::new(vol.clone(), &t, s).unwrap();
        let want = frame(&mut f, cam);
        assert!(max_diff(&img, &want) <= TOL);
        let mut g = Renderer::new(vol.clone(), &t, Settings { rle_reuse: false, ..s }).unwrap();
        assert!(max_diff(&img, &frame(&mut g, cam)) <= TOL);
    }
    assert_eq!(r.rle_cache().encodings_built(), 2);
}
