//! NIfTI-1 single files (`.nii`, `.nii.gz`), read with the `nifti` crate.
//!
//! The header is parsed (either byte order) and checked *before* the crate
//! gets to allocate: `dim[0]` must be 1–7 with every axis past the third of
//! size 1, the dimensions pass [`check_dims`], `vox_offset` must be at least
//! 352 and at most 16 MiB, and an uncompressed file must hold the whole
//! payload. Gzip payloads are read through `Read::take`, so a header that
//! lies costs only what the stream really holds.
//!
//! Voxel type policy: when `scl_slope` is non-zero and `(scl_slope,
//! scl_inter)` is not `(1, 0)`, values are rescaled (`v * slope + inter`) and
//! stored as f32. Otherwise u8, u16 and i16 are kept as they are, i8 widens
//! to i16, and every other type (i32, u32, f32, f64) is converted to f32.
//! 64-bit integers, complex and RGB data are rejected.
//!
//! Spacing is `|pixdim[1..=3]|`, converted to millimetres when `xyzt_units`
//! says metres or microns; an axis of size 1 with no valid pixdim gets 1.
//! Header/image pairs (`.hdr` + `.img`, magic `ni1`) are not supported.
//!
//! Patient orientation follows the NIfTI-1 rules: the sform (`srow_x/y/z`)
//! when `sform_code > 0`, else the qform (quaternion `quatern_b/c/d`,
//! `qfac = pixdim[0]`, `qoffset_x/y/z`) when `qform_code > 0`, else none
//! (unknown, as in an Analyze file). Both are RAS millimetres; mirrored axes
//! are reversed on load (see [`crate::data::orientation`]). An sform whose columns
//! are degenerate falls back to the qform.

use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

use ::nifti::{InMemNiftiVolume, IntoNdArray, NiftiHeader, NiftiType};

use glam::{DMat3, DVec3};

use super::{Sample, io_error, make_volume, read_capped};
use crate::data::orientation::PatientFrame;
use crate::data::volume::{Volume, VoxelData, check_dims};
use crate::error::{Error, Result};

/// Bytes of a NIfTI-1 header.
const HEADER_BYTES: u64 = 348;
/// Largest `vox_offset` accepted (header + extensions).
const MAX_VOX_OFFSET: f32 = (16 << 20) as f32;

/// Loads a `.nii` or `.nii.gz` file (gzip is detected from the content).
pub fn load_nifti(path: &Path) -> Result<Volume> {
    let file = File::open(path).map_err(|e| io_error(path, e))?;
    let file_len = file.metadata().map_err(|e| io_error(path, e))?.len();
    let mut buffered = BufReader::new(file);
    let gz = buffered.fill_buf().map_err(|e| io_error(path, e))?.starts_with(&[0x1f, 0x8b]);
    let mut reader: Box<dyn Read> = if gz { Box::new(flate2::bufread::MultiGzDecoder::new(buffered)) } else { Box::new(buffered) };
    let err = |why: String| Error::file(path, why);

    let header = NiftiHeader::from_reader(&mut reader).map_err(|e| err(format!("not a readable NIfTI-1 header: {}", nifti_error(&e))))?;
    if &header.magic == b"ni1\0" {
        return Err(err("a NIfTI .hdr/.img pair header: only single .nii/.nii.gz files are supported".into()));
    }
    if header.sizeof_hdr != HEADER_BYTES as i32 {
        return Err(err(format!("NIfTI-1 header size field is {}, expected 348", header.sizeof_hdr)));
    }
    let ndim = header.dim[0] as usize;
    if !(1..=7).contains(&ndim) {
        return Err(err(format!("NIfTI dim[0] = {ndim}: must be 1 to 7")));
    }
    let axes = &header.dim[1..=ndim];
    if let Some(i) = axes.iter().position(|&d| d == 0) {
        return Err(err(format!("NIfTI dim[{}] is 0: every axis needs at least one voxel", i + 1)));
    }
    if axes.iter().skip(3).any(|&d| d != 1) {
        return Err(err(format!(
            "NIfTI image is {ndim}-D with dims {axes:?}: only 3-D volumes are supported (extra axes must have size 1)"
        )));
    }
    let raw_dims = [1, 2, 3].map(|i| if i <= ndim { header.dim[i] as u64 } else { 1 });
    let dims = check_dims(raw_dims).map_err(|e| err(format!("NIfTI header: {e}")))?;
    let datatype = header.data_type().map_err(|_| err(format!("NIfTI datatype code {} is unknown", header.datatype)))?;
    let sample = match datatype {
        NiftiType::Uint8 => Sample::U8,
        NiftiType::Int8 => Sample::I8,
        NiftiType::Int16 => Sample::I16,
        NiftiType::Uint16 => Sample::U16,
        NiftiType::Int32 => Sample::I32,
        NiftiType::Uint32 => Sample::U32,
        NiftiType::Float32 => Sample::F32,
        NiftiType::Float64 => Sample::F64,
        other => {
            return Err(err(format!("NIfTI datatype {other:?} is not supported (u8, i8, u16, i16, u32, i32, f32 and f64 are)")));
        }
    };
    let n = (dims[0] * dims[1] * dims[2]) as u64;
    let nbytes = n * sample.size() as u64;
    let vox = header.vox_offset;
    if !(vox.is_finite() && (352.0..=MAX_VOX_OFFSET).contains(&vox) && vox.fract() == 0.0) {
        return Err(err(format!("NIfTI vox_offset {vox} is not a whole number from 352 to {MAX_VOX_OFFSET}")));
    }
    let vox = vox as u64;
    if !gz && file_len < vox + nbytes {
        return Err(err(format!("file is truncated: {file_len} bytes, but the header puts {nbytes} bytes of voxels at offset {vox}")));
    }
    let scaled = header.scl_slope != 0.0 && !(header.scl_slope == 1.0 && header.scl_inter == 0.0);
    if scaled && !(header.scl_slope.is_finite() && header.scl_inter.is_finite()) {
        return Err(err(format!("NIfTI scl_slope {} / scl_inter {} are not finite", header.scl_slope, header.scl_inter)));
    }
    let spacing = spacing(path, &header, dims)?;

    // Skip the extensions, then read exactly the payload.
    let skip = vox - HEADER_BYTES;
    let skipped = std::io::copy(&mut (&mut reader).take(skip), &mut std::io::sink()).map_err(|e| err(format!("NIfTI extensions: {e}")))?;
    if skipped < skip {
        return Err(err(format!("file is truncated: it ends before vox_offset {vox}")));
    }
    let raw = read_capped(path, reader, nbytes, "NIfTI voxel data")?;
    let volume = InMemNiftiVolume::from_raw_data(&header, raw).map_err(|e| err(format!("NIfTI volume: {}", nifti_error(&e))))?;
    let typed = |e: ::nifti::NiftiError| err(format!("NIfTI voxel conversion: {}", nifti_error(&e)));
    let data = match (scaled, sample) {
        (false, Sample::U8) => VoxelData::U8(volume.into_nifti_typed_data::<u8>().map_err(typed)?),
        (false, Sample::U16) => VoxelData::U16(volume.into_nifti_typed_data::<u16>().map_err(typed)?),
        (false, Sample::I16) => VoxelData::I16(volume.into_nifti_typed_data::<i16>().map_err(typed)?),
        (false, Sample::I8) => VoxelData::I16(volume.into_nifti_typed_data::<i8>().map_err(typed)?.into_iter().map(i16::from).collect()),
        _ => {
            // The crate applies scl_slope/scl_inter (when the slope is not 0)
            // and returns the axes x-first in Fortran order: reversing them
            // makes a logical iteration x-fastest.
            let arr = volume.into_ndarray::<f32>().map_err(typed)?;
            VoxelData::F32(arr.reversed_axes().iter().copied().collect())
        }
    };
    Ok(make_volume(path, dims, spacing, data)?.with_frame(patient_frame(&header)))
}

/// The nifti crate's error in words (its I/O variant only has a debug form).
fn nifti_error(e: &::nifti::NiftiError) -> String {
    match e {
        ::nifti::NiftiError::Io(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            "the file ends inside the 348-byte header".to_string()
        }
        ::nifti::NiftiError::Io(io) => io.to_string(),
        other => other.to_string(),
    }
}

/// The index-to-patient frame per the NIfTI-1 rules: sform, else qform, else none.
fn patient_frame(h: &NiftiHeader) -> Option<PatientFrame> {
    let to_mm = match h.xyzt_units & 0x07 {
        1 => 1000.0,
        3 => 0.001,
        _ => 1.0,
    };
    let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
    if h.sform_code > 0 && finite(&h.srow_x) && finite(&h.srow_y) && finite(&h.srow_z) {
        let (x, y, z) = (h.srow_x.map(f64::from), h.srow_y.map(f64::from), h.srow_z.map(f64::from));
        let cols = [0, 1, 2].map(|c| DVec3::new(x[c], y[c], z[c]));
        let origin = DVec3::new(x[3], y[3], z[3]) * to_mm;
        if let Ok(f) = PatientFrame::from_axes(cols, origin) {
            return Some(f);
        }
    }
    if h.qform_code > 0 {
        let q = [h.quatern_b, h.quatern_c, h.quatern_d, h.quatern_x, h.quatern_y, h.quatern_z, h.pixdim[0]];
        if !finite(&q) {
            return None;
        }
        let (mut b, mut c, mut d) = (h.quatern_b as f64, h.quatern_c as f64, h.quatern_d as f64);
        let aa = 1.0 - (b * b + c * c + d * d);
        let a = if aa < 1e-7 {
            // a 180° rotation: renormalise (b, c, d), as nifti1_io does
            let n = (b * b + c * c + d * d).sqrt();
            if n == 0.0 {
                return None;
            }
            (b, c, d) = (b / n, c / n, d / n);
            0.0
        } else {
            aa.sqrt()
        };
        let r = DMat3::from_cols_array(&[
            a * a + b * b - c * c - d * d,
            2.0 * (b * c + a * d),
            2.0 * (b * d - a * c),
            2.0 * (b * c - a * d),
            a * a + c * c - b * b - d * d,
            2.0 * (c * d + a * b),
            2.0 * (b * d + a * c),
            2.0 * (c * d - a * b),
            a * a + d * d - c * c - b * b,
        ]);
        let qfac = if h.pixdim[0] < 0.0 { -1.0 } else { 1.0 };
        let cols = [r.x_axis, r.y_axis, r.z_axis * qfac];
        let origin = DVec3::new(h.quatern_x as f64, h.quatern_y as f64, h.quatern_z as f64) * to_mm;
        return PatientFrame::from_axes(cols, origin).ok();
    }
    None
}

/// Voxel spacing in millimetres from `pixdim` and `xyzt_units`.
fn spacing(path: &Path, header: &NiftiHeader, dims: [usize; 3]) -> Result<[f32; 3]> {
    let to_mm = match header.xyzt_units & 0x07 {
        1 => 1000.0,
        3 => 0.001,
        _ => 1.0,
    };
    let mut s = [1f32; 3];
    for i in 0..3 {
        let p = header.pixdim[i + 1].abs() * to_mm;
        if p.is_finite() && p > 0.0 {
            s[i] = p;
        } else if dims[i] > 1 {
            return Err(Error::file(path, format!("NIfTI pixdim[{}] = {} is not a usable voxel size", i + 1, header.pixdim[i + 1])));
        }
    }
    Ok(s)
}
