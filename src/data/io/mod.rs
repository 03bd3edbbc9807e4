//! Volume file loaders: turning files on disk into a [`Volume`].
//!
//! This module owns every on-disk volume format the crate reads, and the one
//! format it writes (raw voxels with a JSON sidecar):
//!
//! | format | module | files |
//! |---|---|---|
//! | [`Format::Raw`] | [`raw`] | headerless voxels, described by a [`RawSpec`] or a `FILE.raw.json` / `FILE.json` sidecar |
//! | [`Format::Nrrd`] | [`nrrd`] | `.nrrd` (attached) and `.nhdr` + data file (detached), raw or gzip encoding |
//! | [`Format::Nifti`] | [`nifti`] | NIfTI-1 single files, `.nii` and `.nii.gz` |
//! | [`Format::Dicom`] | [`dicom`] | a directory of DICOM slices (or one `.dcm` slice of the series) |
//! | [`Format::Den`] | [`den`] | VolPack `.den` density files (62-byte header, u8 voxels) |
//!
//! The entry point is [`load`]; [`Format::infer`] guesses the format from the
//! extension, then from magic bytes. The library is quiet: nothing here prints
//! or reports progress.
//!
//! **Robustness contract.** Bad input never panics, hangs or over-allocates.
//! Header dimensions go through [`check_dims`]
//! before anything is allocated, uncompressed payloads are checked against
//! the file size before they are read, and compressed payloads are read
//! through `Read::take(expected + 1)` so a decompression bomb stops at the
//! size the header promised. Every failure is an [`Error`] naming the file.

pub mod den;
pub mod dicom;
pub mod nifti;
pub mod nrrd;
pub mod raw;

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use crate::data::orientation::PatientFrame;
use crate::data::volume::{Volume, VoxelData, VoxelType, check_dims};
use crate::error::{Error, Result};

pub use raw::{RawSpec, save_raw, sidecar_path};

/// A supported volume file format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Format {
    /// Headerless voxels plus a raw spec: dimensions, type, spacing (given, or read from a JSON sidecar).
    Raw,
    /// NRRD, attached (`.nrrd`) or detached (`.nhdr`).
    Nrrd,
    /// NIfTI-1 single file (`.nii`, `.nii.gz`).
    Nifti,
    /// A DICOM series: a directory of slices, or one slice of it.
    Dicom,
    /// VolPack `.den`.
    Den,
}

impl Format {
    /// Every supported format.
    pub const ALL: [Format; 5] = [Format::Nrrd, Format::Nifti, Format::Dicom, Format::Den, Format::Raw];

    /// The format's lower-case name (`raw`, `nrrd`, `nifti`, `dicom`, `den`).
    pub fn name(self) -> &'static str {
        match self {
            Format::Raw => "raw",
            Format::Nrrd => "nrrd",
            Format::Nifti => "nifti",
            Format::Dicom => "dicom",
            Format::Den => "den",
        }
    }

    /// Parses a format name as [`Format::name`] prints it (also `nii`, `dcm`).
    pub fn parse(s: &str) -> Result<Format> {
        match s.to_ascii_lowercase().as_str() {
            "raw" => Ok(Format::Raw),
            "nrrd" | "nhdr" => Ok(Format::Nrrd),
            "nifti" | "nii" => Ok(Format::Nifti),
            "dicom" | "dcm" => Ok(Format::Dicom),
            "den" => Ok(Format::Den),
            other => Err(Error::value("format", format!("'{other}' (expected raw, nrrd, nifti, dicom or den)"))),
        }
    }

    /// Infers the format of `path`.
    ///
    /// A directory is a DICOM series. Otherwise the extension decides
    /// (`.raw`, `.nrrd`/`.nhdr`, `.nii`/`.nii.gz`, `.den`, `.dcm`), case-insensitively;
    /// for any other extension the first bytes do: `NRRD000` at the start,
    /// `DICM` at byte 128, the NIfTI-1 magic `n+1\0`/`ni1\0` at byte 344 (after
    /// gunzipping the header if the file is gzip), or a self-consistent VolPack
    /// header. A file with an unknown extension that has a raw JSON sidecar is raw.
    pub fn infer(path: &Path) -> Result<Format> {
        let meta = std::fs::metadata(path).map_err(|e| io_error(path, e))?;
        if meta.is_dir() {
            return Ok(Format::Dicom);
        }
        if !meta.is_file() {
            return Err(Error::file(path, "not a regular file or directory"));
        }
        let name = path.file_name().map(|n| n.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
        let by_ext = [
            (".nii.gz", Format::Nifti),
            (".nii", Format::Nifti),
            (".nrrd", Format::Nrrd),
            (".nhdr", Format::Nrrd),
            (".raw", Format::Raw),
            (".den", Format::Den),
            (".dcm", Format::Dicom),
        ];
        if let Some((_, f)) = by_ext.iter().find(|(ext, _)| name.ends_with(ext)) {
            return Ok(*f);
        }
        if let Some(f) = sniff(path, meta.len())? {
            return Ok(f);
        }
        if raw::find_sidecar(path).is_some() {
            return Ok(Format::Raw);
        }
        Err(Error::file(
            path,
            "cannot tell the volume format: the extension is not one of .raw .nrrd .nhdr .nii .nii.gz .dcm .den \
             and the file starts with no known magic; name the format explicitly",
        ))
    }
}

impl std::fmt::Display for Format {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Options for [`load`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LoadOptions {
    /// The format; `None` infers it with [`Format::infer`].
    pub format: Option<Format>,
    /// The layout of a raw file; `None` reads it from the JSON sidecar.
    pub raw: Option<RawSpec>,
}

/// Loads the volume at `path` (a file, or a directory for a DICOM series).
///
/// Quiet and progress-free. Every error names the file and the problem.
pub fn load(path: &Path, opts: &LoadOptions) -> Result<Volume> {
    // A FIFO or device could block or never end: only files and directories.
    let meta = std::fs::metadata(path).map_err(|e| io_error(path, e))?;
    if !meta.is_file() && !meta.is_dir() {
        return Err(Error::file(path, "not a regular file or directory"));
    }
    let format = match opts.format {
        Some(f) => f,
        None => Format::infer(path)?,
    };
    match format {
        Format::Raw => match &opts.raw {
            Some(spec) => raw::load_raw(path, spec),
            None => raw::load_raw_with_sidecar(path),
        },
        Format::Nrrd => nrrd::load_nrrd(path),
        Format::Nifti => nifti::load_nifti(path),
        Format::Dicom => dicom::load_dicom(path),
        Format::Den => den::load_den(path),
    }
}

/// Where the voxels of a file lie, for reading a box of them by seeking
/// ([`read_box`]): a raw file, a `.den` file or an uncompressed NRRD, found
/// by [`seekable_layout`].
#[derive(Clone, Debug, PartialEq)]
pub struct Layout {
    /// The file holding the voxels (a detached NRRD header names another).
    pub data: PathBuf,
    /// Grid size `[nx, ny, nz]`, x fastest in the file.
    pub dims: [usize; 3],
    /// The stored sample type (converted as the loader converts it).
    pub sample: Sample,
    /// Byte order of multi-byte samples.
    pub big_endian: bool,
    /// Voxel size along x, y, z.
    pub spacing: [f32; 3],
    /// The byte of [`Layout::data`] where voxel `(0, 0, 0)` starts.
    pub offset: u64,
    /// The patient frame the loaded volume carries, if the file has one
    /// (right-handed: see [`Volume::set_frame`]).
    pub frame: Option<PatientFrame>,
    /// The index axis the loader reverses to unmirror the file's frame: a
    /// box of the loaded volume is then read mirrored and reversed.
    pub reversed_axis: Option<usize>,
}

impl Layout {
    /// The layout of the raw file `path` laid out as `spec` says.
    pub fn raw(path: &Path, spec: &RawSpec) -> Layout {
        Layout {
            data: path.to_path_buf(),
            dims: spec.dims,
            sample: Sample::from_voxel_type(spec.voxel_type),
            big_endian: spec.big_endian,
            spacing: spec.spacing,
            offset: spec.header_bytes,
            frame: None,
            reversed_axis: None,
        }
    }
}

/// The layout of the voxels of `path` when a box of them can be read by
/// seeking: a raw file (by `opts.raw` or its sidecar), a `.den` file, or an
/// NRRD with raw encoding (attached, or a detached header and its data
/// file), with the patient frame the loader gives the volume; `None` for a
/// format that must be read whole (gzip NRRD, NIfTI, DICOM). Reads and
/// checks the header only, with the loader's own parser.
pub fn seekable_layout(path: &Path, opts: &LoadOptions) -> Result<Option<Layout>> {
    let meta = std::fs::metadata(path).map_err(|e| io_error(path, e))?;
    if !meta.is_file() {
        return Ok(None);
    }
    let format = match opts.format {
        Some(f) => f,
        None => Format::infer(path)?,
    };
    match format {
        Format::Raw => match &opts.raw {
            Some(spec) => Ok(Some(Layout::raw(path, spec))),
            None => raw::sidecar_layout(path).map(|(spec, frame)| Some(Layout { frame, ..Layout::raw(path, &spec) })),
        },
        Format::Den => den::layout(path).map(|spec| Some(Layout::raw(path, &spec))),
        Format::Nrrd => nrrd::layout(path),
        _ => Ok(None),
    }
}

/// Reads the voxels `[lo, hi)` (along x, y, z) of the volume that loading
/// the file laid out as `layout` says gives, by seeking to each slice's
/// rows: a brick of a volume without reading the rest. An error names the
/// file (missing, shorter than the layout, unreadable).
pub fn read_box(layout: &Layout, lo: [usize; 3], hi: [usize; 3]) -> Result<Volume> {
    use std::io::{Seek, SeekFrom};
    let path = layout.data.as_path();
    let dims = check_dims(layout.dims.map(|d| d as u64)).map_err(|e| Error::file(path, e.to_string()))?;
    let [nx, ny, nz] = dims;
    if (0..3).any(|a| lo[a] >= hi[a] || hi[a] > dims[a]) {
        return Err(Error::file(path, format!("voxels {lo:?}..{hi:?} are not inside its {nx}×{ny}×{nz} voxels")));
    }
    // the box as the file stores it (mirrored along a reversed axis)
    let (mut flo, mut fhi) = (lo, hi);
    if let Some(a) = layout.reversed_axis.filter(|&a| a < 3) {
        (flo[a], fhi[a]) = (dims[a] - hi[a], dims[a] - lo[a]);
    }
    let mut f = File::open(path).map_err(|e| io_error(path, e))?;
    let size = f.metadata().map_err(|e| io_error(path, e))?.len();
    let b = layout.sample.size();
    let len = (nx * ny * nz * b) as u64;
    // the box's last byte (the whole layout was checked against the dims above)
    let end = layout.offset + (((fhi[2] - 1) * ny + fhi[1]) * nx * b) as u64;
    if size < end {
        return Err(Error::file(
            path,
            format!(
                "file is truncated: {size} bytes, voxels {flo:?}..{fhi:?} end at byte {end} (the layout needs {})",
                layout.offset + len
            ),
        ));
    }
    let (w, rows) = (fhi[0] - flo[0], fhi[1] - flo[1]);
    let mut out = Vec::with_capacity(w * rows * (fhi[2] - flo[2]) * b);
    // one read per slice: its rows y0..y1 whole, then the x range of each
    let mut slab = vec![0u8; rows * nx * b];
    for z in flo[2]..fhi[2] {
        let at = layout.offset + ((z * ny + flo[1]) * nx * b) as u64;
        f.seek(SeekFrom::Start(at)).map_err(|e| io_error(path, e))?;
        f.read_exact(&mut slab).map_err(|e| io_error(path, e))?;
        for y in 0..rows {
            out.extend_from_slice(&slab[(y * nx + flo[0]) * b..(y * nx + fhi[0]) * b]);
        }
    }
    drop(slab);
    let data = decode_samples(out, layout.sample, layout.big_endian);
    let mut v = make_volume(path, [w, rows, fhi[2] - flo[2]], layout.spacing, data)?;
    if let Some(a) = layout.reversed_axis {
        v.reverse_axis(a);
    }
    Ok(v)
}

/// Reads up to 352 bytes and looks for a known magic.
fn sniff(path: &Path, len: u64) -> Result<Option<Format>> {
    let mut head = Vec::with_capacity(352);
    File::open(path).map_err(|e| io_error(path, e))?.take(352).read_to_end(&mut head).map_err(|e| io_error(path, e))?;
    if head.starts_with(b"NRRD000") {
        return Ok(Some(Format::Nrrd));
    }
    if head.get(128..132) == Some(b"DICM") {
        return Ok(Some(Format::Dicom));
    }
    if is_nifti_magic(&head) {
        return Ok(Some(Format::Nifti));
    }
    if head.starts_with(&[0x1f, 0x8b]) {
        let mut unzipped = Vec::with_capacity(352);
        let file = File::open(path).map_err(|e| io_error(path, e))?;
        // A corrupt stream simply is not NIfTI: ignore the error.
        let _ = flate2::read::MultiGzDecoder::new(std::io::BufReader::new(file)).take(352).read_to_end(&mut unzipped);
        if is_nifti_magic(&unzipped) {
            return Ok(Some(Format::Nifti));
        }
    }
    if den::sniff(&head, len) {
        return Ok(Some(Format::Den));
    }
    Ok(None)
}

fn is_nifti_magic(head: &[u8]) -> bool {
    matches!(head.get(344..348), Some(b"n+1\0") | Some(b"ni1\0"))
}

/// The scalar type of samples stored in a file, before conversion to a
/// [`VoxelType`]: u8, u16 and i16 are kept, i8 widens to i16 and the
/// others become f32.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sample {
    /// Unsigned 8-bit.
    U8,
    /// Signed 8-bit.
    I8,
    /// Unsigned 16-bit.
    U16,
    /// Signed 16-bit.
    I16,
    /// Unsigned 32-bit.
    U32,
    /// Signed 32-bit.
    I32,
    /// 32-bit float.
    F32,
    /// 64-bit float.
    F64,
}

impl Sample {
    /// Bytes per sample.
    pub fn size(self) -> usize {
        match self {
            Sample::U8 | Sample::I8 => 1,
            Sample::U16 | Sample::I16 => 2,
            Sample::U32 | Sample::I32 | Sample::F32 => 4,
            Sample::F64 => 8,
        }
    }

    /// The sample type of voxels of type `t`.
    pub fn from_voxel_type(t: VoxelType) -> Sample {
        match t {
            VoxelType::U8 => Sample::U8,
            VoxelType::U16 => Sample::U16,
            VoxelType::I16 => Sample::I16,
            VoxelType::F32 => Sample::F32,
        }
    }
}

/// Decodes `bytes` (a whole number of samples) into voxels: u8, u16 and i16
/// are kept, i8 widens to i16 losslessly, and everything else becomes f32.
pub(crate) fn decode_samples(bytes: impl AsRef<[u8]> + Into<Vec<u8>>, sample: Sample, big_endian: bool) -> VoxelData {
    // 8-bit voxels keep the bytes as they are: no second copy of the volume
    if let Sample::U8 = sample {
        return VoxelData::U8(bytes.into());
    }
    let bytes = bytes.as_ref();
    macro_rules! words {
        ($t:ty, $n:expr) => {
            bytes.chunks_exact($n).map(move |c| {
                let mut a = [0u8; $n];
                a.copy_from_slice(c);
                if big_endian { <$t>::from_be_bytes(a) } else { <$t>::from_le_bytes(a) }
            })
        };
    }
    match sample {
        Sample::U8 => VoxelData::U8(bytes.to_vec()),
        Sample::I8 => VoxelData::I16(bytes.iter().map(|&b| b as i8 as i16).collect()),
        Sample::U16 => VoxelData::U16(words!(u16, 2).collect()),
        Sample::I16 => VoxelData::I16(words!(i16, 2).collect()),
        Sample::U32 => VoxelData::F32(words!(u32, 4).map(|v| v as f32).collect()),
        Sample::I32 => VoxelData::F32(words!(i32, 4).map(|v| v as f32).collect()),
        Sample::F32 => VoxelData::F32(words!(f32, 4).collect()),
        Sample::F64 => VoxelData::F32(words!(f64, 8).map(|v| v as f32).collect()),
    }
}

/// Builds the volume, turning a rejection (NaN voxels, bad spacing, ...) into
/// an error that names the file.
pub(crate) fn make_volume(path: &Path, dims: [usize; 3], spacing: [f32; 3], data: VoxelData) -> Result<Volume> {
    Volume::new(dims, spacing, data).map_err(|e| match e {
        Error::File { .. } | Error::Io { .. } => e,
        other => Error::file(path, other.to_string()),
    })
}

/// An [`Error::Io`] for `path`.
pub(crate) fn io_error(path: &Path, source: std::io::Error) -> Error {
    Error::Io { path: path.to_path_buf(), error: source }
}

/// Reads at most `expected + 1` bytes from `r` (a decompressor, typically)
/// and checks that exactly `expected` came out. Memory grows with what is
/// actually read, so a header that lies about the size costs nothing, and a
/// decompression bomb stops one byte past the promised size.
pub(crate) fn read_capped(path: &Path, r: impl Read, expected: u64, what: &str) -> Result<Vec<u8>> {
    let mut buf = Vec::with_capacity(expected.min(64 << 20) as usize);
    r.take(expected.saturating_add(1)).read_to_end(&mut buf).map_err(|e| Error::file(path, format!("{what}: {e}")))?;
    let got = buf.len() as u64;
    if got < expected {
        return Err(Error::file(path, format!("{what} is truncated: expected {expected} bytes, found only {got}")));
    }
    if got > expected {
        return Err(Error::file(path, format!("{what} holds more than the {expected} bytes the header describes")));
    }
    Ok(buf)
}

/// Reads exactly `len` bytes at `offset` of the file at `path`, after checking
/// that the file is exactly `offset + len` bytes long (or at least that long
/// when `allow_trailing`).
pub(crate) fn read_region(path: &Path, offset: u64, len: u64, allow_trailing: bool) -> Result<Vec<u8>> {
    use std::io::{Seek, SeekFrom};
    let mut f = File::open(path).map_err(|e| io_error(path, e))?;
    let size = f.metadata().map_err(|e| io_error(path, e))?.len();
    let need = offset.saturating_add(len);
    if size < need {
        return Err(Error::file(
            path,
            format!("file is truncated: {size} bytes, but {offset} header bytes + {len} data bytes = {need} are needed"),
        ));
    }
    if size > need && !allow_trailing {
        return Err(Error::file(
            path,
            format!(
                "file has {} bytes more than expected ({offset} header bytes + {len} data bytes = {need}); \
                 check the dimensions and type, or set the header size to skip",
                size - need
            ),
        ));
    }
    f.seek(SeekFrom::Start(offset)).map_err(|e| io_error(path, e))?;
    let mut buf = vec![0u8; len as usize];
    f.read_exact(&mut buf).map_err(|e| io_error(path, e))?;
    Ok(buf)
}

/// The path with `suffix` appended to its file name (`a/b.raw` + `.json` → `a/b.raw.json`).
pub(crate) fn with_suffix(path: &Path, suffix: &str) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(suffix);
    PathBuf::from(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decode_samples_endianness_and_widening() {
        let b = [0x01, 0x02, 0xff, 0xfe];
        assert_eq!(decode_samples(b, Sample::U16, false), VoxelData::U16(vec![0x0201, 0xfeff]));
        assert_eq!(decode_samples(b, Sample::U16, true), VoxelData::U16(vec![0x0102, 0xfffe]));
        assert_eq!(decode_samples(b, Sample::I16, true), VoxelData::I16(vec![0x0102, -2]));
        assert_eq!(decode_samples(b, Sample::I8, true), VoxelData::I16(vec![1, 2, -1, -2]));
        assert_eq!(decode_samples(1.5f64.to_be_bytes(), Sample::F64, true), VoxelData::F32(vec![1.5]));
        assert_eq!(decode_samples((-7i32).to_le_bytes(), Sample::I32, false), VoxelData::F32(vec![-7.0]));
    }

    #[test]
    fn read_capped_stops_at_expected_plus_one() {
        let p = Path::new("x");
        let endless = std::io::repeat(7);
        let e = read_capped(p, endless, 10, "data").unwrap_err().to_string();
        assert!(e.contains("more than the 10 bytes"), "{e}");
        let e = read_capped(p, &[1u8, 2][..], 10, "data").unwrap_err().to_string();
        assert!(e.contains("truncated"), "{e}");
        assert_eq!(read_capped(p, &[1u8, 2][..], 2, "data").unwrap(), vec![1, 2]);
    }

    #[test]
    fn format_names_round_trip() {
        for f in Format::ALL {
            assert_eq!(Format::parse(f.name()).unwrap(), f);
        }
        assert!(Format::parse("png").is_err());
    }
}
