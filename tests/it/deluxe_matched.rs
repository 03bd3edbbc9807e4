//! Shear-Warp Deluxe M (matched sampling on zoom, Sweeney & Mueller 2002
//! §3.3): as many samples per voxel as the warp magnifies (eq. 3), the warp
//! divided by them. The paper's sample counts (Table 1), the sharpness of a
//! magnified edge, and every accelerated path equal to its brute force with M
//! (and with I and M) bit for bit.

use crate::common;

use common::{bits, blobs};
use glam::{DMat3, EulerRot};
use shearwarp::classify::TransferFunction;
use shearwarp::composite::Mode;
use shearwarp::data::volume::Volume;
use shearwarp::render::{Deluxe, Method, Renderer, Settings, WordSize};
use shearwarp::view::{Camera, Projection, rotate_eye};
use shearwarp::warp::Image;

const M: Deluxe = Deluxe { intermediate: false, post: false, matched: true };
const IM: Deluxe = Deluxe { intermediate: true, post: false, matched: true };

fn try_render(r: &mut Renderer, cam: &Camera) -> Option<Image> {
    let mut img = Image::new(cam.size[0], cam.size[1]);
    r.render(cam, &mut img).ok().map(|_| img)
}

/// A solid cube of density 200 in a `d`³ volume, `m` voxels of air around it.
fn cube(d: usize, m: usize) -> Volume {
    let inside = |c: usize| (m..d - m).contains(&c);
    Volume::from_fn([d; 3], [1.0; 3], |x, y, z| if inside(x) && inside(y) && inside(z) { 200.0 } else { 0.0 }).unwrap()
}

/// The paper's Table 1: a 64³ cube whose view fits a 74² image at one pixel
/// per voxel, rendered into 512², takes 7² samples per voxel; a 128³ volume
/// (148²) takes 4². The grid's pitch is 1/ns, and without M it stays 1; an
/// anisotropic warp takes a pitch per axis.
#[test]
fn deluxe_m_sample_counts_are_the_papers() {
    let tf = TransferFunction::threshold(100.0, [1.0; 3]);
    // about 10° about y: a 64-voxel side spans 64 (cos θ + sin θ) ≈ 74 pixels
    let rot = rotate_eye(DMat3::IDENTITY, 1, 9.85);
    for (d, image, ns) in [(64, 74.0, 7), (128, 148.0, 4)] {
        let vol = cube(d, 4);
        for (deluxe, want) in [(M, ns), (Deluxe::STANDARD, 1)] {
            for method in [Method::Binary, Method::Rle] {
                let s = Settings { method, mode: Mode::Iso, threads: 2, deluxe, ..Settings::default() };
                let mut r = Renderer::new(vol.clone(), &tf, s).unwrap();
                let cam = Camera { rotation: rot, zoom: Some(512.0 / image), size: [512, 512] };
                try_render(&mut r, &cam).unwrap();
                let plan = r.last_plan().unwrap();
                assert_eq!(plan.matched_samples(), [ns, ns], "{d}³ into 512²");
                assert_eq!(plan.grid.pitch, [1.0 / want as f64; 2], "{d}³ {deluxe:?} {method:?}");
                // at the matched image's own size: one sample per voxel
                let cam = Camera { rotation: rot, zoom: Some(1.0), size: [image as usize, image as usize] };
                try_render(&mut r, &cam).unwrap();
                assert_eq!(r.last_plan().unwrap().matched_samples(), [1, 1]);
                assert_eq!(r.last_plan().unwrap().grid.pitch, [1.0; 2]);
            }
        }
    }
    // an anisotropic warp (voxels 1 × 2.5 × 1 mm): a pitch per axis, each its own count
    let vol = Volume::from_fn([20, 12, 20], [1.0, 2.5, 1.0], |x, y, z| ((x + y + z) % 5) as f32 * 50.0).unwrap();
    let s = Settings { method: Method::Binary, mode: Mode::Iso, threads: 2, deluxe: M, ..Settings::default() };
    let mut r = Renderer::new(vol, &tf, s).unwrap();
    let cam = Camera { rotation: DMat3::IDENTITY, zoom: Some(3.0), size: [128, 128] };
    try_render(&mut r, &cam).unwrap();
    let plan = r.last_plan().unwrap();
    let ns = plan.matched_samples();
    assert_eq!(ns, [3, 8], "{:?}", plan.warp);
    assert_eq!(plan.grid.pitch, [1.0 / 3.0, 1.0 / 8.0]);
}

/// The 10–90 % rise, in output pixels, of the alpha along the middle row
/// across the first edge from the left.
fn edge_width(img: &Image) -> f64 {
    let v = img.height / 2;
    let a: Vec<f64> = (0..img.width).map(|u| img.data[v * img.width + u][3] as f64).collect();
    let cross = |t: f64| {
        let u = a.iter().position(|&x| x >= t).expect("the row reaches the level");
        if u == 0 { 0.0 } else { (u - 1) as f64 + (t - a[u - 1]) / (a[u] - a[u - 1]) }
    };
    cross(0.9) - cross(0.1)
}

/// At 7× magnification (ns = 7) the silhouette edge of a solid cube (iso
/// surface: post-classified, a step at the crossing) rises within 1.5
/// output pixels with M on the raycast paths, and over about 0.8 · 7 pixels
/// without it (the warp's bilinear magnification of one-voxel pixels). The
/// pre-classified RLE path interpolates opacity, so its edge keeps the
/// one-voxel ramp of the classified voxels (reported, and narrower with M).
#[test]
fn deluxe_m_keeps_a_magnified_edge_sharp() {
    let vol = cube(40, 8);
    let tf = TransferFunction::threshold(100.0, [1.0; 3]);
    let cam = Camera { rotation: DMat3::IDENTITY, zoom: Some(6.9), size: [320, 320] };
    let mut report = vec![];
    for method in [Method::Binary, Method::Brute, Method::Rle] {
        let mut w = vec![];
        for deluxe in [Deluxe::STANDARD, M, IM] {
            if deluxe.intermediate && method == Method::Rle {
                continue;
            }
            let s = Settings { method, mode: Mode::Iso, threads: 2, deluxe, ..Settings::default() };
            let mut r = Renderer::new(vol.clone(), &tf, s).unwrap();
            let img = try_render(&mut r, &cam).unwrap();
            if deluxe.matched {
                assert_eq!(r.last_plan().unwrap().grid.pitch, [1.0 / 7.0; 2]);
            }
            w.push(edge_width(&img));
        }
        report.push(format!("{method:?}: S {:.2}, M {:.2} px", w[0], w[1]));
        assert!(w[0] > 4.0, "{method:?}: {w:?}");
        if method == Method::Rle {
            assert!(w[1] < w[0], "{method:?}: {w:?}");
        } else {
            assert!(w[1] <= 1.5 && w[2] <= 1.5, "{method:?}: {w:?}");
        }
    }
    eprintln!("{}", report.join("\n"));
}

/// Every accelerated path equals its brute force with M, bit for bit (ERT
/// off): binary == brute and rle == brute-rle, parallel and perspective, both
/// modes, u32/u64 and super cells on the binary path; and with I and M on the
/// binary path. Magnifications 1.5–4.5 (2–5 samples per voxel), oblique
/// views and anisotropic voxels, so grids with a pitch per axis among them.
#[test]
fn deluxe_m_accelerated_equals_brute_force_bit_for_bit() {
    let mut rnd = common::uniform(23);
    let (mut checked, mut anisotropic) = (0, 0);
    for case in 0..48 {
        let dims = [6 + (rnd() * 12.0) as usize, 5 + (rnd() * 12.0) as usize, 4 + (rnd() * 20.0) as usize];
        let vol = blobs(dims, 900 + case as u64, [[1.0, 1.0, 1.0], [1.0, 0.7, 1.6]][case % 2]);
        let rot = DMat3::from_euler(EulerRot::XYZ, rnd() * 7.0, rnd() * 7.0, rnd() * 7.0);
        let persp = case % 3 == 2;
        let zoom = 1.5 + rnd() * 3.0;
        let proj = if persp { Projection::perspective(8.0 + rnd() * 12.0, 1.8 + rnd() * 2.0).unwrap() } else { Projection::Parallel };
        let cam = Camera { rotation: rot, zoom: Some(zoom), size: [72, 64] };
        let mode = if (case / 2) % 2 == 0 { Mode::Blend } else { Mode::Iso };
        let tf = TransferFunction::ramp(40.0, 160.0, 0.5, [0.9, 0.7, 0.5]);
        let s = Settings {
            mode,
            threads: 2,
            ert: 1.0,
            cell: 1 + case % 3,
            word: if case % 4 == 0 { WordSize::U32 } else { WordSize::U64 },
            ..Settings::default()
        };
        let pairs: &[(Method, Method, Deluxe)] = match case % 3 {
            0 => &[(Method::Binary, Method::Brute, M), (Method::Rle, Method::BruteRle, M)],
            1 => &[(Method::Binary, Method::Brute, IM), (Method::Rle, Method::BruteRle, M)],
            _ => &[(Method::Binary, Method::Brute, M), (Method::Binary, Method::Brute, IM), (Method::Rle, Method::BruteRle, M)],
        };
        for &(fast, brute, deluxe) in pairs {
            let make = |method| {
                let mut r = Renderer::new(vol.clone(), &tf, Settings { method, deluxe, ..s }).unwrap();
                r.set_projection(proj).unwrap();
                r
            };
            let (mut a, mut b) = (make(fast), make(brute));
            let Some(x) = try_render(&mut a, &cam) else {
                assert!(try_render(&mut b, &cam).is_none());
                continue;
            };
            let y = try_render(&mut b, &cam).unwrap();
            let pitch = a.last_plan().unwrap().grid.pitch;
            assert!(pitch.iter().any(|&p| p < 1.0), "case {case}: not magnified");
            anisotropic += usize::from(pitch[0] != pitch[1]);
            assert_eq!(bits(&x), bits(&y), "case {case} {fast:?} {deluxe:?} {proj:?}: differs from brute force");
            if x.coverage() > 0.0 {
                checked += 1;
            }
        }
    }
    assert!(checked >= 60, "only {checked}");
    assert!(anisotropic >= 10, "only {anisotropic} frames with a pitch per axis");
}

/// A grid past the pixel limit is a clear error, not an allocation failure:
/// a 2000×1500×2 slab at 16 samples per voxel would need 3·10⁶ · 256 pixels.
#[test]
fn deluxe_m_grid_past_the_limit_is_an_error() {
    let vol = Volume::from_fn([2000, 1500, 2], [1.0; 3], |x, _, _| (x % 3) as f32 * 100.0).unwrap();
    let tf = TransferFunction::threshold(100.0, [1.0; 3]);
    let s = Settings { method: Method::Brute, mode: Mode::Iso, threads: 2, deluxe: M, ..Settings::default() };
    let mut r = Renderer::new(vol, &tf, s).unwrap();
    let cam = Camera { rotation: DMat3::IDENTITY, zoom: Some(16.5), size: [64, 64] };
    let mut img = Image::new(64, 64);
    let err = r.render(&cam, &mut img).unwrap_err().to_string();
    assert!(err.contains("intermediate image") && err.contains("Deluxe M"), "{err}");
    // without M the same view renders
    r.set_settings(Settings { deluxe: Deluxe::STANDARD, ..r.settings() }).unwrap();
    r.render(&cam, &mut img).unwrap();
}
