//! A volume split into bricks, each rendered by its own renderer and the
//! partial images composited sort-last ([`shearwarp::bricks`]), gives one
//! renderer's image: iso frames bit for bit, blended frames within 1/255
//! per channel and the same on every run, over random volumes (f32, 8- and
//! 16-bit), views (every principal axis, both directions), cell sizes,
//! tissue codes and 1 to 4 bricks.

use glam::{DMat3, EulerRot};
use proptest::prelude::*;
use shearwarp::bricks::render_split;
use shearwarp::classify::presets::Tissue;
use shearwarp::composite::Mode;
use shearwarp::data::volume::{Volume, VoxelData};
use shearwarp::render::{Method, Renderer, Settings};
use shearwarp::view::Camera;
use shearwarp::warp::Image8;

use crate::common::{random_volume, typed};

/// Case count: `PROPTEST_CASES` when set (for long soak runs), else `default`.
fn cases(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

fn tissues(scale: f32) -> Vec<Tissue> {
    crate::common::three_tissues(scale, scale, [0.3, 0.8])
}

/// One renderer's image and the image of `n` bricks, for `vol` under `cam`.
fn both(vol: &Volume, tissue: usize, s: Settings, cam: &Camera, n: usize) -> (Image8, Image8) {
    let scale = if matches!(vol.data(), VoxelData::U16(_)) { 7.0 } else { 1.0 };
    let ts = tissues(scale);
    let mut one = Renderer::with_tissues(vol.clone(), &ts, s).unwrap();
    one.select_tissue(tissue).unwrap();
    let mut a = Image8::new(cam.size[0], cam.size[1]);
    one.render(cam, &mut a).unwrap();
    let mut b = Image8::new(cam.size[0], cam.size[1]);
    render_split(vol, &ts, tissue, s, cam, n, &mut b).unwrap();
    (a, b)
}

fn cam(rx: f64, ry: f64, rz: f64) -> Camera {
    Camera::new(DMat3::from_euler(EulerRot::XYZ, rx, ry, rz), [56, 52])
}

fn covered(img: &Image8) -> usize {
    img.data.iter().filter(|px| px[3] > 0).count()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases(40)))]

    /// Iso frames of 1–4 bricks equal one renderer's bit for bit.
    #[test]
    fn iso_bricks_equal_one_renderer(
        nx in 6usize..30, ny in 6usize..30, nz in 6usize..30, seed in any::<u64>(), ty in 0u8..3,
        cell in 1usize..=4, tissue in 0usize..3, n in 1usize..=4, rlean in any::<bool>(),
        rx in -3.2f64..3.2, ry in -3.2f64..3.2, rz in -1.0f64..1.0,
    ) {
        let vol = typed(&random_volume([nx, ny, nz], seed, [1.0, 0.9, 1.2]), ty);
        let s = Settings { mode: Mode::Iso, method: if rlean { Method::Binary } else { Method::Brute }, cell, threads: 1, ..Settings::default() };
        let c = cam(rx, ry, rz);
        let (a, b) = both(&vol, tissue, s, &c, n);
        prop_assert!(a.data == b.data, "{n} bricks: the image differs in {} of {} pixels",
            a.data.iter().zip(&b.data).filter(|(x, y)| x != y).count(), a.data.len());
    }

    /// Blended frames (the RLE path and the raycast one) of 1–4 bricks are
    /// within 1/255 of one renderer's without early ray termination, and the
    /// same every run. With it (at 0.99) each image leaves out at most the
    /// last 1 % of a ray's opacity, one renderer where its sum reaches 0.99,
    /// a brick where its own does: within 1/255 + 1 % (4/255).
    #[test]
    fn blend_bricks_are_within_one_level(
        nx in 6usize..30, ny in 6usize..30, nz in 6usize..30, seed in any::<u64>(), ty in 0u8..3,
        tissue in 0usize..3, n in 1usize..=4, rle in any::<bool>(), ert in any::<bool>(),
        rx in -3.2f64..3.2, ry in -3.2f64..3.2, rz in -1.0f64..1.0,
    ) {
        let vol = typed(&random_volume([nx, ny, nz], seed, [1.0, 1.0, 1.1]), ty);
        let s = Settings {
            mode: Mode::Blend,
            method: if rle { Method::Rle } else { Method::Binary },
            ert: if ert { 0.99 } else { 1.0 },
            threads: 1,
            ..Settings::default()
        };
        let c = cam(rx, ry, rz);
        let (a, b) = both(&vol, tissue, s, &c, n);
        let worst = a.data.iter().zip(&b.data).flat_map(|(x, y)| (0..4).map(move |i| x[i].abs_diff(y[i]))).max().unwrap_or(0);
        let bound = if ert { 4 } else { 1 };
        prop_assert!(worst <= bound, "{n} bricks: a channel {worst}/255 off");
        let (_, again) = both(&vol, tissue, s, &c, n);
        prop_assert!(again.data == b.data, "two runs differ");
    }
}

/// Views along every axis, both directions, and the axis-aligned views
/// (no shear: rays along the bricks' faces), at every brick count 1–4 and a
/// larger count: iso bit for bit, the frames cover pixels.
#[test]
fn iso_bricks_at_axis_views_and_many_bricks() {
    use std::f64::consts::{FRAC_PI_2, PI};
    let vol = random_volume([33, 27, 41], 12345, [1.0; 3]);
    let s = Settings { mode: Mode::Iso, method: Method::Binary, cell: 2, ..Settings::default() };
    let mut px = 0;
    for c in [
        cam(0.0, 0.0, 0.0),
        cam(0.0, PI, 0.0),
        cam(FRAC_PI_2, 0.0, 0.0),
        cam(-FRAC_PI_2, 0.0, 0.0),
        cam(0.0, FRAC_PI_2, 0.0),
        cam(0.0, -FRAC_PI_2, 0.3),
        cam(0.4, 0.7, 0.1),
    ] {
        for n in [1, 2, 3, 4, 7] {
            let (a, b) = both(&vol, 1, s, &c, n);
            assert!(a.data == b.data, "{n} bricks differ");
            px += covered(&a);
        }
    }
    assert!(px > 5000, "only {px} covered pixels");
}

/// The whole volume's statistics merged from its bricks' owned voxels (and,
/// for f32 voxels, the presets' histogram summed) are the whole volume's:
/// the same value range and the same tissue presets, for every voxel type.
#[test]
fn bricks_agree_on_the_whole_volumes_statistics_and_presets() {
    use shearwarp::bricks::{preset_histogram_range, split};
    use shearwarp::classify::presets::tissues_for;
    for ty in 0..3 {
        let vol = typed(&random_volume([31, 26, 35], 77 + ty as u64, [1.0; 3]), ty);
        let want = tissues_for(&vol);
        for n in [2, 3, 4] {
            let (bricks, _) = split(vol.dims(), n).unwrap();
            // each brick holds its voxels only, with its own statistics
            let held: Vec<Volume> = bricks
                .iter()
                .map(|b| {
                    let e = b.extract(&vol).unwrap();
                    Volume::new(e.dims(), e.spacing(), e.data().clone()).unwrap()
                })
                .collect();
            let parts: Vec<_> = bricks.iter().zip(&held).map(|(b, h)| b.owned_stats(h).unwrap()).collect();
            let mut whole = parts[1..].iter().fold(parts[0].clone(), |a, b| a.merge(b));
            assert_eq!(vol.value_range(), (whole.lo, whole.hi));
            if let Some((bins, range)) = preset_histogram_range(&held[0], &whole) {
                let mut sum = vec![0u64; bins];
                for (b, h) in bricks.iter().zip(&held) {
                    sum.iter_mut().zip(b.owned_histogram(h, bins, range).unwrap()).for_each(|(s, x)| *s += x);
                }
                whole = whole.with_histogram(range[0], range[1], sum);
            }
            for h in &held {
                let got = tissues_for(&h.clone().with_stats(whole.clone()));
                let key = |t: &[Tissue]| t.iter().map(|t| (t.name, t.threshold)).collect::<Vec<_>>();
                assert_eq!(key(&got), key(&want), "type {ty}, {n} bricks");
            }
        }
    }
}

/// A compositor reused from frame to frame (clearing only the last frame's
/// rectangle) composites what a new one does, as the views change axis.
#[test]
fn a_reused_compositor_composites_what_a_new_one_does() {
    use shearwarp::bricks::{Compositor, Partial, split};
    let vol = random_volume([30, 26, 34], 99, [1.0; 3]);
    let ts = tissues(1.0);
    let s = Settings { mode: Mode::Iso, method: Method::Binary, ..Settings::default() };
    let (bricks, tree) = split(vol.dims(), 3).unwrap();
    let mut renderers: Vec<Renderer> = bricks.iter().map(|b| Renderer::with_tissues(b.extract(&vol).unwrap(), &ts, s).unwrap()).collect();
    let mut reused: Option<Compositor> = None;
    for c in [cam(0.2, 0.3, 0.0), cam(1.4, 0.1, 0.2), cam(0.1, -2.0, 0.0), cam(0.1, -2.05, 0.0)] {
        let parts: Vec<Partial> = bricks
            .iter()
            .zip(&mut renderers)
            .map(|(b, r)| {
                let f = r.render_brick(&c, &b.view(vol.dims())).unwrap();
                let grid = shearwarp::bricks::grid_of(&c, vol.dims(), vol.spacing(), &s).unwrap();
                Partial::of(r.intermediate(), f.rect, f.offset, grid).unwrap()
            })
            .collect();
        let mut fresh = Compositor::new(&c, vol.dims(), vol.spacing(), &tree, &s).unwrap();
        let comp = match &mut reused {
            Some(x) => {
                x.reset(&c, vol.dims(), vol.spacing(), &tree, &s).unwrap();
                x
            }
            None => reused.insert(Compositor::new(&c, vol.dims(), vol.spacing(), &tree, &s).unwrap()),
        };
        let (mut a, mut b) = (Image8::new(56, 52), Image8::new(56, 52));
        for i in fresh.order().to_vec() {
            fresh.add(&parts[i]);
            comp.add(&parts[i]);
        }
        fresh.finish(&c, &mut a);
        comp.finish(&c, &mut b);
        assert!(a.data == b.data && covered(&a) > 100);
    }
}

/// An NRRD whose voxels are `n` values below 200 stored as `ty` (`endian`
/// for multi-byte types), with the given extra header lines, before the
/// data: `pre` bytes (what a line or byte skip passes over). Returns the
/// header and the data bytes.
fn nrrd_parts(dims: [usize; 3], ty: &str, big: bool, extra: &str, pre: &[u8], seed: u64) -> (String, Vec<u8>) {
    let mut rng = crate::common::xorshift(seed);
    let n = dims[0] * dims[1] * dims[2];
    let mut data = pre.to_vec();
    for _ in 0..n {
        let v = (rng() % 200) as i64 - if ty == "signed char" { 100 } else { 0 };
        let b: Vec<u8> = match ty {
            "uchar" => vec![v as u8],
            "signed char" => vec![v as i8 as u8],
            "short" => {
                if big {
                    (v as i16).to_be_bytes().to_vec()
                } else {
                    (v as i16).to_le_bytes().to_vec()
                }
            }
            "uint" => {
                if big {
                    (v as u32).to_be_bytes().to_vec()
                } else {
                    (v as u32).to_le_bytes().to_vec()
                }
            }
            "double" => {
                if big {
                    (v as f64 * 0.5).to_be_bytes().to_vec()
                } else {
                    (v as f64 * 0.5).to_le_bytes().to_vec()
                }
            }
            _ => unreachable!(),
        };
        data.extend(b);
    }
    let endian = if big { "big" } else { "little" };
    let header =
        format!("NRRD0004\ntype: {ty}\ndimension: 3\nsizes: {} {} {}\nendian: {endian}\nencoding: raw\n{extra}", dims[0], dims[1], dims[2]);
    (header, data)
}

/// The voxels `[lo, hi)` of `v`, as f32.
fn box_of(v: &Volume, lo: [usize; 3], hi: [usize; 3]) -> Vec<f32> {
    let [nx, ny, _] = v.dims();
    let all = v.to_f32();
    let mut out = vec![];
    for z in lo[2]..hi[2] {
        for y in lo[1]..hi[1] {
            out.extend_from_slice(&all[(z * ny + y) * nx + lo[0]..(z * ny + y) * nx + hi[0]]);
        }
    }
    out
}

/// A test NRRD: its name, type, big endian, extra header lines, the bytes
/// before the data, and whether the header is detached.
type NrrdCase<'a> = (&'a str, &'a str, bool, &'a str, &'a [u8], bool);

#[test]
fn an_uncompressed_nrrd_is_read_box_by_box_as_it_loads() {
    use shearwarp::data::io::{LoadOptions, load, read_box, seekable_layout};
    let dir = tempfile::tempdir().unwrap();
    let dims = [13, 9, 11];
    let cases: [NrrdCase; 6] = [
        ("u8.nrrd", "uchar", false, "spacings: 1 1 2.5\n", b"", false),
        ("i16.nrrd", "short", true, "line skip: 1\nbyte skip: 3\n", b"skip me\nabc", false),
        ("f64.nhdr", "double", false, "space: left-posterior-superior\nspace directions: (0.7,0,0) (0,0.7,0) (0,0,3)\n", b"", true),
        // a mirrored frame: the loader reverses x, the box is read mirrored
        (
            "i8.nrrd",
            "signed char",
            false,
            "space: right-anterior-superior\nspace directions: (-1.5,0,0) (0,1,0) (0,0,2)\nspace origin: (10,20,30)\n",
            b"",
            false,
        ),
        ("u32.nhdr", "uint", true, "byte skip: -1\n", b"leading junk", true),
        ("u8-skip.nrrd", "uchar", false, "byte skip: -1\n", b"", false),
    ];
    for (i, (name, ty, big, extra, pre, detached)) in cases.into_iter().enumerate() {
        let (header, data) = nrrd_parts(dims, ty, big, extra, pre, 17 + i as u64);
        let path = dir.path().join(name);
        if detached {
            let data_name = format!("{name}.data");
            std::fs::write(dir.path().join(&data_name), &data).unwrap();
            std::fs::write(&path, format!("{header}data file: {data_name}\n\n")).unwrap();
        } else {
            std::fs::write(&path, [format!("{header}\n").into_bytes(), data].concat()).unwrap();
        }
        let whole = load(&path, &LoadOptions::default()).unwrap();
        let layout = seekable_layout(&path, &LoadOptions::default()).unwrap().unwrap_or_else(|| panic!("{name}: not seekable"));
        assert_eq!((layout.dims, layout.spacing), (whole.dims(), whole.spacing()), "{name}");
        assert_eq!(layout.frame.as_ref(), whole.frame(), "{name}");
        assert_eq!(layout.reversed_axis.is_some(), name.starts_with("i8"), "{name}");
        for (lo, hi) in [([0, 0, 0], dims), ([2, 3, 4], [7, 9, 10]), ([12, 0, 5], [13, 1, 6]), ([0, 4, 0], [6, 8, 11])] {
            let b = read_box(&layout, lo, hi).unwrap();
            assert_eq!(b.dims(), [0, 1, 2].map(|a| hi[a] - lo[a]), "{name}");
            assert_eq!(b.data().voxel_type(), whole.data().voxel_type(), "{name}");
            assert_eq!(b.to_f32(), box_of(&whole, lo, hi), "{name}: voxels {lo:?}..{hi:?}");
        }
    }
    // gzip data are read whole (by rank 0 in a distributed run)
    let (header, data) = nrrd_parts(dims, "uchar", false, "", b"", 3);
    let header = header.replace("encoding: raw", "encoding: gzip");
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    std::io::Write::write_all(&mut gz, &data).unwrap();
    let path = dir.path().join("gz.nrrd");
    std::fs::write(&path, [format!("{header}\n").into_bytes(), gz.finish().unwrap()].concat()).unwrap();
    assert!(load(&path, &LoadOptions::default()).is_ok());
    assert_eq!(seekable_layout(&path, &LoadOptions::default()).unwrap(), None);
}

#[test]
fn a_bad_or_truncated_nrrd_names_the_file() {
    use shearwarp::data::io::{LoadOptions, read_box, seekable_layout};
    let dir = tempfile::tempdir().unwrap();
    let dims = [8, 6, 5];
    let (header, data) = nrrd_parts(dims, "short", false, "", b"", 5);
    let write = |name: &str, bytes: Vec<u8>| {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    let opts = LoadOptions::default();
    let err = |p: &std::path::Path| seekable_layout(p, &opts).unwrap_err().to_string();
    // the data end early, or run on: the loader's own checks
    let short = write("short.nrrd", [format!("{header}\n").into_bytes(), data[..data.len() - 7].to_vec()].concat());
    let e = err(&short);
    assert!(e.contains("short.nrrd") && e.contains("truncated"), "{e}");
    let long = write("long.nrrd", [format!("{header}\n").into_bytes(), data.clone(), vec![0; 4]].concat());
    let e = err(&long);
    assert!(e.contains("long.nrrd") && e.contains("more than the header"), "{e}");
    // a header line that is no field, a missing data file
    let bad = write("bad.nrrd", format!("{header}this is not a field\n\n").into_bytes());
    let e = err(&bad);
    assert!(e.contains("bad.nrrd") && e.contains("neither a field nor a comment"), "{e}");
    let lost = write("lost.nhdr", format!("{header}data file: gone.raw\n\n").into_bytes());
    let e = err(&lost);
    assert!(e.contains("lost.nhdr") && e.contains("gone.raw"), "{e}");
    // a file cut after its layout was read: the box that reaches past the end fails, naming it
    let cut = write("cut.nrrd", [format!("{header}\n").into_bytes(), data.clone()].concat());
    let layout = seekable_layout(&cut, &opts).unwrap().unwrap();
    let bytes = std::fs::read(&cut).unwrap();
    std::fs::write(&cut, &bytes[..bytes.len() - 2 * 8 * 6]).unwrap();
    assert!(read_box(&layout, [0, 0, 0], [8, 6, 4]).is_ok());
    let e = read_box(&layout, [0, 0, 3], [8, 6, 5]).unwrap_err().to_string();
    assert!(e.contains("cut.nrrd") && e.contains("truncated"), "{e}");
}
