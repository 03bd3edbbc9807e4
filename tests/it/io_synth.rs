//! Synthetic round trips and error cases for every loader, in temp dirs:
//! tiny NRRD (attached/detached, raw/gzip, both byte orders), NIfTI (written
//! by the `nifti` crate, with scl_slope), DICOM CT slices (shuffled on disk),
//! VolPack .den and raw files, plus the malformed inputs every loader must
//! turn into a clear error.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use dicom_core::value::C;
use dicom_core::{DataElement, PrimitiveValue, VR};
use dicom_dictionary_std::{tags, uids};
use dicom_object::{FileMetaTableBuilder, InMemDicomObject};
use flate2::Compression;
use flate2::write::GzEncoder;
use shearwarp::data::io::{Format, LoadOptions, RawSpec, den, load, save_raw};
use shearwarp::{Error, Volume, VoxelData, VoxelType};

fn opts() -> LoadOptions {
    LoadOptions::default()
}

fn load_err(p: &Path) -> String {
    match load(p, &opts()) {
        Ok(v) => panic!("{} loaded but should not have: {:?}", p.display(), v.dims()),
        Err(e) => e.to_string(),
    }
}

fn gz(bytes: &[u8]) -> Vec<u8> {
    let mut e = GzEncoder::new(Vec::new(), Compression::fast());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

/// Voxel value pattern used by the synthetic volumes.
fn pattern(x: usize, y: usize, z: usize) -> i32 {
    (x as i32) * 7 - (y as i32) * 100 + (z as i32) * 1000 - 300
}

const DIMS: [usize; 3] = [5, 4, 3];

fn i16_voxels() -> Vec<i16> {
    let mut v = Vec::new();
    for z in 0..DIMS[2] {
        for y in 0..DIMS[1] {
            for x in 0..DIMS[0] {
                v.push(pattern(x, y, z) as i16);
            }
        }
    }
    v
}

// ---------------------------------------------------------------- NRRD

fn nrrd_header(typ: &str, endian: &str, encoding: &str, extra: &str) -> String {
    format!(
        "NRRD0004\n# a comment\ntype: {typ}\ndimension: 3\nsizes: 5 4 3\n\
         space directions: (0.5,0,0) (0,0.75,0) (0,0,2.5)\nendian: {endian}\nencoding: {encoding}\n\
         origin:=key value pair\n{extra}"
    )
}

fn i16_bytes(big: bool) -> Vec<u8> {
    i16_voxels().iter().flat_map(|v| if big { v.to_be_bytes() } else { v.to_le_bytes() }).collect()
}

fn check_i16_volume(v: &Volume) {
    assert_eq!(v.dims(), DIMS);
    assert_eq!(v.data(), &VoxelData::I16(i16_voxels()));
    assert_eq!(v.get(4, 3, 2), pattern(4, 3, 2) as f32);
}

#[test]
fn nrrd_attached_raw_and_gzip_both_endians() {
    let dir = tempfile::tempdir().unwrap();
    for (big, endian) in [(false, "little"), (true, "big")] {
        for encoding in ["raw", "gzip", "gz"] {
            let payload = i16_bytes(big);
            let payload = if encoding == "raw" { payload } else { gz(&payload) };
            let mut file = nrrd_header("short", endian, encoding, "\n").into_bytes();
            file.extend_from_slice(&payload);
            let p = dir.path().join(format!("a-{endian}-{encoding}.nrrd"));
            std::fs::write(&p, file).unwrap();
            let v = load(&p, &opts()).unwrap();
            check_i16_volume(&v);
            assert_eq!(v.spacing(), [0.5, 0.75, 2.5]);
        }
    }
}

#[test]
fn nrrd_detached_raw_and_gzip() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("data")).unwrap();
    std::fs::write(dir.path().join("data/vol.raw"), i16_bytes(true)).unwrap();
    std::fs::write(dir.path().join("data/vol.raw.gz"), gz(&i16_bytes(false))).unwrap();
    let h1 = dir.path().join("raw.nhdr");
    std::fs::write(&h1, nrrd_header("int16", "big", "raw", "data file: data/vol.raw\n")).unwrap();
    check_i16_volume(&load(&h1, &opts()).unwrap());
    let h2 = dir.path().join("gz.nhdr");
    std::fs::write(&h2, nrrd_header("signed short int", "little", "gzip", "datafile: data/vol.raw.gz\n")).unwrap();
    check_i16_volume(&load(&h2, &opts()).unwrap());
    // Absolute data file path and byte skip -1 with junk before the data.
    let mut junk = b"some preamble\n".to_vec();
    junk.extend(i16_bytes(false));
    std::fs::write(dir.path().join("junk.raw"), junk).unwrap();
    let abs = dir.path().join("junk.raw");
    let h3 = dir.path().join("skip.nhdr");
    let extra = format!("data file: {}\nbyte skip: -1\n", abs.display());
    std::fs::write(&h3, nrrd_header("short", "little", "raw", &extra)).unwrap();
    check_i16_volume(&load(&h3, &opts()).unwrap());
    // line skip
    let h4 = dir.path().join("lines.nhdr");
    std::fs::write(&h4, nrrd_header("short", "little", "raw", "data file: junk.raw\nline skip: 1\n")).unwrap();
    check_i16_volume(&load(&h4, &opts()).unwrap());
}

#[test]
fn nrrd_types_spacings_and_squeeze() {
    let dir = tempfile::tempdir().unwrap();
    let n = 60;
    let cases: [(&str, usize, VoxelType); 7] = [
        ("uchar", 1, VoxelType::U8),
        ("unsigned char", 1, VoxelType::U8),
        ("uint8", 1, VoxelType::U8),
        ("ushort", 2, VoxelType::U16),
        ("unsigned short int", 2, VoxelType::U16),
        ("float", 4, VoxelType::F32),
        ("signed char", 1, VoxelType::I16),
    ];
    for (typ, size, want) in cases {
        let body: Vec<u8> = (0..n * size).map(|i| (i % 50) as u8).collect();
        let hdr = format!("NRRD0005\ntype: {typ}\ndimension: 3\nsizes: 5 4 3\nspacings: 1.5 2 3\nendian: little\nencoding: raw\n\n");
        let mut file = hdr.into_bytes();
        file.extend_from_slice(&body);
        let p = dir.path().join(format!("t-{}.nrrd", typ.replace(' ', "_")));
        std::fs::write(&p, file).unwrap();
        let v = load(&p, &opts()).unwrap();
        assert_eq!(v.data().voxel_type(), want, "{typ}");
        assert_eq!(v.spacing(), [1.5, 2.0, 3.0]);
    }
    // double → f32, values preserved.
    let body: Vec<u8> = (0..n).flat_map(|i| (i as f64 * 0.25).to_be_bytes()).collect();
    let mut file = b"NRRD0004\ntype: double\ndimension: 3\nsizes: 5 4 3\nendian: big\nencoding: raw\n\n".to_vec();
    file.extend(body);
    let p = dir.path().join("double.nrrd");
    std::fs::write(&p, file).unwrap();
    let v = load(&p, &opts()).unwrap();
    assert_eq!(v.get(3, 0, 0), 0.75);
    assert_eq!(v.spacing(), [1.0; 3]);
    // 4-D with a size-1 vector axis is squeezed; its "none" direction is dropped.
    let mut file = b"NRRD0004\ntype: short\ndimension: 4\nsizes: 1 5 4 3\n\
        space directions: none (2,0,0) (0,2,0) (0,0,4)\nkinds: vector domain domain domain\n\
        endian: little\nencoding: raw\n\n"
        .to_vec();
    file.extend(i16_bytes(false));
    let p = dir.path().join("4d.nrrd");
    std::fs::write(&p, file).unwrap();
    let v = load(&p, &opts()).unwrap();
    check_i16_volume(&v);
    assert_eq!(v.spacing(), [2.0, 2.0, 4.0]);
}

#[test]
fn nrrd_rejections_are_clear() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, bytes: Vec<u8>| {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    let with_body = |hdr: String, body: &[u8]| {
        let mut f = hdr.into_bytes();
        f.extend_from_slice(body);
        f
    };
    let good = i16_bytes(false);
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("bz2.nrrd", with_body(nrrd_header("short", "little", "bzip2", "\n"), &good), "bzip2"),
        ("ascii.nrrd", with_body(nrrd_header("short", "little", "ascii", "\n"), b"1 2 3"), "ascii"),
        ("hex.nrrd", with_body(nrrd_header("short", "little", "hex", "\n"), b"00ff"), "hex"),
        ("trunc.nrrd", with_body(nrrd_header("short", "little", "raw", "\n"), &good[..50]), "truncated"),
        ("extra.nrrd", with_body(nrrd_header("short", "little", "raw", "\n"), &[good.clone(), vec![0; 9]].concat()), "more"),
        ("gztrunc.nrrd", with_body(nrrd_header("short", "little", "gzip", "\n"), &gz(&good[..80])), "truncated"),
        ("gzlong.nrrd", with_body(nrrd_header("short", "little", "gzip", "\n"), &gz(&vec![0; 100_000])), "more than"),
        ("noendian.nrrd", with_body("NRRD0004\ntype: short\ndimension: 3\nsizes: 5 4 3\nencoding: raw\n\n".into(), &good), "endian"),
        ("block.nrrd", with_body("NRRD0004\ntype: block\ndimension: 3\nsizes: 5 4 3\nencoding: raw\n\n".into(), &good), "type 'block'"),
        ("2d.nrrd", with_body("NRRD0004\ntype: uchar\ndimension: 2\nsizes: 12 10\nencoding: raw\n\n".into(), &[0; 120]), "3-D"),
        ("zero.nrrd", with_body("NRRD0004\ntype: uchar\ndimension: 3\nsizes: 5 0 3\nencoding: raw\n\n".into(), &[]), "size of 0"),
        (
            "neg.nrrd",
            with_body("NRRD0004\ntype: uchar\ndimension: 3\nsizes: 5 -4 3\nencoding: raw\n\n".into(), &[]),
            "not positive integers",
        ),
        ("sizes.nrrd", with_body("NRRD0004\ntype: uchar\ndimension: 3\nsizes: 5 4\nencoding: raw\n\n".into(), &[]), "dimension is 3"),
        ("list.nhdr", nrrd_header("short", "little", "raw", "data file: LIST\nslice1.raw\n").into_bytes(), "several files"),
        ("nodata.nhdr", nrrd_header("short", "little", "raw", "").into_bytes(), "no data"),
        ("missing.nhdr", nrrd_header("short", "little", "raw", "data file: nowhere.raw\n").into_bytes(), "nowhere.raw"),
        ("gzskip.nrrd", with_body(nrrd_header("short", "little", "gzip", "byte skip: 999999999\n\n"), &gz(&good)), "byte skip"),
        ("device.nhdr", nrrd_header("short", "little", "gzip", "data file: /dev/zero\n").into_bytes(), "not a regular file"),
        ("magic.nrrd", b"NRRDXXXX\ntype: short\n\n".to_vec(), "magic"),
        ("dup.nrrd", with_body(nrrd_header("short", "little", "raw", "type: short\n\n"), &good), "repeats"),
        ("empty.nrrd", Vec::new(), "empty"),
        ("binary.nrrd", b"NRRD0004\n\xff\xfe\n\n".to_vec(), "not text"),
    ];
    for (name, bytes, want) in cases {
        let p = write(name, bytes);
        let e = load_err(&p);
        assert!(e.contains(want), "{name}: '{e}' lacks '{want}'");
        assert!(e.contains(name), "{name}: '{e}' does not name the file");
    }
}

#[test]
fn absurd_dims_fail_fast_in_every_header_format() {
    let dir = tempfile::tempdir().unwrap();
    let t = Instant::now();
    // NRRD 100000³ with a tiny gzip payload.
    let mut f = b"NRRD0004\ntype: float\ndimension: 3\nsizes: 100000 100000 100000\nendian: little\nencoding: gzip\n\n".to_vec();
    f.extend(gz(&[0; 64]));
    let p = dir.path().join("huge.nrrd");
    std::fs::write(&p, f).unwrap();
    assert!(load_err(&p).contains("100000"));
    // A header within the limits (2^30 voxels) that lies about the data: no allocation happens
    // before the size check, and gzip reading stops at what the stream holds.
    let mut f = b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 1024 1024 1024\nencoding: gzip\n\n".to_vec();
    f.extend(gz(&[1; 1000]));
    let p = dir.path().join("lying.nrrd");
    std::fs::write(&p, f).unwrap();
    assert!(load_err(&p).contains("truncated"));
    let mut f = b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 1024 1024 1024\nencoding: raw\n\n".to_vec();
    f.extend([1; 1000]);
    let p = dir.path().join("lying-raw.nrrd");
    std::fs::write(&p, f).unwrap();
    assert!(load_err(&p).contains("truncated"));
    // Raw spec.
    let p = dir.path().join("x.raw");
    std::fs::write(&p, [0u8; 16]).unwrap();
    let spec = RawSpec::new([100_000; 3], VoxelType::U16);
    let e = load(&p, &LoadOptions { format: Some(Format::Raw), raw: Some(spec) }).unwrap_err().to_string();
    assert!(e.contains("100000"), "{e}");
    // .den with 32767³.
    let p = dir.path().join("huge.den");
    let mut h = vec![0u8; 62];
    h[0] = 1;
    for i in [50, 52, 54] {
        h[i..i + 2].copy_from_slice(&32767i16.to_le_bytes());
    }
    std::fs::write(&p, &h).unwrap();
    assert!(load_err(&p).contains("32767"));
    // NIfTI with 65535³ (the largest a u16 dim can claim).
    let p = dir.path().join("huge.nii");
    let mut n = nifti_bytes_u8([2, 2, 2], &[0; 8]);
    for i in 0..3 {
        n[42 + 2 * i..44 + 2 * i].copy_from_slice(&65535u16.to_le_bytes());
    }
    std::fs::write(&p, &n).unwrap();
    assert!(load_err(&p).contains("65535"));
    assert!(t.elapsed().as_secs_f64() < 2.0, "took {:?}", t.elapsed());
}

// ---------------------------------------------------------------- NIfTI

/// A minimal little-endian NIfTI-1 u8 file, written with the nifti crate.
fn nifti_bytes_u8(dims: [usize; 3], data: &[u8]) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("t.nii");
    let arr = ndarray::Array3::from_shape_fn((dims[0], dims[1], dims[2]), |(x, y, z)| data[x + dims[0] * (y + dims[1] * z)]);
    nifti::writer::WriterOptions::new(&p).write_nifti(&arr).unwrap();
    std::fs::read(&p).unwrap()
}

fn set_f32(b: &mut [u8], at: usize, v: f32, big: bool) {
    b[at..at + 4].copy_from_slice(&if big { v.to_be_bytes() } else { v.to_le_bytes() });
}

#[test]
fn nifti_written_by_the_crate_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let arr = ndarray::Array3::from_shape_fn((5, 4, 3), |(x, y, z)| pattern(x, y, z) as i16);
    let mut hdr = nifti::NiftiHeader {
        pixdim: [1.0, 0.5, 0.75, 2.5, 1.0, 1.0, 1.0, 1.0],
        xyzt_units: 2, // mm
        ..Default::default()
    };
    for (name, big) in [("le.nii", false), ("be.nii.gz", true)] {
        hdr.endianness = if big { nifti::Endianness::Big } else { nifti::Endianness::Little };
        let p = dir.path().join(name);
        nifti::writer::WriterOptions::new(&p).reference_header(&hdr).write_nifti(&arr).unwrap();
        assert_eq!(Format::infer(&p).unwrap(), Format::Nifti);
        let v = load(&p, &opts()).unwrap();
        check_i16_volume(&v);
        assert_eq!(v.spacing(), [0.5, 0.75, 2.5], "{name}");
    }
    // f32 data, and metres → millimetres.
    let arrf = ndarray::Array3::from_shape_fn((5, 4, 3), |(x, y, z)| pattern(x, y, z) as f32 * 0.5);
    hdr.endianness = nifti::Endianness::Little;
    hdr.xyzt_units = 1; // metres
    hdr.pixdim = [1.0, 0.001, 0.002, 0.003, 1.0, 1.0, 1.0, 1.0];
    let p = dir.path().join("f.nii");
    nifti::writer::WriterOptions::new(&p).reference_header(&hdr).write_nifti(&arrf).unwrap();
    let v = load(&p, &opts()).unwrap();
    assert_eq!(v.data().voxel_type(), VoxelType::F32);
    assert_eq!(v.get(4, 3, 2), pattern(4, 3, 2) as f32 * 0.5);
    assert_eq!(v.spacing(), [1.0, 2.0, 3.0]);
}

#[test]
fn nifti_scl_slope_gives_f32_and_unit_slope_keeps_type() {
    let dir = tempfile::tempdir().unwrap();
    let data: Vec<u8> = (0..60).map(|i| i as u8 * 4).collect();
    let base = nifti_bytes_u8(DIMS, &data);
    // scl_slope at byte 112, scl_inter at 116 (the writer sets 1 and 0).
    let mut scaled = base.clone();
    set_f32(&mut scaled, 112, 0.5, false);
    set_f32(&mut scaled, 116, -10.0, false);
    for (name, bytes) in [("s.nii", scaled.clone()), ("s.nii.gz", gz(&scaled))] {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        let v = load(&p, &opts()).unwrap();
        assert_eq!(v.data().voxel_type(), VoxelType::F32, "{name}");
        for (i, &d) in data.iter().enumerate() {
            assert_eq!(v.data().get(i), d as f32 * 0.5 - 10.0);
        }
    }
    // (1, 0) and slope 0 mean "no scaling": keep u8.
    for slope in [1.0f32, 0.0] {
        let mut b = base.clone();
        set_f32(&mut b, 112, slope, false);
        let p = dir.path().join(format!("u{slope}.nii"));
        std::fs::write(&p, b).unwrap();
        let v = load(&p, &opts()).unwrap();
        assert_eq!(v.data(), &VoxelData::U8(data.clone()));
    }
    // A 4-D file with a single time point loads; two time points do not.
    let mut b = base.clone();
    b[40..42].copy_from_slice(&4u16.to_le_bytes());
    b[48..50].copy_from_slice(&1u16.to_le_bytes());
    let p = dir.path().join("t1.nii");
    std::fs::write(&p, &b).unwrap();
    assert_eq!(load(&p, &opts()).unwrap().dims(), DIMS);
    b[48..50].copy_from_slice(&2u16.to_le_bytes());
    let p = dir.path().join("t2.nii");
    std::fs::write(&p, &b).unwrap();
    assert!(load_err(&p).contains("4-D"));
}

#[test]
fn nifti_rejections_are_clear() {
    let dir = tempfile::tempdir().unwrap();
    let base = nifti_bytes_u8(DIMS, &[7; 60]);
    let mut cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("trunc.nii", base[..base.len() - 10].to_vec(), "truncated"),
        ("trunc.nii.gz", gz(&base[..base.len() - 10]), "truncated"),
        ("hdr.nii", base[..200].to_vec(), "header"),
        ("extra.nii.gz", gz(&[base.clone(), vec![0; 50]].concat()), "more than"),
    ];
    let mut b = base.clone();
    b[42..44].copy_from_slice(&0u16.to_le_bytes());
    cases.push(("zero.nii", b, "dim[1] is 0"));
    let mut b = base.clone();
    b[70..72].copy_from_slice(&32i16.to_le_bytes()); // complex64
    cases.push(("complex.nii", b, "not supported"));
    let mut b = base.clone();
    set_f32(&mut b, 108, 1.0e9, false);
    cases.push(("voxoff.nii", b, "vox_offset"));
    let mut b = base.clone();
    set_f32(&mut b, 112, f32::NAN, false);
    cases.push(("nanslope.nii", b, "not finite"));
    let mut b = base.clone();
    set_f32(&mut b, 80, -0.0, false);
    set_f32(&mut b, 80, f32::NAN, false);
    cases.push(("pixdim.nii", b, "pixdim[1]"));
    let mut b = base.clone();
    b[344..348].copy_from_slice(b"ni1\0");
    cases.push(("pair.nii", b, "pair"));
    let mut b = base.clone();
    b[344..348].copy_from_slice(b"xxxx");
    cases.push(("magic.nii", b, "NIfTI"));
    cases.push(("bomb.nii.gz", gz(&[base.clone(), vec![0; 5_000_000]].concat()), "more than"));
    for (name, bytes, want) in cases {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        let e = load_err(&p);
        assert!(e.contains(want), "{name}: '{e}' lacks '{want}'");
        assert!(e.contains(name), "{name}: '{e}' does not name the file");
    }
}

// ---------------------------------------------------------------- DICOM

/// Where a CT slice sits: its series, instance number and position z (mm).
struct SliceAt<'a> {
    series: &'a str,
    instance: u32,
    z: f64,
}

/// One CT slice of `rows` × `cols` at `at`: `values` are stored pixel values
/// (u16), HU = value - 1024.
fn ct_slice(path: &Path, at: SliceAt, [rows, cols]: [u16; 2], values: &[u16], ts: &str) {
    let SliceAt { series, instance, z } = at;
    let el = |tag, vr, v: PrimitiveValue| DataElement::new(tag, vr, v);
    let obj = InMemDicomObject::from_element_iter([
        el(tags::SOP_CLASS_UID, VR::UI, uids::CT_IMAGE_STORAGE.into()),
        el(tags::SOP_INSTANCE_UID, VR::UI, format!("1.2.826.0.1.3680043.10.99.{instance}").into()),
        el(tags::MODALITY, VR::CS, "CT".into()),
        el(tags::SERIES_INSTANCE_UID, VR::UI, series.into()),
        el(tags::INSTANCE_NUMBER, VR::IS, instance.to_string().into()),
        el(tags::IMAGE_POSITION_PATIENT, VR::DS, format!("-10\\-20\\{z}").into()),
        el(tags::IMAGE_ORIENTATION_PATIENT, VR::DS, "1\\0\\0\\0\\1\\0".into()),
        el(tags::PIXEL_SPACING, VR::DS, "0.75\\0.5".into()),
        el(tags::SLICE_THICKNESS, VR::DS, "9".into()),
        el(tags::SAMPLES_PER_PIXEL, VR::US, 1u16.into()),
        el(tags::PHOTOMETRIC_INTERPRETATION, VR::CS, "MONOCHROME2".into()),
        el(tags::ROWS, VR::US, rows.into()),
        el(tags::COLUMNS, VR::US, cols.into()),
        el(tags::BITS_ALLOCATED, VR::US, 16u16.into()),
        el(tags::BITS_STORED, VR::US, 16u16.into()),
        el(tags::HIGH_BIT, VR::US, 15u16.into()),
        el(tags::PIXEL_REPRESENTATION, VR::US, 0u16.into()),
        el(tags::RESCALE_INTERCEPT, VR::DS, "-1024".into()),
        el(tags::RESCALE_SLOPE, VR::DS, "1".into()),
        el(tags::PIXEL_DATA, VR::OW, PrimitiveValue::U16(C::from_vec(values.to_vec()))),
    ]);
    let file = obj.with_meta(FileMetaTableBuilder::new().transfer_syntax(ts)).unwrap();
    file.write_to_file(path).unwrap();
}

/// Stored value of pixel (x, y) of slice k.
fn ct_value(x: usize, y: usize, k: usize) -> u16 {
    (1024 + x * 3 + y * 50 + k * 400) as u16
}

fn ct_values(cols: usize, rows: usize, k: usize) -> Vec<u16> {
    (0..rows).flat_map(|y| (0..cols).map(move |x| ct_value(x, y, k))).collect()
}

/// Writes a 4-slice series at z = 0, 2.5, 5, 7.5 under shuffled file names.
fn ct_series(dir: &Path, ts: &str) -> Vec<PathBuf> {
    let order = [2usize, 0, 3, 1]; // file i holds slice order[i]
    order
        .iter()
        .enumerate()
        .map(|(i, &k)| {
            let p = dir.join(format!("img{i:02}.dcm"));
            ct_slice(&p, SliceAt { series: "1.2.3.4", instance: 10 + k as u32, z: k as f64 * 2.5 }, [3, 4], &ct_values(4, 3, k), ts);
            p
        })
        .collect()
}

#[test]
fn dicom_series_is_sorted_and_rescaled_to_hu() {
    // Explicit VR big endian is retired (so its constant is deprecated) but still read.
    let explicit_be = "1.2.840.10008.1.2.2";
    for ts in [uids::EXPLICIT_VR_LITTLE_ENDIAN, uids::IMPLICIT_VR_LITTLE_ENDIAN, explicit_be] {
        let dir = tempfile::tempdir().unwrap();
        let files = ct_series(dir.path(), ts);
        std::fs::write(dir.path().join("README.txt"), "not a slice").unwrap();
        let v = load(dir.path(), &opts()).unwrap();
        assert_eq!(v.dims(), [4, 3, 4], "{ts}");
        assert_eq!(v.spacing(), [0.5, 0.75, 2.5], "{ts}");
        assert_eq!(v.data().voxel_type(), VoxelType::I16);
        for k in 0..4 {
            for y in 0..3 {
                for x in 0..4 {
                    assert_eq!(v.get(x, y, k), ct_value(x, y, k) as f32 - 1024.0, "{ts} ({x},{y},{k})");
                }
            }
        }
        // One slice file selects its series.
        assert_eq!(load(&files[3], &opts()).unwrap(), v);
    }
}

#[test]
fn dicom_pixel_data_must_match_rows_and_columns() {
    // 16×16 pixels stored, Columns 15 (or Rows 15): refused, naming the file,
    // in every native transfer syntax; the true 16×16 loads
    #[allow(deprecated)]
    for ts in [uids::EXPLICIT_VR_LITTLE_ENDIAN, uids::IMPLICIT_VR_LITTLE_ENDIAN, uids::EXPLICIT_VR_BIG_ENDIAN] {
        for (rows, cols) in [(16u16, 15u16), (15, 16), (16, 17)] {
            let dir = tempfile::tempdir().unwrap();
            for k in 0..3 {
                ct_slice(
                    &dir.path().join(format!("s{k}.dcm")),
                    SliceAt { series: "1.2.3.9", instance: k + 1, z: k as f64 },
                    [rows, cols],
                    &ct_values(16, 16, k as usize),
                    ts,
                );
            }
            let e = load_err(dir.path());
            assert!(e.contains(".dcm") && e.contains("pixel data holds 512 bytes") && e.contains(&format!("Columns {cols}")), "{e}");
        }
        let dir = tempfile::tempdir().unwrap();
        for k in 0..3 {
            ct_slice(
                &dir.path().join(format!("s{k}.dcm")),
                SliceAt { series: "1.2.3.9", instance: k + 1, z: k as f64 },
                [16, 16],
                &ct_values(16, 16, k as usize),
                ts,
            );
        }
        assert_eq!(load(dir.path(), &LoadOptions::default()).unwrap().dims(), [16, 16, 3]);
    }
}

#[test]
fn dicom_rejections_are_clear() {
    let ts = uids::EXPLICIT_VR_LITTLE_ENDIAN;
    // Mixed slice sizes: the error names the odd file.
    let dir = tempfile::tempdir().unwrap();
    ct_series(dir.path(), ts);
    ct_slice(&dir.path().join("odd.dcm"), SliceAt { series: "1.2.3.4", instance: 99, z: 10.0 }, [5, 4], &ct_values(4, 5, 0), ts);
    let e = load_err(dir.path());
    assert!(e.contains("odd.dcm") && e.contains("slice size"), "{e}");
    // Duplicated position.
    let dir = tempfile::tempdir().unwrap();
    ct_series(dir.path(), ts);
    ct_slice(&dir.path().join("dup.dcm"), SliceAt { series: "1.2.3.4", instance: 98, z: 5.0 }, [3, 4], &ct_values(4, 3, 0), ts);
    let e = load_err(dir.path());
    assert!(e.contains("same position"), "{e}");
    // A gap (missing slice).
    let dir = tempfile::tempdir().unwrap();
    ct_series(dir.path(), ts);
    ct_slice(&dir.path().join("far.dcm"), SliceAt { series: "1.2.3.4", instance: 97, z: 20.0 }, [3, 4], &ct_values(4, 3, 0), ts);
    let e = load_err(dir.path());
    assert!(e.contains("inconsistent slice positions"), "{e}");
    // Two series in one directory.
    let dir = tempfile::tempdir().unwrap();
    ct_series(dir.path(), ts);
    ct_slice(&dir.path().join("other.dcm"), SliceAt { series: "9.9.9", instance: 1, z: 0.0 }, [3, 4], &ct_values(4, 3, 0), ts);
    let e = load_err(dir.path());
    assert!(e.contains("2 DICOM series"), "{e}");
    // ... but naming a file of the other series loads it alone.
    let v = load(&dir.path().join("other.dcm"), &opts()).unwrap();
    assert_eq!(v.dims(), [4, 3, 1]);
    assert_eq!(v.spacing(), [0.5, 0.75, 9.0]);
    // Truncated pixel data.
    let dir = tempfile::tempdir().unwrap();
    let files = ct_series(dir.path(), ts);
    let b = std::fs::read(&files[1]).unwrap();
    std::fs::write(&files[1], &b[..b.len() - 7]).unwrap();
    let e = load_err(dir.path());
    assert!(e.contains("img01.dcm"), "{e}");
    // An element length that claims 64 KiB in a small file.
    let dir = tempfile::tempdir().unwrap();
    let files = ct_series(dir.path(), ts);
    let mut b = std::fs::read(&files[0]).unwrap();
    let at = b.windows(4).position(|w| w == [0x08, 0x00, 0x60, 0x00]).unwrap(); // (0008,0060) Modality
    b[at + 6..at + 8].copy_from_slice(&0xFFFFu16.to_le_bytes());
    std::fs::write(&files[0], &b).unwrap();
    let e = load_err(dir.path());
    assert!(e.contains("img00.dcm") && e.contains("claims"), "{e}");
    // No DICOM at all, and a missing path.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("a.txt"), "hello").unwrap();
    assert!(load_err(dir.path()).contains("no DICOM"));
    let missing = dir.path().join("gone");
    let e = load(&missing, &LoadOptions { format: Some(Format::Dicom), raw: None }).unwrap_err();
    assert!(matches!(e, Error::Io { .. }), "{e}");
}

// ---------------------------------------------------------------- den

#[test]
fn den_round_trip_and_rejections() {
    let dir = tempfile::tempdir().unwrap();
    let voxels: Vec<u8> = (0..60).map(|i| (i * 3) as u8).collect();
    let p = dir.path().join("v.den");
    den::save_den(&p, DIMS, &voxels).unwrap();
    let v = load(&p, &opts()).unwrap();
    assert_eq!(v.dims(), DIMS);
    assert_eq!(v.data(), &VoxelData::U8(voxels.clone()));
    // The byte-swapped header of a big-endian writer.
    let mut b = std::fs::read(&p).unwrap();
    for i in (0..58).step_by(2) {
        b.swap(i, i + 1);
    }
    b[58..62].reverse();
    let pb = dir.path().join("be.den");
    std::fs::write(&pb, &b).unwrap();
    assert_eq!(load(&pb, &opts()).unwrap(), v);
    // Sniffed without the extension.
    let pn = dir.path().join("noext");
    std::fs::copy(&p, &pn).unwrap();
    assert_eq!(Format::infer(&pn).unwrap(), Format::Den);
    let good = std::fs::read(&p).unwrap();
    let mut cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("trunc.den", good[..good.len() - 1].to_vec(), "truncated"),
        ("extra.den", [good.clone(), vec![0]].concat(), "more than expected"),
        ("short.den", good[..30].to_vec(), "truncated"),
    ];
    let mut b = good.clone();
    b[0] = 7;
    cases.push(("magic.den", b, "not a VolPack"));
    let mut b = good.clone();
    b[58] = 61;
    cases.push(("len.den", b, "inconsistent"));
    let mut b = good.clone();
    b[52..54].copy_from_slice(&(-4i16).to_le_bytes());
    cases.push(("neg.den", b, "positive"));
    for (name, bytes, want) in cases {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        let e = load_err(&p);
        assert!(e.contains(want) && e.contains(name), "{name}: '{e}' lacks '{want}'");
    }
}

// ---------------------------------------------------------------- raw

#[test]
fn raw_spec_sidecars_and_rejections() {
    let dir = tempfile::tempdir().unwrap();
    let body = i16_bytes(true);
    let p = dir.path().join("v.raw");
    let mut with_header = vec![9u8; 16];
    with_header.extend(&body);
    std::fs::write(&p, &with_header).unwrap();
    let spec = RawSpec { dims: DIMS, voxel_type: VoxelType::I16, big_endian: true, spacing: [0.5, 0.75, 2.5], header_bytes: 16 };
    let o = LoadOptions { format: None, raw: Some(spec.clone()) };
    check_i16_volume(&load(&p, &o).unwrap());
    // Without header_bytes the 16 extra bytes are an error; one byte short is truncation.
    let e = load(&p, &LoadOptions { raw: Some(RawSpec { header_bytes: 0, ..spec.clone() }), ..o.clone() }).unwrap_err().to_string();
    assert!(e.contains("16 bytes more"), "{e}");
    let e = load(&p, &LoadOptions { raw: Some(RawSpec { header_bytes: 17, ..spec.clone() }), ..o.clone() }).unwrap_err().to_string();
    assert!(e.contains("truncated"), "{e}");
    // Sidecar FILE.raw.json.
    std::fs::write(
        dir.path().join("v.raw.json"),
        r#"{"dims":[5,4,3],"type":"i16","endian":"big","spacing":[0.5,0.75,2.5],"header_bytes":16}"#,
    )
    .unwrap();
    let v = load(&p, &opts()).unwrap();
    check_i16_volume(&v);
    assert_eq!(v.spacing(), [0.5, 0.75, 2.5]);
    // Sidecar FILE.json, for a file without the .raw extension (found by the sidecar).
    let q = dir.path().join("w.bin");
    std::fs::write(&q, i16_bytes(false)).unwrap();
    std::fs::write(dir.path().join("w.json"), r#"{"dims":[5,4,3],"type":"i16"}"#).unwrap();
    assert_eq!(Format::infer(&q).unwrap(), Format::Raw);
    check_i16_volume(&load(&q, &opts()).unwrap());
    // Bad sidecars and none at all.
    for (json, want) in [
        (r#"{"dims":[5,4],"type":"i16"}"#, "not valid"),
        (r#"{"dims":[5,4,3],"type":"i64"}"#, "i64"),
        (r#"{"dims":[5,0,3],"type":"u8"}"#, "at least 1"),
        (r#"{"dims":[5,4,3],"type":"u8","endian":"middle"}"#, "middle"),
        (r#"{"dims":[5,4,3],"type":"u8","colour":1}"#, "unknown field"),
        ("not json", "not valid"),
    ] {
        std::fs::write(dir.path().join("w.json"), json).unwrap();
        let e = load_err(&q);
        assert!(e.contains(want) && e.contains("w.json"), "{json}: '{e}'");
    }
    let r = dir.path().join("lonely.raw");
    std::fs::write(&r, [0u8; 8]).unwrap();
    assert!(load_err(&r).contains("lonely.raw.json"));
    // Writing and reading back every voxel type.
    for data in [
        VoxelData::U8(vec![1, 2, 3, 4, 5, 6]),
        VoxelData::U16(vec![1, 2, 3, 65535, 5, 6]),
        VoxelData::I16(vec![-1, 2, -3, 4, -32768, 6]),
        VoxelData::F32(vec![0.1, 2.5, -3.0, 4e9, 5.0, 1e-9]),
    ] {
        let v = Volume::new([3, 2, 1], [0.3, 1.0 / 3.0, 7.0], data).unwrap();
        let p = dir.path().join(format!("rt-{}.raw", v.data().voxel_type().name()));
        save_raw(&v, &p).unwrap();
        assert_eq!(load(&p, &opts()).unwrap(), v);
    }
}

#[test]
fn format_inference_and_missing_files() {
    let dir = tempfile::tempdir().unwrap();
    for (name, want) in [
        ("a.NRRD", Format::Nrrd),
        ("a.nhdr", Format::Nrrd),
        ("a.nii", Format::Nifti),
        ("a.nii.gz", Format::Nifti),
        ("a.den", Format::Den),
        ("a.dcm", Format::Dicom),
        ("a.raw", Format::Raw),
    ] {
        let p = dir.path().join(name);
        std::fs::write(&p, b"x").unwrap();
        assert_eq!(Format::infer(&p).unwrap(), want, "{name}");
    }
    assert_eq!(Format::infer(dir.path()).unwrap(), Format::Dicom);
    let p = dir.path().join("mystery.dat");
    std::fs::write(&p, b"nothing recognisable here").unwrap();
    let e = Format::infer(&p).unwrap_err().to_string();
    assert!(e.contains("mystery.dat") && e.contains("format"), "{e}");
    let gone = dir.path().join("gone.nrrd");
    assert!(matches!(load(&gone, &opts()).unwrap_err(), Error::Io { .. }));
    let gone = dir.path().join("gone");
    assert!(matches!(Format::infer(&gone).unwrap_err(), Error::Io { .. }));
    // Devices (and FIFOs) are refused instead of read.
    let o = LoadOptions { format: Some(Format::Raw), raw: None };
    let e = load(Path::new("/dev/zero"), &o).unwrap_err();
    assert!(e.to_string().contains("not a regular file"), "{e}");
    assert!(Format::infer(Path::new("/dev/null")).is_err());
}

#[test]
fn dicom_missing_slice_names_its_neighbours() {
    // slices at z = 0, 2.5, …, 17.5 without the one at 7.5: the error names
    // the two slices around the hole (it used to name the first slice whose
    // gap differed from the mean, which the hole itself inflates)
    let dir = tempfile::tempdir().unwrap();
    let ts = dicom_dictionary_std::uids::EXPLICIT_VR_LITTLE_ENDIAN;
    for k in (0..8).filter(|&k| k != 3) {
        ct_slice(
            &dir.path().join(format!("k{k}.dcm")),
            SliceAt { series: "1.2.3.5", instance: 10 + k, z: k as f64 * 2.5 },
            [3, 4],
            &ct_values(4, 3, 0),
            ts,
        );
    }
    let e = load_err(dir.path());
    assert!(e.contains("k4.dcm") && e.contains("k2.dcm"), "{e}");
    assert!(e.contains("5.0000 mm") && e.contains("2.5000 mm apart") && e.contains("1 slice(s) missing"), "{e}");
    assert!(!e.contains("k1.dcm") && !e.contains("k0.dcm"), "{e}");
}
