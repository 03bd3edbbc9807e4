//! Invariants of the run-length-encoded pre-classified path: it equals its
//! brute-force reference (runs and skip links lose nothing; with the central
//! differences' normal codes or the cubic reconstruction's), it is deterministic
//! across thread counts, its encoding round-trips to the classified voxels, it
//! follows classification changes, and it draws the same object as the binary path.

use crate::common;

use common::{random_tf, random_volume};
use glam::{DMat3, EulerRot};
use proptest::prelude::*;
use shearwarp::classify::presets::{Tissue, ct_tissues};
use shearwarp::classify::{Classifier, TransferFunction};
use shearwarp::composite::Mode;
use shearwarp::data::normals::StackNormals;
use shearwarp::data::phantom;
use shearwarp::data::slices::SliceStack;
use shearwarp::data::volume::Volume;
use shearwarp::encode::rle::{BRIDGE_NORMAL, Preclass, RleVolume};
use shearwarp::kernels::Reconstruction;
use shearwarp::render::{Method, Renderer, Settings};
use shearwarp::view::{Camera, Projection, rotate_eye};
use shearwarp::warp::Image;

/// Largest difference allowed per channel between the RLE path and its
/// reference: float rounding. (They share every operation, so in practice the
/// images are bit-identical; `skipping_is_lossless_without_ert` asserts that.)
const TOL: f32 = 1e-5;

/// One frame: the final image and the full intermediate grid (transparent
/// outside the valid rectangle).
fn frame(r: &mut Renderer, cam: &Camera) -> (Image, Vec<[f32; 4]>) {
    let mut img = Image::new(cam.size[0], cam.size[1]);
    r.render(cam, &mut img).unwrap();
    let inter = r.intermediate();
    let [w, h] = inter.size;
    let px = (0..h).flat_map(|q| (0..w).map(move |p| (p, q))).map(|(p, q)| inter.get(p as isize, q as isize)).collect();
    (img, px)
}

fn render(vol: &Volume, tf: &TransferFunction, s: Settings, cam: &Camera) -> (Image, Vec<[f32; 4]>) {
    frame(&mut Renderer::new(vol.clone(), tf, s).unwrap(), cam)
}

fn max_diff(a: &[[f32; 4]], b: &[[f32; 4]]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).flat_map(|(x, y)| (0..4).map(move |c| (x[c] - y[c]).abs())).fold(0.0, f32::max)
}

fn same_bits(a: &[[f32; 4]], b: &[[f32; 4]]) -> bool {
    a.len() == b.len() && a.iter().flatten().zip(b.iter().flatten()).all(|(x, y)| x.to_bits() == y.to_bits())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases(40)))]

    /// The RLE image equals the brute-force pre-classified image within float
    /// rounding (TOL per channel), intermediate and final, in both modes, for
    /// several early-termination thresholds, with either reconstruction's
    /// normal codes.
    #[test]
    fn rle_equals_brute_preclassified(
        nx in 2usize..24, ny in 2usize..24, nz in 2usize..40, seed in any::<u64>(), tfs in any::<u64>(),
        rx in -3.2f64..3.2, ry in -3.2f64..3.2, rz in -3.2f64..3.2,
        blend in any::<bool>(), aniso in any::<bool>(), ert in prop::sample::select(vec![0.5f32, 0.9, 0.99, 1.0]),
        cubic in any::<bool>(),
    ) {
        let sp = if aniso { [1.0, 0.7, 2.5] } else { [1.0; 3] };
        let vol = random_volume([nx, ny, nz], seed, sp);
        let tf = random_tf(tfs);
        let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, rx, ry, rz), [48, 40]);
        let mode = if blend { Mode::Blend } else { Mode::Iso };
        let base = Settings { mode, ert, threads: 2, reconstruction: recon(cubic), ..Settings::default() };
        let (ri, rpx) = render(&vol, &tf, Settings { method: Method::Rle, ..base }, &cam);
        let (bi, bpx) = render(&vol, &tf, Settings { method: Method::BruteRle, ..base }, &cam);
        let d = max_diff(&rpx, &bpx);
        prop_assert!(d <= TOL, "intermediate images differ by {d}");
        let d = max_diff(&ri.data, &bi.data);
        prop_assert!(d <= TOL, "final images differ by {d}");
    }

    /// Lossless skipping: with early termination off (ert = 1), runs and skip
    /// links give exactly the brute-force image, bit for bit, with either
    /// reconstruction's normal codes (the cubic's on thick slices).
    #[test]
    fn skipping_is_lossless_without_ert(
        nx in 2usize..30, ny in 2usize..30, nz in 2usize..30, seed in any::<u64>(), tfs in any::<u64>(),
        rx in -3.2f64..3.2, ry in -3.2f64..3.2, blend in any::<bool>(), cubic in any::<bool>(),
    ) {
        let sp = if cubic { [0.8, 0.8, 3.0] } else { [1.0; 3] };
        let vol = random_volume([nx, ny, nz], seed, sp);
        let tf = random_tf(tfs);
        let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, rx, ry, 0.4), [40, 40]);
        let mode = if blend { Mode::Blend } else { Mode::Iso };
        let base = Settings { mode, ert: 1.0, threads: 1, reconstruction: recon(cubic), ..Settings::default() };
        let (ri, rpx) = render(&vol, &tf, Settings { method: Method::Rle, ..base }, &cam);
        let (bi, bpx) = render(&vol, &tf, Settings { method: Method::BruteRle, ..base }, &cam);
        prop_assert!(same_bits(&rpx, &bpx), "intermediate images differ by {}", max_diff(&rpx, &bpx));
        prop_assert!(same_bits(&ri.data, &bi.data), "final images differ");
    }

    /// Under perspective, with and without early termination, the RLE path
    /// equals its brute force bit for bit (intermediate and final images):
    /// random volumes and transfer functions, both modes, fields of view
    /// 15–80°, the eye 0.05–4 diagonals away (inside the volume and the
    /// pyramid split included), anisotropic voxels, either reconstruction's
    /// normal codes.
    #[test]
    fn rle_equals_brute_force_in_perspective_with_termination(
        nx in 2usize..22, ny in 2usize..22, nz in 2usize..30, seed in any::<u64>(), tfs in any::<u64>(),
        rx in -3.2f64..3.2, ry in -3.2f64..3.2, rz in -3.2f64..3.2, blend in any::<bool>(), aniso in any::<bool>(),
        fov in 15.0f64..80.0, dist in prop_oneof![0.05f64..1.0, 1.0f64..4.0],
        ert in prop::sample::select(vec![0.3f32, 0.9, 0.99, 1.0]), cubic in any::<bool>(),
    ) {
        let sp = if aniso { [1.0, 0.7, 2.5] } else { [1.0; 3] };
        let vol = random_volume([nx, ny, nz], seed, sp);
        let tf = random_tf(tfs);
        let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, rx, ry, rz), [44, 40]);
        let mode = if blend { Mode::Blend } else { Mode::Iso };
        let base = Settings { mode, ert, threads: 2, reconstruction: recon(cubic), ..Settings::default() };
        let proj = Projection::perspective(fov, dist).unwrap();
        let run = |method| {
            let mut r = Renderer::new(vol.clone(), &tf, Settings { method, ..base }).unwrap();
            r.set_projection(proj).unwrap();
            frame(&mut r, &cam)
        };
        let (ri, rpx) = run(Method::Rle);
        let (bi, bpx) = run(Method::BruteRle);
        prop_assert!(same_bits(&rpx, &bpx), "intermediate images differ by {}", max_diff(&rpx, &bpx));
        prop_assert!(same_bits(&ri.data, &bi.data), "final images differ by {}", max_diff(&ri.data, &bi.data));
    }

    /// Same RLE image for 1, 2 and 3 threads, bit for bit.
    #[test]
    fn rle_is_deterministic_across_thread_counts(seed in any::<u64>(), ry in -3.2f64..3.2, blend in any::<bool>()) {
        let vol = random_volume([20, 18, 22], seed, [1.0; 3]);
        let tf = random_tf(seed >> 3);
        let cam = Camera::new(rotate_eye(DMat3::from_rotation_x(0.3), 1, ry.to_degrees()), [64, 64]);
        let s = Settings { method: Method::Rle, mode: if blend { Mode::Blend } else { Mode::Iso }, ..Settings::default() };
        let (a, apx) = render(&vol, &tf, Settings { threads: 1, ..s }, &cam);
        for threads in [2, 3] {
            let (b, bpx) = render(&vol, &tf, Settings { threads, ..s }, &cam);
            prop_assert!(same_bits(&apx, &bpx), "{threads} threads: intermediate images differ");
            prop_assert_eq!(&a, &b);
        }
    }

    /// Decoding the runs of every scanline gives back exactly the classified
    /// non-transparent voxels (position, class, normal: the central
    /// differences' or the cubic's code), the raw opacity and colour a voxel
    /// stands for are its classifier node's, and bridged gap voxels are
    /// transparent.
    #[test]
    fn encoding_round_trips(
        nx in 1usize..26, ny in 1usize..26, nz in 1usize..26, seed in any::<u64>(), tfs in any::<u64>(),
        axis in 0usize..3, aniso in any::<bool>(), cubic in any::<bool>(),
    ) {
        let sp = if aniso { [0.8, 1.0, 2.0] } else { [1.0; 3] };
        let vol = random_volume([nx, ny, nz], seed, sp);
        let tf = random_tf(tfs);
        let (lo, hi) = vol.value_range();
        let cls = Classifier::new(&tf, lo, hi);
        let pre = Preclass::new(&cls, sp);
        let slices = SliceStack::new(&vol, axis);
        let stack = StackNormals::new(&slices, recon(cubic));
        let rle = RleVolume::encode(&stack, &pre);
        let [ni, nj, nk] = slices.n;
        let mut count = 0;
        for k in 0..nk {
            for j in 0..nj {
                let decoded: Vec<_> = rle.decode_scanline(j, k).collect();
                let want: Vec<_> = (0..ni).filter_map(|i| pre.classify_voxel(&stack, i, j, k).map(|v| (i, v))).collect();
                prop_assert_eq!(&decoded, &want, "scanline ({}, {})", j, k);
                // runs: (transparent, non-transparent) pairs, every run non-empty, within the scanline
                let runs = rle.scanline_runs(j, k);
                prop_assert!(runs.len().is_multiple_of(2));
                prop_assert!(runs.chunks(2).all(|p| p[1] > 0));
                prop_assert!(runs.iter().map(|&r| r as usize).sum::<usize>() <= ni);
                // bridged voxels sit at transparent positions, with zero opacity
                for (i, v) in rle.stored_scanline(j, k).filter(|(_, v)| v.normal == BRIDGE_NORMAL) {
                    prop_assert!(pre.classify_voxel(&stack, i, j, k).is_none());
                    prop_assert_eq!(pre.opacity(v), 0.0);
                }
                for (_, v) in &decoded {
                    prop_assert!(pre.opacity(*v) > 0.0);
                    let node = cls.raw_node(v.class as usize);
                    prop_assert_eq!(pre.opacity(*v), node.a);
                    prop_assert_eq!(pre.color(*v), [node.r, node.g, node.b]);
                }
                count += decoded.len();
            }
        }
        // stored: the non-transparent voxels plus the bridged transparent ones
        prop_assert_eq!(count + rle.bridged_count(), rle.voxel_count());
        prop_assert!(rle.bytes() >= 4 * rle.voxel_count());
    }
}

/// The reconstruction whose normal codes the RLE paths read.
fn recon(cubic: bool) -> Reconstruction {
    if cubic { Reconstruction::Cubic } else { Reconstruction::Linear }
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

/// Axes are encoded lazily, and a tissue switch, a new transfer function, a new
/// iso value or a mode change re-encodes: every frame equals a fresh renderer's.
#[test]
fn classification_changes_reencode() {
    let vol = random_volume([22, 20, 26], 11, [1.0; 3]);
    let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, 0.3, 0.5, 0.1), [48, 48]);
    let s = Settings { method: Method::Rle, mode: Mode::Blend, threads: 2, ..Settings::default() };
    let mut r = Renderer::with_tissues(vol.clone(), &tissues(), s).unwrap();
    assert_eq!(r.rle_bytes(), 0);
    frame(&mut r, &cam);
    let axis = r.last_factorization().unwrap().axis;
    let bytes = r.rle_axis_bytes();
    assert!(bytes[axis] > 0 && bytes.iter().filter(|&&b| b > 0).count() == 1, "only the view's axis is encoded: {bytes:?}");
    r.prepare_all_axes();
    assert!(r.rle_axis_bytes().iter().all(|&b| b > 0));

    let fresh_tissue = |i: usize, mode: Mode| {
        let mut f = Renderer::with_tissues(vol.clone(), &tissues(), Settings { mode, ..s }).unwrap();
        f.select_tissue(i).unwrap();
        frame(&mut f, &cam).1
    };
    for i in [1, 2, 0] {
        r.select_tissue(i).unwrap();
        assert!(same_bits(&frame(&mut r, &cam).1, &fresh_tissue(i, Mode::Blend)), "tissue {i}");
    }
    r.set_settings(Settings { mode: Mode::Iso, ..s }).unwrap();
    assert!(same_bits(&frame(&mut r, &cam).1, &fresh_tissue(0, Mode::Iso)), "mode change");

    let tf = random_tf(4);
    r.set_transfer_function(&tf);
    let fresh = render(&vol, &tf, Settings { mode: Mode::Iso, ..s }, &cam).1;
    assert!(same_bits(&frame(&mut r, &cam).1, &fresh), "new transfer function");

    r.set_iso(90.0).unwrap();
    let mut f = Renderer::new(vol.clone(), &tf, Settings { mode: Mode::Iso, ..s }).unwrap();
    f.set_iso(90.0).unwrap();
    assert!(same_bits(&frame(&mut r, &cam).1, &frame(&mut f, &cam).1), "new iso value");
}

/// The pre-classified path draws the same object as the binary (post-classified)
/// path: on the head phantom, iso and blend, the final images' coverage agrees
/// and their mean difference is small. Catches geometry slips the RLE and its
/// reference would share.
#[test]
fn rle_agrees_with_the_binary_path() {
    let vol = phantom::head([64, 64, 56]).unwrap();
    let ts = ct_tissues();
    for (mode, tissue) in [(Mode::Iso, "skin"), (Mode::Iso, "bone"), (Mode::Blend, "skin"), (Mode::Blend, "bone")] {
        for deg in [0.0, 37.0, 90.0, 200.0] {
            let cam = Camera::new(rotate_eye(DMat3::from_rotation_x(-1.2), 1, deg), [128, 128]);
            let img = |method| {
                let mut r = Renderer::with_tissues(vol.clone(), &ts, Settings { method, mode, threads: 2, ..Settings::default() }).unwrap();
                r.select_tissue_named(tissue).unwrap();
                frame(&mut r, &cam).0
            };
            let (a, b) = (img(Method::Binary), img(Method::Rle));
            let n = a.data.len() as f32;
            let mean_alpha: f32 = a.data.iter().zip(&b.data).map(|(x, y)| (x[3] - y[3]).abs()).sum::<f32>() / n;
            let mean_rgb: f32 =
                a.data.iter().zip(&b.data).map(|(x, y)| (0..3).map(|c| (x[c] - y[c]).abs()).sum::<f32>() / 3.0).sum::<f32>() / n;
            let cov = |i: &Image| i.data.iter().filter(|c| c[3] > 0.5).count() as f32;
            let (ca, cb) = (cov(&a), cov(&b));
            assert!((ca - cb).abs() <= 0.05 * ca.max(1.0), "{mode:?} {tissue} {deg}°: coverage {ca} vs {cb}");
            assert!(mean_alpha < 0.02 && mean_rgb < 0.03, "{mode:?} {tissue} {deg}°: mean differences α {mean_alpha}, rgb {mean_rgb}");
        }
    }
}

/// Degenerate inputs render without panicking and agree with the reference:
/// flat volumes (one voxel thick along any axis), nothing visible, everything
/// opaque, and an early-termination threshold of 0 (nothing composites); a NaN
/// threshold is refused before any frame (`tests/plan.rs` checks every path).
#[test]
fn degenerate_inputs_are_handled() {
    let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, 0.4, 0.9, 0.2), [24, 24]);
    for dims in [[1, 6, 7], [6, 1, 7], [6, 7, 1], [1, 1, 5], [1, 1, 1], [3, 4, 5]] {
        let vol = random_volume(dims, 5, [1.0; 3]);
        let tfs = [TransferFunction::threshold(1e6, [1.0; 3]), TransferFunction::threshold(-1e6, [1.0; 3]), random_tf(7)];
        for tf in &tfs {
            for (mode, ert) in [(Mode::Iso, 0.99), (Mode::Blend, 0.99), (Mode::Blend, 0.0), (Mode::Iso, 0.0)] {
                let base = Settings { mode, ert, threads: 2, ..Settings::default() };
                let (ri, rpx) = render(&vol, tf, Settings { method: Method::Rle, ..base }, &cam);
                let (bi, bpx) = render(&vol, tf, Settings { method: Method::BruteRle, ..base }, &cam);
                assert!(max_diff(&rpx, &bpx) <= TOL && max_diff(&ri.data, &bi.data) <= TOL, "{dims:?} {mode:?} ert {ert}");
                if ert <= 0.0 {
                    assert!(ri.data.iter().all(|c| *c == [0.0; 4]), "ert {ert} composites nothing");
                }
            }
            let nan = Settings { method: Method::Rle, ert: f32::NAN, ..Settings::default() };
            assert!(Renderer::new(vol.clone(), tf, nan).is_err(), "a NaN threshold is refused");
        }
    }
}

/// What early ray termination costs in accuracy: RMSE (premultiplied RGB in
/// [0, 1], over all pixels) between ert 0.95 and ert 1.0 on the head phantom at
/// 512², iso and blend. Prints; run with `--ignored --nocapture`.
#[test]
#[ignore]
fn ert_rmse_on_head_phantom() {
    let vol = phantom::head([128, 128, 113]).unwrap();
    let ts = ct_tissues();
    let anterior = DMat3::from_cols_array(&[-1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0]);
    for (mode, tissue) in [(Mode::Iso, "skin"), (Mode::Iso, "bone"), (Mode::Blend, "skin"), (Mode::Blend, "bone")] {
        let mut worst = 0f64;
        let mut sum2 = 0f64;
        let mut n = 0usize;
        for deg in [0.0, 30.0, 60.0, 90.0, 135.0] {
            let cam = Camera::new(rotate_eye(anterior, 1, deg), [512, 512]);
            let img = |ert| {
                let s = Settings { method: Method::Rle, mode, ert, ..Settings::default() };
                let mut r = Renderer::with_tissues(vol.clone(), &ts, s).unwrap();
                r.select_tissue_named(tissue).unwrap();
                frame(&mut r, &cam).0
            };
            let (a, b) = (img(0.95), img(1.0));
            for (x, y) in a.data.iter().zip(&b.data) {
                for c in 0..3 {
                    let d = (x[c] - y[c]) as f64;
                    sum2 += d * d;
                    worst = worst.max(d.abs());
                }
            }
            n += a.data.len() * 3;
        }
        println!("{} {tissue}: RMSE(ert 0.95 vs 1.0) = {:.5} (max {:.4}, 5 views, 512²)", mode.name(), (sum2 / n as f64).sqrt(), worst);
    }
}

/// Case count: `PROPTEST_CASES` when set (for long soak runs), else `default`.
fn cases(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}
