//! Steady-state frames allocate nothing of their own: after warm-up, rotating
//! frames (incremental shears, cached axes) make no heap allocations on any
//! thread, except that rayon's job injector grows by one 1.5 KB block per 63
//! jobs it has queued, and a frame queues exactly one job.

use glam::DMat3;
use shearwarp::classify::presets::tissues_for;
use shearwarp::composite::Mode;
use shearwarp::data::volume::Volume;
use shearwarp::render::{Renderer, Settings};
use shearwarp::view::{Camera, rotate_eye};
use shearwarp::warp::Image;

use crate::counting_alloc::{allocations, serial};

#[test]
fn steady_state_frames_do_not_allocate() {
    let _serial = serial();
    let vol = Volume::from_fn([40, 36, 44], [1.0; 3], |x, y, z| {
        let d = ((x as f32 - 20.0).powi(2) + (y as f32 - 18.0).powi(2) + (z as f32 - 22.0).powi(2)).sqrt();
        (200.0 - 10.0 * d).max(0.0)
    })
    .unwrap();
    for mode in [Mode::Iso, Mode::Blend] {
        for threads in [1, 2] {
            let tissues = tissues_for(&vol);
            let mut r = Renderer::with_tissues(vol.clone(), &tissues, Settings { mode, threads, ..Settings::default() }).unwrap();
            r.prepare_all_axes();
            let mut img = Image::new(96, 96);
            let cam = |deg: f64| Camera::new(rotate_eye(DMat3::from_rotation_x(0.2), 1, deg), [96, 96]);
            // warm up: visit every axis and grow every buffer
            for d in (0..360).step_by(15) {
                r.render(&cam(d as f64), &mut img).unwrap();
            }
            let n = allocations(|| {
                for d in 0..40 {
                    r.render(&cam(d as f64 * 0.7), &mut img).unwrap();
                }
            });
            assert!(n <= 1, "{n} allocations in 40 frames ({mode:?}, {threads} threads)");
        }
    }
}
