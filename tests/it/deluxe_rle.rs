//! Shear-Warp Deluxe options I (intermediate slices) and P (post-classified
//! sampling) on the run-length-encoded path:
//!
//! - the intermediate sample is trilinear interpolation of the premultiplied
//!   colours at the ray's midpoint between two slices;
//! - two half steps through a homogeneous medium equal one full step;
//! - the accelerated path equals its brute force bit for bit with I, P and IP
//!   (parallel, perspective, ray limits from clip planes), and with P and S
//!   under the cubic reconstruction's normal codes;
//! - switching the reconstruction re-encodes;
//! - I lowers the staircase error of a cube seen along its diagonal;
//! - P sharpens a step edge that pre-classification blurs;
//! - a tissue switch under P re-classifies without re-encoding.

use crate::common;

use std::sync::Arc;

use glam::{DMat3, EulerRot};
use proptest::prelude::*;
use shearwarp::accuracy::metrics::compare;
use shearwarp::accuracy::reference::{ReferenceOptions, ReferenceRenderer, Scene};
use shearwarp::classify::TransferFunction;
use shearwarp::classify::presets::ct_tissues;
use shearwarp::classify::shading::Shading;
use shearwarp::composite::{Mode, composite_premultiplied};
use shearwarp::data::volume::{Volume, VoxelData};
use shearwarp::encode::rle::{PostTables, Preclass, RleVoxel, ViewTables};
use shearwarp::kernels::Reconstruction;
use shearwarp::render::{Deluxe, Method, Renderer, Settings};
use shearwarp::view::clip::{ClipPlane, ClipPlanes};
use shearwarp::view::{Camera, Projection};
use shearwarp::warp::Image;

const I: Deluxe = Deluxe { intermediate: true, post: false, matched: false };
const P: Deluxe = Deluxe { intermediate: false, post: true, matched: false };
const IP: Deluxe = Deluxe { intermediate: true, post: true, matched: false };
const S: Deluxe = Deluxe::STANDARD;

fn volume(dims: [usize; 3], f: impl Fn(usize, usize, usize) -> f32) -> Volume {
    let mut data = Vec::with_capacity(dims[0] * dims[1] * dims[2]);
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                data.push(f(x, y, z));
            }
        }
    }
    Volume::new(dims, [1.0; 3], VoxelData::F32(data)).unwrap()
}

/// One frame: the final image and the whole intermediate image.
fn frame(r: &mut Renderer, cam: &Camera) -> (Image, Vec<[f32; 4]>) {
    let mut img = Image::new(cam.size[0], cam.size[1]);
    r.render(cam, &mut img).unwrap();
    (img, r.intermediate().rgba.clone())
}

fn same_bits(a: &[[f32; 4]], b: &[[f32; 4]]) -> bool {
    a.len() == b.len() && a.iter().flatten().zip(b.iter().flatten()).all(|(x, y)| x.to_bits() == y.to_bits())
}

fn cases(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// The intermediate sample between two slices is trilinear interpolation of
/// the premultiplied voxel colours at the ray's midpoints: a three-slice volume,
/// unshaded (ambient 1), each intermediate pixel against over(slice, mid,
/// slice, mid, slice) computed here in f64 from the plan's sample positions.
#[test]
fn deluxe_midpoint_sample_is_trilinear() {
    let vol = volume([12, 11, 3], |x, y, z| 40.0 + 13.0 * ((x * 7 + y * 3 + z * 5) % 11) as f32);
    let tf = TransferFunction::new(vec![(40.0, 0.05), (180.0, 0.6)], vec![(40.0, [1.0, 0.2, 0.1]), (180.0, [0.1, 0.5, 1.0])]).unwrap();
    let shading = Shading { ambient: 1.0, diffuse: 0.0, specular: 0.0, shininess: 1 };
    let s = Settings { method: Method::BruteRle, mode: Mode::Blend, ert: 1.0, threads: 1, shading, deluxe: I, ..Settings::default() };
    for method in [Method::BruteRle, Method::Rle] {
        let mut r = Renderer::new(vol.clone(), &tf, Settings { method, ..s }).unwrap();
        let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, 0.25, -0.35, 0.1), [40, 40]);
        let (_, inter) = frame(&mut r, &cam);
        let plan = r.last_plan().unwrap().clone();
        assert_eq!(plan.view.axis, 2);
        assert!(plan.intermediate());
        let cls = r.classifier().clone();
        let ratio = plan.opacity_ratio as f64 * 0.5;
        let dims = vol.dims();
        let voxel = |i: usize, j: usize, k: usize| -> [f64; 4] {
            let mut v = [0usize; 3];
            v[plan.view.perm[0]] = i;
            v[plan.view.perm[1]] = j;
            v[plan.view.perm[2]] = k;
            let d = 40.0 + 13.0 * ((v[0] * 7 + v[1] * 3 + v[2] * 5) % 11) as f32;
            let n = cls.raw_node(cls.nearest_node(d));
            let a = 1.0 - (1.0 - n.a as f64).powf(ratio);
            [a * n.r as f64, a * n.g as f64, a * n.b as f64, a]
        };
        let (ni, nj) = (dims[plan.view.perm[0]], dims[plan.view.perm[1]]);
        // the bilinear sample of slice k at (x, y), None outside its cells
        let bilinear = |k: usize, x: f64, y: f64| -> Option<[f64; 4]> {
            let (ci, cj) = (x.floor(), y.floor());
            if ci < 0.0 || cj < 0.0 || ci as usize > ni - 2 || cj as usize > nj - 2 {
                return None;
            }
            let (wi, wj) = (x - ci, y - cj);
            let (ci, cj) = (ci as usize, cj as usize);
            let mut s = [0.0; 4];
            for (di, dj, w) in [(0, 0, (1.0 - wi) * (1.0 - wj)), (1, 0, wi * (1.0 - wj)), (0, 1, (1.0 - wi) * wj), (1, 1, wi * wj)] {
                let v = voxel(ci + di, cj + dj, k);
                for c in 0..4 {
                    s[c] += w * v[c];
                }
            }
            Some(s)
        };
        let [w, h] = r.intermediate().size;
        let nk = dims[plan.view.perm[2]];
        let order: Vec<usize> = if plan.view.ascending { (0..nk).collect() } else { (0..nk).rev().collect() };
        let mut checked = 0;
        for q in 0..h {
            'pixel: for p in 0..w {
                let pos = |k: usize| [plan.sample_at(k, 0, p), plan.sample_at(k, 1, q)];
                // away from the slice's first and last voxel, where rounding may
                // pick a cell inside or none (inside, a bilinear sample on a
                // cell border is the same from either cell)
                let near = |m: [f64; 2]| {
                    let edge = |x: f64, n: usize| (x - x.round()).abs() < 1e-6 && (x.round() <= 0.0 || x.round() >= (n - 1) as f64);
                    edge(m[0], ni) || edge(m[1], nj)
                };
                let mut mids = 0;
                let mut samples = vec![];
                for (t, &k) in order.iter().enumerate() {
                    if t > 0 {
                        let (a, b) = (pos(order[t - 1]), pos(k));
                        let m = [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])];
                        if near(m) {
                            continue 'pixel;
                        }
                        if let (Some(x), Some(y)) = (bilinear(k.min(order[t - 1]), m[0], m[1]), bilinear(k.max(order[t - 1]), m[0], m[1])) {
                            samples.push([0, 1, 2, 3].map(|c| 0.5 * (x[c] + y[c])));
                            mids += 1;
                        }
                    }
                    if near(pos(k)) {
                        continue 'pixel;
                    }
                    samples.extend(bilinear(k, pos(k)[0], pos(k)[1]));
                }
                let mut acc = [0.0f64; 4];
                for s in samples {
                    let t = 1.0 - acc[3];
                    for c in 0..4 {
                        acc[c] += t * s[c];
                    }
                }
                let got = inter[q * w + p];
                for c in 0..4 {
                    assert!((got[c] as f64 - acc[c]).abs() < 2e-5, "{method:?} pixel ({p}, {q}): {got:?} vs {acc:?}");
                }
                // (counted only where the pixel was compared)
                checked += mids;
            }
        }
        assert!(checked > 50, "only {checked} intermediate samples compared");
    }
}

/// Two half steps through a homogeneous medium equal one full step, colour
/// and opacity, for both samplers (the half step is the tables' correction
/// to half the ratio, as the plan's `sample_ratio` gives it).
#[test]
fn deluxe_two_half_steps_equal_one_full_step() {
    let vol = volume([4, 4, 4], |_, _, _| 100.0);
    for (alpha, ratio) in [(0.3f32, 1.0f32), (0.8, 1.3), (0.02, 1.7), (0.999, 1.0)] {
        let tf = TransferFunction::new(vec![(0.0, alpha), (200.0, alpha)], vec![(0.0, [0.9, 0.5, 0.2])]).unwrap();
        let r = Renderer::new(vol.clone(), &tf, Settings::default()).unwrap();
        let pre = Preclass::new(r.classifier(), [1.0; 3]);
        let v = RleVoxel { class: r.classifier().nearest_node(100.0) as u16, normal: 0 };
        let shading = Shading::default();
        let (mut full, mut half) = (ViewTables::default(), ViewTables::default());
        full.update(&pre, ratio, [0.0, 0.0, 1.0], shading);
        half.update(&pre, 0.5 * ratio, [0.0, 0.0, 1.0], shading);
        let (mut pfull, mut phalf) = (PostTables::default(), PostTables::default());
        pfull.update(&pre, ratio, [0.0, 0.0, 1.0], shading);
        phalf.update(&pre, 0.5 * ratio, [0.0, 0.0, 1.0], shading);
        for (one, h) in [(full.voxel(v), half.voxel(v)), (pfull.finish(pfull.voxel(v)), phalf.finish(phalf.voxel(v)))] {
            let mut two = [0.0; 4];
            composite_premultiplied(&mut two, h);
            composite_premultiplied(&mut two, h);
            for c in 0..4 {
                assert!((one[c] - two[c]).abs() < 1e-6, "α {alpha}, ratio {ratio}: {one:?} vs {two:?}");
            }
        }
    }
    // the plan's half step
    let tf = TransferFunction::ramp(50.0, 150.0, 0.5, [1.0; 3]);
    let mut r = Renderer::new(vol, &tf, Settings { method: Method::Rle, deluxe: I, ..Settings::default() }).unwrap();
    frame(&mut r, &Camera::new(DMat3::from_rotation_y(0.4), [16, 16]));
    let plan = r.last_plan().unwrap();
    assert!(plan.intermediate());
    assert_eq!(plan.sample_ratio(), 0.5 * plan.opacity_ratio);
}

/// A blobby volume with empty gaps, its densities in [0, 250].
fn blobs(dims: [usize; 3], seed: u64) -> Volume {
    common::blobs(dims, seed, [1.0; 3])
}

fn tf_of(sel: u64) -> TransferFunction {
    match sel % 3 {
        0 => TransferFunction::threshold(60.0, [0.9, 0.8, 0.7]),
        1 => TransferFunction::ramp(40.0, 120.0, 0.6, [0.5, 0.7, 0.9]),
        _ => TransferFunction::new(vec![(50.0, 0.0), (60.0, 0.8), (70.0, 0.0)], vec![(0.0, [1.0, 0.2, 0.2]), (250.0, [0.2, 0.2, 1.0])])
            .unwrap(),
    }
}

/// The settings of one RLE case: everything but the method.
fn case(mode: Mode, deluxe: Deluxe, threads: usize, ert: f32) -> Settings {
    Settings { mode, ert, threads, deluxe, ..Settings::default() }
}

/// [`case`] with the cubic reconstruction's normal codes.
fn cubic(s: Settings) -> Settings {
    Settings { reconstruction: Reconstruction::Cubic, ..s }
}

/// The case rendered by the RLE path and its brute force (`base`'s method is
/// replaced by each in turn).
fn rle_pair(
    vol: &Volume,
    tf: &TransferFunction,
    base: Settings,
    rot: DMat3,
    persp: Option<(f64, f64)>,
    planes: Option<&[ClipPlane]>,
) -> Option<[(Image, Vec<[f32; 4]>); 2]> {
    let mut out = Vec::new();
    let mode = base.mode;
    for method in [Method::Rle, Method::BruteRle] {
        let s = Settings { method, ..base };
        let mut r = Renderer::new(vol.clone(), tf, s).unwrap();
        if mode == Mode::Iso {
            r.set_iso(70.0).unwrap();
        }
        if let Some((fov, d)) = persp {
            r.set_projection(Projection::perspective(fov, d).unwrap()).unwrap();
        }
        if let Some(pl) = planes {
            r.set_limiter(Some(Arc::new(ClipPlanes::new(pl, vol.spacing()).unwrap())));
        }
        let cam = Camera::new(rot, [40, 40]);
        let mut img = Image::new(40, 40);
        r.render(&cam, &mut img).ok()?;
        out.push((img, r.intermediate().rgba.clone()));
    }
    let b = out.pop().unwrap();
    Some([out.pop().unwrap(), b])
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases(24)))]

    /// The RLE path equals its brute force bit for bit with I, P and IP, and
    /// with P and S under the cubic reconstruction's normal codes (on thick
    /// slices): parallel and perspective (eye inside the volume included),
    /// with and without clip planes limiting the rays, with early termination
    /// off and at several thresholds (the runs of midpoints stop at a
    /// terminated pixel as the brute force's per-pixel test does).
    #[test]
    fn deluxe_rle_equals_brute_force_bit_for_bit(
        nx in 2usize..20, ny in 2usize..20, nz in 2usize..24, seed in any::<u64>(), tfs in any::<u64>(),
        rx in -3.2f64..3.2, ry in -3.2f64..3.2, rz in -3.2f64..3.2, blend in any::<bool>(),
        which in 0usize..5, persp in any::<bool>(), fov in 20.0f64..70.0, dist in 0.05f64..3.0,
        clip in any::<bool>(), plane in ((-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0), -4.0f64..4.0),
        ert in prop::sample::select(vec![0.3f32, 0.9, 0.99, 1.0]),
    ) {
        let is_cubic = which >= 3;
        let vol = common::blobs([nx, ny, nz], seed, if is_cubic { [0.7, 0.7, 2.5] } else { [1.0; 3] });
        let tf = tf_of(tfs);
        let deluxe = [I, P, IP, P, S][which];
        let mode = if blend { Mode::Blend } else { Mode::Iso };
        let rot = DMat3::from_euler(EulerRot::XYZ, rx, ry, rz);
        let ((a, b, c), d) = plane;
        let planes: Vec<ClipPlane> = ClipPlane::new([a, b, c], d).ok().into_iter().filter(|_| clip).collect();
        let planes = (!planes.is_empty()).then_some(&planes[..]);
        let persp = persp.then_some((fov, dist));
        let s = if is_cubic { cubic(case(mode, deluxe, 2, ert)) } else { case(mode, deluxe, 2, ert) };
        let got = rle_pair(&vol, &tf, s, rot, persp, planes);
        prop_assert!(got.is_some() || persp.is_some(), "a parallel view failed");
        if let Some([(ri, rpx), (bi, bpx)]) = got {
            prop_assert!(same_bits(&rpx, &bpx), "{} cubic {is_cubic} {:?}: intermediate images differ", deluxe.label(), persp);
            prop_assert!(same_bits(&ri.data, &bi.data), "{} cubic {is_cubic} {:?}: final images differ", deluxe.label(), persp);
        }
    }
}

/// Deterministic for any thread count, with I and P.
#[test]
fn deluxe_rle_is_deterministic_across_thread_counts() {
    let vol = blobs([30, 26, 34], 7);
    let tf = tf_of(1);
    for deluxe in [I, P, IP] {
        let rot = DMat3::from_euler(EulerRot::XYZ, 0.5, -0.8, 0.3);
        let one = rle_pair(&vol, &tf, case(Mode::Blend, deluxe, 1, 1.0), rot, Some((40.0, 1.5)), None).unwrap();
        let three = rle_pair(&vol, &tf, case(Mode::Blend, deluxe, 3, 1.0), rot, Some((40.0, 1.5)), None).unwrap();
        assert!(same_bits(&one[0].1, &three[0].1) && same_bits(&one[1].1, &three[1].1), "{}", deluxe.label());
        assert!(one[0].0.coverage() > 0.05, "{}: empty image", deluxe.label());
    }
}

/// A solid axis-aligned cube (sharp faces) seen along its main diagonal: the
/// slices' staircase on its flat faces; the intermediate slices halve the
/// sample spacing, so the error against the reference ray caster drops.
#[test]
fn deluxe_i_reduces_the_staircase_on_a_cube_diagonal() {
    let n = 40;
    let vol = volume([n, n, n], |x, y, z| if [x, y, z].iter().all(|&c| (10..30).contains(&c)) { 200.0 } else { 0.0 });
    let tf = TransferFunction::ramp(60.0, 140.0, 0.25, [0.9, 0.8, 0.6]);
    let refr = ReferenceRenderer::new(&vol);
    let rot = DMat3::from_euler(EulerRot::XYZ, 35.264f64.to_radians(), 45f64.to_radians(), 0.0);
    let cam = Camera::new(rot, [96, 96]);
    let mut errs = vec![];
    for mode in [Mode::Blend, Mode::Iso] {
        for deluxe in [Deluxe::STANDARD, I] {
            let s = Settings { method: Method::Rle, mode, threads: 2, deluxe, ..Settings::default() };
            let mut r = Renderer::new(vol.clone(), &tf, s).unwrap();
            if mode == Mode::Iso {
                r.set_iso(100.0).unwrap();
            }
            let reference = refr.render(&Scene::from_renderer(&r), &cam, &ReferenceOptions { step: 0.1, ..Default::default() }).unwrap();
            let (img, _) = frame(&mut r, &cam);
            errs.push(compare(&img, &reference.image).unwrap().rmse);
        }
    }
    println!("cube diagonal RMSE: blend S {:.5} I {:.5}; iso S {:.5} I {:.5}", errs[0], errs[1], errs[2], errs[3]);
    assert!(errs[1] < errs[0], "blend: I {} vs S {}", errs[1], errs[0]);
    assert!(errs[3] < errs[2], "iso: I {} vs S {}", errs[3], errs[2]);
}

/// The 10–90 % rise, in output pixels, of the opacity along row `y` of `img`.
fn edge_width(img: &Image, y: usize) -> f64 {
    let w = img.width;
    let row: Vec<f64> = (0..w).map(|x| img.data[y * w + x][3] as f64).collect();
    let (lo, hi) = (row[2], row[w - 3]);
    let cross = |f: f64| {
        let t = lo + f * (hi - lo);
        let i = (0..w - 1).find(|&i| (row[i] - t) * (row[i + 1] - t) <= 0.0 && row[i] != row[i + 1]).unwrap();
        i as f64 + (t - row[i]) / (row[i + 1] - row[i])
    };
    (cross(0.9) - cross(0.1)).abs()
}

/// A step edge (a half-space of density 200 beside 0) sampled between its
/// voxels (two intermediate pixels per voxel) and zoomed in: pre-classified,
/// the interpolated opacity ramps over the voxel (the blur of interpolating
/// classified voxels); post-classified, the interpolated density is
/// classified, so the edge is a step at the threshold. P's edge is narrower.
#[test]
fn deluxe_p_sharpens_a_step_edge() {
    let n = 16;
    let vol = volume([n, n, n], |x, _, _| if x >= n / 2 { 200.0 } else { 0.0 });
    let tf = TransferFunction::ramp(55.0, 65.0, 0.05, [1.0; 3]);
    let mut widths = vec![];
    for deluxe in [Deluxe::STANDARD, P] {
        let s = Settings { method: Method::Rle, mode: Mode::Blend, threads: 1, deluxe, ..Settings::default() };
        let mut r = Renderer::new(vol.clone(), &tf, s).unwrap();
        r.set_quality(2.0).unwrap();
        let cam = Camera { rotation: DMat3::IDENTITY, zoom: Some(24.0), size: [96, 48] };
        let (img, _) = frame(&mut r, &cam);
        widths.push(edge_width(&img, 24));
    }
    println!("edge width (10-90 %, output pixels): S {:.2}, P {:.2}", widths[0], widths[1]);
    assert!(widths[1] < 0.75 * widths[0], "P {} vs S {}", widths[1], widths[0]);
}

/// Under P the encoding keeps the cells every tissue preset may show: a
/// switch re-classifies without re-encoding, and renders what a fresh
/// renderer of that tissue renders.
#[test]
fn deluxe_p_tissue_switch_keeps_the_encoding() {
    let vol = shearwarp::data::phantom::head([64, 64, 56]).unwrap();
    let tissues = ct_tissues();
    let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, 0.3, 0.7, 0.0), [64, 64]);
    for mode in [Mode::Blend, Mode::Iso] {
        let s = Settings { method: Method::Rle, mode, threads: 2, deluxe: P, ..Settings::default() };
        let mut r = Renderer::with_tissues(vol.clone(), &tissues, s).unwrap();
        frame(&mut r, &cam);
        let axis = r.last_plan().unwrap().view.axis;
        let enc = r.rle_cache().axis(axis).unwrap() as *const _;
        let times = r.build_times().rle;
        for t in 1..tissues.len() {
            r.select_tissue(t).unwrap();
            let (img, _) = frame(&mut r, &cam);
            assert!(std::ptr::eq(enc, r.rle_cache().axis(axis).unwrap()), "tissue {t} re-encoded");
            assert_eq!(r.build_times().rle, times, "tissue {t} re-encoded");
            let mut fresh = Renderer::with_tissues(vol.clone(), &tissues, s).unwrap();
            fresh.select_tissue(t).unwrap();
            let (want, _) = frame(&mut fresh, &cam);
            assert_eq!(common::bits(&img), common::bits(&want), "{} tissue {t}", mode.name());
        }
    }
}

/// The reconstruction is part of the encoding's key: after a switch on a
/// renderer (pre-classified and under P) each frame is a fresh renderer's of
/// that reconstruction, bit for bit, and on thick slices the cubic's codes
/// change the image — so the switch re-encoded.
#[test]
fn reconstruction_switch_reencodes() {
    let vol = common::blobs([30, 26, 14], 5, [0.7, 0.7, 3.0]);
    let tf = tf_of(1);
    let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, 0.9, 0.4, 0.0), [48, 48]);
    for (mode, deluxe) in [(Mode::Blend, P), (Mode::Iso, P), (Mode::Blend, S)] {
        let linear = case(mode, deluxe, 2, 1.0);
        let mut r = Renderer::new(vol.clone(), &tf, Settings { method: Method::Rle, ..linear }).unwrap();
        let mut images = vec![];
        for s in [linear, cubic(linear), linear] {
            let s = Settings { method: Method::Rle, ..s };
            r.set_settings(s).unwrap();
            let (img, _) = frame(&mut r, &cam);
            let (want, _) = frame(&mut Renderer::new(vol.clone(), &tf, s).unwrap(), &cam);
            assert_eq!(common::bits(&img), common::bits(&want), "{} {} {}", mode.name(), deluxe.label(), s.reconstruction.name());
            images.push(common::bits(&img));
        }
        assert!(images[0] != images[1], "{} {}: the cubic codes change nothing", mode.name(), deluxe.label());
    }
}

/// P on the raycast paths is accepted and changes nothing (they classify
/// after interpolation already); I there renders its midpoint samples.
#[test]
fn deluxe_p_is_a_no_op_on_the_raycast_paths() {
    let vol = blobs([20, 18, 16], 3);
    let tf = tf_of(1);
    let cam = Camera::new(DMat3::from_rotation_y(0.6), [32, 32]);
    for method in [Method::Binary, Method::Brute] {
        let s = Settings { method, threads: 1, ..Settings::default() };
        let (a, _) = frame(&mut Renderer::new(vol.clone(), &tf, s).unwrap(), &cam);
        let (b, _) = frame(&mut Renderer::new(vol.clone(), &tf, Settings { deluxe: P, ..s }).unwrap(), &cam);
        assert_eq!(common::bits(&a), common::bits(&b));
        let (c, _) = frame(&mut Renderer::new(vol.clone(), &tf, Settings { deluxe: I, ..s }).unwrap(), &cam);
        assert!(common::bits(&a) != common::bits(&c), "I changes the raycast image");
    }
}

/// Regression: with the eye near, consecutive slices' positions
/// differ by more than a cell at the image's edge, so a pixel samples the
/// volume at the midpoint between two slices and outside it at both. The
/// brute force's rectangle held only the slices' pixels and left those
/// midpoints out (the RLE path composited them): found by the bit-for-bit
/// property test above, this is its shrunk case.
#[test]
fn deluxe_i_brute_force_keeps_midpoints_outside_both_slices() {
    let vol = blobs([2, 5, 6], 0);
    let tf = tf_of(30226927442339151);
    let rot = DMat3::from_euler(EulerRot::XYZ, 0.0, -2.1050138258659707, 1.0014697563744366);
    for ert in [0.3, 1.0] {
        let [(ri, rpx), (bi, bpx)] = rle_pair(&vol, &tf, case(Mode::Iso, I, 1, ert), rot, Some((20.0, 0.7604588208701587)), None).unwrap();
        assert!(rpx.iter().any(|p| p[3] > 0.0), "the view shows something");
        assert!(same_bits(&rpx, &bpx), "ert {ert}: intermediate images differ");
        assert!(same_bits(&ri.data, &bi.data), "ert {ert}: final images differ");
    }
}
