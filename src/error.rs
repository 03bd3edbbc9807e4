//! The crate's error type: every fallible public function returns [`Result`].
//!
//! Errors name what went wrong in words a user can act on (which file, which
//! dimension, which value). Nothing in the library panics on bad input.

use std::path::PathBuf;

/// Everything that can go wrong in shearwarp.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Volume dimensions that are zero, negative or too large to allocate.
    #[error("invalid dimensions {dims:?}: {why}")]
    BadDims { dims: Vec<u64>, why: String },
    /// A value that is out of its allowed range (spacing, zoom, threshold, ...).
    #[error("invalid {what}: {why}")]
    BadValue { what: &'static str, why: String },
    /// A voxel that is NaN or infinite.
    #[error("voxel {index} is {value} (NaN and infinite voxels are rejected; clean the data first)")]
    NonFinite { index: usize, value: f32 },
    /// A file that could not be read or parsed.
    #[error("{path}: {why}")]
    File { path: PathBuf, why: String },
    /// I/O error with the path it happened on. (Not marked as the error's
    /// source: the message already holds it, and a report that walks the
    /// chain would print it twice.)
    #[error("{path}: {error}")]
    Io { path: PathBuf, error: std::io::Error },
    /// Anything else (image encoding, ...).
    #[error("{0}")]
    Other(String),
}

/// Shorthand for results carrying [`Error`].
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    /// Builds a [`Error::File`] for `path`.
    pub fn file(path: impl Into<PathBuf>, why: impl Into<String>) -> Self {
        Error::File { path: path.into(), why: why.into() }
    }
    /// Builds a [`Error::BadValue`].
    pub fn value(what: &'static str, why: impl Into<String>) -> Self {
        Error::BadValue { what, why: why.into() }
    }
}
