//! Helpers shared by the integration tests; each test module uses
//! some of them.
#![allow(dead_code)]

use shearwarp::classify::TransferFunction;
use shearwarp::composite::Mode;
use shearwarp::data::volume::{Volume, VoxelData};
use shearwarp::render::{Method, Renderer, Settings};
use shearwarp::view::{Camera, Projection};
use shearwarp::warp::Image;

/// A renderer of `vol` with one transfer function, `method` and `mode` on two
/// threads, in `projection`.
pub fn renderer(vol: &Volume, tf: &TransferFunction, method: Method, mode: Mode, projection: Projection) -> Renderer {
    let s = Settings { method, mode, threads: 2, ..Settings::default() };
    let mut r = Renderer::new(vol.clone(), tf, s).unwrap();
    r.set_projection(projection).unwrap();
    r
}

/// One frame of `cam` into a new image.
pub fn render(r: &mut Renderer, cam: &Camera) -> Image {
    let mut img = Image::new(cam.size[0], cam.size[1]);
    r.render(cam, &mut img).unwrap();
    img
}

/// The image's bits (for bit-for-bit comparisons).
pub fn bits(img: &Image) -> Vec<u32> {
    img.data.iter().flatten().map(|x| x.to_bits()).collect()
}

/// Deterministic pseudo-random u64s (xorshift64) from a non-zero `seed`.
pub fn xorshift(mut s: u64) -> impl FnMut() -> u64 {
    move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    }
}

/// Four blobs plus sparse noise, with voxel `spacing`: a small volume with
/// soft and hard edges for the accuracy tests.
pub fn blobs(dims: [usize; 3], seed: u64, spacing: [f32; 3]) -> Volume {
    let mut next = xorshift(seed | 1);
    let centres: Vec<([f32; 3], f32)> =
        (0..4).map(|_| ([0, 1, 2].map(|a| (next() % 1000) as f32 / 1000.0 * dims[a] as f32), 2.0 + (next() % 8) as f32)).collect();
    let mut data = vec![0f32; dims[0] * dims[1] * dims[2]];
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                let mut v = 0f32;
                for (c, r) in &centres {
                    let d = ((x as f32 - c[0]).powi(2) + (y as f32 - c[1]).powi(2) + (z as f32 - c[2]).powi(2)).sqrt();
                    v = v.max((200.0 * (1.0 - d / r)).max(0.0));
                }
                if (x * 73 + y * 19 + z * 83) % 29 == 0 {
                    v += 60.0;
                }
                data[x + dims[0] * (y + dims[1] * z)] = v;
            }
        }
    }
    Volume::new(dims, spacing, VoxelData::F32(data)).unwrap()
}

/// `v` in voxel type `ty` (0: f32, 1: u8, 2: u16), values rounded to integers
/// for the integer types (the 16-bit values spread seven apart).
pub fn typed(v: &Volume, ty: u8) -> Volume {
    let f = v.to_f32();
    let data = match ty {
        0 => return v.clone(),
        1 => shearwarp::data::volume::VoxelData::U8(f.iter().map(|x| x.round().clamp(0.0, 255.0) as u8).collect()),
        _ => shearwarp::data::volume::VoxelData::U16(f.iter().map(|x| (x.round() * 7.0) as u16).collect()),
    };
    Volume::new(v.dims(), v.spacing(), data).unwrap()
}

/// A random volume of four soft blobs and hashed noise, with internal empty
/// regions (the property tests' volumes: `invariants.rs`, `rle.rs`).
pub fn random_volume(dims: [usize; 3], seed: u64, spacing: [f32; 3]) -> Volume {
    let mut next = xorshift(seed | 1);
    let blobs: Vec<([f32; 3], f32, f32)> = (0..4)
        .map(|_| {
            let c = [0, 1, 2].map(|a| (next() % 1000) as f32 / 1000.0 * dims[a] as f32);
            let r = 1.0 + (next() % 1000) as f32 / 1000.0 * dims.iter().copied().max().unwrap() as f32 * 0.4;
            let v = 50.0 + (next() % 200) as f32;
            (c, r, v)
        })
        .collect();
    let noise_seed = next();
    let mut data = vec![0f32; dims[0] * dims[1] * dims[2]];
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                let mut v = 0f32;
                for (c, r, val) in &blobs {
                    let d = ((x as f32 - c[0]).powi(2) + (y as f32 - c[1]).powi(2) + (z as f32 - c[2]).powi(2)).sqrt();
                    if d < *r {
                        v = v.max(val * (1.0 - d / r).min(0.5) * 2.0);
                    }
                }
                let h = (x as u64 * 73856093) ^ (y as u64 * 19349663) ^ (z as u64 * 83492791) ^ noise_seed;
                if h.is_multiple_of(17) {
                    v += (h % 97) as f32;
                }
                data[x + dims[0] * (y + dims[1] * z)] = v;
            }
        }
    }
    Volume::new(dims, spacing, VoxelData::F32(data)).unwrap()
}

/// A spherical shell and a little hashed noise: structure at every depth.
pub fn shell_volume(dims: [usize; 3], seed: u64) -> Volume {
    let c = [0.37, 0.55, 0.46].map(|x: f32| x + (seed % 7) as f32 * 0.01);
    Volume::from_fn(dims, [1.0, 1.1, 0.9], |x, y, z| {
        let p = [x as f32 / dims[0] as f32, y as f32 / dims[1] as f32, z as f32 / dims[2] as f32];
        let d = ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2)).sqrt();
        let shell = (200.0 * (1.0 - (d - 0.3).abs() * 8.0)).max(0.0);
        let h = (x as u64 * 73_856_093) ^ (y as u64 * 19_349_663) ^ (z as u64 * 83_492_791) ^ seed;
        shell + if h.is_multiple_of(13) { (h % 120) as f32 } else { 0.0 }
    })
    .unwrap()
}

/// Deterministic uniform numbers in [0, 1) from `seed` (a 64-bit LCG's top 53 bits).
pub fn uniform(mut seed: u64) -> impl FnMut() -> f64 {
    move || {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// The three views the accuracy tests compare at: 0°, 45° about y, and along
/// the main diagonal (the hardest view).
pub fn three_views() -> [(&'static str, glam::DMat3); 3] {
    use shearwarp::view::rotate_eye;
    let id = glam::DMat3::IDENTITY;
    let diag = rotate_eye(rotate_eye(id, 1, 45.0), 0, 35.264_389_682_754_654);
    [("0°", id), ("45°", rotate_eye(id, 1, 45.0)), ("diagonal", diag)]
}

/// [`blobs`] 24×20×28 (spacing 1, 0.7, 1.6) with empty faces: a parallel
/// view along an axis has rays exactly on the faces (closed box), which any
/// perspective ray of them leaves on one side.
pub fn closed_blobs() -> Volume {
    let b = blobs([24, 20, 28], 7, [1.0, 0.7, 1.6]);
    let edge = |x: usize, n: usize| x == 0 || x + 1 == n;
    Volume::from_fn([24, 20, 28], [1.0, 0.7, 1.6], |x, y, z| if edge(x, 24) || edge(y, 20) || edge(z, 28) { 0.0 } else { b.get(x, y, z) })
        .unwrap()
}

/// As the eye recedes through `distances` (diagonals; the field of view
/// shrunk to keep the parallel fit's image scale), the image `at(projection)`
/// converges to `par`: its RMSE never grows, and ends below 1e-3 with a
/// largest difference below 0.02. Returns the RMSEs.
pub fn assert_recedes_to_parallel(par: &Image, distances: &[f64], mut at: impl FnMut(Projection) -> Image, what: &str) -> Vec<f64> {
    use shearwarp::accuracy::metrics::{max_abs_error, rmse};
    let mut errs = vec![];
    let mut far = par.clone();
    for &d in distances {
        // the parallel fit's zoom: f / (d · diagonal) = size / diagonal
        let fov = 2.0 * (1.0f64 / (2.0 * d)).atan().to_degrees();
        let p = at(Projection::perspective(fov, d).unwrap());
        let e = rmse(&p, par).unwrap();
        assert!(errs.last().is_none_or(|&l: &f64| e <= l + 1e-6), "{what}: RMSE {errs:?} then {e}: did not shrink as the eye receded");
        errs.push(e);
        far = p;
    }
    let m = max_abs_error(&far, par).unwrap();
    eprintln!("{what}: RMSE to parallel {errs:?}, max {m}");
    assert!(errs.last().is_some_and(|&l| l < 1e-3) && m < 0.02, "{what}: RMSE to parallel {errs:?}, max {m}");
    errs
}

/// The sphere phantom (40³) the reference-accuracy tests render, its generic
/// transfer function at the analytic iso value, and its reference renderer.
pub fn sphere_scene() -> (Volume, TransferFunction, shearwarp::accuracy::reference::ReferenceRenderer) {
    use shearwarp::data::phantom;
    let vol = phantom::sphere([40, 40, 40]).unwrap();
    let tf = shearwarp::classify::presets::generic(phantom::SPHERE_ISO, 200.0).tf;
    let refr = shearwarp::accuracy::reference::ReferenceRenderer::new(&vol);
    (vol, tf, refr)
}

/// The transfer functions of the invariant tests, by seed: a threshold, a
/// ramp and a band of opacity (non-monotone: what the blend mask's range
/// test is for).
pub fn random_tf(seed: u64) -> TransferFunction {
    let a = 20.0 + (seed % 80) as f32;
    match seed % 3 {
        0 => TransferFunction::threshold(a, [0.9, 0.8, 0.7]),
        1 => TransferFunction::ramp(a, a + 60.0, 0.4 + (seed % 5) as f32 * 0.1, [0.5, 0.7, 0.9]),
        _ => TransferFunction::new(vec![(a, 0.0), (a + 5.0, 0.8), (a + 10.0, 0.0)], vec![(0.0, [1.0, 0.2, 0.2]), (250.0, [0.2, 0.2, 1.0])])
            .unwrap(),
    }
}

/// Three threshold tissues `a`, `b`, `c` at 60, 110 and 170 times `scale`,
/// each opaque from its threshold on: opacity `alpha[0]` at `30·span` above
/// it and `alpha[1]` at `300·span`, its colour ramping over the same span.
pub fn three_tissues(scale: f32, span: f32, alpha: [f32; 2]) -> Vec<shearwarp::classify::presets::Tissue> {
    [(60.0, "a"), (110.0, "b"), (170.0, "c")]
        .into_iter()
        .map(|(t, name)| {
            let t = t * scale;
            shearwarp::classify::presets::Tissue {
                name,
                threshold: t,
                rgb: [0.8, 0.7, 0.6],
                tf: TransferFunction::new(
                    vec![(t, 0.0), (t + 30.0 * span, alpha[0]), (t + 300.0 * span, alpha[1])],
                    vec![(t, [0.9, 0.5, 0.3]), (t + 300.0 * span, [0.3, 0.5, 0.9])],
                )
                .unwrap(),
            }
        })
        .collect()
}
