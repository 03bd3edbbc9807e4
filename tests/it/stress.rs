//! Numerical stability and extreme inputs.
//!
//! The normal suite runs short (but real) versions; the long ones are
//! `#[ignore]`d: `cargo test --release --test it stress:: -- --ignored --nocapture`.
//! Tests that compare against the reference print what they measured
//! (`--nocapture`), so the worst cases can be read off.

use glam::{DMat3, EulerRot};
use predicates::prelude::PredicateBooleanExt;
use shearwarp::Error;
use shearwarp::accuracy::metrics::{ImageError, compare, rmse};
use shearwarp::accuracy::reference::{ReferenceOptions, ReferenceRenderer, Scene};
use shearwarp::classify::TransferFunction;
use shearwarp::composite::Mode;
use shearwarp::data::phantom;
use shearwarp::data::slices::SliceStack;
use shearwarp::data::volume::{Volume, VoxelData, VoxelType};
use shearwarp::encode::depth::Search;
use shearwarp::encode::mask::{BinaryMask, CellCodes};
use shearwarp::render::{Method, Renderer, Settings, WordSize};
use shearwarp::view::NamedView;
use shearwarp::view::shear::ShearState;
use shearwarp::view::{Camera, rotate_eye};
use shearwarp::view::{diagonal_view, standard_views};
use shearwarp::warp::Image;

/// Blobs and sparse noise in `[0, ~250]`, with empty space inside.
fn random_volume(dims: [usize; 3], seed: u64, spacing: [f32; 3]) -> Volume {
    let mut s = seed | 1;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    let m = dims.iter().copied().max().unwrap() as f32;
    let blobs: Vec<([f32; 3], f32)> = (0..4)
        .map(|_| ([0, 1, 2].map(|a| (next() % 1000) as f32 / 1000.0 * dims[a] as f32), 1.5 + (next() % 1000) as f32 / 1000.0 * m * 0.4))
        .collect();
    let mut data = vec![0f32; dims[0] * dims[1] * dims[2]];
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                let mut v = 0f32;
                for (c, r) in &blobs {
                    let d = ((x as f32 - c[0]).powi(2) + (y as f32 - c[1]).powi(2) + (z as f32 - c[2]).powi(2)).sqrt();
                    v = v.max((220.0 * (1.0 - d / r)).max(0.0));
                }
                if (x * 31 + y * 17 + z * 7) % 23 == 0 {
                    v += 40.0;
                }
                data[x + dims[0] * (y + dims[1] * z)] = v;
            }
        }
    }
    Volume::new(dims, spacing, VoxelData::F32(data)).unwrap()
}

fn iso_tf() -> TransferFunction {
    TransferFunction::threshold(80.0, [0.9, 0.8, 0.7])
}

fn blend_tf() -> TransferFunction {
    TransferFunction::ramp(30.0, 200.0, 0.5, [0.6, 0.8, 1.0])
}

fn tf_for(mode: Mode) -> TransferFunction {
    if mode == Mode::Iso { iso_tf() } else { blend_tf() }
}

fn bits(img: &Image) -> Vec<u32> {
    img.data.iter().flatten().map(|x| x.to_bits()).collect()
}

/// Finite, premultiplied, alpha in [0, 1].
fn assert_sane(img: &Image, ctx: &str) {
    for (i, c) in img.data.iter().enumerate() {
        assert!(c.iter().all(|x| x.is_finite()), "{ctx}: pixel {i} is {c:?}");
        assert!(c[3] >= 0.0 && c[3] <= 1.0 + 1e-5, "{ctx}: pixel {i} alpha {}", c[3]);
        assert!(c[..3].iter().all(|&x| x >= 0.0), "{ctx}: pixel {i} is {c:?}");
    }
}

fn render(r: &mut Renderer, cam: &Camera) -> Image {
    let mut img = Image::new(cam.size[0], cam.size[1]);
    r.render(cam, &mut img).unwrap();
    img
}

/// Binary variants: cell 1–3, both words, both searches.
fn all_variants() -> Vec<(usize, WordSize, Search)> {
    let mut v = Vec::new();
    for cell in 1..=3 {
        for word in [WordSize::U32, WordSize::U64] {
            for search in [Search::Lut, Search::Bitscan] {
                v.push((cell, word, search));
            }
        }
    }
    v
}

/// A few binary variants (for volumes whose every renderer is expensive).
fn some_variants() -> Vec<(usize, WordSize, Search)> {
    vec![(1, WordSize::U32, Search::Lut), (1, WordSize::U64, Search::Bitscan), (3, WordSize::U64, Search::Lut)]
}

/// Renders `cam` with brute force and every binary variant, asserts they are
/// bit-identical and sane, and returns the brute-force image and renderer.
fn render_all_equal(vol: &Volume, tf: &TransferFunction, mode: Mode, cam: &Camera, ctx: &str) -> (Image, Renderer) {
    render_equal(vol, tf, mode, cam, ctx, &all_variants())
}

fn render_equal(
    vol: &Volume,
    tf: &TransferFunction,
    mode: Mode,
    cam: &Camera,
    ctx: &str,
    variants: &[(usize, WordSize, Search)],
) -> (Image, Renderer) {
    let base = Settings { mode, threads: 2, ..Settings::default() };
    let mut brute = Renderer::new(vol.clone(), tf, Settings { method: Method::Brute, ..base }).unwrap();
    let bi = render(&mut brute, cam);
    assert_sane(&bi, ctx);
    for &(cell, word, search) in variants {
        let s = Settings { method: Method::Binary, cell, word, search, ..base };
        let mut r = Renderer::new(vol.clone(), tf, s).unwrap();
        let fi = render(&mut r, cam);
        assert!(bits(&fi) == bits(&bi), "{ctx}: binary c{cell} {} {} differs from brute force", word.name(), search.name());
    }
    (bi, brute)
}

/// What a fast image got wrong against the reference.
#[derive(Debug)]
struct Against {
    error: ImageError,
    /// Fraction of pixels whose coverage disagrees with the reference by more
    /// than half a voxel's diagonal (plus a pixel): see [`silhouette_beyond`].
    far_silhouette: f64,
}

/// The reference of what `r` renders (its last frame used `cam`), and the fast image's error against it.
fn against_reference(vol: &Volume, r: &Renderer, cam: &Camera, img: &Image) -> Against {
    let reference = ReferenceRenderer::new(vol).render(&Scene::from_renderer(r), cam, &ReferenceOptions::default()).unwrap();
    assert_sane(&reference.image, "reference");
    let max_sp = vol.spacing().iter().fold(0f32, |a, &b| a.max(b)) as f64;
    let px_per_voxel = r.last_factorization().unwrap().zoom * max_sp;
    Against {
        error: compare(img, &reference.image).unwrap(),
        far_silhouette: silhouette_beyond(img, &reference.image, std::f64::consts::FRAC_1_SQRT_2 * px_per_voxel + 1.0),
    }
}

/// Fraction of pixels whose coverage (alpha > 0.5) disagrees with `reference`
/// by more than `r` pixels: covered with no covered reference pixel within `r`,
/// or uncovered with no uncovered one. The fast paths cast one ray per voxel
/// and warp bilinearly, so a silhouette can sit up to about half a voxel away
/// from the reference's (whose rays see the exact box of voxel centres), a
/// little more at the corners of a single cell; at 27 pixels per voxel that is
/// 14 to 20 pixels. A few more pixels may differ: in blend mode alpha crosses
/// 0.5 inside translucent material too, and when an output pixel spans many
/// voxels both renderers point-sample sub-pixel features at slightly
/// different places; the tests allow 0.5 % of the pixels.
fn silhouette_beyond(img: &Image, reference: &Image, r: f64) -> f64 {
    let (w, h) = (img.width as isize, img.height as isize);
    let cov = |im: &Image, x: isize, y: isize| im.data[(y * w + x) as usize][3] > 0.5;
    let ri = r.ceil() as isize;
    let mut wrong = 0;
    for y in 0..h {
        for x in 0..w {
            let c = cov(img, x, y);
            if c == cov(reference, x, y) {
                continue;
            }
            let near = (-ri..=ri).any(|dy| {
                (-ri..=ri).any(|dx| {
                    let (xx, yy) = (x + dx, y + dy);
                    ((dx * dx + dy * dy) as f64) <= r * r && xx >= 0 && yy >= 0 && xx < w && yy < h && cov(reference, xx, yy) == c
                })
            });
            wrong += (!near) as usize;
        }
    }
    wrong as f64 / (w * h) as f64
}

// ---------------------------------------------------------------------------
// Shear drift
// ---------------------------------------------------------------------------

/// `steps` incremental shear steps in random directions, with occasional jumps
/// (direct shears) to random, partly fractional, translations; the mask is
/// compared with a direct shear of the same state every `steps / 10` steps and
/// at the end, for u32 and u64 words and cell sizes 1 and 3.
fn random_shear_walk(steps: usize) {
    let vol = random_volume([28, 24, 61], 3, [1.0; 3]);
    let st = SliceStack::new(&vol, 2);
    let codes = CellCodes::binary(&st, |_, hi| hi > 60.0);
    let nk = st.n[2];
    let lim = ((nk - 1) / 2) as f64;
    for cell in [1usize, 3] {
        for word64 in [false, true] {
            let mut seed = 0xC0FFEE_u64 ^ cell as u64 ^ ((word64 as u64) << 8);
            let mut rnd = move || {
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                seed >> 11
            };
            macro_rules! walk {
                ($w:ty) => {{
                    let mut m = BinaryMask::<$w>::from_codes(&codes, cell);
                    let mut state = ShearState::identity(nk);
                    let s = cell as f64;
                    let (mut incremental, mut jumps) = (0usize, 0usize);
                    for step in 0..steps {
                        if rnd() % 64 == 0 {
                            // any line of translations within ±lim − s, fractional end points included
                            let e = [0, 1].map(|_| [0, 1].map(|_| ((rnd() % 2001) as f64 / 1000.0 - 1.0) * (lim - s)));
                            state = ShearState::from_ends(nk, e);
                            m.shear_to(&state);
                            jumps += 1;
                        } else {
                            let along = (rnd() & 1) as usize;
                            let dir = if rnd() & 1 == 0 { 1 } else { -1 };
                            let [a, b] = state.ends[along];
                            if (a - dir as f64 * s).abs() > lim || (b + dir as f64 * s).abs() > lim {
                                continue;
                            }
                            state = m.rotate_step(&state, along, dir);
                            incremental += 1;
                        }
                        if step % (steps / 10).max(1) == 0 || step + 1 == steps {
                            let mut d = BinaryMask::<$w>::from_codes(&codes, cell);
                            d.shear_direct(&state);
                            assert!(m.words() == d.words(), "cell {cell}: drift after {step} steps");
                        }
                    }
                    assert!(incremental > steps / 2 && jumps > 0, "{incremental} incremental, {jumps} jumps");
                    // translations are the closed form of the end points: nothing accumulated
                    for a in 0..2 {
                        for k in 0..nk {
                            let l = (nk - 1) as f64;
                            let closed = (state.ends[a][0] * (l - k as f64) + state.ends[a][1] * k as f64) / l;
                            assert!((state.trans[a][k] - closed).abs() < 1e-9);
                        }
                    }
                }};
            }
            if word64 { walk!(u64) } else { walk!(u32) }
        }
    }
}

#[test]
fn hundred_thousand_random_shear_steps_match_a_direct_shear() {
    random_shear_walk(100_000);
}

#[test]
#[ignore = "long: a million steps per configuration"]
fn million_random_shear_steps_match_a_direct_shear() {
    random_shear_walk(1_000_000);
}

// ---------------------------------------------------------------------------
// Ties between principal axes
// ---------------------------------------------------------------------------

#[test]
fn exact_ties_render_and_match_brute_force() {
    let vol = random_volume([22, 22, 22], 17, [1.0; 3]);
    let base = NamedView::Anterior.rotation();
    let mut views: Vec<(String, DMat3)> = Vec::new();
    for eps in [0.0, 1e-12, -1e-12] {
        views.push((format!("45°{eps:+e} about y"), rotate_eye(base, 1, 45.0 + eps)));
        views.push((format!("45°{eps:+e} about x"), rotate_eye(base, 0, 45.0 + eps)));
        views.push((format!("-45°{eps:+e} about y"), rotate_eye(DMat3::IDENTITY, 1, -45.0 + eps)));
    }
    views.push(("main diagonal".into(), diagonal_view()));
    // the diagonal seen from the other side, and a diagonal of the x-y plane
    views.push(("opposite diagonal".into(), rotate_eye(diagonal_view(), 1, 180.0)));
    views.push(("x-y diagonal".into(), rotate_eye(rotate_eye(DMat3::IDENTITY, 0, -90.0), 1, 45.0)));
    let mut worst = (0.0, String::new());
    for (name, rot) in &views {
        for mode in [Mode::Iso, Mode::Blend] {
            let cam = Camera::new(*rot, [64, 64]);
            let ctx = format!("{name} {}", mode.name());
            let (img, r) = render_all_equal(&vol, &tf_for(mode), mode, &cam, &ctx);
            assert!(img.coverage() > 0.05, "{ctx}: nearly empty");
            let a = against_reference(&vol, &r, &cam, &img);
            if a.error.rmse > worst.0 {
                worst = (a.error.rmse, ctx.clone());
            }
            assert!(a.error.rmse < 0.08 && a.error.silhouette < 0.03 && a.far_silhouette == 0.0, "{ctx}: {a:?}");
        }
    }
    eprintln!("ties: worst RMSE vs reference {:.5} at {}", worst.0, worst.1);
}

// ---------------------------------------------------------------------------
// Degenerate and extreme volumes
// ---------------------------------------------------------------------------

fn extreme_views() -> Vec<(String, DMat3)> {
    let mut v: Vec<(String, DMat3)> = vec![
        ("identity".into(), DMat3::IDENTITY),
        ("30° about y".into(), rotate_eye(DMat3::IDENTITY, 1, 30.0)),
        ("60° about y".into(), rotate_eye(DMat3::IDENTITY, 1, 60.0)),
        ("90° about y".into(), rotate_eye(DMat3::IDENTITY, 1, 90.0)),
        ("45° about x".into(), rotate_eye(DMat3::IDENTITY, 0, 45.0)),
        ("90° about x".into(), rotate_eye(DMat3::IDENTITY, 0, 90.0)),
        ("diagonal".into(), diagonal_view()),
    ];
    v.push(("random".into(), standard_views(DMat3::IDENTITY, 1, 4)[7].rotation));
    v
}

/// Renders every view and mode (one renderer per variant for all views, as an
/// interactive session would); returns the worst RMSE against the reference
/// over the views where the reference is meaningful (no flat axis).
fn extreme_volume(name: &str, vol: &Volume, zoom: Option<f64>, size: usize) -> (f64, String) {
    let flat = vol.dims().contains(&1);
    let line = vol.dims().iter().filter(|&&n| n == 1).count() >= 2;
    let mut worst = (0.0, String::new());
    let mut any = false;
    let variants = if vol.len() > 100_000 { some_variants() } else { all_variants() };
    for mode in [Mode::Iso, Mode::Blend] {
        let tf = tf_for(mode);
        let base = Settings { mode, threads: 2, ..Settings::default() };
        let mut brute = Renderer::new(vol.clone(), &tf, Settings { method: Method::Brute, ..base }).unwrap();
        let mut fast: Vec<Renderer> = variants
            .iter()
            .map(|&(cell, word, search)| {
                Renderer::new(vol.clone(), &tf, Settings { method: Method::Binary, cell, word, search, ..base }).unwrap()
            })
            .collect();
        for (vname, rot) in extreme_views() {
            let cam = Camera { rotation: rot, zoom, size: [size, size] };
            let ctx = format!("{name} {vname} {}", mode.name());
            let img = render(&mut brute, &cam);
            assert_sane(&img, &ctx);
            for (r, (cell, word, search)) in fast.iter_mut().zip(&variants) {
                assert!(
                    bits(&render(r, &cam)) == bits(&img),
                    "{ctx}: binary c{cell} {} {} differs from brute force",
                    word.name(),
                    search.name()
                );
            }
            any |= img.coverage() > 0.0;
            if line {
                // a point or a line has no cell to interpolate: nothing is drawn
                assert_eq!(img.coverage(), 0.0, "{ctx}");
            }
            if !flat {
                let a = against_reference(vol, &brute, &cam, &img);
                assert!(a.far_silhouette <= 0.005, "{ctx}: {a:?}");
                if a.error.rmse > worst.0 {
                    worst = (a.error.rmse, format!("{ctx}: {:?}", a.error));
                }
            }
        }
    }
    if !line {
        assert!(any, "{name}: every view is empty");
    }
    worst
}

#[test]
fn degenerate_and_extreme_volumes_render() {
    let cases: Vec<(&str, Volume, Option<f64>)> = vec![
        ("1×1×1", Volume::new([1, 1, 1], [1.0; 3], VoxelData::F32(vec![150.0])).unwrap(), None),
        ("2×2×2", Volume::from_fn([2, 2, 2], [1.0; 3], |x, y, z| (x * 100 + y * 60 + z * 40) as f32).unwrap(), None),
        ("1×37×1", Volume::from_fn([1, 37, 1], [1.0; 3], |_, y, _| (y * 7) as f32).unwrap(), None),
        ("9×1×7", Volume::from_fn([9, 1, 7], [1.0; 3], |x, _, z| (x * 20 + z * 10) as f32).unwrap(), None),
        ("512×8×300", random_volume([512, 8, 300], 5, [1.0; 3]), None),
        // at the fitting zoom a 4096-long bar is thinner than a pixel: look at its middle
        ("4096×4×4", Volume::from_fn([4096, 4, 4], [1.0; 3], |x, y, z| ((x * 7 + y * 50 + z * 30) % 230) as f32).unwrap(), Some(3.0)),
    ];
    for (name, vol, zoom) in &cases {
        let t = std::time::Instant::now();
        let worst = extreme_volume(name, vol, *zoom, 48);
        eprintln!("{name}: worst RMSE vs reference {:.5} ({}) [{:.1} s]", worst.0, worst.1, t.elapsed().as_secs_f64());
    }
}

#[test]
fn a_too_elongated_volume_is_an_error_not_an_abort() {
    let vol = Volume::from_fn([16384, 4, 4], [1.0; 3], |x, _, _| (x % 200) as f32).unwrap();
    let mut r = Renderer::new(vol, &iso_tf(), Settings::default()).unwrap();
    // prepare skips the axis it cannot build
    r.prepare_all_axes();
    let mut img = Image::new(32, 32);
    let along_x = Camera::new(rotate_eye(DMat3::IDENTITY, 1, 90.0), [32, 32]);
    let e = r.render(&along_x, &mut img).unwrap_err();
    assert!(matches!(e, Error::BadValue { .. }) && e.to_string().contains("too elongated"), "{e}");
    // the other axes still render
    r.render(&Camera { zoom: Some(1.0), ..Camera::new(DMat3::IDENTITY, [32, 32]) }, &mut img).unwrap();
    assert!(img.coverage() > 0.0);
}

// ---------------------------------------------------------------------------
// Spacing and zoom
// ---------------------------------------------------------------------------

#[test]
fn tiny_and_huge_spacings_give_the_same_image() {
    for aniso in [[1.0f32, 1.0, 1.0], [1.0, 0.5, 2.0]] {
        let at = |s: f32| {
            let vol = random_volume([16, 18, 20], 8, aniso.map(|a| a * s));
            let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, 0.4, -0.7, 0.2), [64, 64]);
            (0..2)
                .map(|m| {
                    let mode = [Mode::Iso, Mode::Blend][m];
                    render_all_equal(&vol, &tf_for(mode), mode, &cam, &format!("spacing {s} × {aniso:?}")).0
                })
                .collect::<Vec<Image>>()
        };
        let one = at(1.0);
        for s in [1e-3f32, 1e3] {
            for (a, b) in at(s).iter().zip(&one) {
                let e = rmse(a, b).unwrap();
                assert!(e < 1e-4, "spacing {s} × {aniso:?}: RMSE {e} against spacing 1");
            }
        }
    }
}

#[test]
fn anisotropy_up_to_the_limit_renders() {
    let mut worst = (0.0, String::new());
    for sp in [[1.0f32, 1.0, 1e4], [1e-3, 1e-3, 10.0], [1e3, 0.1, 0.1], [1.0, 100.0, 0.01]] {
        let vol = random_volume([12, 14, 10], 21, sp);
        for (vname, rot) in extreme_views() {
            for mode in [Mode::Iso, Mode::Blend] {
                let cam = Camera::new(rot, [48, 48]);
                let ctx = format!("spacing {sp:?} {vname} {}", mode.name());
                let (img, r) = render_all_equal(&vol, &tf_for(mode), mode, &cam, &ctx);
                let a = against_reference(&vol, &r, &cam, &img);
                assert!(a.far_silhouette <= 0.005, "{ctx}: {a:?}");
                if a.error.rmse > worst.0 {
                    worst = (a.error.rmse, format!("{ctx}: {:?}", a.error));
                }
            }
        }
    }
    eprintln!("anisotropy: worst RMSE vs reference {:.5} ({})", worst.0, worst.1);
    // beyond the limit: a clear error
    let e = Volume::new([2, 2, 2], [1.0, 1.0, 1.0001e4], VoxelData::U8(vec![0; 8])).unwrap_err();
    assert!(e.to_string().contains("anisotropy"), "{e}");
}

#[test]
fn zoom_from_a_hundredth_to_a_hundred() {
    let vol = phantom::sphere([24, 24, 24]).unwrap();
    // grey, so that shading stays below the clamp at 1 and differences show
    let tf = |mode| {
        if mode == Mode::Iso { TransferFunction::threshold(100.0, [0.5; 3]) } else { TransferFunction::ramp(50.0, 200.0, 0.3, [0.5; 3]) }
    };
    let rot = DMat3::from_euler(EulerRot::XYZ, 0.3, 0.5, -0.1);
    let mut worst = (0.0, String::new());
    for zoom in [0.01, 0.1, 1.0, 10.0, 100.0] {
        for mode in [Mode::Iso, Mode::Blend] {
            let cam = Camera { rotation: rot, zoom: Some(zoom), size: [64, 64] };
            let ctx = format!("zoom {zoom} {}", mode.name());
            let (img, r) = render_all_equal(&vol, &tf(mode), mode, &cam, &ctx);
            if zoom >= 1.0 {
                assert!(img.coverage() > 0.05, "{ctx}: coverage {}", img.coverage());
            }
            let a = against_reference(&vol, &r, &cam, &img);
            eprintln!("{ctx}: {a:?}");
            if a.error.rmse > worst.0 {
                worst = (a.error.rmse, ctx.clone());
            }
            assert!(a.far_silhouette == 0.0, "{ctx}: {a:?}");
        }
    }
    eprintln!("zoom: worst RMSE vs reference {:.5} ({})", worst.0, worst.1);
}

// ---------------------------------------------------------------------------
// Transfer-function extremes
// ---------------------------------------------------------------------------

#[test]
fn all_transparent_and_all_opaque_transfer_functions() {
    let vol = random_volume([20, 17, 23], 4, [1.0, 1.2, 0.8]);
    let clear = TransferFunction::new(vec![(0.0, 0.0)], vec![(0.0, [1.0; 3])]).unwrap();
    let opaque = TransferFunction::new(vec![(0.0, 1.0)], vec![(0.0, [0.5, 0.6, 0.7])]).unwrap();
    for (vname, rot) in extreme_views() {
        for mode in [Mode::Iso, Mode::Blend] {
            let cam = Camera::new(rot, [48, 48]);
            let ctx = format!("{vname} {}", mode.name());
            let (img, r) = render_all_equal(&vol, &clear, mode, &cam, &format!("transparent {ctx}"));
            assert!(img.data.iter().all(|c| *c == [0.0; 4]), "transparent {ctx}: something drawn");
            let reference = ReferenceRenderer::new(&vol).render(&Scene::from_renderer(&r), &cam, &ReferenceOptions::default()).unwrap();
            assert!(reference.image.data.iter().all(|c| *c == [0.0; 4]));
            let (img, r) = render_all_equal(&vol, &opaque, mode, &cam, &format!("opaque {ctx}"));
            // every ray through the box is opaque: the image is the box's silhouette
            let covered = img.data.iter().filter(|c| c[3] > 0.5).count();
            assert!(covered > 100, "opaque {ctx}: {covered} pixels");
            let a = against_reference(&vol, &r, &cam, &img);
            assert!(a.far_silhouette == 0.0, "opaque {ctx}: {a:?}");
        }
    }
}

// ---------------------------------------------------------------------------
// Non-finite voxels
// ---------------------------------------------------------------------------

#[test]
fn non_finite_voxels_are_rejected_at_construction() {
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut v = vec![1.0f32; 27];
        v[13] = bad;
        let e = Volume::new([3, 3, 3], [1.0; 3], VoxelData::F32(v)).unwrap_err();
        assert!(matches!(e, Error::NonFinite { index: 13, .. }), "{e}");
        let e = Volume::from_fn([3, 3, 3], [1.0; 3], |x, y, z| if (x, y, z) == (2, 1, 0) { bad } else { 0.0 }).unwrap_err();
        assert!(matches!(e, Error::NonFinite { index: 5, .. }), "{e}");
    }
}

#[test]
fn non_finite_voxels_are_rejected_by_the_raw_loader() {
    let dir = tempfile::tempdir().unwrap();
    for (i, (bad, big)) in [(f32::NAN, false), (f32::INFINITY, true), (f32::NEG_INFINITY, false)].into_iter().enumerate() {
        let mut v = [10.0f32; 4 * 3 * 2];
        v[7] = bad;
        let bytes: Vec<u8> = v.iter().flat_map(|x| if big { x.to_be_bytes() } else { x.to_le_bytes() }).collect();
        let path = dir.path().join(format!("bad{i}.raw"));
        std::fs::write(&path, bytes).unwrap();
        let e = load_raw(&path, [4, 3, 2], VoxelType::F32, big).unwrap_err();
        let ours = &e;
        // Volume::new says NonFinite; the loaders re-wrap it as a File error naming the file
        match ours {
            Error::NonFinite { index: 7, .. } => {}
            Error::File { path: p, why } => assert!(p == &path && why.contains("voxel 7 is") && why.contains("rejected"), "{ours}"),
            other => panic!("unexpected error {other}"),
        }
        assert!(format!("{e:#}").contains(&path.display().to_string()), "{e:#}");
        // the same file through the command line (--raw, and the positional FILE):
        // a usage error (exit 2) naming the voxel, and no output
        let out = dir.path().join("out.png");
        for positional in [false, true] {
            let mut cmd = assert_cmd::Command::cargo_bin("shearwarp").unwrap();
            cmd.arg("render");
            if positional {
                cmd.arg(&path).args(["--format", "raw"]);
            } else {
                cmd.arg("--raw").arg(&path);
            }
            cmd.args(["--dims", "4,3,2", "--type", "f32", "--size", "16", "-o"])
                .arg(&out)
                .args(if big { vec!["--big-endian"] } else { vec![] })
                .assert()
                .code(2)
                .stderr(predicates::str::contains("voxel 7 is").and(predicates::str::contains("rejected")));
            assert!(!out.exists());
        }
    }
    // finite data in the same layout loads
    let v: Vec<u8> = (0..24).flat_map(|i| (i as f32).to_le_bytes()).collect();
    let path = dir.path().join("good.raw");
    std::fs::write(&path, v).unwrap();
    assert_eq!(load_raw(&path, [4, 3, 2], VoxelType::F32, false).unwrap().get(3, 2, 1), 23.0);
}

// ---------------------------------------------------------------------------
// Long rotation sequences
// ---------------------------------------------------------------------------

/// `n` increments of `deg / n` about each eye axis, composed one by one, against
/// the closed-form rotation by `deg`: matrices and renders.
fn composed_increments(n: usize) {
    let vol = random_volume([26, 22, 30], 12, [1.0, 1.0, 1.3]);
    let base = DMat3::from_euler(EulerRot::XYZ, 0.2, -0.4, 0.1);
    let total = 123.456;
    for axis in 0..3 {
        let step = total / n as f64;
        let mut r = base;
        for _ in 0..n {
            r = rotate_eye(r, axis, step);
        }
        let closed = rotate_eye(base, axis, total);
        let diff =
            (0..3).flat_map(|c| (0..3).map(move |k| (c, k))).map(|(c, k)| (r.col(c)[k] - closed.col(c)[k]).abs()).fold(0.0, f64::max);
        let ortho = (r * r.transpose() - DMat3::IDENTITY).to_cols_array().iter().fold(0.0f64, |a, &b| a.max(b.abs()));
        assert!(diff < 1e-9, "axis {axis}: composed rotation is {diff} off the closed form");
        assert!(ortho < 1e-9, "axis {axis}: composed rotation lost orthonormality by {ortho}");
        for mode in [Mode::Iso, Mode::Blend] {
            let mut rr = Renderer::new(vol.clone(), &tf_for(mode), Settings { mode, ..Settings::default() }).unwrap();
            let a = render(&mut rr, &Camera::new(r, [80, 80]));
            let b = render(&mut rr, &Camera::new(closed, [80, 80]));
            let e = compare(&a, &b).unwrap();
            eprintln!(
                "{n} increments about axis {axis} ({}): matrix off by {diff:.2e}, orthonormality {ortho:.2e}, images {e:?}",
                mode.name()
            );
            assert!(e.rmse < 1e-4 && e.silhouette == 0.0, "axis {axis} {}: {e:?}", mode.name());
        }
    }
}

#[test]
fn a_million_small_increments_match_the_closed_form_rotation() {
    composed_increments(1_000_000);
}

#[test]
#[ignore = "long: ten million increments per axis"]
fn ten_million_small_increments_match_the_closed_form_rotation() {
    composed_increments(10_000_000);
}

// ---------------------------------------------------------------------------
// History independence
// ---------------------------------------------------------------------------

/// A frame depends on its camera and settings only, not on the frames before
/// it (the blend classifier's spacing correction used to keep a trace of the
/// previous views' ratios).
#[test]
fn a_frame_does_not_depend_on_the_frames_before_it() {
    let vol = random_volume([24, 20, 26], 31, [1.0, 1.0, 1.5]);
    let views = standard_views(NamedView::Anterior.rotation(), 3, 9);
    for mode in [Mode::Iso, Mode::Blend] {
        for method in [Method::Binary, Method::Brute] {
            let s = Settings { mode, method, ..Settings::default() };
            let mut walker = Renderer::new(vol.clone(), &tf_for(mode), s).unwrap();
            for v in views.iter().rev() {
                render(&mut walker, &Camera::new(v.rotation, [64, 64]));
            }
            for v in &views {
                let cam = Camera::new(v.rotation, [64, 64]);
                let mut fresh = Renderer::new(vol.clone(), &tf_for(mode), s).unwrap();
                let a = render(&mut fresh, &cam);
                let b = render(&mut walker, &cam);
                assert!(bits(&a) == bits(&b), "{} {} {}: the frame depends on history", mode.name(), method.name(), v.name);
            }
        }
    }
}

/// Reads a headerless voxel file of exactly `dims` voxels of type `t`.
fn load_raw(path: &std::path::Path, dims: [usize; 3], t: VoxelType, big_endian: bool) -> shearwarp::Result<shearwarp::Volume> {
    use shearwarp::data::io;
    let mut spec = io::RawSpec::new(dims, t);
    spec.big_endian = big_endian;
    io::load(path, &io::LoadOptions { format: Some(io::Format::Raw), raw: Some(spec) })
}
