//! Raw volumes: headerless voxels whose layout comes from a [`RawSpec`] or a
//! JSON sidecar, and [`save_raw`], the crate's one volume writer.
//!
//! The sidecar sits next to the data as `FILE.raw.json` (preferred) or
//! `FILE.json` (`vol.raw` → `vol.raw.json`, else `vol.json`):
//!
//! ```json
//! {"dims": [256, 256, 64], "type": "u16", "endian": "little", "spacing": [0.9, 0.9, 2.0]}
//! ```
//!
//! `type` is `u8`, `u16`, `i16` or `f32`; `endian` (`little`/`big`, default
//! little), `spacing` (default 1,1,1) and `header_bytes` (bytes to skip before
//! the voxels, default 0) are optional; unknown keys are rejected. `frame`
//! (optional; [`save_raw`] writes it for a volume that has one) places the
//! index axes in the patient: `{"directions_ras": [[x], [y], [z]],
//! "origin_ras": [..], "reversed_axis": 0, "skew_deg": 0}`, the RAS unit
//! direction of each index axis (orthonormal, right-handed) and the RAS
//! position of voxel 0 (see [`crate::data::orientation`]). The file
//! must be exactly `header_bytes` + the voxel bytes long: a shorter file is
//! truncated, a longer one means the spec is wrong.

use std::fs::File;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use glam::{DMat3, DVec3};

use super::{Sample, decode_samples, io_error, make_volume, read_region, with_suffix};
use crate::data::orientation::PatientFrame;
use crate::data::volume::{Volume, VoxelData, VoxelType, check_dims};
use crate::error::{Error, Result};

/// Largest sidecar accepted, in bytes.
const MAX_SIDECAR: u64 = 1 << 20;

/// The layout of a raw volume file.
#[derive(Clone, Debug, PartialEq)]
pub struct RawSpec {
    /// Grid size `[nx, ny, nz]`, x fastest in the file.
    pub dims: [usize; 3],
    /// Stored voxel type.
    pub voxel_type: VoxelType,
    /// Byte order of multi-byte voxels.
    pub big_endian: bool,
    /// Voxel size along x, y, z.
    pub spacing: [f32; 3],
    /// Bytes to skip at the start of the file.
    pub header_bytes: u64,
}

impl RawSpec {
    /// A little-endian spec with unit spacing and no header.
    pub fn new(dims: [usize; 3], voxel_type: VoxelType) -> RawSpec {
        RawSpec { dims, voxel_type, big_endian: false, spacing: [1.0; 3], header_bytes: 0 }
    }

    /// Number of voxel bytes the spec describes (after checking the dims).
    pub fn data_bytes(&self) -> Result<u64> {
        let d = check_dims(self.dims.map(|d| d as u64))?;
        Ok((d[0] * d[1] * d[2]) as u64 * self.voxel_type.size() as u64)
    }
}

/// The sidecar's JSON form.
#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct Sidecar {
    dims: [u64; 3],
    #[serde(rename = "type")]
    voxel_type: String,
    #[serde(default = "little")]
    endian: String,
    #[serde(default = "unit_spacing")]
    spacing: [f32; 3],
    #[serde(default)]
    header_bytes: u64,
    /// Where the index axes point in the patient (written by [`save_raw`]
    /// for a volume that has a frame).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    frame: Option<SidecarFrame>,
}

/// A [`PatientFrame`] in a sidecar: RAS unit directions of index axes x, y, z
/// (right-handed), the RAS position of voxel 0, and what the original file had.
#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct SidecarFrame {
    directions_ras: [[f64; 3]; 3],
    origin_ras: [f64; 3],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    reversed_axis: Option<usize>,
    #[serde(default)]
    skew_deg: f64,
}

impl SidecarFrame {
    fn of(f: &PatientFrame) -> Self {
        let d = f.directions;
        SidecarFrame {
            directions_ras: [d.x_axis.to_array(), d.y_axis.to_array(), d.z_axis.to_array()],
            origin_ras: f.origin.to_array(),
            reversed_axis: f.reversed_axis,
            skew_deg: f.skew_deg,
        }
    }

    /// The frame, exactly as written; an error unless it is a finite
    /// right-handed orthonormal frame.
    fn frame(&self, path: &Path) -> Result<PatientFrame> {
        let [x, y, z] = self.directions_ras.map(DVec3::from_array);
        let d = DMat3::from_cols(x, y, z);
        let origin = DVec3::from_array(self.origin_ras);
        let ok = d.is_finite()
            && origin.is_finite()
            && (d.transpose() * d).abs_diff_eq(DMat3::IDENTITY, 1e-6)
            && d.determinant() > 0.0
            && self.reversed_axis.is_none_or(|a| a < 3)
            && self.skew_deg.is_finite();
        if !ok {
            return Err(Error::file(path, "raw sidecar: frame.directions_ras must be three orthonormal right-handed unit vectors"));
        }
        Ok(PatientFrame { directions: d, origin, reversed_axis: self.reversed_axis, skew_deg: self.skew_deg })
    }
}

fn little() -> String {
    "little".into()
}
fn unit_spacing() -> [f32; 3] {
    [1.0; 3]
}

/// Loads a raw file laid out as `spec` says.
pub fn load_raw(path: &Path, spec: &RawSpec) -> Result<Volume> {
    let len = spec.data_bytes().map_err(|e| Error::file(path, e.to_string()))?;
    let bytes = read_region(path, spec.header_bytes, len, false)?;
    let data = decode_samples(bytes, Sample::from_voxel_type(spec.voxel_type), spec.big_endian);
    make_volume(path, spec.dims, spec.spacing, data)
}

/// The sidecar that describes `path`, if one exists: `FILE.json` appended to
/// the full name first (`vol.raw.json`), then the extension replaced (`vol.json`).
pub fn find_sidecar(path: &Path) -> Option<PathBuf> {
    let appended = sidecar_path(path);
    if appended.is_file() {
        return Some(appended);
    }
    let replaced = path.with_extension("json");
    (replaced != path && replaced.is_file()).then_some(replaced)
}

/// Where [`save_raw`] writes the sidecar of `path`: the name with `.json` appended.
pub fn sidecar_path(path: &Path) -> PathBuf {
    with_suffix(path, ".json")
}

/// Reads and checks a sidecar.
pub fn read_sidecar(path: &Path) -> Result<RawSpec> {
    let s = read_sidecar_text(path)?;
    let dims = check_dims(s.dims).map_err(|e| Error::file(path, e.to_string()))?;
    let voxel_type = VoxelType::parse(&s.voxel_type).map_err(|e| Error::file(path, e.to_string()))?;
    let big_endian = match s.endian.to_ascii_lowercase().as_str() {
        "little" => false,
        "big" => true,
        other => {
            return Err(Error::file(path, format!("raw sidecar: endian '{other}' (expected little or big)")));
        }
    };
    Ok(RawSpec { dims, voxel_type, big_endian, spacing: s.spacing, header_bytes: s.header_bytes })
}

/// Reads a sidecar's JSON.
fn read_sidecar_text(path: &Path) -> Result<Sidecar> {
    let mut text = String::new();
    File::open(path)
        .map_err(|e| io_error(path, e))?
        .take(MAX_SIDECAR + 1)
        .read_to_string(&mut text)
        .map_err(|e| Error::file(path, format!("raw sidecar is not UTF-8 text: {e}")))?;
    if text.len() as u64 > MAX_SIDECAR {
        return Err(Error::file(path, format!("raw sidecar is larger than {MAX_SIDECAR} bytes")));
    }
    serde_json::from_str(&text).map_err(|e| Error::file(path, format!("raw sidecar is not valid: {e}")))
}

/// The layout of a raw file from its sidecar (see [`find_sidecar`]) and the
/// patient frame the sidecar gives (right-handed, so the voxels load as
/// they lie); an error naming the file when it has none.
pub fn sidecar_layout(path: &Path) -> Result<(RawSpec, Option<PatientFrame>)> {
    let Some(sidecar) = find_sidecar(path) else {
        return Err(Error::file(
            path,
            format!("a raw file needs its layout: write {} or pass the dimensions and type", sidecar_path(path).display()),
        ));
    };
    let frame = read_sidecar_text(&sidecar)?.frame.map(|f| f.frame(&sidecar)).transpose()?;
    Ok((read_sidecar(&sidecar)?, frame))
}

/// Loads a raw file described by its sidecar (see [`find_sidecar`]).
pub fn load_raw_with_sidecar(path: &Path) -> Result<Volume> {
    if !path.exists() {
        return Err(io_error(path, std::io::Error::new(std::io::ErrorKind::NotFound, "no such file")));
    }
    let Some(sidecar) = find_sidecar(path) else {
        return Err(Error::file(
            path,
            format!(
                "a raw file needs its layout: write {} (e.g. {{\"dims\":[x,y,z],\"type\":\"u16\",\
                 \"endian\":\"little\",\"spacing\":[1,1,1]}}) or pass the dimensions and type",
                sidecar_path(path).display()
            ),
        ));
    };
    let spec = read_sidecar(&sidecar)?;
    let frame = read_sidecar_text(&sidecar)?.frame.map(|f| f.frame(&sidecar)).transpose()?;
    Ok(load_raw(path, &spec)?.with_frame(frame))
}

/// Writes `volume` as little-endian raw voxels to `path` and its sidecar to
/// [`sidecar_path`]`(path)`; returns the sidecar's path.
pub fn save_raw(volume: &Volume, path: &Path) -> Result<PathBuf> {
    crate::output::write_with(path, |w| match volume.data() {
        VoxelData::U8(v) => w.write_all(v),
        VoxelData::U16(v) => v.iter().try_for_each(|x| w.write_all(&x.to_le_bytes())),
        VoxelData::I16(v) => v.iter().try_for_each(|x| w.write_all(&x.to_le_bytes())),
        VoxelData::F32(v) => v.iter().try_for_each(|x| w.write_all(&x.to_le_bytes())),
    })?;
    let sidecar = Sidecar {
        dims: volume.dims().map(|d| d as u64),
        voxel_type: volume.data().voxel_type().name().into(),
        endian: little(),
        spacing: volume.spacing(),
        header_bytes: 0,
        frame: volume.frame().map(SidecarFrame::of),
    };
    let json = serde_json::to_string_pretty(&sidecar).map_err(|e| Error::Other(e.to_string()))?;
    let side = sidecar_path(path);
    crate::output::write_bytes(&side, (json + "\n").as_bytes())?;
    Ok(side)
}
