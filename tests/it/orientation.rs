//! Patient orientation end to end: one synthetic "head" with asymmetric
//! markers — a nose on the anterior side and a notch cut out of its upper left
//! — stored in many index layouts and formats (NRRD LPS/RAS/LAS, NIfTI sform
//! and qform, a DICOM series with a tilted ImageOrientationPatient). Each file
//! is loaded, rendered with the named views, and compared with the render of a
//! plain RAS copy: the same view gives the same picture in every case, the
//! markers where the anatomy says, never mirrored.

use std::path::Path;

use dicom_core::value::C;
use dicom_core::{DataElement, PrimitiveValue, VR};
use dicom_dictionary_std::{tags, uids};
use dicom_object::{FileMetaTableBuilder, InMemDicomObject};
use glam::{DMat3, DVec3};
use shearwarp::classify::TransferFunction;
use shearwarp::data::io::{LoadOptions, load};
use shearwarp::data::orientation::{PatientFrame, parse_code, view_rotation};
use shearwarp::render::{Renderer, Settings};
use shearwarp::view::{Camera, NamedView};
use shearwarp::warp::Image;
use shearwarp::{Volume, VoxelData};

const SIZE: usize = 48;
/// Pixels per millimetre: the same framing for every layout.
const ZOOM: f64 = 1.6;

/// The anatomy, in RAS millimetres: a density 0..100 with its iso-surface
/// (50) on the boundary of an ellipsoidal head, a nose in front and a notch
/// cut from the patient's upper left.
fn anatomy(p: DVec3) -> f64 {
    let r = DVec3::new(8.0, 8.0, 9.0);
    let head = ((p / r).length() - 1.0) * 8.0;
    let nose = (p - DVec3::new(0.0, 8.0, 1.0)).length() - 2.5;
    // the notch: x < −3 (left) and z > 2 (upper)
    let notch = (p.x + 3.0).max(2.0 - p.z);
    let d = head.min(nose).max(-notch);
    (50.0 - 25.0 * d).clamp(0.0, 100.0)
}

/// A voxel grid placed in the patient: unit RAS directions of the index axes,
/// sizes and spacings, centred on the patient origin.
#[derive(Clone, Copy, Debug)]
struct Grid {
    dirs: DMat3,
    n: [usize; 3],
    s: [f64; 3],
}

impl Grid {
    fn code(code: &str, n: [usize; 3], s: [f64; 3]) -> Grid {
        Grid { dirs: parse_code(code).unwrap(), n, s }
    }
    /// RAS position of voxel `i`.
    fn at(&self, i: [usize; 3]) -> DVec3 {
        (0..3).map(|a| self.dirs.col(a) * self.s[a] * (i[a] as f64 - (self.n[a] as f64 - 1.0) / 2.0)).sum()
    }
    fn origin(&self) -> DVec3 {
        self.at([0, 0, 0])
    }
    /// One voxel step along each index axis (RAS).
    fn steps(&self) -> [DVec3; 3] {
        [0, 1, 2].map(|a| self.dirs.col(a) * self.s[a])
    }
    /// The voxels, x fastest.
    fn values(&self) -> Vec<f32> {
        let [nx, ny, nz] = self.n;
        let mut v = Vec::with_capacity(nx * ny * nz);
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    v.push(anatomy(self.at([x, y, z])) as f32);
                }
            }
        }
        v
    }
}

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn vec3(v: DVec3) -> String {
    format!("({},{},{})", v.x, v.y, v.z)
}

/// A NRRD file of `g` in `space` (`RAS`, `LPS` or `LAS`).
fn write_nrrd(path: &Path, g: &Grid, space: &str) {
    let sign = match space {
        "RAS" => DVec3::new(1.0, 1.0, 1.0),
        "LPS" => DVec3::new(-1.0, -1.0, 1.0),
        "LAS" => DVec3::new(-1.0, 1.0, 1.0),
        _ => unreachable!(),
    };
    let name = match space {
        "RAS" => "right-anterior-superior",
        "LPS" => "left-posterior-superior",
        _ => "left-anterior-superior",
    };
    let [a, b, c] = g.steps().map(|v| vec3(v * sign));
    let hdr = format!(
        "NRRD0004\ntype: float\ndimension: 3\nsizes: {} {} {}\nspace: {name}\nspace directions: {a} {b} {c}\n\
         space origin: {}\nendian: little\nencoding: raw\n\n",
        g.n[0],
        g.n[1],
        g.n[2],
        vec3(g.origin() * sign)
    );
    let mut bytes = hdr.into_bytes();
    bytes.extend(f32_bytes(&g.values()));
    std::fs::write(path, bytes).unwrap();
}

/// A NIfTI-1 header (348 bytes + 4 bytes of extension flag) for f32 voxels.
fn nifti_header(n: [usize; 3], pixdim: [f32; 4]) -> Vec<u8> {
    let mut h = vec![0u8; 352];
    h[0..4].copy_from_slice(&348i32.to_le_bytes());
    let dim = [3i16, n[0] as i16, n[1] as i16, n[2] as i16, 1, 1, 1, 1];
    for (i, d) in dim.iter().enumerate() {
        h[40 + 2 * i..42 + 2 * i].copy_from_slice(&d.to_le_bytes());
    }
    h[70..72].copy_from_slice(&16i16.to_le_bytes()); // float32
    h[72..74].copy_from_slice(&32i16.to_le_bytes());
    for (i, p) in pixdim.iter().enumerate() {
        h[76 + 4 * i..80 + 4 * i].copy_from_slice(&p.to_le_bytes());
    }
    h[108..112].copy_from_slice(&352f32.to_le_bytes()); // vox_offset
    h[123] = 2; // mm
    h[344..348].copy_from_slice(b"n+1\0");
    h
}

fn put_f32(h: &mut [u8], at: usize, v: f64) {
    h[at..at + 4].copy_from_slice(&(v as f32).to_le_bytes());
}

/// A NIfTI file of `g` with its placement in the sform (qform_code 0).
fn write_nifti_sform(path: &Path, g: &Grid) {
    let mut h = nifti_header(g.n, [1.0, g.s[0] as f32, g.s[1] as f32, g.s[2] as f32]);
    h[254..256].copy_from_slice(&1i16.to_le_bytes()); // sform_code scanner
    let st = g.steps();
    let o = g.origin();
    for r in 0..3 {
        for (c, col) in st.iter().enumerate() {
            put_f32(&mut h, 280 + 16 * r + 4 * c, col[r]);
        }
        put_f32(&mut h, 280 + 16 * r + 12, o[r]);
    }
    h.extend(f32_bytes(&g.values()));
    std::fs::write(path, h).unwrap();
}

/// A NIfTI file placed by its qform only (sform_code 0): quaternion `(b, c, d)`
/// and `qfac`; returns the grid that placement describes.
fn write_nifti_qform(path: &Path, bcd: [f64; 3], qfac: f64, expect_code: &str, n: [usize; 3], s: [f64; 3]) -> Grid {
    let g = Grid::code(expect_code, n, s);
    let mut h = nifti_header(n, [qfac as f32, s[0] as f32, s[1] as f32, s[2] as f32]);
    h[252..254].copy_from_slice(&1i16.to_le_bytes()); // qform_code
    for (i, q) in bcd.iter().enumerate() {
        put_f32(&mut h, 256 + 4 * i, *q);
    }
    let o = g.origin();
    for r in 0..3 {
        put_f32(&mut h, 268 + 4 * r, o[r]);
    }
    h.extend(f32_bytes(&g.values()));
    std::fs::write(path, h).unwrap();
    g
}

/// A DICOM series of `g` (LPS in the files), one slice per z, stored u16.
fn write_dicom(dir: &Path, g: &Grid) {
    let lps = |v: DVec3| DVec3::new(-v.x, -v.y, v.z);
    let [r, c, _] = g.steps().map(|v| lps(v).normalize());
    let values = g.values();
    let per = g.n[0] * g.n[1];
    for k in 0..g.n[2] {
        let ipp = lps(g.at([0, 0, k]));
        let pix: Vec<u16> = values[k * per..(k + 1) * per].iter().map(|v| v.round() as u16).collect();
        let el = |tag, vr, v: PrimitiveValue| DataElement::new(tag, vr, v);
        let obj = InMemDicomObject::from_element_iter([
            el(tags::SOP_CLASS_UID, VR::UI, uids::MR_IMAGE_STORAGE.into()),
            el(tags::SOP_INSTANCE_UID, VR::UI, format!("1.2.826.0.1.3680043.10.98.{k}").into()),
            el(tags::MODALITY, VR::CS, "MR".into()),
            el(tags::SERIES_INSTANCE_UID, VR::UI, "1.2.3.18".into()),
            el(tags::INSTANCE_NUMBER, VR::IS, (k + 1).to_string().into()),
            el(tags::IMAGE_POSITION_PATIENT, VR::DS, format!("{}\\{}\\{}", ipp.x, ipp.y, ipp.z).into()),
            el(tags::IMAGE_ORIENTATION_PATIENT, VR::DS, format!("{}\\{}\\{}\\{}\\{}\\{}", r.x, r.y, r.z, c.x, c.y, c.z).into()),
            el(tags::PIXEL_SPACING, VR::DS, format!("{}\\{}", g.s[1], g.s[0]).into()),
            el(tags::SAMPLES_PER_PIXEL, VR::US, 1u16.into()),
            el(tags::PHOTOMETRIC_INTERPRETATION, VR::CS, "MONOCHROME2".into()),
            el(tags::ROWS, VR::US, (g.n[1] as u16).into()),
            el(tags::COLUMNS, VR::US, (g.n[0] as u16).into()),
            el(tags::BITS_ALLOCATED, VR::US, 16u16.into()),
            el(tags::BITS_STORED, VR::US, 16u16.into()),
            el(tags::HIGH_BIT, VR::US, 15u16.into()),
            el(tags::PIXEL_REPRESENTATION, VR::US, 0u16.into()),
            el(tags::PIXEL_DATA, VR::OW, PrimitiveValue::U16(C::from_vec(pix))),
        ]);
        let file = obj.with_meta(FileMetaTableBuilder::new().transfer_syntax(uids::EXPLICIT_VR_LITTLE_ENDIAN)).unwrap();
        // shuffled names: the loader sorts by position
        file.write_to_file(dir.join(format!("s{:03}.dcm", (k * 7) % g.n[2]))).unwrap();
    }
}

fn render(vol: &Volume, view: NamedView) -> Image {
    let rot = view_rotation(view, vol.frame());
    let mut r = Renderer::new(vol.clone(), &TransferFunction::threshold(50.0, [1.0, 1.0, 1.0]), Settings::default()).unwrap();
    let mut img = Image::new(SIZE, SIZE);
    r.render(&Camera { rotation: rot, zoom: Some(ZOOM), size: [SIZE, SIZE] }, &mut img).unwrap();
    img
}

/// Grey level (premultiplied luminance) of each pixel.
fn grey(img: &Image) -> Vec<f64> {
    img.data.iter().map(|c| (c[0] + c[1] + c[2]) as f64 / 3.0).collect()
}

/// Mean absolute difference of two grey images; `flip` mirrors `b` left–right
/// (1) or upside down (2) first.
fn diff(a: &[f64], b: &[f64], flip: u8) -> f64 {
    let mut s = 0.0;
    for y in 0..SIZE {
        for x in 0..SIZE {
            let (xb, yb) = match flip {
                1 => (SIZE - 1 - x, y),
                2 => (x, SIZE - 1 - y),
                _ => (x, y),
            };
            s += (a[y * SIZE + x] - b[yb * SIZE + xb]).abs();
        }
    }
    s / (SIZE * SIZE) as f64
}

/// Covered pixels in the column range `[x0, x1)` and row range `[y0, y1)`.
fn covered(img: &Image, xs: std::ops::Range<usize>, ys: std::ops::Range<usize>) -> usize {
    ys.flat_map(|y| xs.clone().map(move |x| (x, y))).filter(|&(x, y)| img.at(x, y)[3] > 0.5).count()
}

fn load_file(p: &Path) -> Volume {
    load(p, &LoadOptions::default()).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// The reference: the anatomy stored RAS, as a volume with the RAS frame.
fn reference() -> Volume {
    let g = Grid::code("RAS", [24, 24, 24], [1.0; 3]);
    Volume::new(g.n, [1.0; 3], VoxelData::F32(g.values())).unwrap().with_frame(Some(PatientFrame::ras()))
}

/// The markers where the anatomy puts them, in each named view of `v`.
fn check_markers(name: &str, v: &Volume) {
    let h = SIZE / 2;
    // anterior: facing the patient, whose left (the notch, upper) is on the image right
    let a = render(v, NamedView::Anterior);
    let (ul, ur) = (covered(&a, 0..h, 0..h), covered(&a, h..SIZE, 0..h));
    assert!(ul > ur + 20, "{name}, anterior: the notch must cut the upper right: upper left {ul}, upper right {ur}");
    // posterior: the patient's left on the image left
    let p = render(v, NamedView::Posterior);
    let (ul, ur) = (covered(&p, 0..h, 0..h), covered(&p, h..SIZE, 0..h));
    assert!(ur > ul + 20, "{name}, posterior: the notch must cut the upper left: {ul} vs {ur}");
    // left: the face (nose) toward the image left
    let l = render(v, NamedView::Left);
    let (left, right) = (covered(&l, 0..h, 0..SIZE), covered(&l, h..SIZE, 0..SIZE));
    assert!(left > right + 10, "{name}, left view: the nose must stick out on the image left: {left} vs {right}");
    // right: the face toward the image right
    let r = render(v, NamedView::Right);
    let (left, right) = (covered(&r, 0..h, 0..SIZE), covered(&r, h..SIZE, 0..SIZE));
    assert!(right > left + 10, "{name}, right view: the nose must stick out on the image right: {left} vs {right}");
    // superior: looking down, the nose at the bottom (anterior)
    let s = render(v, NamedView::Superior);
    let (top, bottom) = (covered(&s, 0..SIZE, 0..h), covered(&s, 0..SIZE, h..SIZE));
    assert!(bottom > top + 10, "{name}, superior view: the nose must point down: top {top}, bottom {bottom}");
    // inferior: looking up from the feet, the nose at the top
    let i = render(v, NamedView::Inferior);
    let (top, bottom) = (covered(&i, 0..SIZE, 0..h), covered(&i, 0..SIZE, h..SIZE));
    assert!(top > bottom + 10, "{name}, inferior view: the nose must point up: top {top}, bottom {bottom}");
}

#[test]
fn the_reference_shows_the_markers_where_the_anatomy_says() {
    check_markers("RAS reference", &reference());
}

#[test]
fn every_format_and_orientation_gives_the_same_picture() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let n = [24, 24, 24];
    let mut cases: Vec<(String, Volume)> = Vec::new();
    for (space, code) in [("RAS", "RAS"), ("LPS", "LPS"), ("LAS", "LAS"), ("LPS", "LAS"), ("RAS", "PIR"), ("LPS", "ASL")] {
        let p = d.join(format!("{space}-{code}.nrrd"));
        write_nrrd(&p, &Grid::code(code, n, [1.0; 3]), space);
        cases.push((format!("NRRD space {space}, index axes {code}"), load_file(&p)));
    }
    // anisotropic, other sizes
    let p = d.join("aniso.nrrd");
    write_nrrd(&p, &Grid::code("LPS", [30, 24, 20], [0.8, 1.0, 1.2]), "LPS");
    cases.push(("NRRD LPS, 30×24×20 at 0.8×1×1.2 mm".into(), load_file(&p)));
    for code in ["LPS", "LAS", "PIR", "SAR"] {
        let p = d.join(format!("sform-{code}.nii"));
        write_nifti_sform(&p, &Grid::code(code, n, [1.0; 3]));
        cases.push((format!("NIfTI sform {code}"), load_file(&p)));
    }
    // qform only: 180° about S with qfac −1 (LPI, mirrored); 90° about R (RSP)
    let h = std::f64::consts::FRAC_1_SQRT_2;
    for (bcd, qfac, code) in [([0.0, 0.0, 1.0], -1.0, "LPI"), ([h, 0.0, 0.0], 1.0, "RSP"), ([h, 0.0, 0.0], -1.0, "RSA")] {
        let p = d.join(format!("qform-{code}.nii"));
        write_nifti_qform(&p, bcd, qfac, code, n, [1.0; 3]);
        let v = load_file(&p);
        cases.push((format!("NIfTI qform {code}"), v));
    }
    // oblique: index axes tilted 20° about S and 12° about R, written as NRRD and DICOM
    let tilt = DMat3::from_rotation_x(12f64.to_radians()) * DMat3::from_rotation_z(20f64.to_radians());
    let oblique = Grid { dirs: tilt * parse_code("LPS").unwrap(), n, s: [1.0; 3] };
    let p = d.join("oblique.nrrd");
    write_nrrd(&p, &oblique, "LPS");
    cases.push(("NRRD LPS tilted 20°/12°".into(), load_file(&p)));
    let dcm = d.join("dicom");
    std::fs::create_dir(&dcm).unwrap();
    write_dicom(&dcm, &oblique);
    let v = load_file(&dcm);
    assert!(v.frame().unwrap().obliquity_deg() > 15.0, "{:?}", v.frame());
    cases.push(("DICOM tilted 20°/12°".into(), v));

    let reference = reference();
    for (name, vol) in &cases {
        let f = vol.frame().unwrap_or_else(|| panic!("{name}: no orientation"));
        assert!(!f.is_mirrored(), "{name}: a mirrored frame was attached");
        check_markers(name, vol);
    }
    for view in NamedView::ALL {
        let want = grey(&render(&reference, view));
        // the reference's own asymmetry, left-right or up-down, whichever is larger
        let flip = if diff(&want, &want, 1) >= diff(&want, &want, 2) { 1 } else { 2 };
        let asym = diff(&want, &want, flip);
        assert!(asym > 0.01, "{view:?}: the reference must not be symmetric ({asym})");
        for (name, vol) in &cases {
            let got = grey(&render(vol, view));
            let (same, flipped) = (diff(&got, &want, 0), diff(&got, &want, flip));
            // axis-aligned copies sample the same points (up to rounding); tilted
            // and anisotropic grids sample others, and differ by resampling
            let resampled = name.contains("tilted") || name.contains("0.8");
            let tol = if resampled { 0.7 } else { 0.1 };
            assert!(
                same < tol * asym && same < 0.5 * flipped,
                "{view:?} of {name}: differs from the reference by {same}, from its mirror image by {flipped} (the reference's asymmetry: {asym})"
            );
        }
    }
}

#[test]
fn mirrored_files_are_reversed_and_record_it() {
    let dir = tempfile::tempdir().unwrap();
    let g = Grid::code("LAS", [24, 22, 20], [1.0, 1.5, 2.0]);
    let p = dir.path().join("las.nrrd");
    write_nrrd(&p, &g, "LAS");
    let v = load_file(&p);
    let f = v.frame().unwrap();
    assert_eq!((f.code().as_str(), f.stored_code().as_str(), f.reversed_axis), ("RAS", "LAS", Some(0)));
    // the new voxel 0 is the file's last voxel along x, at the patient's right
    assert!(f.origin.abs_diff_eq(g.at([23, 0, 0]), 1e-4), "{:?} vs {:?}", f.origin, g.at([23, 0, 0]));
    let raw = g.values();
    assert_eq!(v.get(0, 3, 4), raw[23 + 24 * (3 + 22 * 4)]);
    // raw + sidecar keep the frame, reversal included
    let r = dir.path().join("las.raw");
    shearwarp::data::io::save_raw(&v, &r).unwrap();
    assert_eq!(load_file(&r), v);
    // the same file without `space` has no orientation and keeps its order
    let text = std::fs::read(&p).unwrap();
    let text = String::from_utf8_lossy(&text[..200]).replace("space: left-anterior-superior\n", "space dimension: 3\n");
    let cut = text.find("\n\n").unwrap() + 2;
    let mut bytes = text.as_bytes()[..cut].to_vec();
    bytes.extend(f32_bytes(&raw));
    std::fs::write(&p, bytes).unwrap();
    let v = load_file(&p);
    assert!(v.frame().is_none());
    assert_eq!(v.get(0, 3, 4), raw[24 * (3 + 22 * 4)]);
}

#[test]
fn nifti_without_sform_or_qform_has_no_orientation_and_sform_wins() {
    let dir = tempfile::tempdir().unwrap();
    let g = Grid::code("RAS", [6, 5, 4], [1.0; 3]);
    let p = dir.path().join("none.nii");
    let mut h = nifti_header(g.n, [1.0; 4]);
    h.extend(f32_bytes(&g.values()));
    std::fs::write(&p, &h).unwrap();
    assert!(load_file(&p).frame().is_none());
    // an sform (LPS) and a conflicting qform (identity): the sform is used
    let g = Grid::code("LPS", [6, 5, 4], [1.0; 3]);
    write_nifti_sform(&p, &g);
    let mut b = std::fs::read(&p).unwrap();
    b[252..254].copy_from_slice(&1i16.to_le_bytes());
    std::fs::write(&p, &b).unwrap();
    let v = load_file(&p);
    assert_eq!(v.frame().unwrap().code(), "LPS");
    assert!(v.frame().unwrap().origin.abs_diff_eq(g.origin(), 1e-5));
}

/// The shared chest CT is stored LPS: its anterior view must look at the
/// patient's front (the sternum side), i.e. the index axis toward posterior
/// (+y) must point away from the viewer.
#[test]
fn chest_ct_anterior_view_faces_the_sternum() {
    let Some(dir) = std::env::var_os("SHEARWARP_DATA") else {
        eprintln!("SHEARWARP_DATA unset: chest CT orientation test skipped");
        return;
    };
    let v = load_file(&Path::new(&dir).join("chest-ct-lung1.nrrd"));
    let f = v.frame().expect("the chest CT has an orientation");
    assert_eq!(f.code(), "LPS");
    let r = view_rotation(NamedView::Anterior, Some(f));
    assert!((r * DVec3::Y).abs_diff_eq(-DVec3::Z, 1e-9), "index +y (posterior) must point away from the viewer");
    assert!((r * DVec3::Z).abs_diff_eq(DVec3::Y, 1e-9), "index +z (superior) must point up");
    assert!((r * DVec3::X).abs_diff_eq(DVec3::X, 1e-9), "index +x (the patient's left) must point to the image right");
    // and the picture: seen from the front, wherever the front half of the
    // chest (sternum, anterior ribs) has bone it hides the back half (spine,
    // scapulae), so there the render matches that of the front half alone,
    // not that of the back half
    let ny = v.dims()[1];
    let half = |keep_front: bool| -> Volume {
        let VoxelData::I16(d) = v.data() else { panic!("the chest CT is i16") };
        let [nx, _, _] = v.dims();
        let d: Vec<i16> = d.iter().enumerate().map(|(i, &x)| if ((i / nx) % ny < ny / 2) == keep_front { x } else { -1024 }).collect();
        Volume::new(v.dims(), v.spacing(), VoxelData::I16(d)).unwrap().with_frame(Some(*f))
    };
    let shot = |vol: &Volume| -> Image {
        let mut ren = Renderer::new(vol.clone(), &TransferFunction::threshold(300.0, [1.0; 3]), Settings::default()).unwrap();
        let mut img = Image::new(128, 128);
        ren.render(&Camera { rotation: r, zoom: None, size: [128, 128] }, &mut img).unwrap();
        assert!(img.coverage() > 0.02);
        if let Some(d) = std::env::var_os("SHEARWARP_SHOTS") {
            let n = std::fs::read_dir(&d).map(|r| r.count()).unwrap_or(0);
            img.save_png(&Path::new(&d).join(format!("chest-{n}.png"))).unwrap();
        }
        img
    };
    let (full, front, back) = (shot(&v), shot(&half(true)), shot(&half(false)));
    let (mut to_front, mut to_back, mut n) = (0.0, 0.0, 0);
    for i in 0..full.data.len() {
        if front.data[i][3] > 0.99 {
            let g = |c: [f32; 4]| (c[0] + c[1] + c[2]) as f64 / 3.0;
            to_front += (g(full.data[i]) - g(front.data[i])).abs();
            to_back += (g(full.data[i]) - g(back.data[i])).abs();
            n += 1;
        }
    }
    assert!(n > 200, "the front half shows only {n} pixels of bone");
    assert!(
        to_front < 0.25 * to_back,
        "the anterior view does not show the front: where the front half has bone the image differs from it by {} and from the back half by {}",
        to_front / n as f64,
        to_back / n as f64
    );
}
