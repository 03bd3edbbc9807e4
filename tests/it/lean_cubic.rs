//! The lean cubic iso frame ([`shearwarp::composite::lean_cubic`], the
//! cubic's first crossing shaded by its gradient) and the lean frame with the
//! cubic crossing ([`shearwarp::composite::raycast::RayContext::with_cubic_crossing`],
//! the cubic's normal codes) each render exactly the general ray loop's and
//! the brute force's intermediate image, depths and final image under the
//! cubic reconstruction, bit for bit: over
//! random volumes (f32, 8- and 16-bit), spacings that put the volume's z
//! along the slices or in them, views, cell sizes, one transfer function or
//! the tissue presets' threshold codes, u32 and u64 words, slice counts
//! below and above one word, and 1, 2 or 3 threads. The frames are compared
//! by the lean binary frame's check ([`crate::lean_frame::check`]), with the
//! cubic reconstruction in the settings.

use proptest::prelude::*;
use shearwarp::kernels::Reconstruction;
use shearwarp::render::{Normals, Settings, WordSize};
use shearwarp::view::Camera;

use crate::common::{random_volume, typed};
use crate::lean_frame::{cam, cases, check};

/// The settings of a cubic frame: its first crossing shaded by its gradient
/// (`codes` false), or the linear frame's hit at the cubic's crossing shaded
/// by the cubic's normal codes.
fn cubic(s: Settings, codes: bool) -> Settings {
    Settings { reconstruction: Reconstruction::Cubic, normals: if codes { Normals::Codes } else { Normals::Gradient }, ..s }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases(32)))]

    /// The lean cubic frame equals the general path and the brute force bit
    /// for bit over random volumes, spacings, views (a rotation sequence
    /// crossing axes and directions), cell sizes, tissue codes or one iso
    /// value, voxel types, word sizes and thread counts.
    #[test]
    fn lean_cubic_frame_equals_general_and_brute_force(
        nx in 3usize..24, ny in 3usize..24, nz in 3usize..24, long in 0usize..3, nlong in 3usize..100,
        seed in any::<u64>(), ty in 0u8..3, cell in 1usize..=8, u32w in any::<bool>(), threads in 1usize..=3,
        tissue in prop::option::of(0usize..3), rx in -3.2f64..3.2, ry in -3.2f64..3.2, step in -1.2f64..1.2,
        spacing in prop::sample::select(vec![[1.0f32, 1.0, 1.0], [1.0, 1.0, 3.0], [0.6, 0.6, 5.0], [3.0, 1.0, 1.0], [1.0, 2.5, 0.7]]),
        codes in any::<bool>(),
    ) {
        let mut dims = [nx, ny, nz];
        dims[long] = nlong;
        let vol = typed(&random_volume(dims, seed, spacing), ty);
        let s = cubic(Settings { word: if u32w { WordSize::U32 } else { WordSize::U64 }, cell, threads, ..Settings::default() }, codes);
        let cams: Vec<Camera> = (0..4).map(|f| cam(rx + f as f64 * step, ry - f as f64 * 0.3 * step, 0.2)).collect();
        check(&vol, tissue, s, &cams);
    }
}

/// Slice counts at and around one word (u32 and u64), the volume's z along
/// the slices (views along z, both ways and obliquely) and in them (views
/// across): the lean cubic frame equals the general path and the brute
/// force, and the frames cover pixels.
#[test]
fn lean_cubic_frame_at_word_boundaries() {
    let mut covered = 0;
    let mut checked = 0;
    for nk in [3usize, 31, 32, 33, 63, 64, 65] {
        let vol = random_volume([17, 13, nk], nk as u64 * 977, [1.0, 1.0, 2.0]);
        let cams = [cam(0.0, 0.0, 0.0), cam(0.0, std::f64::consts::PI, 0.3), cam(0.35, -0.4, 0.1), cam(1.4, 0.2, 0.1), cam(0.1, -1.5, 0.4)];
        for (word, tissue, threads) in [(WordSize::U32, None, 1), (WordSize::U64, Some(1), 2)] {
            for cell in [1, 3] {
                for codes in [false, true] {
                    covered += check(&vol, tissue, cubic(Settings { word, cell, threads, ..Settings::default() }, codes), &cams);
                    checked += 1;
                }
            }
        }
    }
    assert_eq!(checked, 56);
    assert!(covered > 5_000, "only {covered} covered pixels");
}

/// Views whose principal axis is a tie (45° and its odd multiples about each
/// eye axis from the superior view: one voxel a slice): the lean cubic frame
/// walks them and equals the general path and the brute force, the volume's
/// z along the slices or in them, isotropic and with thick slices.
#[test]
fn lean_cubic_frame_at_one_voxel_a_slice() {
    use shearwarp::view::{NamedView, rotate_eye};
    let mut covered = 0;
    for spacing in [[1.0f32, 1.0, 1.0], [1.0, 1.0, 3.0]] {
        let vol = random_volume([21, 19, 23], 4242, spacing);
        let cams: Vec<Camera> = [(0usize, 45.0f64), (0, 135.0), (1, 45.0), (1, 135.0), (1, 225.0), (1, 315.0)]
            .into_iter()
            .map(|(axis, deg)| Camera::new(rotate_eye(NamedView::Superior.rotation(), axis, deg), [48, 44]))
            .collect();
        for codes in [false, true] {
            covered += check(&vol, None, cubic(Settings { threads: 2, ..Settings::default() }, codes), &cams);
        }
    }
    assert!(covered > 1_000, "only {covered} covered pixels");
}

/// Without prefetches (`Settings::prefetch` off) the lean cubic frame is the
/// same frame: it equals the general path and the brute force, the cubic
/// along the slices and in them.
#[test]
fn lean_cubic_frame_without_prefetches() {
    let mut covered = 0;
    for spacing in [[1.0f32, 1.0, 1.0], [1.0, 1.0, 3.0], [3.0, 1.0, 1.0]] {
        let vol = random_volume([19, 17, 21], 7171, spacing);
        let cams = [cam(0.0, 0.0, 0.0), cam(0.35, -0.4, 0.1), cam(1.4, 0.2, 0.1)];
        for codes in [false, true] {
            covered += check(&vol, None, cubic(Settings { prefetch: false, threads: 2, ..Settings::default() }, codes), &cams);
        }
    }
    assert!(covered > 400, "only {covered} covered pixels");
}
