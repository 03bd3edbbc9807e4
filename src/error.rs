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
    /// Structures that would exceed the memory budget (checked before anything
    /// is allocated), or an allocation the system refused.
    #[error("{}", memory_message(what, *needed, *held, *budget))]
    Memory { what: String, needed: u64, held: u64, budget: u64 },
    /// Anything else (image encoding, ...).
    #[error("{0}")]
    Other(String),
}

fn memory_message(what: &str, needed: u64, held: u64, budget: u64) -> String {
    let b = crate::fmt::fmt_bytes;
    if budget == 0 {
        format!("{what} needs {}: the system refused the allocation (not enough memory or address space)", b(needed))
    } else {
        format!("{what} needs {} with {} held already, over the memory budget of {}", b(needed), b(held), b(budget))
    }
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
