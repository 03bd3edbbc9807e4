//! VolPack `.den` density files (Stanford VolPack's `denfile.c`).
//!
//! A 62-byte header of 16-bit shorts in the writer's byte order, then
//! `map_length` u8 voxels, x fastest:
//!
//! | bytes | field |
//! |---|---|
//! | 0–1 | `map_version` = 1 (the magic; reads as 0x0100 when byte-swapped) |
//! | 2–19 | `orig_min[3]`, `orig_max[3]`, `orig_len[3]` (the original scan) |
//! | 20–37 | `extr_min[3]`, `extr_max[3]`, `extr_len[3]` (the extracted part) |
//! | 38–55 | `map_min[3]`, `map_max[3]`, `map_len[3]` (this map: the dims) |
//! | 56–57 | `map_warps` |
//! | 58–61 | `map_length` (i32) = the product of `map_len` |
//!
//! The format carries no voxel spacing, so the volume gets unit spacing.
//! The file must be exactly 62 + `map_length` bytes long.

use std::fs::File;
use std::io::{Read, Write};
use std::path::Path;

use super::raw::RawSpec;
use super::{io_error, make_volume, read_region};
use crate::data::volume::{Volume, VoxelData, check_dims};
use crate::error::{Error, Result};

/// Size of the header.
pub const DEN_HEADER_BYTES: u64 = 62;

/// The parts of a `.den` header the loader uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DenHeader {
    /// True when the header is big-endian.
    pub big_endian: bool,
    /// `map_len`: the dimensions.
    pub map_len: [i16; 3],
    /// `map_length`: the voxel count.
    pub map_length: i32,
}

/// Parses the first 62 bytes of a `.den` file; `Err` holds the reason.
pub fn parse_header(h: &[u8]) -> std::result::Result<DenHeader, String> {
    if h.len() < DEN_HEADER_BYTES as usize {
        return Err(format!("file is truncated: {} bytes, shorter than the {DEN_HEADER_BYTES}-byte .den header", h.len()));
    }
    let big_endian = match [h[0], h[1]] {
        [1, 0] => false,
        [0, 1] => true,
        [a, b] => {
            return Err(format!("not a VolPack .den file: the version field is 0x{a:02x}{b:02x}, expected 1 in either byte order"));
        }
    };
    let short = |i: usize| {
        let b = [h[i], h[i + 1]];
        if big_endian { i16::from_be_bytes(b) } else { i16::from_le_bytes(b) }
    };
    let map_len = [short(50), short(52), short(54)];
    let w = [h[58], h[59], h[60], h[61]];
    let map_length = if big_endian { i32::from_be_bytes(w) } else { i32::from_le_bytes(w) };
    Ok(DenHeader { big_endian, map_len, map_length })
}

/// True when `head` (the file's first bytes) is a self-consistent `.den`
/// header for a file of `file_len` bytes.
pub(crate) fn sniff(head: &[u8], file_len: u64) -> bool {
    match parse_header(head) {
        Ok(h) => {
            h.map_len.iter().all(|&l| l > 0)
                && h.map_len.iter().map(|&l| l as i64).product::<i64>() == h.map_length as i64
                && file_len == DEN_HEADER_BYTES + h.map_length as u64
        }
        Err(_) => false,
    }
}

/// The voxel layout of a VolPack `.den` file: 8-bit voxels after the header.
pub fn layout(path: &Path) -> Result<RawSpec> {
    let mut head = Vec::with_capacity(DEN_HEADER_BYTES as usize);
    File::open(path).map_err(|e| io_error(path, e))?.take(DEN_HEADER_BYTES).read_to_end(&mut head).map_err(|e| io_error(path, e))?;
    let h = parse_header(&head).map_err(|why| Error::file(path, why))?;
    if h.map_len.iter().any(|&l| l <= 0) {
        return Err(Error::file(path, format!(".den header: dimensions {:?} must all be positive", h.map_len)));
    }
    let dims = check_dims(h.map_len.map(|l| l as u64)).map_err(|e| Error::file(path, format!(".den header: {e}")))?;
    let n = (dims[0] * dims[1] * dims[2]) as u64;
    if h.map_length as i64 != n as i64 {
        return Err(Error::file(
            path,
            format!(".den header is inconsistent: map_length {} is not {}×{}×{} = {n}", h.map_length, dims[0], dims[1], dims[2]),
        ));
    }
    Ok(RawSpec { header_bytes: DEN_HEADER_BYTES, ..RawSpec::new(dims, crate::data::volume::VoxelType::U8) })
}

/// Loads a VolPack `.den` file.
pub fn load_den(path: &Path) -> Result<Volume> {
    let spec = layout(path)?;
    let dims = spec.dims;
    let n = (dims[0] * dims[1] * dims[2]) as u64;
    let bytes = read_region(path, DEN_HEADER_BYTES, n, false)?;
    make_volume(path, dims, [1.0; 3], VoxelData::U8(bytes))
}

/// Writes `voxels` (x fastest, `dims` = nx, ny, nz) as a little-endian `.den`
/// file with the header VolPack's `write_den` produces.
pub fn save_den(path: &Path, dims: [usize; 3], voxels: &[u8]) -> Result<()> {
    let d = check_dims(dims.map(|d| d as u64))?;
    if d.iter().any(|&x| x > i16::MAX as usize) || voxels.len() != d[0] * d[1] * d[2] {
        return Err(Error::value("den volume", format!("{dims:?} with {} voxels does not fit a .den file", voxels.len())));
    }
    let len = d.map(|x| x as i16);
    let max = len.map(|x| x - 1);
    let mut out = Vec::with_capacity(DEN_HEADER_BYTES as usize);
    out.extend_from_slice(&1i16.to_le_bytes());
    for group in [[0i16; 3], max, len, [0; 3], max, len, [0; 3], max, len] {
        for v in group {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out.extend_from_slice(&0i16.to_le_bytes());
    out.extend_from_slice(&(voxels.len() as i32).to_le_bytes());
    crate::output::write_with(path, |w| {
        w.write_all(&out)?;
        w.write_all(voxels)
    })
}
