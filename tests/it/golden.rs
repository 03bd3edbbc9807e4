//! Golden images: every method × mode × standard view, on the built-in phantoms
//! and on a small crop of each shared scan, hashed bit for bit and compared with
//! the hashes in `tests/golden/hashes.txt`.
//!
//! The hashes were recorded before the frame-plan redesign; any refactor of the
//! traversals, the factorization or the warp must leave them unchanged. A change
//! that alters images on purpose re-records them with
//! `SHEARWARP_BLESS=1 cargo test --release --test it golden::` and names each changed
//! case in its commit message.
//!
//! Views are given as explicit object-to-eye rotations of the voxel index axes
//! (not as named anatomical views), so metadata such as patient orientation does
//! not enter: these images pin the renderer, not the loaders.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::{DMat3, DVec3};
use shearwarp::classify::TransferFunction;
use shearwarp::data::volume::{Volume, VoxelData};
use shearwarp::render::{Method, Normals, Renderer, Settings, WordSize};
use shearwarp::view::{Camera, rotate_eye};
use shearwarp::warp::Image;

const SIZE: usize = 40;

fn hashes_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden/hashes.txt")
}

/// FNV-1a over the image's f32 bit patterns (and its size).
fn hash(img: &Image) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    let mut eat = |b: u8| {
        h ^= b as u64;
        h = h.wrapping_mul(0x100_0000_01b3);
    };
    for b in (img.width as u32).to_le_bytes().into_iter().chain((img.height as u32).to_le_bytes()) {
        eat(b);
    }
    for px in &img.data {
        for c in px {
            for b in c.to_bits().to_le_bytes() {
                eat(b);
            }
        }
    }
    h
}

/// The views: index +y toward the viewer, index +z up (what the "anterior"
/// view of a RAS volume is), turned about the vertical by 0°, 22.5°, 44.9°,
/// 45°, 45.1° and 60°; from above; the main diagonal; and two fixed obliques.
fn views() -> Vec<(String, DMat3)> {
    let front = shearwarp::NamedView::Anterior.rotation();
    let mut v: Vec<(String, DMat3)> =
        [0.0, 22.5, 44.9, 45.0, 45.1, 60.0].iter().map(|&a| (format!("y{a}"), rotate_eye(front, 1, a))).collect();
    v.push(("top".into(), rotate_eye(front, 0, 90.0)));
    let z = DVec3::ONE.normalize();
    let y = (DVec3::Z - z * z.z).normalize();
    v.push(("diagonal".into(), DMat3::from_cols(y.cross(z), y, z).transpose()));
    v.push(("oblique-a".into(), DMat3::from_euler(glam::EulerRot::XYZ, 0.7, -1.1, 0.4)));
    v.push(("oblique-b".into(), DMat3::from_euler(glam::EulerRot::XYZ, -2.2, 0.35, 2.9)));
    v
}

/// A centred crop of at most `max` voxels per axis, in the volume's own type.
fn crop(v: &Volume, max: [usize; 3]) -> Volume {
    let d = v.dims();
    let n = [0, 1, 2].map(|a| d[a].min(max[a]));
    let o = [0, 1, 2].map(|a| (d[a] - n[a]) / 2);
    let idx = |x: usize, y: usize, z: usize| (o[0] + x) + d[0] * ((o[1] + y) + d[1] * (o[2] + z));
    fn take<T: Copy>(src: &[T], n: [usize; 3], idx: &dyn Fn(usize, usize, usize) -> usize) -> Vec<T> {
        let mut out = Vec::with_capacity(n[0] * n[1] * n[2]);
        for z in 0..n[2] {
            for y in 0..n[1] {
                for x in 0..n[0] {
                    out.push(src[idx(x, y, z)]);
                }
            }
        }
        out
    }
    let data = match v.data() {
        VoxelData::U8(s) => VoxelData::U8(take(s, n, &idx)),
        VoxelData::U16(s) => VoxelData::U16(take(s, n, &idx)),
        VoxelData::I16(s) => VoxelData::I16(take(s, n, &idx)),
        VoxelData::F32(s) => VoxelData::F32(take(s, n, &idx)),
    };
    Volume::new(n, v.spacing(), data).unwrap()
}

fn scenes() -> Vec<(String, Volume)> {
    use shearwarp::data::phantom::Phantom;
    let mut s = vec![
        ("head".to_string(), Phantom::Head.build([40, 44, 36]).unwrap()),
        ("sphere".to_string(), Phantom::Sphere.build([24, 28, 20]).unwrap()),
        ("ml".to_string(), Phantom::MarschnerLobb.build([25, 25, 25]).unwrap()),
    ];
    if let Some(dir) = std::env::var_os("SHEARWARP_DATA") {
        let dir = PathBuf::from(dir);
        for (name, file, max) in [
            ("brainsmall", "brainsmall.den", [40, 40, 30]),
            ("chest", "chest-ct-lung1.nrrd", [48, 48, 20]),
            ("colin", "head-mri-ch2.nii.gz", [40, 40, 40]),
            ("dicom", "dicom-brain-pd", [40, 40, 20]),
        ] {
            let p = dir.join(file);
            if p.exists() {
                let v = shearwarp::data::io::load(&p, &Default::default()).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
                s.push((name.to_string(), crop(&v, max)));
            }
        }
    }
    s
}

/// The settings variants: every method in both modes, plus the binary path's
/// knobs that change which code runs (cell size, word, search, shading).
fn variants() -> Vec<(String, Settings)> {
    use shearwarp::composite::Mode;
    use shearwarp::encode::depth::Search;
    let base = Settings { threads: 2, ..Settings::default() };
    let mut v = vec![];
    for mode in [Mode::Iso, Mode::Blend] {
        for method in [Method::Binary, Method::Brute, Method::Rle, Method::BruteRle] {
            v.push((format!("{}-{}", method.name(), mode.name()), Settings { method, mode, ..base }));
        }
        let b = Settings { mode, ..base };
        v.push((format!("binary-{}-cell2", mode.name()), Settings { cell: 2, ..b }));
        v.push((format!("binary-{}-u32-lut", mode.name()), Settings { word: WordSize::U32, search: Search::Lut, ..b }));
        v.push((format!("binary-{}-gradient", mode.name()), Settings { normals: Normals::Gradient, ..b }));
        v.push((format!("binary-{}-unpacked", mode.name()), Settings { pack: false, ..b }));
        v.push((format!("rle-{}-ert1", mode.name()), Settings { method: Method::Rle, ert: 1.0, ..b }));
    }
    v
}

/// Every golden image of the suite: key → hash.
fn render_all() -> BTreeMap<String, u64> {
    let mut out = BTreeMap::new();
    let views = views();
    for (sname, vol) in scenes() {
        let tissues = shearwarp::classify::presets::tissues_for(&vol);
        let (lo, hi) = vol.value_range();
        let iso = lo + 0.4 * (hi - lo);
        for (vname, s) in variants() {
            // the tissue presets (the CLI's default classification), and one custom transfer function
            let mut classes: Vec<(String, Renderer)> = vec![];
            let r = Renderer::with_tissues(vol.clone(), &tissues, s).unwrap();
            classes.push(("tissue0".into(), r));
            let mut r = Renderer::with_tissues(vol.clone(), &tissues, s).unwrap();
            r.select_tissue(tissues.len() - 1).unwrap();
            classes.push(("tissue-last".into(), r));
            let tf = TransferFunction::ramp(iso, iso + 0.2 * (hi - lo), 0.6, [0.9, 0.8, 0.7]);
            let mut r = Renderer::new(vol.clone(), &tf, s).unwrap();
            r.set_iso(iso).unwrap();
            if s.mode == shearwarp::composite::Mode::Blend {
                r.set_transfer_function(&tf);
            }
            classes.push(("custom".into(), r));
            for (cname, mut r) in classes {
                for (view, rotation) in &views {
                    let cam = Camera::new(*rotation, [SIZE, SIZE]);
                    let mut img = Image::new(SIZE, SIZE);
                    r.render(&cam, &mut img).unwrap();
                    out.insert(format!("{sname} {vname} {cname} {view}"), hash(&img));
                }
            }
            // zoomed in, off the fit-to-window zoom
            let mut r = Renderer::with_tissues(vol.clone(), &tissues, s).unwrap();
            let cam = Camera { zoom: Some(3.0), ..Camera::new(views[2].1, [SIZE, SIZE]) };
            let mut img = Image::new(SIZE, SIZE);
            r.render(&cam, &mut img).unwrap();
            out.insert(format!("{sname} {vname} tissue0 zoom3"), hash(&img));
        }
    }
    out
}

fn read_hashes() -> BTreeMap<String, u64> {
    let text = std::fs::read_to_string(hashes_path()).unwrap_or_default();
    text.lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .map(|l| {
            let (k, h) = l.rsplit_once(' ').expect("a line is 'key hash'");
            (k.to_string(), u64::from_str_radix(h, 16).expect("hex hash"))
        })
        .collect()
}

#[test]
fn golden_images_are_unchanged() {
    let got = render_all();
    if std::env::var_os("SHEARWARP_BLESS").is_some() {
        let mut text = String::from("# golden image hashes (tests/golden.rs): scene variant classification view fnv1a64\n");
        // keep recorded scans whose data is absent here
        let mut all = read_hashes();
        all.extend(got.iter().map(|(k, v)| (k.clone(), *v)));
        for (k, h) in &all {
            text.push_str(&format!("{k} {h:016x}\n"));
        }
        std::fs::create_dir_all(hashes_path().parent().unwrap()).unwrap();
        std::fs::write(hashes_path(), text).unwrap();
        eprintln!("blessed {} golden hashes", all.len());
        return;
    }
    let want = read_hashes();
    assert!(!want.is_empty(), "no golden hashes recorded in {}", hashes_path().display());
    let mut bad = vec![];
    let mut missing = 0;
    for (k, h) in &want {
        match got.get(k) {
            Some(g) if g == h => {}
            Some(g) => bad.push(format!("{k}: want {h:016x}, got {g:016x}")),
            None => missing += 1,
        }
    }
    let new: Vec<&String> = got.keys().filter(|k| !want.contains_key(*k)).collect();
    assert!(new.is_empty(), "{} images have no recorded hash (bless them): {:?}", new.len(), &new[..new.len().min(5)]);
    if missing > 0 {
        eprintln!("{missing} recorded golden images not rendered here (SHEARWARP_DATA not set?)");
    }
    assert!(bad.is_empty(), "{} of {} golden images changed:\n{}", bad.len(), want.len(), bad.join("\n"));
    // the scans' crops are part of the suite wherever the data is
    if std::env::var_os("SHEARWARP_DATA").is_some() {
        assert_eq!(missing, 0, "SHEARWARP_DATA is set but some scans' golden images were not rendered");
    }
}
