//! Steady-state RLE frames allocate nothing of their own: after warm-up (every
//! axis encoded, every scratch buffer grown), rotating frames with the
//! pre-classified paths make no heap allocations on any thread, except rayon's
//! job injector growing by one block per 63 queued jobs (a frame queues one).

use glam::DMat3;
use shearwarp::classify::presets::tissues_for;
use shearwarp::composite::Mode;
use shearwarp::data::volume::Volume;
use shearwarp::render::{Method, Renderer, Settings};
use shearwarp::view::{Camera, Projection, rotate_eye};
use shearwarp::warp::Image;

use crate::counting_alloc::{allocations, serial};

#[test]
fn steady_state_rle_frames_do_not_allocate() {
    let _serial = serial();
    let vol = Volume::from_fn([40, 36, 44], [1.0; 3], |x, y, z| {
        let d = ((x as f32 - 20.0).powi(2) + (y as f32 - 18.0).powi(2) + (z as f32 - 22.0).powi(2)).sqrt();
        (200.0 - 10.0 * d).max(0.0)
    })
    .unwrap();
    for method in [Method::Rle, Method::BruteRle] {
        for mode in [Mode::Iso, Mode::Blend] {
            for (threads, projection) in [
                (1, Projection::Parallel),
                (2, Projection::Parallel),
                (2, Projection::perspective(40.0, 2.0).unwrap()),
                // the eye inside: the pyramid split
                (2, Projection::perspective(60.0, 0.1).unwrap()),
            ] {
                let tissues = tissues_for(&vol);
                let s = Settings { method, mode, threads, ..Settings::default() };
                let mut r = Renderer::with_tissues(vol.clone(), &tissues, s).unwrap();
                r.set_projection(projection).unwrap();
                r.prepare_all_axes();
                let mut img = Image::new(96, 96);
                let cam = |deg: f64| Camera::new(rotate_eye(DMat3::from_rotation_x(0.2), 1, deg), [96, 96]);
                // warm up: visit every axis and grow every buffer (a perspective
                // plan's grid changes with the view: visit the measured views too)
                for d in (0..360).step_by(15) {
                    r.render(&cam(d as f64), &mut img).unwrap();
                }
                for d in 0..40 {
                    r.render(&cam(d as f64 * 0.7), &mut img).unwrap();
                }
                let n = allocations(|| {
                    for d in 0..40 {
                        r.render(&cam(d as f64 * 0.7), &mut img).unwrap();
                    }
                });
                assert!(n <= 1, "{n} allocations in 40 frames ({method:?}, {mode:?}, {threads} threads, {projection:?})");
            }
        }
    }
}
