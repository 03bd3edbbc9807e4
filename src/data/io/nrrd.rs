//! NRRD (teem's "nearly raw raster data"): our own header parser.
//!
//! Supported: attached headers (`.nrrd`, data after the blank line) and
//! detached ones (`.nhdr` or any header with `data file: NAME`, relative to
//! the header's folder); encodings `raw` and `gzip`/`gz` (concatenated gzip
//! members are fine); the types uchar, signed char, short, ushort, int,
//! uint, float and double under all of the spec's synonyms (`unsigned char`,
//! `uint8`, `int16_t`, `signed short int`, ...); `endian`; `byte skip`
//! (including -1 for raw: the data are the file's last bytes; at most 64 MiB
//! into gzip data) and `line skip`.
//! u8, u16 and i16 data are kept as they are, signed char widens to i16, and
//! the rest becomes f32.
//!
//! Spacing comes from the norms of the `space directions` vectors, else from
//! `spacings`, else it is 1. Patient orientation: with `space` set to a
//! patient space (`left-posterior-superior`/`LPS`, `right-anterior-superior`/
//! `RAS`, `left-anterior-superior`/`LAS`, and their `-time` forms) and a
//! direction vector for every axis, the volume carries the index-to-patient
//! frame (`space origin` gives voxel (0,0,0); 0 without it), converted to
//! RAS; mirrored axes are reversed on load (see [`crate::data::orientation`]).
//! Other spaces (`scanner-xyz`, `3D-right-handed`, none) leave it unknown. `dimension` must be 3; a 4-D (or higher) file is
//! accepted when squeezing out axes of size 1 leaves exactly 3 (so a 4-D
//! file with a size-1 vector or time axis loads), anything else is rejected.
//!
//! Rejected with a clear error: bzip2, ascii/text and hex encodings, `block`
//! and 64-bit integer types, multi-file data (`data file: LIST` or a format
//! pattern), and any header whose sizes disagree with the data.

use std::fs::File;
use std::io::{BufRead, BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use glam::DVec3;

use super::{Layout, Sample, decode_samples, io_error, make_volume, read_capped};
use crate::data::orientation::PatientFrame;
use crate::data::volume::{Volume, check_dims};
use crate::error::{Error, Result};

/// Longest header line accepted, in bytes.
const MAX_LINE: u64 = 64 << 10;
/// Largest header accepted, in bytes.
const MAX_HEADER: u64 = 1 << 20;
/// Largest `byte skip` accepted inside gzip data (skipped bytes must be
/// decompressed, so this bounds the work a header can ask for).
const MAX_GZIP_SKIP: u64 = 64 << 20;
/// Largest `line skip` accepted.
const MAX_LINE_SKIP: u64 = 1 << 20;

/// How the data are encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Encoding {
    Raw,
    Gzip,
}

/// The parsed header fields this loader uses.
#[derive(Debug)]
struct Header {
    sample: Sample,
    sizes: Vec<u64>,
    big_endian: Option<bool>,
    encoding: Encoding,
    spacings: Option<Vec<f64>>,
    directions: Option<Vec<Option<Vec<f64>>>>,
    /// Signs that turn the `space` coordinates into RAS (`None`: not a patient space).
    space_to_ras: Option<[f64; 3]>,
    origin: Option<Vec<f64>>,
    data_file: Option<String>,
    byte_skip: i64,
    line_skip: u64,
}

/// A parsed header and where its data start: what [`load_nrrd`] and
/// [`layout`] share, so a file seek-read is read as the loader reads it.
struct Located {
    h: Header,
    dims: [usize; 3],
    spacing: [f32; 3],
    frame: Option<PatientFrame>,
    /// The file holding the data: this one, or the detached header's data file.
    data_path: PathBuf,
    /// The data file, standing at `pos` (past the header and the line skip).
    reader: Box<dyn BufRead>,
    pos: u64,
    data_len: u64,
    /// The bytes of the voxels.
    expected: u64,
}

/// Reads and checks the header of `path` and finds its data.
fn locate(path: &Path) -> Result<Located> {
    let file = File::open(path).map_err(|e| io_error(path, e))?;
    let mut reader = BufReader::new(file);
    let (fields, data_offset) = read_header(path, &mut reader)?;
    let h = parse_fields(path, &fields)?;

    // Axes, squeezed to three.
    let n_axes = h.sizes.len();
    let mut axes: Vec<(u64, f64, Option<Vec<f64>>)> = Vec::with_capacity(n_axes);
    for i in 0..n_axes {
        let sp = match (&h.directions, &h.spacings) {
            (Some(d), _) => d[i].as_ref().map(|v| v.iter().map(|x| x * x).sum::<f64>().sqrt()),
            (None, Some(s)) => Some(s[i]).filter(|x| !x.is_nan()),
            (None, None) => None,
        };
        let dir = h.directions.as_ref().and_then(|d| d[i].clone());
        axes.push((h.sizes[i], sp.unwrap_or(1.0), dir));
    }
    while axes.len() > 3 {
        match axes.iter().position(|a| a.0 == 1) {
            Some(i) => {
                axes.remove(i);
            }
            None => break,
        }
    }
    if axes.len() != 3 {
        return Err(Error::file(
            path,
            format!(
                "NRRD dimension {n_axes} with sizes {:?}: only 3-D volumes are supported \
                 (4-D and up only when the extra axes have size 1)",
                h.sizes
            ),
        ));
    }
    let dims = check_dims([axes[0].0, axes[1].0, axes[2].0]).map_err(|e| Error::file(path, format!("NRRD sizes: {e}")))?;
    let mut spacing = [0f32; 3];
    for (s, a) in spacing.iter_mut().zip(&axes) {
        let v = a.1 as f32;
        if !(v.is_finite() && v > 0.0) {
            return Err(Error::file(path, format!("NRRD spacing {} is not a positive finite number", a.1)));
        }
        *s = v;
    }
    let size = h.sample.size() as u64;
    if size > 1 && h.big_endian.is_none() {
        return Err(Error::file(path, "NRRD header has no 'endian' field, which a multi-byte type requires"));
    }
    let expected = (dims[0] * dims[1] * dims[2]) as u64 * size;

    let frame = patient_frame(path, &h, &axes)?;

    // Where the data are: this file after the header, or the named data file.
    let (data_path, mut reader, start): (PathBuf, Box<dyn BufRead>, u64) = match &h.data_file {
        None => {
            let len = std::fs::metadata(path).map_err(|e| io_error(path, e))?.len();
            if data_offset >= len {
                return Err(Error::file(
                    path,
                    "NRRD header is followed by no data and has no 'data file' field (a detached header needs one)",
                ));
            }
            (path.to_path_buf(), Box::new(reader), data_offset)
        }
        Some(name) => {
            let p = Path::new(name);
            let p = if p.is_absolute() { p.to_path_buf() } else { path.parent().unwrap_or(Path::new(".")).join(p) };
            // Only a regular file: a FIFO or device named by a header could
            // block or never end.
            match std::fs::metadata(&p) {
                Ok(m) if m.is_file() => {}
                Ok(_) => {
                    return Err(Error::file(path, format!("the NRRD data file {} is not a regular file", p.display())));
                }
                Err(e) => {
                    return Err(Error::file(path, format!("cannot open the NRRD data file {}: {e}", p.display())));
                }
            }
            let f = File::open(&p).map_err(|e| Error::file(path, format!("cannot open the NRRD data file {}: {e}", p.display())))?;
            (p, Box::new(BufReader::new(f)), 0)
        }
    };
    let data_len = std::fs::metadata(&data_path).map_err(|e| io_error(&data_path, e))?.len();

    // line skip, then (for raw) byte skip.
    let mut pos = start;
    for i in 0..h.line_skip {
        let mut line = Vec::new();
        let n = (&mut reader).take(MAX_LINE).read_until(b'\n', &mut line).map_err(|e| io_error(&data_path, e))?;
        if n == 0 || line.last() != Some(&b'\n') {
            return Err(Error::file(&data_path, format!("NRRD 'line skip' {}: the data end after {i} lines", h.line_skip)));
        }
        pos += n as u64;
    }
    Ok(Located { h, dims, spacing, frame, data_path, reader, pos, data_len, expected })
}

/// Where the voxels of raw-encoded data start in the data file, after the
/// byte skip, once the data are checked to be exactly as long as the
/// header describes.
fn raw_start(l: &Located) -> Result<u64> {
    let Located { h, dims, data_path, pos, data_len, expected, .. } = l;
    let (pos, expected, size) = (*pos, *expected, h.sample.size() as u64);
    let remaining = data_len.saturating_sub(pos);
    let skip = if h.byte_skip == -1 {
        if remaining < expected {
            return Err(Error::file(data_path, format!("NRRD data are truncated: expected {expected} bytes, found only {remaining}")));
        }
        remaining - expected
    } else {
        h.byte_skip as u64
    };
    let avail = remaining.saturating_sub(skip);
    if avail < expected {
        return Err(Error::file(
            data_path,
            format!(
                "NRRD data are truncated: the header describes {expected} bytes ({}×{}×{} × {size}), found only {avail}",
                dims[0], dims[1], dims[2]
            ),
        ));
    }
    if avail > expected {
        return Err(Error::file(
            data_path,
            format!("NRRD data hold {} bytes more than the header describes ({expected})", avail - expected),
        ));
    }
    Ok(pos + skip)
}

/// Loads a `.nrrd` or `.nhdr` file.
pub fn load_nrrd(path: &Path) -> Result<Volume> {
    let l = locate(path)?;
    let bytes = match l.h.encoding {
        Encoding::Raw => {
            let start = raw_start(&l)?;
            let Located { data_path, reader, expected, .. } = l;
            drop(reader);
            let mut f = File::open(&data_path).map_err(|e| io_error(&data_path, e))?;
            f.seek(SeekFrom::Start(start)).map_err(|e| io_error(&data_path, e))?;
            read_capped(&data_path, f, expected, "NRRD data")?
        }
        Encoding::Gzip => {
            if l.h.byte_skip < 0 {
                return Err(Error::file(path, "NRRD 'byte skip: -1' is only allowed with raw encoding"));
            }
            if l.h.byte_skip as u64 > MAX_GZIP_SKIP {
                return Err(Error::file(
                    path,
                    format!("NRRD byte skip {} into gzip data is more than the {MAX_GZIP_SKIP} bytes supported", l.h.byte_skip),
                ));
            }
            let mut gz = flate2::bufread::MultiGzDecoder::new(l.reader);
            let skipped = std::io::copy(&mut (&mut gz).take(l.h.byte_skip as u64), &mut std::io::sink())
                .map_err(|e| Error::file(&l.data_path, format!("NRRD gzip data: {e}")))?;
            if skipped < l.h.byte_skip as u64 {
                return Err(Error::file(&l.data_path, format!("NRRD gzip data end inside the {}-byte skip", l.h.byte_skip)));
            }
            read_capped(&l.data_path, gz, l.expected, "NRRD gzip data")?
        }
    };
    let data = decode_samples(bytes, l.h.sample, l.h.big_endian.unwrap_or(false));
    Ok(make_volume(path, l.dims, l.spacing, data)?.with_frame(l.frame))
}

/// The layout of the voxels of `path` when they are raw-encoded (attached,
/// or in a detached header's data file), for reading a box of them by
/// seeking ([`super::read_box`]): the same header parse and the same checks
/// of the data's length as [`load_nrrd`]; `None` for gzip data, which must
/// be decompressed from the start.
pub fn layout(path: &Path) -> Result<Option<Layout>> {
    let l = locate(path)?;
    if l.h.encoding != Encoding::Raw {
        return Ok(None);
    }
    let offset = raw_start(&l)?;
    let (frame, reversed_axis) = match l.frame {
        Some(f) => {
            let (f, a) = f.unmirrored(l.dims, l.spacing);
            (Some(f), a)
        }
        None => (None, None),
    };
    Ok(Some(Layout {
        data: l.data_path,
        dims: l.dims,
        sample: l.h.sample,
        big_endian: l.h.big_endian.unwrap_or(false),
        spacing: l.spacing,
        offset,
        frame,
        reversed_axis,
    }))
}

/// The index-to-patient frame of the three (squeezed) axes, when the header
/// places them in a patient space.
fn patient_frame(path: &Path, h: &Header, axes: &[(u64, f64, Option<Vec<f64>>)]) -> Result<Option<PatientFrame>> {
    let Some(sign) = h.space_to_ras else { return Ok(None) };
    let to_ras = |v: &[f64]| DVec3::new(sign[0] * v[0], sign[1] * v[1], sign[2] * v[2]);
    let mut dirs = [DVec3::ZERO; 3];
    for (d, a) in dirs.iter_mut().zip(axes) {
        match &a.2 {
            Some(v) if v.len() >= 3 => *d = to_ras(v),
            _ => return Ok(None),
        }
    }
    let origin = match &h.origin {
        Some(o) if o.len() >= 3 => to_ras(o),
        Some(o) => return Err(Error::file(path, format!("NRRD space origin {o:?} has fewer than 3 coordinates"))),
        None => DVec3::ZERO,
    };
    PatientFrame::from_axes(dirs, origin).map(Some).map_err(|e| Error::file(path, format!("NRRD space directions: {e}")))
}

/// RAS signs of a NRRD `space`: `Some` for the patient spaces, `None` for the
/// others (`scanner-xyz`, `3D-right-handed`, …, and unknown names).
fn parse_space(value: &str) -> Option<[f64; 3]> {
    let v = value.trim().to_ascii_lowercase();
    let v = v.strip_suffix("-time").unwrap_or(&v);
    match v {
        "right-anterior-superior" | "ras" | "rast" => Some([1.0, 1.0, 1.0]),
        "left-anterior-superior" | "las" | "last" => Some([-1.0, 1.0, 1.0]),
        "left-posterior-superior" | "lps" | "lpst" => Some([-1.0, -1.0, 1.0]),
        _ => None,
    }
}

/// Reads the header lines: returns `(field, value)` pairs and the byte
/// offset just past the header (past the blank line, or the end of file).
fn read_header(path: &Path, r: &mut impl BufRead) -> Result<(Vec<(String, String)>, u64)> {
    let mut fields = Vec::new();
    let mut offset = 0u64;
    let mut first = true;
    loop {
        let mut line = Vec::new();
        let n = r.take(MAX_LINE + 1).read_until(b'\n', &mut line).map_err(|e| io_error(path, e))?;
        if n == 0 {
            if first {
                return Err(Error::file(path, "empty file: not a NRRD file"));
            }
            break;
        }
        if n as u64 > MAX_LINE {
            return Err(Error::file(path, format!("NRRD header line longer than {MAX_LINE} bytes")));
        }
        offset += n as u64;
        if offset > MAX_HEADER {
            return Err(Error::file(path, format!("NRRD header longer than {MAX_HEADER} bytes")));
        }
        let text =
            std::str::from_utf8(&line).map_err(|_| Error::file(path, format!("NRRD header line {} is not text", fields.len() + 1)))?;
        let text = text.trim_end_matches(['\n', '\r']);
        if first {
            first = false;
            let ok = text.len() == 8 && text.starts_with("NRRD000") && text.as_bytes()[7].is_ascii_digit();
            if !ok {
                return Err(Error::file(path, "not a NRRD file: the first line is not the magic NRRD000N"));
            }
            continue;
        }
        if text.is_empty() {
            break;
        }
        if text.starts_with('#') {
            continue;
        }
        if let Some((k, v)) = text.split_once(": ") {
            // "key:=value" pairs are metadata; field names never contain ":=".
            if k.contains(":=") {
                continue;
            }
            let (k, v) = (k.trim().to_ascii_lowercase(), v.trim().to_string());
            // "data file: LIST" ends the header: the file names follow.
            let list = (k == "data file" || k == "datafile") && v.starts_with("LIST");
            fields.push((k, v));
            if list {
                break;
            }
        } else if text.contains(":=") {
            continue;
        } else {
            return Err(Error::file(path, format!("NRRD header line '{}' is neither a field nor a comment", clip(text))));
        }
    }
    Ok((fields, offset))
}

/// Shortens long text for an error message.
fn clip(s: &str) -> String {
    if s.chars().count() > 60 { s.chars().take(60).collect::<String>() + "…" } else { s.to_string() }
}

fn parse_fields(path: &Path, fields: &[(String, String)]) -> Result<Header> {
    let err = |why: String| Error::file(path, why);
    let mut seen = std::collections::HashSet::new();
    let (mut sample, mut dimension, mut sizes, mut endian, mut encoding) = (None, None, None, None, None);
    let (mut spacings, mut directions, mut data_file) = (None, None, None);
    let (mut space_to_ras, mut origin) = (None, None);
    let (mut byte_skip, mut line_skip) = (0i64, 0u64);
    for (key, value) in fields {
        let key = match key.as_str() {
            "datafile" => "data file",
            "byteskip" => "byte skip",
            "lineskip" => "line skip",
            k => k,
        };
        if !seen.insert(key.to_string()) {
            return Err(err(format!("NRRD header repeats the field '{key}'")));
        }
        match key {
            "type" => sample = Some(parse_type(value).ok_or_else(|| err(type_error(value)))?),
            "dimension" => {
                let d: usize = value
                    .parse()
                    .ok()
                    .filter(|d| (1..=16).contains(d))
                    .ok_or_else(|| err(format!("NRRD dimension '{}' is not a number from 1 to 16", clip(value))))?;
                dimension = Some(d);
            }
            "sizes" => {
                let v: Option<Vec<u64>> = value.split_whitespace().map(|s| s.parse().ok()).collect();
                sizes = Some(v.ok_or_else(|| err(format!("NRRD sizes '{}' are not positive integers", clip(value))))?);
            }
            "endian" => {
                endian = Some(match value.as_str() {
                    "little" => false,
                    "big" => true,
                    other => {
                        return Err(err(format!("NRRD endian '{}' (expected little or big)", clip(other))));
                    }
                })
            }
            "encoding" => {
                encoding = Some(match value.as_str() {
                    "raw" => Encoding::Raw,
                    "gzip" | "gz" => Encoding::Gzip,
                    "bzip2" | "bz2" | "txt" | "text" | "ascii" | "hex" | "zrl" | "zstd" => {
                        return Err(err(format!("NRRD encoding '{value}' is not supported: re-save the file with raw or gzip encoding")));
                    }
                    other => {
                        return Err(err(format!("NRRD encoding '{}' is unknown", clip(other))));
                    }
                })
            }
            "spacings" => {
                let v: Option<Vec<f64>> =
                    value.split_whitespace().map(|s| s.parse::<f64>().ok().filter(|x| x.is_nan() || x.is_finite())).collect();
                spacings = Some(v.ok_or_else(|| err(format!("NRRD spacings '{}' are not numbers", clip(value))))?);
            }
            "space directions" => directions = Some(parse_directions(value).map_err(err)?),
            "space" => space_to_ras = parse_space(value),
            "space origin" => {
                let o = parse_directions(value)
                    .map_err(|_| err(format!("NRRD space origin '{}' is not a vector like (0,0,0)", clip(value))))?;
                match o.as_slice() {
                    [Some(v)] => origin = Some(v.clone()),
                    _ => return Err(err(format!("NRRD space origin '{}' is not one vector like (0,0,0)", clip(value)))),
                }
            }
            "data file" => {
                let v = value.as_str();
                let tokens: Vec<&str> = v.split_whitespace().collect();
                if v.starts_with("LIST") || (tokens.len() >= 4 && v.contains('%')) {
                    return Err(err(format!("NRRD 'data file: {}': data split over several files are not supported", clip(v))));
                }
                if v.is_empty() {
                    return Err(err("NRRD 'data file' is empty".into()));
                }
                data_file = Some(v.to_string());
            }
            "byte skip" => {
                byte_skip = value
                    .parse::<i64>()
                    .ok()
                    .filter(|&b| b >= -1)
                    .ok_or_else(|| err(format!("NRRD byte skip '{}' is not -1 or a count of bytes", clip(value))))?;
            }
            "line skip" => {
                line_skip = value
                    .parse::<u64>()
                    .ok()
                    .filter(|&l| l <= MAX_LINE_SKIP)
                    .ok_or_else(|| err(format!("NRRD line skip '{}' is not a count of lines up to {MAX_LINE_SKIP}", clip(value))))?;
            }
            _ => {}
        }
    }
    let sample = sample.ok_or_else(|| err("NRRD header has no 'type' field".into()))?;
    let dimension = dimension.ok_or_else(|| err("NRRD header has no 'dimension' field".into()))?;
    let sizes = sizes.ok_or_else(|| err("NRRD header has no 'sizes' field".into()))?;
    let encoding = encoding.ok_or_else(|| err("NRRD header has no 'encoding' field".into()))?;
    if sizes.len() != dimension {
        return Err(err(format!("NRRD sizes list {} numbers but the dimension is {dimension}", sizes.len())));
    }
    if let Some(&s) = sizes.iter().find(|&&s| s == 0) {
        return Err(err(format!("NRRD sizes {sizes:?}: a size of {s} is not allowed")));
    }
    if let Some(s) = &spacings
        && s.len() != dimension
    {
        return Err(err(format!("NRRD spacings list {} numbers but the dimension is {dimension}", s.len())));
    }
    if let Some(d) = &directions {
        if d.len() != dimension {
            return Err(err(format!("NRRD space directions list {} entries but the dimension is {dimension}", d.len())));
        }
        let lens: Vec<usize> = d.iter().flatten().map(Vec::len).collect();
        if lens.windows(2).any(|w| w[0] != w[1]) {
            return Err(err("NRRD space directions have vectors of different lengths".into()));
        }
    }
    Ok(Header { sample, sizes, big_endian: endian, encoding, spacings, directions, space_to_ras, origin, data_file, byte_skip, line_skip })
}

fn type_error(value: &str) -> String {
    format!("NRRD type '{}' is not supported (use uchar, signed char, short, ushort, int, uint, float or double)", clip(value))
}

/// Maps every NRRD spelling of a supported type to its sample type.
fn parse_type(t: &str) -> Option<Sample> {
    Some(match t {
        "signed char" | "int8" | "int8_t" => Sample::I8,
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => Sample::U8,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => Sample::I16,
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => Sample::U16,
        "int" | "signed int" | "int32" | "int32_t" => Sample::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => Sample::U32,
        "float" => Sample::F32,
        "double" => Sample::F64,
        _ => return None,
    })
}

/// Parses `(x,y,z) (x,y,z) none ...`; spaces inside the parentheses are allowed.
fn parse_directions(value: &str) -> std::result::Result<Vec<Option<Vec<f64>>>, String> {
    let bad = || format!("NRRD space directions '{}' are not vectors like (1,0,0) or 'none'", clip(value));
    let mut out = Vec::new();
    let mut rest = value.trim_start();
    while !rest.is_empty() {
        if let Some(r) = rest.strip_prefix("none") {
            out.push(None);
            rest = r.trim_start();
        } else if let Some(r) = rest.strip_prefix('(') {
            let end = r.find(')').ok_or_else(bad)?;
            let v: Option<Vec<f64>> = r[..end].split(',').map(|s| s.trim().parse::<f64>().ok().filter(|x| x.is_finite())).collect();
            let v = v.filter(|v| !v.is_empty() && v.len() <= 16).ok_or_else(bad)?;
            out.push(Some(v));
            rest = r[end + 1..].trim_start();
        } else {
            return Err(bad());
        }
        if out.len() > 16 {
            return Err(bad());
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn directions_parse_with_spaces_and_none() {
        let d = parse_directions("none (1, 0,0) (0,2,0)(0,0,3.5)").unwrap();
        assert_eq!(d, vec![None, Some(vec![1.0, 0.0, 0.0]), Some(vec![0.0, 2.0, 0.0]), Some(vec![0.0, 0.0, 3.5])]);
        assert!(parse_directions("(1,0,0").is_err());
        assert!(parse_directions("(1,x,0)").is_err());
        assert!(parse_directions("1,0,0").is_err());
        assert!(parse_directions("(nan,0,0)").is_err());
    }

    #[test]
    fn type_synonyms() {
        for t in ["short", "signed short", "int16", "short int", "int16_t", "signed short int"] {
            assert_eq!(parse_type(t), Some(Sample::I16), "{t}");
        }
        for t in ["uchar", "unsigned char", "uint8", "uint8_t"] {
            assert_eq!(parse_type(t), Some(Sample::U8), "{t}");
        }
        for t in ["ushort", "unsigned short", "uint16", "unsigned short int", "uint16_t"] {
            assert_eq!(parse_type(t), Some(Sample::U16), "{t}");
        }
        assert_eq!(parse_type("float"), Some(Sample::F32));
        assert_eq!(parse_type("block"), None);
        assert_eq!(parse_type("long long"), None);
    }
}
