//! The typed voxel storage of a volume ([`VoxelData`], u8/u16/i16/f32) and its
//! scalar type ([`VoxelType`]); [`crate::data::volume::Volume`] holds one, and
//! [`crate::data::stats`] reads it.

use crate::error::{Error, Result};

/// The scalar type of the stored voxels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum VoxelType {
    U8,
    U16,
    I16,
    F32,
}

impl VoxelType {
    /// Bytes per voxel.
    pub fn size(self) -> usize {
        match self {
            VoxelType::U8 => 1,
            VoxelType::U16 | VoxelType::I16 => 2,
            VoxelType::F32 => 4,
        }
    }
    /// Parses `u8`, `u16`, `i16` or `f32`.
    pub fn parse(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().as_str() {
            "u8" | "uint8" | "uchar" => Ok(VoxelType::U8),
            "u16" | "uint16" | "ushort" => Ok(VoxelType::U16),
            "i16" | "int16" | "short" => Ok(VoxelType::I16),
            "f32" | "float" | "float32" => Ok(VoxelType::F32),
            other => Err(Error::value("voxel type", format!("'{other}' (expected u8, u16, i16 or f32)"))),
        }
    }
    /// The canonical name (`u8`, ...).
    pub fn name(self) -> &'static str {
        match self {
            VoxelType::U8 => "u8",
            VoxelType::U16 => "u16",
            VoxelType::I16 => "i16",
            VoxelType::F32 => "f32",
        }
    }
}

/// Typed voxel storage.
#[derive(Clone, Debug, PartialEq)]
pub enum VoxelData {
    U8(Vec<u8>),
    U16(Vec<u16>),
    I16(Vec<i16>),
    F32(Vec<f32>),
}

impl VoxelData {
    /// Number of voxels.
    pub fn len(&self) -> usize {
        match self {
            VoxelData::U8(v) => v.len(),
            VoxelData::U16(v) => v.len(),
            VoxelData::I16(v) => v.len(),
            VoxelData::F32(v) => v.len(),
        }
    }
    /// True when there are no voxels.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The voxel type.
    pub fn voxel_type(&self) -> VoxelType {
        match self {
            VoxelData::U8(_) => VoxelType::U8,
            VoxelData::U16(_) => VoxelType::U16,
            VoxelData::I16(_) => VoxelType::I16,
            VoxelData::F32(_) => VoxelType::F32,
        }
    }
    /// Voxel `i` as f32.
    #[inline]
    pub fn get(&self, i: usize) -> f32 {
        match self {
            VoxelData::U8(v) => v[i] as f32,
            VoxelData::U16(v) => v[i] as f32,
            VoxelData::I16(v) => v[i] as f32,
            VoxelData::F32(v) => v[i],
        }
    }
}
