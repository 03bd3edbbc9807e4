//! Shared by the fuzz targets: a per-process scratch directory and a helper
//! that writes the input to a file there.

use std::path::PathBuf;
use std::sync::OnceLock;

/// The scratch directory (deleted when the process exits normally).
pub fn scratch() -> &'static tempfile::TempDir {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| tempfile::tempdir().expect("create a scratch directory"))
}

/// Writes `data` to `name` in the scratch directory and returns its path.
pub fn write(name: &str, data: &[u8]) -> PathBuf {
    let p = scratch().path().join(name);
    std::fs::write(&p, data).expect("write the fuzz input");
    p
}
