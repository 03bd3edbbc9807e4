//! Property tests that throw malformed input at every loader: valid
//! synthetic files (and, when `$SHEARWARP_DATA` is set, heads of the real
//! scans) mutated by truncation, byte flips, inserted and deleted runs,
//! binary header words set to extreme values and header numbers replaced by
//! huge, zero or negative ones — plus plain random bytes.
//!
//! The property: the loader returns (`Ok` or `Err`) — it never panics, every
//! input finishes within 5 s, and the process's peak memory stays
//! under [`MAX_RSS_MIB`]. Each loader gets `IO_FUZZ_CASES` inputs (default
//! 10,000) from a fixed seed; `IO_FUZZ_RANDOM=1` draws a fresh seed instead.
//! Each test prints its input count, time and slowest input.
//!
//! The mesh readers (OBJ, STL ASCII and binary, PLY ASCII and binary) get
//! the same treatment (`fuzz_obj`, `fuzz_stl`, `fuzz_ply`, behind `#[ignore]`:
//! `cargo test --release --test io_fuzz -- --ignored mesh_`), each loaded
//! within a memory budget as the command line does.

use std::cell::Cell;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use dicom_core::value::C;
use dicom_core::{DataElement, PrimitiveValue, VR};
use dicom_dictionary_std::{tags, uids};
use dicom_object::{FileMetaTableBuilder, InMemDicomObject};
use flate2::Compression;
use flate2::write::GzEncoder;
use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
use shearwarp::Volume;
use shearwarp::data::io::{Format, LoadOptions, RawSpec, load};
use shearwarp::data::volume::VoxelType;

/// Longest time one input may take (`IO_FUZZ_MAX_MS` overrides).
fn max_case() -> Duration {
    let ms = std::env::var("IO_FUZZ_MAX_MS").ok().and_then(|s| s.parse().ok()).unwrap_or(5_000);
    Duration::from_millis(ms)
}
/// Largest peak resident memory of the test process, in MiB.
const MAX_RSS_MIB: u64 = 1536;

fn cases() -> u32 {
    std::env::var("IO_FUZZ_CASES").ok().and_then(|s| s.parse().ok()).unwrap_or(10_000)
}

fn runner() -> TestRunner {
    let config = Config { cases: cases(), failure_persistence: None, max_shrink_iters: 2_000, ..Config::default() };
    if std::env::var_os("IO_FUZZ_RANDOM").is_some() {
        TestRunner::new(config)
    } else {
        TestRunner::new_with_rng(config, TestRng::deterministic_rng(RngAlgorithm::ChaCha))
    }
}

/// A temp dir in memory (`/dev/shm`) where there is one: the suite writes a
/// file per input, and on a busy disk that, not the loaders, dominates.
fn scratch() -> tempfile::TempDir {
    let shm = Path::new("/dev/shm");
    if shm.is_dir()
        && let Ok(d) = tempfile::Builder::new().prefix("io_fuzz").tempdir_in(shm)
    {
        return d;
    }
    tempfile::tempdir().unwrap()
}

/// Peak resident set size of this process, in MiB (0 where unknown).
fn peak_rss_mib() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        .map_or(0, |kb| kb / 1024)
}

/// Runs `cases()` volume inputs through `run` (see [`fuzz_with`]); a volume
/// that loads holds as many voxels as its dims say.
fn fuzz<S: Strategy>(name: &str, strategy: S, run: impl Fn(S::Value) -> shearwarp::Result<Volume>) {
    fuzz_with(name, strategy, run, |v| {
        let d = v.dims();
        prop_assert_eq!(v.len(), d[0] * d[1] * d[2]);
        Ok(())
    });
}

/// Runs `cases()` inputs through `run`, checks every input's time, `check`s
/// what loads, checks the peak memory and prints the figures.
fn fuzz_with<S: Strategy, T>(
    name: &str,
    strategy: S,
    run: impl Fn(S::Value) -> shearwarp::Result<T>,
    check: impl Fn(&T) -> Result<(), TestCaseError>,
) {
    let (n, ok, slowest) = (Cell::new(0u64), Cell::new(0u64), Cell::new(Duration::ZERO));
    let start = Instant::now();
    let result = runner().run(&strategy, |input| {
        let t = Instant::now();
        let r = run(input);
        let dt = t.elapsed();
        n.set(n.get() + 1);
        slowest.set(slowest.get().max(dt));
        prop_assert!(dt < max_case(), "one input took {dt:?}");
        if let Ok(loaded) = r {
            ok.set(ok.get() + 1);
            check(&loaded)?;
        }
        Ok(())
    });
    let secs = start.elapsed().as_secs_f64();
    let rss = peak_rss_mib();
    println!(
        "io_fuzz {name}: {} inputs ({} loaded, {} rejected) in {secs:.2} s, slowest {:.1} ms, peak RSS {rss} MiB",
        n.get(),
        ok.get(),
        n.get() - ok.get(),
        slowest.get().as_secs_f64() * 1e3
    );
    if let Err(e) = result {
        panic!("{name}: {e}");
    }
    assert!(n.get() >= cases() as u64, "{name}: only {} inputs ran", n.get());
    assert!(rss < MAX_RSS_MIB, "{name}: peak RSS {rss} MiB");
}

// ------------------------------------------------------------ mutations

/// One edit of a file's bytes. Positions are fractions (of 1e6) of the
/// whole file, or of its first 512 bytes when `head` is set.
#[derive(Clone, Debug)]
enum Mut {
    Truncate(u32),
    Xor(bool, u32, u8),
    Insert(bool, u32, Vec<u8>),
    Remove(bool, u32, u16),
    Word(bool, u32, u8, u32, bool),
    Number(u16, &'static str),
}

const WORDS: [u32; 16] =
    [0, 1, 2, 3, 0x7f, 0x80, 0xff, 0x100, 0x7fff, 0x8000, 0xffff, 0x1_0000, 0x7fff_ffff, 0x8000_0000, 0xffff_fffe, 0xffff_ffff];

const NUMBERS: [&str; 14] = [
    "0",
    "-1",
    "-7",
    "1",
    "100000",
    "65536",
    "4294967296",
    "18446744073709551617",
    "99999999999999999999999",
    "1e308",
    "nan",
    "",
    "3.5",
    "16384",
];

fn mutation() -> impl Strategy<Value = Mut> {
    prop_oneof![
        (0u32..1_000_000).prop_map(Mut::Truncate),
        (any::<bool>(), 0u32..1_000_000, 1u8..=255).prop_map(|(h, p, x)| Mut::Xor(h, p, x)),
        (any::<bool>(), 0u32..1_000_000, prop::collection::vec(any::<u8>(), 1..64)).prop_map(|(h, p, b)| Mut::Insert(h, p, b)),
        (any::<bool>(), 0u32..1_000_000, 1u16..512).prop_map(|(h, p, n)| Mut::Remove(h, p, n)),
        (
            any::<bool>(),
            0u32..1_000_000,
            prop_oneof![Just(2u8), Just(4u8)],
            prop_oneof![3 => prop::sample::select(&WORDS[..]), 1 => any::<u32>()],
            any::<bool>()
        )
            .prop_map(|(h, p, w, v, big)| Mut::Word(h, p, w, v, big)),
        (any::<u16>(), prop::sample::select(&NUMBERS[..])).prop_map(|(i, s)| Mut::Number(i, s)),
    ]
}

fn position(len: usize, head: bool, frac: u32) -> usize {
    let span = if head { len.min(512) } else { len };
    (span as u64 * frac as u64 / 1_000_000) as usize
}

fn apply(mut b: Vec<u8>, muts: &[Mut]) -> Vec<u8> {
    for m in muts {
        let len = b.len();
        match m {
            Mut::Truncate(f) => b.truncate(position(len, false, *f)),
            Mut::Xor(h, f, x) => {
                if len > 0 {
                    let p = position(len, *h, *f).min(len - 1);
                    b[p] ^= x;
                }
            }
            Mut::Insert(h, f, bytes) => {
                let p = position(len, *h, *f);
                b.splice(p..p, bytes.iter().copied());
            }
            Mut::Remove(h, f, n) => {
                let p = position(len, *h, *f);
                let e = (p + *n as usize).min(len);
                b.drain(p..e);
            }
            Mut::Word(h, f, w, v, big) => {
                let w = *w as usize;
                if len >= w {
                    let p = position(len, *h, *f).min(len - w);
                    let bytes = if *big { v.to_be_bytes() } else { v.to_le_bytes() };
                    let bytes = if w == 2 { &bytes[if *big { 2 } else { 0 }..][..2] } else { &bytes[..] };
                    b[p..p + w].copy_from_slice(bytes);
                }
            }
            Mut::Number(i, s) => {
                // Replace the i-th run of digits (with its sign) in the first 4 KiB.
                let scan = len.min(4096);
                let mut runs = Vec::new();
                let mut k = 0;
                while k < scan {
                    if b[k].is_ascii_digit() {
                        let start = if k > 0 && b[k - 1] == b'-' { k - 1 } else { k };
                        while k < scan && (b[k].is_ascii_digit() || b[k] == b'.') {
                            k += 1;
                        }
                        runs.push((start, k));
                    } else {
                        k += 1;
                    }
                }
                if !runs.is_empty() {
                    let (s0, e0) = runs[*i as usize % runs.len()];
                    b.splice(s0..e0, s.bytes());
                }
            }
        }
    }
    b
}

/// An input: a seed (by index) with edits, gzipped after editing when
/// `regzip`; or plain random bytes.
#[derive(Clone, Debug)]
enum Input {
    Mutated { seed: usize, muts: Vec<Mut>, regzip: bool },
    Random(Vec<u8>),
}

fn inputs(n_seeds: usize) -> impl Strategy<Value = Input> {
    prop_oneof![
        9 => (0..n_seeds, prop::collection::vec(mutation(), 1..5), prop::bool::weighted(0.2))
            .prop_map(|(seed, muts, regzip)| Input::Mutated { seed, muts, regzip }),
        1 => prop::collection::vec(any::<u8>(), 0..2048).prop_map(Input::Random),
    ]
}

fn gz(bytes: &[u8]) -> Vec<u8> {
    let mut e = GzEncoder::new(Vec::new(), Compression::fast());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

fn gunzip_head(bytes: &[u8], n: u64) -> Vec<u8> {
    let mut out = Vec::new();
    let _ = flate2::read::MultiGzDecoder::new(bytes).take(n).read_to_end(&mut out);
    out
}

fn realize(seeds: &[Vec<u8>], input: &Input) -> Vec<u8> {
    match input {
        Input::Mutated { seed, muts, regzip } => {
            let b = apply(seeds[*seed].clone(), muts);
            if *regzip { gz(&b) } else { b }
        }
        Input::Random(b) => b.clone(),
    }
}

fn real(name: &str) -> Option<Vec<u8>> {
    let dir = std::env::var_os("SHEARWARP_DATA").filter(|d| !d.is_empty())?;
    std::fs::read(PathBuf::from(dir).join(name)).ok()
}

fn with(format: Format) -> LoadOptions {
    LoadOptions { format: Some(format), raw: None }
}

// ------------------------------------------------------------ seeds

fn voxel_bytes(n: usize, size: usize, big: bool) -> Vec<u8> {
    (0..n)
        .flat_map(|i| {
            let v = (i as u32).wrapping_mul(2654435761) >> 20;
            let b = if big { v.to_be_bytes() } else { v.to_le_bytes() };
            if big { b[4 - size..].to_vec() } else { b[..size].to_vec() }
        })
        .collect()
}

fn nrrd_seeds() -> Vec<Vec<u8>> {
    let mut seeds = Vec::new();
    let hdr = |typ: &str, sizes: &str, endian: &str, enc: &str, extra: &str| {
        format!(
            "NRRD0004\n# comment\ntype: {typ}\ndimension: {}\nsizes: {sizes}\n{extra}endian: {endian}\nencoding: {enc}\n\n",
            sizes.split(' ').count()
        )
    };
    for (typ, size) in [("short", 2), ("uchar", 1), ("float", 4), ("unsigned short", 2)] {
        for big in [false, true] {
            let endian = if big { "big" } else { "little" };
            let body = voxel_bytes(60, size, big);
            let dirs = "space directions: (0.5,0,0) (0,0.5,0) (0,0,2)\nspace dimension: 3\n";
            let mut f = hdr(typ, "5 4 3", endian, "raw", dirs).into_bytes();
            f.extend(&body);
            seeds.push(f);
            let mut f = hdr(typ, "5 4 3", endian, "gzip", "spacings: 1 1 3\n").into_bytes();
            f.extend(gz(&body));
            seeds.push(f);
        }
    }
    let mut f = hdr("short", "1 5 4 3", "little", "raw", "space directions: none (1,0,0) (0,1,0) (0,0,1)\n").into_bytes();
    f.extend(voxel_bytes(60, 2, false));
    seeds.push(f);
    let mut f = hdr("uchar", "5 4 3", "little", "raw", "byte skip: -1\nline skip: 0\n").into_bytes();
    f.extend(voxel_bytes(60, 1, false));
    seeds.push(f);
    if let Some(chest) = real("chest-ct-lung1.nrrd") {
        let end = chest.windows(2).position(|w| w == b"\n\n").map_or(chest.len(), |p| p + 2);
        seeds.push(chest[..(end + 2048).min(chest.len())].to_vec());
    }
    seeds
}

fn nifti_seed(arr_kind: u8, big: bool, slope: Option<(f32, f32)>) -> Vec<u8> {
    let dir = scratch();
    let p = dir.path().join("s.nii");
    let hdr = nifti::NiftiHeader {
        endianness: if big { nifti::Endianness::Big } else { nifti::Endianness::Little },
        pixdim: [1.0, 0.5, 0.5, 2.0, 1.0, 1.0, 1.0, 1.0],
        ..Default::default()
    };
    let w = nifti::writer::WriterOptions::new(&p).reference_header(&hdr);
    match arr_kind {
        0 => w.write_nifti(&ndarray::Array3::from_shape_fn((5, 4, 3), |(x, y, z)| (x + 5 * y + 20 * z) as u8)),
        1 => w.write_nifti(&ndarray::Array3::from_shape_fn((5, 4, 3), |(x, y, z)| (x * 100) as i16 - (y * z) as i16)),
        2 => w.write_nifti(&ndarray::Array3::from_shape_fn((5, 4, 3), |(x, y, z)| x as f32 * 0.5 + (y + z) as f32)),
        _ => w.write_nifti(&ndarray::Array4::from_shape_fn((5, 4, 3, 1), |(x, y, z, _)| (x + y + z) as u16)),
    }
    .unwrap();
    let mut b = std::fs::read(&p).unwrap();
    if let Some((s, i)) = slope {
        let put = |b: &mut Vec<u8>, at: usize, v: f32| b[at..at + 4].copy_from_slice(&if big { v.to_be_bytes() } else { v.to_le_bytes() });
        put(&mut b, 112, s);
        put(&mut b, 116, i);
    }
    b
}

fn nifti_seeds() -> Vec<Vec<u8>> {
    let mut seeds = vec![
        nifti_seed(0, false, None),
        nifti_seed(1, true, None),
        nifti_seed(2, false, None),
        nifti_seed(3, false, None),
        nifti_seed(1, false, Some((0.5, -3.0))),
        nifti_seed(0, true, Some((2.0, 1.0))),
    ];
    seeds.push(gz(&seeds[0]));
    seeds.push(gz(&seeds[1]));
    if let Some(ch2) = real("head-mri-ch2.nii.gz") {
        let head = gunzip_head(&ch2, 352 + 4096);
        seeds.push(gz(&head));
        seeds.push(head);
    }
    seeds
}

/// How a DICOM seed stores its pixels.
#[derive(Clone, Copy, PartialEq)]
enum Pixels {
    Native16,
    Native8,
    Rle8,
    Rle16,
    Jpeg8,
}

/// PackBits-encodes `bytes` as literal runs (what an RLE Lossless segment holds).
fn packbits(bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    for chunk in bytes.chunks(128) {
        out.push((chunk.len() - 1) as u8);
        out.extend_from_slice(chunk);
    }
    out
}

/// An RLE Lossless frame of `segments` (one per byte plane, MSB first).
fn rle_frame(segments: &[Vec<u8>]) -> Vec<u8> {
    let mut header = vec![0u8; 64];
    header[..4].copy_from_slice(&(segments.len() as u32).to_le_bytes());
    let mut body = Vec::new();
    for (i, seg) in segments.iter().enumerate() {
        let off = 64 + body.len() as u32;
        header[4 + 4 * i..8 + 4 * i].copy_from_slice(&off.to_le_bytes());
        body.extend(packbits(seg));
    }
    header.extend(body);
    if header.len() % 2 == 1 {
        header.push(0);
    }
    header
}

fn dicom_seed(ts: &str, with_sequence: bool, pixels: Pixels) -> Vec<u8> {
    type Elem = dicom_object::mem::InMemElement;
    let el = |tag, vr, v: PrimitiveValue| -> Elem { DataElement::new(tag, vr, v) };
    let bits: u16 = if matches!(pixels, Pixels::Native8 | Pixels::Rle8 | Pixels::Jpeg8) { 8 } else { 16 };
    let values16: Vec<u16> = (0..20u16).map(|i| i * 97).collect();
    let values8: Vec<u8> = (0..20u8).map(|i| i * 11).collect();
    let pixel_element = match pixels {
        Pixels::Native16 => el(tags::PIXEL_DATA, VR::OW, PrimitiveValue::U16(C::from_vec(values16.clone()))),
        Pixels::Native8 | Pixels::Jpeg8 => el(tags::PIXEL_DATA, VR::OB, PrimitiveValue::from(values8.clone())),
        Pixels::Rle8 => Elem::new(
            tags::PIXEL_DATA,
            VR::OB,
            dicom_core::value::PixelFragmentSequence::new(C::<u32>::new(), vec![rle_frame(std::slice::from_ref(&values8))]),
        ),
        Pixels::Rle16 => {
            let hi: Vec<u8> = values16.iter().map(|v| (v >> 8) as u8).collect();
            let lo: Vec<u8> = values16.iter().map(|v| *v as u8).collect();
            Elem::new(tags::PIXEL_DATA, VR::OB, dicom_core::value::PixelFragmentSequence::new(C::<u32>::new(), vec![rle_frame(&[hi, lo])]))
        }
    };
    let mut elems = vec![
        el(tags::SOP_CLASS_UID, VR::UI, uids::CT_IMAGE_STORAGE.into()),
        el(tags::SOP_INSTANCE_UID, VR::UI, "1.2.826.0.1.3680043.10.99.1".into()),
        el(tags::MODALITY, VR::CS, "CT".into()),
        el(tags::SERIES_INSTANCE_UID, VR::UI, "1.2.3".into()),
        el(tags::IMAGE_POSITION_PATIENT, VR::DS, "0\\0\\5".into()),
        el(tags::IMAGE_ORIENTATION_PATIENT, VR::DS, "1\\0\\0\\0\\1\\0".into()),
        el(tags::PIXEL_SPACING, VR::DS, "0.5\\0.5".into()),
        el(tags::SAMPLES_PER_PIXEL, VR::US, 1u16.into()),
        el(tags::PHOTOMETRIC_INTERPRETATION, VR::CS, "MONOCHROME2".into()),
        el(tags::ROWS, VR::US, 4u16.into()),
        el(tags::COLUMNS, VR::US, 5u16.into()),
        el(tags::BITS_ALLOCATED, VR::US, bits.into()),
        el(tags::BITS_STORED, VR::US, if bits == 8 { 8u16 } else { 12 }.into()),
        el(tags::HIGH_BIT, VR::US, if bits == 8 { 7u16 } else { 11 }.into()),
        el(tags::PIXEL_REPRESENTATION, VR::US, if bits == 8 { 0u16 } else { 1 }.into()),
        el(tags::RESCALE_INTERCEPT, VR::DS, "-1024".into()),
        el(tags::RESCALE_SLOPE, VR::DS, "1.5".into()),
        pixel_element,
    ];
    if with_sequence {
        let item = InMemDicomObject::from_element_iter([
            el(tags::REFERENCED_SOP_CLASS_UID, VR::UI, uids::CT_IMAGE_STORAGE.into()),
            el(tags::REFERENCED_SOP_INSTANCE_UID, VR::UI, "1.2.3.4.5".into()),
        ]);
        elems.push(DataElement::new(
            tags::REFERENCED_IMAGE_SEQUENCE,
            VR::SQ,
            dicom_core::value::DataSetSequence::from(vec![item.clone(), item]),
        ));
    }
    let obj = InMemDicomObject::from_element_iter(elems);
    let mut file = obj.with_meta(FileMetaTableBuilder::new().transfer_syntax(ts)).unwrap();
    if pixels == Pixels::Jpeg8 {
        use dicom_pixeldata::Transcode;
        file.transcode(&dicom_transfer_syntax_registry::entries::JPEG_BASELINE.erased()).unwrap();
    }
    let dir = scratch();
    let p = dir.path().join("s.dcm");
    file.write_to_file(&p).unwrap();
    std::fs::read(&p).unwrap()
}

fn dicom_seeds() -> Vec<Vec<u8>> {
    let (ele, ile, rle) = (uids::EXPLICIT_VR_LITTLE_ENDIAN, uids::IMPLICIT_VR_LITTLE_ENDIAN, "1.2.840.10008.1.2.5");
    let mut seeds = vec![
        dicom_seed(ele, false, Pixels::Native16),
        dicom_seed(ele, true, Pixels::Native16),
        dicom_seed(ile, true, Pixels::Native16),
        dicom_seed("1.2.840.10008.1.2.2", true, Pixels::Native16),
        dicom_seed(ele, false, Pixels::Native8),
        dicom_seed(rle, false, Pixels::Rle8),
        dicom_seed(rle, true, Pixels::Rle16),
        dicom_seed(ele, false, Pixels::Jpeg8),
    ];
    if let Some(b) = real("dicom-brain-pd/brain_002.dcm") {
        seeds.push(b);
    }
    seeds
}

fn den_seeds() -> Vec<Vec<u8>> {
    let dir = scratch();
    let p = dir.path().join("s.den");
    shearwarp::data::io::den::save_den(&p, [5, 4, 3], &voxel_bytes(60, 1, false)).unwrap();
    let le = std::fs::read(&p).unwrap();
    let mut be = le.clone();
    for i in (0..58).step_by(2) {
        be.swap(i, i + 1);
    }
    be[58..62].reverse();
    let mut seeds = vec![le, be];
    if let Some(b) = real("brainsmall.den") {
        seeds.push(b[..62 + 4096].to_vec());
    }
    seeds
}

// ------------------------------------------------------------ the tests

#[test]
fn fuzz_nrrd() {
    let seeds = nrrd_seeds();
    let dir = scratch();
    std::fs::write(dir.path().join("d.raw"), voxel_bytes(60, 2, false)).unwrap();
    let detached = b"NRRD0004\ntype: short\ndimension: 3\nsizes: 5 4 3\nspacings: 1 2 3\nendian: little\n\
        encoding: raw\ndata file: d.raw\nbyte skip: 0\n"
        .to_vec();
    let mut all = seeds.clone();
    all.push(detached);
    let n = all.len();
    fuzz("nrrd", inputs(n), |input| {
        let bytes = realize(&all, &input);
        let is_detached = matches!(input, Input::Mutated { seed, .. } if seed == n - 1);
        let p = dir.path().join(if is_detached { "f.nhdr" } else { "f.nrrd" });
        std::fs::write(&p, &bytes).unwrap();
        load(&p, &with(Format::Nrrd))
    });
}

#[test]
fn fuzz_nifti() {
    let seeds = nifti_seeds();
    let dir = scratch();
    fuzz("nifti", inputs(seeds.len()), |input| {
        let p = dir.path().join("f.nii");
        std::fs::write(&p, realize(&seeds, &input)).unwrap();
        load(&p, &with(Format::Nifti))
    });
}

#[test]
fn fuzz_dicom() {
    let seeds = dicom_seeds();
    let dir = scratch();
    let series = dir.path().join("series");
    std::fs::create_dir(&series).unwrap();
    // A valid companion slice 5 mm above the seeds (only the synthetic seeds share its series).
    let mut companion = dicom_seed(uids::EXPLICIT_VR_LITTLE_ENDIAN, false, Pixels::Native16);
    let at = companion.windows(5).position(|w| w == b"0\\0\\5").unwrap();
    companion[at..at + 5].copy_from_slice(b"0\\0\\0");
    let strategy = (inputs(seeds.len()), any::<bool>());
    fuzz("dicom", strategy, |(input, pair)| {
        let a = series.join("a.dcm");
        let b = series.join("b.dcm");
        std::fs::write(&a, realize(&seeds, &input)).unwrap();
        if pair {
            std::fs::write(&b, &companion).unwrap();
        } else {
            let _ = std::fs::remove_file(&b);
        }
        load(&series, &with(Format::Dicom))
    });
}

#[test]
fn fuzz_den() {
    let seeds = den_seeds();
    let dir = scratch();
    fuzz("den", inputs(seeds.len()), |input| {
        let p = dir.path().join("f.den");
        std::fs::write(&p, realize(&seeds, &input)).unwrap();
        load(&p, &with(Format::Den))
    });
}

#[test]
fn fuzz_raw() {
    // Half the inputs mutate a sidecar (and the data's length); half give a
    // random RawSpec (zero, huge and odd dims, header sizes) for random data.
    let sidecar = br#"{"dims":[5,4,3],"type":"u16","endian":"big","spacing":[0.5,0.5,2],"header_bytes":4}"#.to_vec();
    let data = voxel_bytes(64, 2, true)[..124].to_vec();
    let seeds = [sidecar, data];
    let dir = scratch();
    let dim = prop_oneof![
        8 => 1usize..6,
        1 => Just(0usize),
        1 => Just(1usize << 14),
        1 => Just((1usize << 14) + 1),
        1 => Just(100_000usize),
        1 => any::<usize>(),
    ];
    let ty = prop::sample::select(&[VoxelType::U8, VoxelType::U16, VoxelType::I16, VoxelType::F32][..]);
    let spec = ([dim.clone(), dim.clone(), dim], ty, any::<bool>(), prop_oneof![4 => 0u64..16, 1 => any::<u64>()], 0usize..512).prop_map(
        |(dims, voxel_type, big_endian, header_bytes, len)| {
            (RawSpec { dims, voxel_type, big_endian, spacing: [1.0, 1.0, 1.0], header_bytes }, len)
        },
    );
    // A well-formed sidecar with extreme field values, and data whose length
    // is exact, off by a few bytes, or arbitrary.
    let json_num = prop::sample::select(&["3", "2", "1", "4", "5", "0", "-1", "16385", "100000", "1e9", "2.5", "\"x\""][..]);
    let json_f = prop::sample::select(&["1", "0.5", "2", "1", "0", "-1", "1e30", "\"nan\""][..]);
    let side_json = (
        [json_num.clone(), json_num.clone(), json_num.clone()],
        prop::sample::select(&["u8", "u16", "i16", "f32", "float", "i64", ""][..]),
        prop::sample::select(&["little", "big", "middle"][..]),
        [json_f.clone(), json_f.clone(), json_f],
        prop_oneof![3 => Just("0"), 2 => Just("4"), 1 => Just("-4"), 1 => Just("18446744073709551615")],
        -3i64..=3,
        prop::bool::weighted(0.7),
    )
        .prop_map(|(d, t, e, sp, hb, delta, exact)| {
            let json = format!(
                r#"{{"dims":[{},{},{}],"type":"{t}","endian":"{e}","spacing":[{},{},{}],"header_bytes":{hb}}}"#,
                d[0], d[1], d[2], sp[0], sp[1], sp[2]
            );
            let size = match t {
                "u8" => 1,
                "u16" | "i16" => 2,
                _ => 4,
            };
            let n: i64 = d.iter().map(|x| x.parse::<i64>().unwrap_or(1).clamp(0, 64)).product();
            let len = (n * size + hb.parse::<i64>().unwrap_or(0).clamp(0, 64) + if exact { 0 } else { delta }).max(0);
            (json.into_bytes(), voxel_bytes(len as usize, 1, false))
        });
    let strategy = prop_oneof![
        (inputs(2), inputs(2)).prop_map(|(s, d)| (Some((s, d)), None, None)),
        spec.prop_map(|s| (None, Some(s), None)),
        side_json.prop_map(|j| (None, None, Some(j))),
    ];
    fuzz("raw", strategy, |(side, spec, json)| {
        let p = dir.path().join("f.raw");
        match (side, spec, json) {
            (Some((s, d)), _, _) => {
                let s = match s {
                    Input::Mutated { muts, .. } => apply(seeds[0].clone(), &muts),
                    Input::Random(b) => b,
                };
                let d = match d {
                    Input::Mutated { muts, .. } => apply(seeds[1].clone(), &muts),
                    Input::Random(b) => b,
                };
                std::fs::write(&p, d).unwrap();
                std::fs::write(dir.path().join("f.raw.json"), s).unwrap();
                load(&p, &LoadOptions::default())
            }
            (None, Some((spec, len)), _) => {
                let expected = spec.dims.iter().try_fold(spec.voxel_type.size(), |a, &d| a.checked_mul(d));
                let len = match expected {
                    Some(e) if e <= 4096 && len % 3 == 0 => e + spec.header_bytes.min(64) as usize,
                    _ => len,
                };
                std::fs::write(&p, voxel_bytes(len, 1, false)).unwrap();
                load(&p, &LoadOptions { format: Some(Format::Raw), raw: Some(spec) })
            }
            (None, None, Some((json, data))) => {
                std::fs::write(&p, data).unwrap();
                std::fs::write(dir.path().join("f.raw.json"), json).unwrap();
                load(&p, &LoadOptions::default())
            }
            (None, None, None) => unreachable!(),
        }
    });
}

#[test]
fn seeds_are_valid_files() {
    // The fuzz seeds themselves load, so mutations start from real structure.
    let dir = scratch();
    let check = |name: &str, bytes: &[u8], f: Format| {
        let p: &Path = &dir.path().join(name);
        std::fs::write(p, bytes).unwrap();
        load(p, &with(f)).unwrap_or_else(|e| panic!("{name}: {e}"));
    };
    let n = nrrd_seeds();
    for (i, s) in n.iter().enumerate().take(if real("chest-ct-lung1.nrrd").is_some() { n.len() - 1 } else { n.len() }) {
        check(&format!("s{i}.nrrd"), s, Format::Nrrd);
    }
    for (i, s) in nifti_seeds().iter().enumerate().take(8) {
        check(&format!("s{i}.nii"), s, Format::Nifti);
    }
    for (i, s) in den_seeds().iter().enumerate().take(2) {
        check(&format!("s{i}.den"), s, Format::Den);
    }
    for (i, s) in dicom_seeds().iter().enumerate() {
        let d = dir.path().join(format!("dcm{i}"));
        std::fs::create_dir(&d).unwrap();
        check(&format!("dcm{i}/a.dcm"), s, Format::Dicom);
    }
}

// ------------------------------------------------------------ meshes

/// [`fuzz_with`] for meshes: a mesh that loads has triangles, each naming
/// vertices it has.
fn fuzz_mesh<S: Strategy>(name: &str, strategy: S, run: impl Fn(S::Value) -> shearwarp::Result<shearwarp::geometry::mesh::Mesh>) {
    fuzz_with(name, strategy, run, |m| {
        prop_assert!(!m.triangles.is_empty());
        prop_assert!(m.triangles.iter().flatten().all(|&i| (i as usize) < m.vertices.len()));
        Ok(())
    });
}

/// The budget the mesh fuzz loads within (the command line passes `--max-memory`).
const MESH_BUDGET: Option<u64> = Some(256 << 20);

/// A small closed mesh: an octahedron's vertices and faces.
fn octahedron() -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let v = vec![[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]];
    let f = vec![[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]];
    (v, f)
}

fn obj_seeds() -> Vec<Vec<u8>> {
    let (v, f) = octahedron();
    let mut a = String::from("# octahedron\no oct\n");
    for p in &v {
        a += &format!("v {} {} {}\n", p[0], p[1], p[2]);
    }
    for t in &f {
        a += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    // quads, normals and texture coordinates, negative indices
    let b = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nvt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3/1/1 4/1/1\nf -1 -2 -3\nusemtl none\nl 1 2\n";
    vec![a.into_bytes(), b.as_bytes().to_vec()]
}

fn stl_seeds() -> Vec<Vec<u8>> {
    let (v, f) = octahedron();
    let mut ascii = String::from("solid oct\n");
    for t in &f {
        ascii += "facet normal 0 0 0\n outer loop\n";
        for &i in t {
            let p = v[i as usize];
            ascii += &format!("  vertex {} {} {}\n", p[0], p[1], p[2]);
        }
        ascii += " endloop\nendfacet\n";
    }
    ascii += "endsolid oct\n";
    let mut bin = vec![0u8; 80];
    bin.extend_from_slice(&(f.len() as u32).to_le_bytes());
    for t in &f {
        bin.extend_from_slice(&[0u8; 12]);
        for &i in t {
            for c in v[i as usize] {
                bin.extend_from_slice(&c.to_le_bytes());
            }
        }
        bin.extend_from_slice(&[0u8; 2]);
    }
    vec![ascii.into_bytes(), bin]
}

fn ply_seeds() -> Vec<Vec<u8>> {
    let (v, f) = octahedron();
    let header = |format: &str| {
        format!(
            "ply\nformat {format} 1.0\ncomment octahedron\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
            v.len(),
            f.len()
        )
    };
    let mut ascii = header("ascii");
    for p in &v {
        ascii += &format!("{} {} {}\n", p[0], p[1], p[2]);
    }
    for t in &f {
        ascii += &format!("3 {} {} {}\n", t[0], t[1], t[2]);
    }
    let mut bin = header("binary_little_endian").into_bytes();
    for p in &v {
        for c in p {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    for t in &f {
        bin.push(3);
        for &i in t {
            bin.extend_from_slice(&(i as i32).to_le_bytes());
        }
    }
    vec![ascii.into_bytes(), bin]
}

fn fuzz_mesh_format(name: &str, ext: &str, seeds: Vec<Vec<u8>>) {
    for s in &seeds {
        let dir = scratch();
        let p = dir.path().join(format!("seed.{ext}"));
        std::fs::write(&p, s).unwrap();
        shearwarp::geometry::load_mesh_within(&p, MESH_BUDGET).unwrap_or_else(|e| panic!("{name} seed: {e}"));
    }
    let dir = scratch();
    fuzz_mesh(name, inputs(seeds.len()), |input| {
        let p = dir.path().join(format!("f.{ext}"));
        std::fs::write(&p, realize(&seeds, &input)).unwrap();
        shearwarp::geometry::load_mesh_within(&p, MESH_BUDGET)
    });
}

#[test]
#[ignore = "a fuzz campaign: run with --ignored"]
fn mesh_fuzz_obj() {
    fuzz_mesh_format("obj", "obj", obj_seeds());
}

#[test]
#[ignore = "a fuzz campaign: run with --ignored"]
fn mesh_fuzz_stl() {
    fuzz_mesh_format("stl", "stl", stl_seeds());
}

#[test]
#[ignore = "a fuzz campaign: run with --ignored"]
fn mesh_fuzz_ply() {
    fuzz_mesh_format("ply", "ply", ply_seeds());
}
