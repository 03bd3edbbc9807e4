//! The lean binary iso frame ([`shearwarp::composite::lean`]) renders exactly
//! the general ray loop's and the brute force's intermediate image and final
//! image, bit for bit: over random volumes (f32, 8- and 16-bit: the three cell
//! layouts), views, cell sizes, one transfer function or the tissue presets'
//! threshold codes (read from the presets' code mask and from the current
//! preset's own one-bit mask), u32 and u64 words, slice counts below and
//! above one word, and 1, 2 or 3 threads.

use glam::{DMat3, EulerRot};
use proptest::prelude::*;
use shearwarp::classify::TransferFunction;
use shearwarp::classify::presets::Tissue;
use shearwarp::composite::Mode;
use shearwarp::data::volume::{Volume, VoxelData};
use shearwarp::render::{FrameStats, Method, Renderer, Settings, WordSize};
use shearwarp::view::{Camera, Factorization};
use shearwarp::warp::Image;

use crate::common::{random_volume, typed};

fn tissues(scale: f32) -> Vec<Tissue> {
    crate::common::three_tissues(scale, 1.0, [0.5, 0.9])
}

/// Four presets (as many as the CT presets): five levels, so 4-bit codes.
fn four_tissues(scale: f32) -> Vec<Tissue> {
    let mut t = tissues(scale);
    let mut top = t[2].clone();
    top.name = "d";
    top.threshold = 210.0 * scale;
    top.tf = TransferFunction::threshold(top.threshold, [0.4, 0.6, 0.8]);
    t.push(top);
    t
}

/// What a frame produced: the final image, the whole intermediate grid
/// (transparent outside the valid rectangle) and its depths, as bits.
struct Frame {
    image: Vec<u32>,
    inter: Vec<u32>,
    stats: FrameStats,
}

fn frame(r: &mut Renderer, cam: &Camera) -> Frame {
    let mut img = Image::new(cam.size[0], cam.size[1]);
    let stats = r.render(cam, &mut img).unwrap();
    let inter = r.intermediate();
    let [w, h] = inter.size;
    let mut bits = Vec::with_capacity(w * h * 5);
    for q in 0..h {
        for p in 0..w {
            bits.extend(inter.get(p as isize, q as isize).map(f32::to_bits));
            bits.push(inter.depth_at(p, q).to_bits());
        }
    }
    Frame { image: img.data.iter().flatten().map(|x| x.to_bits()).collect(), inter: bits, stats }
}

/// A renderer of `vol`: one iso value (`tissue` `None`) or the presets with
/// tissue `i` selected.
fn renderer(vol: &Volume, tissue: Option<usize>, s: Settings) -> Renderer {
    let scale = if matches!(vol.data(), VoxelData::U16(_)) { 7.0 } else { 1.0 };
    match tissue {
        None => {
            let tf = TransferFunction::threshold(90.0 * scale, [0.9, 0.8, 0.7]);
            Renderer::new(vol.clone(), &tf, s).unwrap()
        }
        Some(i) if i >= FOUR => {
            let mut r = Renderer::with_tissues(vol.clone(), &four_tissues(scale), s).unwrap();
            r.select_tissue(i - FOUR).unwrap();
            r
        }
        Some(i) => {
            let mut r = Renderer::with_tissues(vol.clone(), &tissues(scale), s).unwrap();
            r.select_tissue(i).unwrap();
            r
        }
    }
}

/// `Some(FOUR + i)` selects tissue `i` of [`four_tissues`] in [`check`].
const FOUR: usize = 100;

/// Renders `frames` views with the lean frame, the general ray loop and the
/// brute force and asserts the three equal bit for bit (intermediate image,
/// depths and final image) and that the lean renderer took the lean path
/// (the settings' reconstruction: linear, or the lean cubic frame's cubic);
/// returns how many covered pixels the frames had.
pub(crate) fn check(vol: &Volume, tissue: Option<usize>, s: Settings, cams: &[Camera]) -> usize {
    let s = Settings { mode: Mode::Iso, method: Method::Binary, ..s };
    let mut lean = renderer(vol, tissue, s);
    let mut general = renderer(vol, tissue, s);
    general.set_lean_frame(false);
    let mut brute = renderer(vol, tissue, Settings { method: Method::Brute, ..s });
    // the presets' threshold-coded mask, where the others read the preset's own one-bit one
    let mut coded = tissue.map(|_| {
        let mut r = renderer(vol, tissue, s);
        r.set_preset_masks(false);
        r
    });
    let mut covered = 0;
    for (f, cam) in cams.iter().enumerate() {
        let a = frame(&mut lean, cam);
        let b = frame(&mut general, cam);
        let c = frame(&mut brute, cam);
        if let Some(r) = coded.as_mut() {
            let d = frame(r, cam);
            assert!(a.stats.preset_mask && !d.stats.preset_mask, "frame {f}: the preset's own mask and the code mask");
            assert!(d.stats.lean, "frame {f}: the code mask's renderer took the general path");
            assert!(a.inter == d.inter && a.image == d.image, "frame {f}: the preset's own mask and the code mask differ");
        }
        assert!(a.stats.lean, "frame {f}: the lean renderer took the general path");
        assert!(!b.stats.lean, "frame {f}: the general renderer took the lean path");
        assert!(a.inter == b.inter, "frame {f}: lean and general intermediate images differ");
        assert!(a.inter == c.inter, "frame {f}: lean and brute-force intermediate images differ");
        assert!(a.image == b.image && a.image == c.image, "frame {f}: final images differ");
        covered += a.inter.chunks(5).filter(|px| f32::from_bits(px[3]) > 0.0).count();
    }
    covered
}

pub(crate) fn cam(rx: f64, ry: f64, rz: f64) -> Camera {
    Camera::new(DMat3::from_euler(EulerRot::XYZ, rx, ry, rz), [48, 44])
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases(32)))]

    /// The lean frame equals the general path and the brute force bit for bit
    /// over random volumes, views (a rotation sequence crossing axes and
    /// directions), cell sizes, tissue codes or one iso value, voxel types,
    /// word sizes and thread counts.
    #[test]
    fn lean_frame_equals_general_and_brute_force(
        nx in 2usize..28, ny in 2usize..28, nz in 2usize..28, long in 0usize..3, nlong in 2usize..140,
        seed in any::<u64>(), ty in 0u8..3, cell in 1usize..=8, u32w in any::<bool>(), threads in 1usize..=3,
        tissue in prop::option::of(0usize..3), rx in -3.2f64..3.2, ry in -3.2f64..3.2, step in -1.2f64..1.2,
    ) {
        let mut dims = [nx, ny, nz];
        dims[long] = nlong;
        let vol = typed(&random_volume(dims, seed, [1.0, 0.9, 1.2]), ty);
        let s = Settings {
            word: if u32w { WordSize::U32 } else { WordSize::U64 },
            cell,
            threads,
            ..Settings::default()
        };
        let cams: Vec<Camera> = (0..4).map(|f| cam(rx + f as f64 * step, ry - f as f64 * 0.3 * step, 0.2)).collect();
        check(&vol, tissue, s, &cams);
    }
}

/// Slice counts at and around one word of every code width (1-bit masks of
/// one iso value, 2-bit codes of the three presets; u32 and u64), and depth
/// rows of three to five u64 words (the walk's four-word seeks), viewed
/// along the long axis both ways and obliquely: the lean frame equals the
/// general path and the brute force, and the frames cover pixels.
#[test]
fn lean_frame_at_word_boundaries() {
    let mut covered = 0;
    let mut checked = 0;
    for nk in [2usize, 15, 16, 17, 31, 32, 33, 63, 64, 65, 129, 192, 256, 257] {
        let vol = random_volume([17, 13, nk], nk as u64 * 977, [1.0; 3]);
        let cams = [cam(0.0, 0.0, 0.0), cam(0.0, std::f64::consts::PI, 0.3), cam(0.35, -0.4, 0.1), cam(-0.2, 2.9, 0.5)];
        // every view looks along the long axis (z)
        for c in &cams {
            let f = Factorization::new(c, vol.dims(), vol.spacing()).unwrap();
            assert_eq!(f.axis, 2, "{nk} slices: a view across the long axis");
        }
        for (word, tissue, threads) in
            [(WordSize::U32, None, 1), (WordSize::U64, None, 2), (WordSize::U32, Some(1), 3), (WordSize::U64, Some(0), 1)]
        {
            for cell in [1, 3] {
                let s = Settings { word, cell, threads, ..Settings::default() };
                covered += check(&vol, tissue, s, &cams);
                checked += 1;
            }
        }
    }
    assert_eq!(checked, 112);
    assert!(covered > 10_000, "only {covered} covered pixels");
}

/// Depth rows of many words (up to 17 u64 words of two-bit codes, 33 of the
/// four presets' 4-bit codes, sheared a chunk of words at a time) with long
/// empty stretches before and between the blobs, seen along the long axis
/// both ways: the walk's four-word seeks (AVX2 level) give the general
/// path's and the brute force's image, for one iso value and each preset of
/// three and of four, u32 and u64 words, cell sizes 1 and 2, one and two threads.
#[test]
fn lean_frame_over_long_depth_rows() {
    let mut covered = 0;
    for (i, nk) in [140usize, 300, 520].into_iter().enumerate() {
        let vol = random_volume([13, 11, nk], 0x5eed + i as u64, [1.0; 3]);
        let cams = [cam(0.0, 0.0, 0.0), cam(0.0, std::f64::consts::PI, 0.2), cam(0.12, -0.15, 0.1), cam(-0.1, 3.0, 0.5)];
        for c in &cams {
            assert_eq!(Factorization::new(c, vol.dims(), vol.spacing()).unwrap().axis, 2);
        }
        let four = (0..4).map(|t| Some(FOUR + t));
        for tissue in [None, Some(0), Some(1), Some(2)].into_iter().chain(four) {
            for (word, cell, threads) in [(WordSize::U64, 1, 1), (WordSize::U64, 2, 2), (WordSize::U32, 1, 2)] {
                covered += check(&vol, tissue, Settings { word, cell, threads, ..Settings::default() }, &cams);
            }
        }
    }
    assert!(covered > 5_000, "only {covered} covered pixels");
}

/// Without prefetches (`Settings::prefetch` off: every visit's hint names the
/// line it reads) the lean frame is the same frame: it equals the general
/// path and the brute force, for one iso value and a preset, cell sizes 1
/// and 3, u32 and u64 words.
#[test]
fn lean_frame_without_prefetches() {
    let vol = random_volume([19, 17, 70], 3131, [1.0; 3]);
    let cams = [cam(0.0, 0.0, 0.0), cam(0.35, -0.4, 0.1), cam(-0.2, 2.9, 0.5)];
    let mut covered = 0;
    for (word, tissue) in [(WordSize::U32, None), (WordSize::U64, Some(1))] {
        for cell in [1, 3] {
            covered += check(&vol, tissue, Settings { word, cell, threads: 2, prefetch: false, ..Settings::default() }, &cams);
        }
    }
    assert!(covered > 1_000, "only {covered} covered pixels");
}

/// Frames the lean path does not cover keep the general path: Deluxe I,
/// gradient shading, blend mode, the paper's byte-table search, perspective
/// (the same image either way; asserted through the frame statistics).
#[test]
fn frames_outside_the_lean_case_take_the_general_path() {
    use shearwarp::encode::depth::Search;
    use shearwarp::render::{Deluxe, Normals};
    use shearwarp::view::Projection;
    let vol = random_volume([20, 18, 22], 7, [1.0; 3]);
    let tf = TransferFunction::threshold(90.0, [0.9, 0.8, 0.7]);
    let c = cam(0.3, 0.2, 0.1);
    let base = Settings { mode: Mode::Iso, method: Method::Binary, ..Settings::default() };
    let mut r = Renderer::new(vol.clone(), &tf, base).unwrap();
    let mut img = Image::new(48, 44);
    assert!(r.render(&c, &mut img).unwrap().lean);
    for s in [
        Settings { deluxe: Deluxe { intermediate: true, ..Deluxe::STANDARD }, ..base },
        Settings { normals: Normals::Gradient, ..base },
        Settings { mode: Mode::Blend, ..base },
        Settings { search: Search::Lut, ..base },
    ] {
        let mut r = Renderer::new(vol.clone(), &tf, s).unwrap();
        assert!(!r.render(&c, &mut img).unwrap().lean, "{s:?}");
    }
    r.set_projection(Projection::Perspective { fov_deg: 40.0, eye_distance: 2.0 }).unwrap();
    assert!(!r.render(&c, &mut img).unwrap().lean, "perspective");
}

pub(crate) fn cases(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}
