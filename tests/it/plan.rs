//! The frame plan's policies and per-pixel ray limits, on every traversal.
//!
//! - Early ray termination means the same on the ray and slice traversals at
//!   the edge thresholds 0, 1 and NaN.
//! - Ray limits written by a limiter are honoured by every traversal: open
//!   limits change nothing, the accelerated paths equal their brute-force
//!   references bit for bit under any limits, and in blend mode the part of
//!   each ray in front of a split composited over the part behind it is the
//!   whole ray.

use crate::common;

use std::sync::Arc;

use glam::{DMat3, EulerRot};
use shearwarp::Volume;
use shearwarp::classify::TransferFunction;
use shearwarp::composite::Mode;
use shearwarp::render::{Method, Renderer, Settings};
use shearwarp::view::Camera;
use shearwarp::view::plan::{FramePlan, RayLimits};
use shearwarp::warp::Image;

use common::shell_volume as volume;

fn tf() -> TransferFunction {
    TransferFunction::ramp(40.0, 180.0, 0.7, [0.9, 0.7, 0.5])
}

fn views() -> Vec<DMat3> {
    vec![
        DMat3::IDENTITY,
        DMat3::from_euler(EulerRot::XYZ, 0.4, -0.9, 0.2),
        DMat3::from_euler(EulerRot::XYZ, -1.3, 2.1, 0.7),
        DMat3::from_euler(EulerRot::XYZ, 2.2, 0.3, -2.5),
    ]
}

/// One frame; returns the final image and the intermediate image.
fn frame(vol: &Volume, s: Settings, rot: DMat3, limiter: Option<Arc<dyn shearwarp::view::plan::Limiter>>) -> (Image, Vec<[f32; 4]>) {
    let mut r = Renderer::new(vol.clone(), &tf(), s).unwrap();
    if s.mode == Mode::Iso {
        r.set_iso(90.0).unwrap();
    }
    r.set_limiter(limiter);
    let mut img = Image::new(48, 40);
    r.render(&Camera::new(rot, [48, 40]), &mut img).unwrap();
    (img, r.intermediate().rgba.clone())
}

fn settings(method: Method, mode: Mode, ert: f32) -> Settings {
    Settings { method, mode, ert, threads: 2, ..Settings::default() }
}

const PATHS: [Method; 4] = [Method::Binary, Method::Brute, Method::Rle, Method::BruteRle];

#[test]
fn plan_early_ray_termination_at_zero_one_and_nan_is_the_same_on_every_path() {
    let vol = volume([20, 22, 18], 3);
    for rot in views() {
        for method in PATHS {
            // 0: even an empty pixel counts as terminated, so nothing composites (blend; RLE iso too)
            let (img, _) = frame(&vol, settings(method, Mode::Blend, 0.0), rot, None);
            assert!(img.data.iter().all(|p| *p == [0.0; 4]), "{method:?} at ert 0 composited something");
            // 1: no early termination: the same image as with a threshold just above every opacity reached
            let (one, _) = frame(&vol, settings(method, Mode::Blend, 1.0), rot, None);
            assert!(one.coverage() > 0.05, "{method:?}: nothing visible");
            // NaN: refused before any frame, with the same error on every path
            let e = Renderer::new(vol.clone(), &tf(), settings(method, Mode::Blend, f32::NAN)).err().expect("NaN ert is refused");
            assert!(e.to_string().contains("early ray termination"), "{e}");
            let mut r = Renderer::new(vol.clone(), &tf(), settings(method, Mode::Blend, 0.9)).unwrap();
            assert!(r.set_settings(settings(method, Mode::Blend, f32::NAN)).is_err());
        }
        // the pre-classified paths apply it in iso mode too
        for method in [Method::Rle, Method::BruteRle] {
            let (img, _) = frame(&vol, settings(method, Mode::Iso, 0.0), rot, None);
            assert!(img.data.iter().all(|p| *p == [0.0; 4]));
        }
        // the accelerated paths equal their references at both ends
        for ert in [0.0, 1.0] {
            for mode in [Mode::Iso, Mode::Blend] {
                assert_eq!(
                    frame(&vol, settings(Method::Binary, mode, ert), rot, None).0,
                    frame(&vol, settings(Method::Brute, mode, ert), rot, None).0
                );
                assert_eq!(
                    frame(&vol, settings(Method::Rle, mode, ert), rot, None).0,
                    frame(&vol, settings(Method::BruteRle, mode, ert), rot, None).0
                );
            }
        }
    }
}

/// A limiter from a per-pixel rule `(p, q, nk) → [k0, k1]`.
fn limiter(rule: impl Fn(usize, usize, usize) -> [u32; 2] + Send + Sync + 'static) -> Arc<dyn shearwarp::view::plan::Limiter> {
    Arc::new(move |plan: &FramePlan, l: &mut RayLimits| {
        let [w, h] = plan.grid.size;
        for q in 0..h {
            for p in 0..w {
                l.set(p, q, rule(p, q, plan.slices()));
            }
        }
    })
}

/// A pseudo-random split slice per pixel (some before the first slice, some after the last).
fn split(p: usize, q: usize, nk: usize) -> usize {
    ((p * 7 + q * 13 + p * q) % (nk + 3)).saturating_sub(1)
}

#[test]
fn plan_open_ray_limits_change_nothing() {
    let vol = volume([21, 19, 23], 5);
    for rot in views() {
        for method in PATHS {
            for mode in [Mode::Iso, Mode::Blend] {
                let s = settings(method, mode, 0.95);
                let open = limiter(|_, _, nk| [0, nk as u32 - 1]);
                assert_eq!(frame(&vol, s, rot, None), frame(&vol, s, rot, Some(open)), "{method:?} {mode:?}");
            }
        }
    }
}

#[test]
fn plan_ray_limits_accelerated_equals_brute_force() {
    for seed in 0..3u64 {
        let vol = volume([18 + seed as usize, 20, 17 + 2 * seed as usize], seed);
        for rot in views() {
            for mode in [Mode::Iso, Mode::Blend] {
                for ert in [0.9, 1.0] {
                    // arbitrary per-pixel windows, some empty
                    let lim = || limiter(move |p, q, nk| [split(p, q, nk) as u32, split(q + 3, p, nk) as u32 + 4]);
                    let fast = frame(&vol, settings(Method::Binary, mode, ert), rot, Some(lim()));
                    let brute = frame(&vol, settings(Method::Brute, mode, ert), rot, Some(lim()));
                    assert_eq!(fast, brute, "binary vs brute, seed {seed} {mode:?} ert {ert}");
                    let rle = frame(&vol, settings(Method::Rle, mode, ert), rot, Some(lim()));
                    let brute_rle = frame(&vol, settings(Method::BruteRle, mode, ert), rot, Some(lim()));
                    if ert == 1.0 {
                        assert_eq!(rle, brute_rle, "rle vs brute-rle, seed {seed} {mode:?}");
                    } else {
                        let d =
                            rle.1.iter().zip(&brute_rle.1).flat_map(|(a, b)| (0..4).map(move |c| (a[c] - b[c]).abs())).fold(0f32, f32::max);
                        assert!(d < 1e-5, "rle vs brute-rle differ by {d}");
                    }
                    // and the limits did something
                    assert_ne!(brute, frame(&vol, settings(Method::Brute, mode, ert), rot, None));
                }
            }
        }
    }
}

#[test]
fn plan_front_part_over_back_part_is_the_whole_ray_in_blend_mode() {
    let vol = volume([22, 20, 19], 11);
    for rot in views() {
        for method in PATHS {
            let s = settings(method, Mode::Blend, 1.0);
            let (_, whole) = frame(&vol, s, rot, None);
            // front and back in walking order: the split slice belongs to the back part
            let (_, f) = frame(&vol, s, rot, Some(front_or_back(true)));
            let (_, b) = frame(&vol, s, rot, Some(front_or_back(false)));
            let mut worst = 0f32;
            for ((w, f), b) in whole.iter().zip(&f).zip(&b) {
                for c in 0..4 {
                    worst = worst.max((w[c] - (f[c] + (1.0 - f[3]) * b[c])).abs());
                }
            }
            assert!(worst < 2e-6, "{method:?}: front over back differs from the whole by {worst}");
            assert!(f.iter().any(|p| p[3] > 0.0) && b.iter().any(|p| p[3] > 0.0), "both parts see something");
        }
    }
}

/// The part of every ray in front of (`front`) or behind its pixel's split.
fn front_or_back(front: bool) -> Arc<dyn shearwarp::view::plan::Limiter> {
    Arc::new(move |plan: &FramePlan, l: &mut RayLimits| {
        let nk = plan.slices();
        let [w, h] = plan.grid.size;
        for q in 0..h {
            for p in 0..w {
                // s slices from the front are in the front part
                let s = split(p, q, nk).min(nk);
                let (k0, k1) = if plan.view.ascending {
                    if front { (0, s as i64 - 1) } else { (s as i64, nk as i64 - 1) }
                } else if front {
                    (nk as i64 - s as i64, nk as i64 - 1)
                } else {
                    (0, nk as i64 - 1 - s as i64)
                };
                // an empty part: k0 > k1
                let (k0, k1) = if k0 > k1 { (1, 0) } else { (k0 as u32, k1 as u32) };
                l.set(p, q, [k0, k1]);
            }
        }
    })
}
