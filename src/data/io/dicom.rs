//! DICOM series: a directory of single-frame slices stacked into a volume,
//! read with dicom-rs (`dicom-object`, `dicom-pixeldata`).
//!
//! The input is a directory, or one slice file, in which case the series is
//! the slices in that file's directory with the same SeriesInstanceUID.
//! Files without `DICM` at byte 128 (READMEs, ...), DICOMDIR files and
//! objects without Rows/Columns are ignored; any other DICOM file in the
//! directory must parse, or loading fails naming it. A directory holding no
//! slice, or several series when a directory was given, is an error. Files
//! must be DICOM Part 10 files (with the 128-byte preamble). Uncompressed
//! transfer syntaxes and the compressed ones dicom-rs decodes natively (RLE,
//! JPEG baseline/extended/lossless) are read; deflate and JPEG 2000 are not.
//!
//! Every file first passes [`check_structure`]: a walk of its element tree,
//! reading it exactly as dicom-rs will, that proves each declared length fits
//! inside the file and that sequences nest at most 32 deep, so dicom-rs
//! (which allocates what a length field claims) never allocates more than
//! the file holds. RLE segments and JPEG frame headers are checked against
//! Rows×Columns before dicom-rs decodes them, because its adapters index out
//! of bounds on inconsistent ones.
//!
//! Slices are read header-only first (`read_until(PixelData)`), checked (same
//! Rows×Columns, ImageOrientationPatient and PixelSpacing; one sample per
//! pixel; one frame; 8 or 16 bits allocated with 1 ≤ BitsStored ≤
//! BitsAllocated; a compressed slice may not claim more than 1024× its file
//! size in decoded pixels) and sorted by ImagePositionPatient · normal,
//! where normal = row cosines × column cosines. x runs along a row (the column index), y down the columns (the
//! row index) and z along the normal. The volume carries that placement in the
//! patient: index axes along the row cosines, column cosines and normal
//! (always right-handed), voxel (0,0,0) at the first slice's
//! ImagePositionPatient, converted from DICOM's LPS to RAS (without
//! ImageOrientationPatient the orientation is unknown). Spacing: x = PixelSpacing\[1\] (the
//! column spacing), y = PixelSpacing\[0\] (the row spacing), z = the distance
//! between consecutive slice positions, which must be non-zero and uniform
//! (within 1% + 0.001 mm; SliceThickness is not used). A single slice gets
//! SpacingBetweenSlices, else SliceThickness, else 1. Missing PixelSpacing
//! means 1×1.
//!
//! Pixels are decoded with `decode_pixel_data()?.to_ndarray::<f32>()`, which
//! applies the Modality LUT (RescaleSlope/RescaleIntercept, so CT comes out
//! in Hounsfield units). Storage type: if every value is an integer in i16
//! range the volume is i16; else if every value is an integer in u16 range,
//! u16; else f32.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use dicom_core::Tag;
use dicom_core::dictionary::{DataDictionary, DataDictionaryEntry, VirtualVr};
use dicom_core::header::VR;
use dicom_dictionary_std::{StandardDataDictionary, tags};
use dicom_object::file::ReadPreamble;
use dicom_object::{DefaultDicomObject, OpenFileOptions};
use dicom_pixeldata::PixelDecoder;

use glam::DVec3;

use super::{io_error, make_volume};
use crate::data::orientation::{PatientFrame, lps_to_ras};
use crate::data::volume::{Volume, VoxelData, check_dims};
use crate::error::{Error, Result};

/// Largest slice file accepted, in bytes.
const MAX_FILE: u64 = 1 << 31;
/// Deepest sequence nesting accepted.
const MAX_DEPTH: u32 = 32;
/// Largest accepted ratio of a compressed slice's decoded size to its file size.
const MAX_EXPANSION: u64 = 1024;
/// Media Storage SOP Class of a DICOMDIR.
const DICOMDIR_CLASS: &str = "1.2.840.10008.1.3.10";

/// What the header pass learns about one slice.
#[derive(Clone, Debug)]
struct SliceInfo {
    path: PathBuf,
    series: String,
    rows: u16,
    cols: u16,
    pixel_spacing: Option<[f64; 2]>,
    orientation: Option<[f64; 6]>,
    position: Option<[f64; 3]>,
    thickness: Option<f64>,
    between: Option<f64>,
}

/// Loads the DICOM series in directory `path`, or the series `path` (a
/// slice file) belongs to.
pub fn load_dicom(path: &Path) -> Result<Volume> {
    let meta = std::fs::metadata(path).map_err(|e| io_error(path, e))?;
    let (dir, chosen) = if meta.is_dir() {
        (path.to_path_buf(), None)
    } else {
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        (dir, Some(path.to_path_buf()))
    };
    let mut files = list_dir(path, &dir)?;
    files.sort();

    // Header pass.
    let mut slices = Vec::new();
    let mut chosen_series = None;
    for f in &files {
        let Some(bytes) = read_if_dicom(f)? else {
            continue;
        };
        let obj = open_object(f, &bytes, true)?;
        if obj.meta().media_storage_sop_class_uid().trim_end_matches(['\0', ' ']) == DICOMDIR_CLASS {
            continue;
        }
        // Non-image objects (reports, presentation states) are not slices.
        let Some(info) = slice_info(f, &obj, bytes.len() as u64)? else {
            continue;
        };
        if chosen.as_deref().is_some_and(|c| same_file(c, f)) {
            chosen_series = Some(info.series.clone());
        }
        slices.push(info);
    }
    if let Some(c) = &chosen
        && chosen_series.is_none()
    {
        // The named file itself must be a slice.
        let bytes = read_if_dicom(c)?.ok_or_else(|| Error::file(c, "not a DICOM file: no 'DICM' at byte 128"))?;
        let obj = open_object(c, &bytes, true)?;
        let info =
            slice_info(c, &obj, bytes.len() as u64)?.ok_or_else(|| Error::file(c, "DICOM file has no Rows/Columns: not an image"))?;
        chosen_series = Some(info.series.clone());
        slices.push(info);
    }
    if slices.is_empty() {
        return Err(Error::file(path, "no DICOM image files (with 'DICM' at byte 128) found here"));
    }
    let mut by_series: BTreeMap<String, Vec<SliceInfo>> = BTreeMap::new();
    for s in slices {
        by_series.entry(s.series.clone()).or_default().push(s);
    }
    let mut slices = match chosen_series {
        Some(uid) => by_series.remove(&uid).unwrap_or_default(),
        None if by_series.len() == 1 => by_series.into_values().next().unwrap_or_default(),
        None => {
            let list: Vec<String> = by_series
                .iter()
                .map(|(uid, v)| {
                    format!("{} ({} slices, e.g. {})", if uid.is_empty() { "<none>" } else { uid }, v.len(), v[0].path.display())
                })
                .collect();
            return Err(Error::file(
                path,
                format!("the directory holds {} DICOM series: {}; pass one slice file to choose", list.len(), list.join("; ")),
            ));
        }
    };

    if slices.is_empty() {
        return Err(Error::file(path, "the chosen DICOM series has no slices"));
    }

    // Consistency and geometry.
    let first = slices[0].clone();
    for s in &slices[1..] {
        if (s.rows, s.cols) != (first.rows, first.cols) {
            return Err(Error::file(
                &s.path,
                format!(
                    "slice is {}×{} (columns×rows) but {} is {}×{}: a series must have one slice size",
                    s.cols,
                    s.rows,
                    first.path.display(),
                    first.cols,
                    first.rows
                ),
            ));
        }
        if !close_opt(&s.orientation, &first.orientation, 1e-3) {
            return Err(Error::file(
                &s.path,
                format!("ImageOrientationPatient differs from {}: the slices are not parallel", first.path.display()),
            ));
        }
        if !close_opt(&s.pixel_spacing, &first.pixel_spacing, 1e-3) {
            return Err(Error::file(&s.path, format!("PixelSpacing differs from {}", first.path.display())));
        }
    }
    let nz = slices.len();
    let dims =
        check_dims([first.cols as u64, first.rows as u64, nz as u64]).map_err(|e| Error::file(path, format!("DICOM series: {e}")))?;
    let z_spacing = if nz == 1 {
        first.between.or(first.thickness).filter(|v| v.is_finite() && *v > 0.0).unwrap_or(1.0)
    } else {
        sort_slices(&mut slices)?
    };
    let [row_sp, col_sp] = first.pixel_spacing.unwrap_or([1.0, 1.0]);
    let spacing = [col_sp as f32, row_sp as f32, z_spacing as f32];
    let frame = slices[0].orientation.and_then(|o| {
        let (r, c) = (DVec3::new(o[0], o[1], o[2]), DVec3::new(o[3], o[4], o[5]));
        let origin = slices[0].position.map_or(DVec3::ZERO, DVec3::from_array);
        PatientFrame::from_axes([lps_to_ras(r), lps_to_ras(c), lps_to_ras(r.cross(c))], lps_to_ras(origin)).ok()
    });

    // Pixel pass.
    let per_slice = dims[0] * dims[1];
    let mut values: Vec<f32> = Vec::new();
    for s in &slices {
        let bytes = read_if_dicom(&s.path)?.ok_or_else(|| Error::file(&s.path, "no longer a DICOM file"))?;
        let obj = open_object(&s.path, &bytes, false)?;
        let now = slice_info(&s.path, &obj, bytes.len() as u64)?;
        if now.map(|n| (n.rows, n.cols)) != Some((s.rows, s.cols)) {
            return Err(Error::file(&s.path, "the slice changed while it was being read"));
        }
        let pix = decode_slice(&s.path, &obj)?;
        if pix.len() != per_slice {
            return Err(Error::file(&s.path, format!("decoded {} pixels, expected {}×{} = {per_slice}", pix.len(), dims[0], dims[1])));
        }
        if values.is_empty() {
            values.reserve_exact(per_slice * nz);
        }
        values.extend_from_slice(&pix);
    }
    let data = if values.iter().all(|v| v.fract() == 0.0 && (i16::MIN as f32..=i16::MAX as f32).contains(v)) {
        VoxelData::I16(values.iter().map(|&v| v as i16).collect())
    } else if values.iter().all(|v| v.fract() == 0.0 && (0.0..=u16::MAX as f32).contains(v)) {
        VoxelData::U16(values.iter().map(|&v| v as u16).collect())
    } else {
        VoxelData::F32(values)
    };
    Ok(make_volume(path, dims, spacing, data)?.with_frame(frame))
}

/// Regular files in `dir`; errors name `shown`.
fn list_dir(shown: &Path, dir: &Path) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| io_error(shown, e))? {
        let entry = entry.map_err(|e| io_error(shown, e))?;
        let p = entry.path();
        if p.is_file() {
            out.push(p);
        }
    }
    Ok(out)
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => a == b,
    }
}

/// The whole file if it has the `DICM` magic at byte 128, else `None`.
fn read_if_dicom(path: &Path) -> Result<Option<Vec<u8>>> {
    use std::io::Read;
    let mut f = std::fs::File::open(path).map_err(|e| io_error(path, e))?;
    let len = f.metadata().map_err(|e| io_error(path, e))?.len();
    if len < 132 {
        return Ok(None);
    }
    let mut head = [0u8; 132];
    f.read_exact(&mut head).map_err(|e| io_error(path, e))?;
    if &head[128..132] != b"DICM" {
        return Ok(None);
    }
    if len > MAX_FILE {
        return Err(Error::file(path, format!("DICOM file larger than {MAX_FILE} bytes")));
    }
    let mut bytes = Vec::with_capacity(len as usize);
    bytes.extend_from_slice(&head);
    f.take(MAX_FILE).read_to_end(&mut bytes).map_err(|e| io_error(path, e))?;
    Ok(Some(bytes))
}

/// Checks the structure, then parses the object (without pixel data when `headers_only`).
fn open_object(path: &Path, bytes: &[u8], headers_only: bool) -> Result<DefaultDicomObject> {
    let end = check_structure(bytes).map_err(|why| Error::file(path, format!("not a valid DICOM file: {why}")))?;
    let mut opts = OpenFileOptions::new().read_preamble(ReadPreamble::Never);
    if headers_only {
        opts = opts.read_until(tags::PIXEL_DATA);
    }
    opts.from_reader(&bytes[128..end]).map_err(|e| Error::file(path, format!("cannot parse DICOM: {e}")))
}

/// The slice's header facts; `None` for an object with no Rows/Columns (not an image).
fn slice_info(path: &Path, obj: &DefaultDicomObject, file_len: u64) -> Result<Option<SliceInfo>> {
    let err = |why: String| Error::file(path, why);
    let floats = |tag: Tag, name: &str| -> Result<Option<Vec<f64>>> {
        match obj.element_opt(tag) {
            Ok(Some(e)) => {
                let v = e.to_multi_float64().map_err(|x| err(format!("{name} {tag}: {x}")))?;
                if v.iter().any(|x| !x.is_finite()) {
                    return Err(err(format!("{name} {tag} holds a non-finite number")));
                }
                Ok(Some(v))
            }
            Ok(None) => Ok(None),
            Err(x) => Err(err(format!("{name} {tag}: {x}"))),
        }
    };
    let int = |tag: Tag, name: &str| -> Result<Option<u32>> {
        match obj.element_opt(tag) {
            Ok(Some(e)) => e.to_int::<u32>().map(Some).map_err(|x| err(format!("{name} {tag}: {x}"))),
            Ok(None) => Ok(None),
            Err(x) => Err(err(format!("{name} {tag}: {x}"))),
        }
    };
    let fixed = |v: Option<Vec<f64>>, n: usize, name: &str| -> Result<Option<Vec<f64>>> {
        match v {
            Some(v) if v.len() != n => Err(err(format!("{name} has {} values, expected {n}", v.len()))),
            v => Ok(v),
        }
    };
    let (Some(rows), Some(cols)) = (int(tags::ROWS, "Rows")?, int(tags::COLUMNS, "Columns")?) else {
        return Ok(None);
    };
    if rows == 0 || cols == 0 || rows > u16::MAX as u32 || cols > u16::MAX as u32 {
        return Err(err(format!("DICOM image size {cols}×{rows} is not valid")));
    }
    let samples = int(tags::SAMPLES_PER_PIXEL, "SamplesPerPixel")?.unwrap_or(1);
    if samples != 1 {
        return Err(err(format!("DICOM image has {samples} samples per pixel: only grey-scale slices are supported")));
    }
    let frames = match obj.element_opt(tags::NUMBER_OF_FRAMES) {
        Ok(Some(e)) => e.to_int::<i64>().map_err(|x| err(format!("NumberOfFrames: {x}")))?,
        _ => 1,
    };
    if frames != 1 {
        return Err(err(format!("DICOM file has {frames} frames: only single-frame slices are supported")));
    }
    // dicom-pixeldata converts 8- and 16-bit samples through a lookup table
    // of 2^BitsStored entries (and asserts 1 <= BitsStored <= 32): check
    // them here so a corrupt header is an error, not a panic or a huge table.
    let bits = int(tags::BITS_ALLOCATED, "BitsAllocated")?.ok_or_else(|| err("DICOM image has no BitsAllocated (0028,0100)".into()))?;
    if bits != 8 && bits != 16 {
        return Err(err(format!("DICOM BitsAllocated {bits} is not supported (8 or 16 are)")));
    }
    let stored = int(tags::BITS_STORED, "BitsStored")?.ok_or_else(|| err("DICOM image has no BitsStored (0028,0101)".into()))?;
    if stored == 0 || stored > bits {
        return Err(err(format!("DICOM BitsStored {stored} does not fit BitsAllocated {bits}")));
    }
    if let Some(high) = int(tags::HIGH_BIT, "HighBit")?
        && high >= bits
    {
        return Err(err(format!("DICOM HighBit {high} does not fit BitsAllocated {bits}")));
    }
    if let Some(rep) = int(tags::PIXEL_REPRESENTATION, "PixelRepresentation")?
        && rep > 1
    {
        return Err(err(format!("DICOM PixelRepresentation {rep} is neither 0 (unsigned) nor 1 (signed)")));
    }
    // A compressed slice may not claim more pixels than its bytes could
    // plausibly expand to, so a tiny file cannot make a decoder allocate
    // gigabytes.
    let ts = obj.meta().transfer_syntax().trim_end_matches(['\0', ' ']);
    let slice_bytes = rows as u64 * cols as u64 * (bits as u64 / 8);
    if !NATIVE.contains(&ts) && slice_bytes > MAX_EXPANSION * file_len + (1 << 20) {
        return Err(err(format!("compressed DICOM slice claims {cols}×{rows} pixels, more than its {file_len} bytes can hold")));
    }
    let series = match obj.element_opt(tags::SERIES_INSTANCE_UID) {
        Ok(Some(e)) => e.to_str().map(|s| s.trim_end_matches(['\0', ' ']).to_string()).unwrap_or_default(),
        _ => String::new(),
    };
    let ps = fixed(floats(tags::PIXEL_SPACING, "PixelSpacing")?, 2, "PixelSpacing")?;
    if let Some(p) = &ps
        && p.iter().any(|&x| x <= 0.0)
    {
        return Err(err(format!("PixelSpacing {p:?} must be positive")));
    }
    let iop = fixed(floats(tags::IMAGE_ORIENTATION_PATIENT, "ImageOrientationPatient")?, 6, "ImageOrientationPatient")?;
    let ipp = fixed(floats(tags::IMAGE_POSITION_PATIENT, "ImagePositionPatient")?, 3, "ImagePositionPatient")?;
    let first = |v: Option<Vec<f64>>| v.and_then(|v| v.first().copied());
    Ok(Some(SliceInfo {
        path: path.to_path_buf(),
        series,
        rows: rows as u16,
        cols: cols as u16,
        pixel_spacing: ps.map(|v| [v[0], v[1]]),
        orientation: iop.map(|v| [v[0], v[1], v[2], v[3], v[4], v[5]]),
        position: ipp.map(|v| [v[0], v[1], v[2]]),
        thickness: first(floats(tags::SLICE_THICKNESS, "SliceThickness").ok().flatten()),
        between: first(floats(tags::SPACING_BETWEEN_SLICES, "SpacingBetweenSlices").ok().flatten()),
    }))
}

fn close_opt<const N: usize>(a: &Option<[f64; N]>, b: &Option<[f64; N]>, tol: f64) -> bool {
    match (a, b) {
        (Some(a), Some(b)) => a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol * (1.0 + x.abs().max(y.abs()))),
        (None, None) => true,
        _ => false,
    }
}

/// Sorts the slices along the normal; returns the uniform slice distance.
fn sort_slices(slices: &mut [SliceInfo]) -> Result<f64> {
    let first = &slices[0];
    let o = first
        .orientation
        .ok_or_else(|| Error::file(&first.path, "no ImageOrientationPatient (0020,0037): cannot order the slices of the series"))?;
    let (r, c) = ([o[0], o[1], o[2]], [o[3], o[4], o[5]]);
    let n = [r[1] * c[2] - r[2] * c[1], r[2] * c[0] - r[0] * c[2], r[0] * c[1] - r[1] * c[0]];
    let norm = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if norm.is_nan() || norm <= 1e-6 {
        return Err(Error::file(&first.path, format!("ImageOrientationPatient {o:?}: the row and column directions are parallel or zero")));
    }
    let n = n.map(|x| x / norm);
    let mut keyed = Vec::with_capacity(slices.len());
    for s in slices.iter() {
        let p =
            s.position.ok_or_else(|| Error::file(&s.path, "no ImagePositionPatient (0020,0032): cannot order the slices of the series"))?;
        keyed.push((p[0] * n[0] + p[1] * n[1] + p[2] * n[2], s.clone()));
    }
    keyed.sort_by(|a, b| a.0.total_cmp(&b.0));
    let gaps: Vec<f64> = keyed.windows(2).map(|w| w[1].0 - w[0].0).collect();
    for (i, g) in gaps.iter().enumerate() {
        if *g < 1e-4 {
            return Err(Error::file(
                &keyed[i + 1].1.path,
                format!(
                    "slice is at the same position ({:.4} mm along the normal) as {}: duplicated slices",
                    keyed[i].0,
                    keyed[i].1.path.display()
                ),
            ));
        }
    }
    // Uniform within 1% (+0.001 mm) of the mean distance. When not, the gap
    // reported is the one farthest from the median distance: a missing slice
    // doubles one gap and inflates the mean, but barely moves the median, so
    // the files named are the neighbours of the hole.
    let mean = (keyed[keyed.len() - 1].0 - keyed[0].0) / gaps.len() as f64;
    if gaps.iter().any(|g| (g - mean).abs() > 0.01 * mean + 1e-3) {
        let mut sorted_gaps = gaps.clone();
        sorted_gaps.sort_by(f64::total_cmp);
        let typical = sorted_gaps[(sorted_gaps.len() - 1) / 2];
        let i = (0..gaps.len()).max_by(|&a, &b| (gaps[a] - typical).abs().total_cmp(&(gaps[b] - typical).abs())).unwrap_or(0);
        let (a, b) = (&keyed[i].1.path, &keyed[i + 1].1.path);
        let missing = gaps[i] / typical - 1.0;
        let hint = if missing > 0.5 && (missing - missing.round()).abs() < 0.1 {
            format!(" ({} slice(s) missing between them?)", missing.round())
        } else {
            String::new()
        };
        return Err(Error::file(
            b,
            format!(
                "inconsistent slice positions: {:.4} mm from the previous slice {} where the series' slices are {typical:.4} mm apart{hint}",
                gaps[i],
                a.display()
            ),
        ));
    }
    for (s, (_, k)) in slices.iter_mut().zip(keyed) {
        *s = k;
    }
    Ok(mean)
}

/// Decodes one slice's pixels, Modality LUT applied, row-major (x fastest).
fn decode_slice(path: &Path, obj: &DefaultDicomObject) -> Result<Vec<f32>> {
    let err = |why: String| Error::file(path, why);
    let ts = obj.meta().transfer_syntax().trim_end_matches(['\0', ' ']);
    if ts == RLE_LOSSLESS {
        check_rle(obj).map_err(|why| err(format!("invalid RLE pixel data: {why}")))?;
    }
    if JPEG.contains(&ts) {
        check_jpeg(obj).map_err(|why| err(format!("invalid JPEG pixel data: {why}")))?;
    }
    // native pixel data holds exactly Rows × Columns × SamplesPerPixel ×
    // NumberOfFrames samples (plus one pad byte to an even length): any other
    // length would load as skewed rows
    if NATIVE.contains(&ts) {
        let int = |tag| obj.element_opt(tag).ok().flatten().and_then(|e| e.to_int::<u64>().ok());
        let (rows, cols, bits) = (int(tags::ROWS).unwrap_or(0), int(tags::COLUMNS).unwrap_or(0), int(tags::BITS_ALLOCATED).unwrap_or(0));
        let (samples, frames) = (int(tags::SAMPLES_PER_PIXEL).unwrap_or(1), int(tags::NUMBER_OF_FRAMES).unwrap_or(1));
        let need = rows * cols * samples * frames * bits.div_ceil(8);
        let have = match obj.element_opt(tags::PIXEL_DATA) {
            Ok(Some(e)) => e.to_bytes().map_err(|e| err(format!("cannot read the pixel data: {e}")))?.len() as u64,
            _ => return Err(err("DICOM image has no pixel data (7FE0,0010)".into())),
        };
        if have != need && have != need + (need & 1) {
            return Err(err(format!(
                "the pixel data holds {have} bytes, but Rows {rows} × Columns {cols} × SamplesPerPixel {samples} × NumberOfFrames {frames} × {} bytes per sample needs {need}",
                bits.div_ceil(8)
            )));
        }
    }
    let decoded = obj.decode_pixel_data().map_err(|e| err(format!("cannot decode the pixel data: {e}")))?;
    let arr = decoded.to_ndarray::<f32>().map_err(|e| err(format!("cannot convert the pixel data: {e}")))?;
    let v: Vec<f32> = arr.iter().copied().collect();
    if let Some(bad) = v.iter().find(|x| !x.is_finite()) {
        return Err(err(format!("a rescaled pixel value is {bad}: check RescaleSlope/RescaleIntercept")));
    }
    Ok(v)
}

/// The native (uncompressed) transfer syntaxes: implicit and explicit VR
/// little endian, explicit VR big endian.
const NATIVE: [&str; 3] = ["1.2.840.10008.1.2", "1.2.840.10008.1.2.1", "1.2.840.10008.1.2.2"];

/// The RLE Lossless transfer syntax.
const RLE_LOSSLESS: &str = "1.2.840.10008.1.2.5";

/// Checks RLE Lossless pixel data the way dicom-rs's decoder will read it,
/// because that decoder indexes past short segments and slices a short
/// header without checking (it panics): one fragment of at least 64 bytes,
/// one segment per byte of a sample, in-bounds increasing offsets, and every
/// segment PackBits-decoding to at least Rows×Columns bytes.
fn check_rle(obj: &DefaultDicomObject) -> std::result::Result<(), String> {
    let get = |tag: Tag| -> std::result::Result<u32, String> {
        obj.element(tag).ok().and_then(|e| e.to_int::<u32>().ok()).ok_or_else(|| format!("missing {tag}"))
    };
    let (rows, cols, bits) = (get(tags::ROWS)?, get(tags::COLUMNS)?, get(tags::BITS_ALLOCATED)?);
    let fragments =
        obj.element(tags::PIXEL_DATA).ok().and_then(|e| e.fragments()).ok_or("the pixel data are not encapsulated fragments")?;
    if fragments.len() != 1 {
        return Err(format!("{} fragments, expected 1 for a single frame", fragments.len()));
    }
    let f = &fragments[0];
    if f.len() < 64 {
        return Err(format!("the fragment has {} bytes, less than the 64-byte RLE header", f.len()));
    }
    let word = |i: usize| u32::from_le_bytes([f[4 * i], f[4 * i + 1], f[4 * i + 2], f[4 * i + 3]]) as usize;
    let segments = word(0);
    let want = (bits / 8) as usize;
    if segments != want {
        return Err(format!("{segments} segments, expected {want} for {bits}-bit samples"));
    }
    let mut offsets: Vec<usize> = (1..=segments).map(word).collect();
    offsets.push(f.len());
    let need = rows as usize * cols as usize;
    for w in offsets.windows(2) {
        if w[0] < 64 || w[0] > w[1] || w[1] > f.len() {
            return Err(format!("segment offsets {:?} are out of order or out of range", &offsets[..segments]));
        }
        // PackBits: n >= 0 copies n+1 literal bytes, -127..=-1 repeats the
        // next byte 1-n times, -128 is a no-op.
        let seg = &f[w[0]..w[1]];
        let (mut i, mut out) = (0usize, 0usize);
        while out < need {
            let Some(&h) = seg.get(i) else {
                return Err(format!("a segment decodes to {out} bytes, expected {need}"));
            };
            let h = h as i8;
            i += 1;
            if h >= 0 {
                let n = h as usize + 1;
                if i + n > seg.len() {
                    return Err("a literal run runs past the end of its segment".into());
                }
                i += n;
                out += n;
            } else if h != -128 {
                if i >= seg.len() {
                    return Err("a repeat run has no byte to repeat".into());
                }
                i += 1;
                out += (1 - h as isize) as usize;
            }
        }
    }
    Ok(())
}

/// The JPEG transfer syntaxes dicom-rs decodes (baseline, extended, lossless).
const JPEG: [&str; 4] = ["1.2.840.10008.1.2.4.50", "1.2.840.10008.1.2.4.51", "1.2.840.10008.1.2.4.57", "1.2.840.10008.1.2.4.70"];

/// Checks the JPEG stream's frame header against the DICOM header, because
/// dicom-rs copies whatever the JPEG decodes into a buffer sized from Rows and
/// Columns (and the decoder's `info()` panics on odd precisions): the first
/// frame header — found the way jpeg-decoder scans markers — must be one
/// grey-scale component of exactly Columns×Rows with a precision that fits
/// BitsAllocated.
fn check_jpeg(obj: &DefaultDicomObject) -> std::result::Result<(), String> {
    let get = |tag: Tag| -> std::result::Result<u32, String> {
        obj.element(tag).ok().and_then(|e| e.to_int::<u32>().ok()).ok_or_else(|| format!("missing {tag}"))
    };
    let (rows, cols, bits) = (get(tags::ROWS)?, get(tags::COLUMNS)?, get(tags::BITS_ALLOCATED)?);
    let fragments =
        obj.element(tags::PIXEL_DATA).ok().and_then(|e| e.fragments()).ok_or("the pixel data are not encapsulated fragments")?;
    let b: Vec<u8> = fragments.iter().flatten().copied().collect();
    if !b.starts_with(&[0xFF, 0xD8]) {
        return Err("the stream does not start with a JPEG SOI marker".into());
    }
    let mut i = 2;
    let (precision, height, width, components) = loop {
        // Like jpeg-decoder: skip to 0xFF, skip fill bytes, 0x00 is no marker.
        while b.get(i).is_some_and(|&x| x != 0xFF) {
            i += 1;
        }
        while b.get(i) == Some(&0xFF) {
            i += 1;
        }
        let Some(&m) = b.get(i) else {
            return Err("no frame header before the end of the stream".into());
        };
        i += 1;
        match m {
            0x00 | 0x01 | 0xD0..=0xD8 => continue,
            0xD9 | 0xDA => return Err("no frame header before the image data".into()),
            _ => {}
        }
        let len = match (b.get(i), b.get(i + 1)) {
            (Some(&h), Some(&l)) => u16::from_be_bytes([h, l]) as usize,
            _ => return Err("a marker segment is cut short".into()),
        };
        if len < 2 || i + len > b.len() {
            return Err("a marker segment length is out of range".into());
        }
        let is_sof = matches!(m, 0xC0..=0xCF) && !matches!(m, 0xC4 | 0xC8 | 0xCC);
        if is_sof {
            if len < 8 {
                return Err("the frame header is too short".into());
            }
            let h = u16::from_be_bytes([b[i + 3], b[i + 4]]);
            let w = u16::from_be_bytes([b[i + 5], b[i + 6]]);
            break (b[i + 2], h, w, b[i + 7]);
        }
        i += len;
    };
    if components != 1 {
        return Err(format!("{components} colour components, expected 1"));
    }
    let fits = match bits {
        8 => (2..=8).contains(&precision),
        16 => (9..=16).contains(&precision),
        _ => false,
    };
    if !fits {
        return Err(format!("{precision}-bit samples in a {bits}-bit image"));
    }
    if (width as u32, height as u32) != (cols, rows) {
        return Err(format!("the JPEG is {width}×{height} but the DICOM header says {cols}×{rows}"));
    }
    Ok(())
}

/// Walks the element tree of a Part 10 file (preamble, `DICM`, file meta
/// group, data set) and checks that every declared length fits inside the
/// file (and its enclosing item or sequence), that VRs are well formed and
/// that sequences nest at most 32 deep. Zero bytes after the last top-level
/// element are accepted as padding. Returns the end of the data set (where
/// the padding starts), or the reason the file is rejected.
pub fn check_structure(b: &[u8]) -> std::result::Result<usize, String> {
    if b.len() < 132 || &b[128..132] != b"DICM" {
        return Err("no 'DICM' magic at byte 128".into());
    }
    let meta = Walker { b, big: false, explicit: true };
    // The file meta group, read as dicom-rs reads it: explicit VR little
    // endian, a (0002,0000) group length first, then elements until that
    // many bytes are consumed (whatever their group).
    let mut pos = 132;
    let (tag, _, len, hdr) = meta.header(pos)?;
    if tag != (0x0002, 0x0000) || len != Some(4) {
        return Err("the file meta group does not start with its group length (0002,0000)".into());
    }
    meta.need(pos + hdr, 4)?;
    let group_length = meta.u32(pos + hdr) as u64;
    pos += hdr + 4;
    let mut consumed = 0u64;
    let mut ts: Option<String> = None;
    while consumed < group_length {
        let (tag, _, len, hdr) = meta.header(pos)?;
        let start = pos + hdr;
        let len = len.ok_or_else(|| format!("file meta element {} has an undefined length", show(tag)))?;
        let end = start.checked_add(len).filter(|&e| e <= b.len()).ok_or_else(|| too_long(tag, len, b.len() - start))?;
        if tag == (0x0002, 0x0010) {
            let s = String::from_utf8_lossy(&b[start..end]).trim_end_matches(['\0', ' ']).to_string();
            ts = Some(s);
        }
        consumed += (hdr + len) as u64;
        pos = end;
    }
    let ts = ts.ok_or("the file meta group has no TransferSyntaxUID (0002,0010)")?;
    let walker = match ts.as_str() {
        "1.2.840.10008.1.2" => Walker { b, big: false, explicit: false },
        "1.2.840.10008.1.2.2" => Walker { b, big: true, explicit: true },
        "1.2.840.10008.1.2.1.99" => {
            return Err("the deflated transfer syntax is not supported".into());
        }
        _ => Walker { b, big: false, explicit: true },
    };
    walker.dataset(pos, b.len(), 0, false)
}

fn show(t: (u16, u16)) -> String {
    format!("({:04X},{:04X})", t.0, t.1)
}

fn too_long(tag: (u16, u16), len: usize, left: usize) -> String {
    format!("element {} claims {len} bytes but only {left} remain", show(tag))
}

/// A cursor-free reader over the file bytes for [`check_structure`].
struct Walker<'a> {
    b: &'a [u8],
    big: bool,
    explicit: bool,
}

const UNDEFINED: u32 = 0xFFFF_FFFF;

impl Walker<'_> {
    fn u16(&self, at: usize) -> u16 {
        let w = [self.b[at], self.b[at + 1]];
        if self.big { u16::from_be_bytes(w) } else { u16::from_le_bytes(w) }
    }
    fn u32(&self, at: usize) -> u32 {
        let w = [self.b[at], self.b[at + 1], self.b[at + 2], self.b[at + 3]];
        if self.big { u32::from_be_bytes(w) } else { u32::from_le_bytes(w) }
    }
    fn need(&self, pos: usize, n: usize) -> std::result::Result<(), String> {
        if pos.checked_add(n).is_some_and(|e| e <= self.b.len()) {
            Ok(())
        } else {
            Err(format!("the file ends inside an element header at byte {pos}"))
        }
    }

    /// Reads an element header at `pos`: tag, VR (explicit only), length
    /// (`None` = undefined) and header size.
    #[allow(clippy::type_complexity)]
    fn header(&self, pos: usize) -> std::result::Result<((u16, u16), Option<[u8; 2]>, Option<usize>, usize), String> {
        self.need(pos, 8)?;
        let tag = (self.u16(pos), self.u16(pos + 2));
        let undefined = |l: u32| {
            if l == UNDEFINED { None } else { Some(l as usize) }
        };
        if tag.0 == 0xFFFE || !self.explicit {
            return Ok((tag, None, undefined(self.u32(pos + 4)), 8));
        }
        let vr = [self.b[pos + 4], self.b[pos + 5]];
        // The VRs with a 16-bit length, as dicom-rs decodes them; dicom-rs
        // reads any unknown VR as UN with a 32-bit length, so unknown VRs are
        // rejected here to keep both readings of the file identical.
        const SHORT: [&[u8; 2]; 21] = [
            b"AE", b"AS", b"AT", b"CS", b"DA", b"DS", b"DT", b"FL", b"FD", b"IS", b"LO", b"LT", b"PN", b"SH", b"SL", b"SS", b"ST", b"TM",
            b"UI", b"UL", b"US",
        ];
        const LONG: [&[u8; 2]; 13] = [b"OB", b"OD", b"OF", b"OL", b"OV", b"OW", b"SQ", b"UC", b"UR", b"UT", b"UN", b"SV", b"UV"];
        if SHORT.contains(&&vr) {
            Ok((tag, Some(vr), Some(self.u16(pos + 6) as usize), 8))
        } else if LONG.contains(&&vr) {
            self.need(pos, 12)?;
            Ok((tag, Some(vr), undefined(self.u32(pos + 8)), 12))
        } else {
            Err(format!("element {} at byte {pos} has an unknown VR {:?}", show(tag), String::from_utf8_lossy(&vr)))
        }
    }

    /// Walks data elements from `pos` to `end`; with `in_item` an item
    /// delimitation item ends the walk. Returns the position after it.
    fn dataset(&self, mut pos: usize, end: usize, depth: u32, in_item: bool) -> std::result::Result<usize, String> {
        if depth > MAX_DEPTH {
            return Err(format!("sequences nest deeper than {MAX_DEPTH} levels"));
        }
        while pos < end {
            if depth == 0 && self.b[pos..end].iter().all(|&x| x == 0) {
                // Trailing zero padding after the data set.
                return Ok(pos);
            }
            let (tag, vr, len, hdr) = self.header(pos)?;
            if tag.0 == 0xFFFE {
                if in_item && tag.1 == 0xE00D {
                    return Ok(pos + 8);
                }
                return Err(format!("unexpected item tag {} at byte {pos}", show(tag)));
            }
            let start = pos + hdr;
            if start > end {
                return Err(format!("element {} at byte {pos} crosses the end of its container", show(tag)));
            }
            let is_sq = match vr {
                Some(v) => &v == b"SQ",
                None => StandardDataDictionary.by_tag(Tag(tag.0, tag.1)).is_some_and(|e| matches!(e.vr(), VirtualVr::Exact(VR::SQ))),
            };
            match len {
                None => {
                    // Undefined length, as dicom-rs reads it: encapsulated
                    // pixel data (fragments) for PixelData, else a sequence
                    // of data set items in the same encoding, whatever the VR.
                    if tag == (0x7FE0, 0x0010) {
                        pos = self.fragments(start, end)?;
                    } else {
                        pos = self.items(start, end, depth + 1, None)?;
                    }
                }
                Some(len) => {
                    let stop = start.checked_add(len).filter(|&e| e <= end).ok_or_else(|| too_long(tag, len, end - start))?;
                    if is_sq {
                        self.items(start, stop, depth + 1, Some(stop))?;
                    }
                    pos = stop;
                }
            }
        }
        if in_item {
            return Err("an item of undefined length has no item delimitation".into());
        }
        Ok(pos)
    }

    /// Walks sequence items from `pos`; `defined_end` for a sequence of
    /// defined length, else up to the sequence delimitation item (within `end`).
    fn items(&self, mut pos: usize, end: usize, depth: u32, defined_end: Option<usize>) -> std::result::Result<usize, String> {
        if depth > MAX_DEPTH {
            return Err(format!("sequences nest deeper than {MAX_DEPTH} levels"));
        }
        let limit = defined_end.unwrap_or(end);
        loop {
            if defined_end == Some(pos) {
                return Ok(pos);
            }
            if pos >= limit {
                return Err("a sequence of undefined length has no sequence delimitation".into());
            }
            self.need(pos, 8)?;
            let tag = (self.u16(pos), self.u16(pos + 2));
            let len = self.u32(pos + 4);
            match tag {
                (0xFFFE, 0xE0DD) if defined_end.is_none() => return Ok(pos + 8),
                (0xFFFE, 0xE000) => {
                    let start = pos + 8;
                    if len == UNDEFINED {
                        pos = self.dataset(start, limit, depth + 1, true)?;
                    } else {
                        let len = len as usize;
                        let stop = start
                            .checked_add(len)
                            .filter(|&e| e <= limit)
                            .ok_or_else(|| too_long(tag, len, limit.saturating_sub(start)))?;
                        self.dataset(start, stop, depth + 1, false)?;
                        pos = stop;
                    }
                }
                _ => {
                    return Err(format!("expected a sequence item at byte {pos}, found tag {}", show(tag)));
                }
            }
        }
    }

    /// Walks encapsulated pixel data fragments up to the sequence delimitation.
    fn fragments(&self, mut pos: usize, end: usize) -> std::result::Result<usize, String> {
        loop {
            self.need(pos, 8)?;
            if pos + 8 > end {
                return Err("encapsulated pixel data have no sequence delimitation".into());
            }
            let tag = (self.u16(pos), self.u16(pos + 2));
            let len = self.u32(pos + 4) as usize;
            match tag {
                (0xFFFE, 0xE0DD) => return Ok(pos + 8),
                (0xFFFE, 0xE000) => {
                    pos = (pos + 8).checked_add(len).filter(|&e| e <= end).ok_or_else(|| too_long(tag, len, end - pos - 8))?;
                }
                _ => {
                    return Err(format!("expected a pixel data fragment at byte {pos}, found tag {}", show(tag)));
                }
            }
        }
    }
}
