//! Every file the crate and its command line write: atomic, checked outputs.
//!
//! - **Atomic.** [`Output::create`] opens a temporary file beside the target
//!   (same directory, so the final rename stays on one file system); the
//!   caller writes through [`Output::writer`], and [`Output::commit`] flushes,
//!   syncs and renames it over the target. Until then the previous file is
//!   untouched; an error, or dropping the output uncommitted, removes the
//!   temporary. Two writers to one path each write their own temporary and
//!   each rename leaves a complete file: the last rename wins.
//! - **In place.** A target that exists and is not a regular file (a device
//!   such as `/dev/full` or `/dev/null`, a FIFO) is never replaced: it is
//!   written directly, and `-` writes to standard output. A symbolic link is
//!   followed: its target is replaced, the link stays.
//! - **Checked.** Every write, the flush, the sync and the rename are
//!   checked, and each error names the path. A write error an encoder
//!   swallows (some write their trailer on drop and ignore its result) is kept
//!   by the writer and reported by [`Output::commit`].
//! - **Signals.** Temporaries are registered while they exist;
//!   [`abandon_pending`] (called by the command line's signal handler)
//!   removes them all and refuses every later commit, so a process
//!   interrupted mid-write leaves the previous files and no temporary.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use crate::error::{Error, Result};

/// The temporaries that exist now, and whether they were abandoned (after
/// which no output is committed).
struct Pending {
    temps: Vec<PathBuf>,
    abandoned: bool,
}

static PENDING: Mutex<Pending> = Mutex::new(Pending { temps: Vec::new(), abandoned: false });

fn pending() -> std::sync::MutexGuard<'static, Pending> {
    // (the list stays consistent whatever panicked while holding it)
    PENDING.lock().unwrap_or_else(|e| e.into_inner())
}

/// Removes every temporary output that exists now and makes every later
/// [`Output::commit`] fail: for a signal handler that then exits. Returns
/// how many temporaries it removed.
pub fn abandon_pending() -> usize {
    let mut p = pending();
    p.abandoned = true;
    let n = p.temps.len();
    for t in p.temps.drain(..) {
        let _ = std::fs::remove_file(&t);
    }
    n
}

/// Where the bytes go.
enum Sink {
    /// A temporary beside the target, renamed over it by [`Output::commit`].
    Temp { file: BufWriter<File>, temp: PathBuf, target: PathBuf },
    /// An existing non-regular file, written in place.
    InPlace(BufWriter<File>),
    /// Standard output (`-`).
    Stdout(BufWriter<io::Stdout>),
}

/// The writer of an [`Output`]: buffered, and keeping the first error any
/// write or flush met (reported again by [`Output::commit`] even when the
/// encoder that met it dropped it).
pub struct OutputWriter {
    sink: Sink,
    failed: Option<io::ErrorKind>,
    first_error: Option<String>,
}

impl OutputWriter {
    fn note<T>(&mut self, r: io::Result<T>) -> io::Result<T> {
        if let Err(e) = &r
            && self.first_error.is_none()
        {
            self.failed = Some(e.kind());
            self.first_error = Some(e.to_string());
        }
        r
    }
}

impl Write for OutputWriter {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        if let Some(kind) = self.failed {
            // (a writer that failed once never writes again: no bytes after a hole)
            return Err(io::Error::new(kind, self.first_error.clone().unwrap_or_default()));
        }
        let r = match &mut self.sink {
            Sink::Temp { file, .. } | Sink::InPlace(file) => file.write(buf),
            Sink::Stdout(s) => s.write(buf),
        };
        self.note(r)
    }

    fn flush(&mut self) -> io::Result<()> {
        if let Some(kind) = self.failed {
            return Err(io::Error::new(kind, self.first_error.clone().unwrap_or_default()));
        }
        let r = match &mut self.sink {
            Sink::Temp { file, .. } | Sink::InPlace(file) => file.flush(),
            Sink::Stdout(s) => s.flush(),
        };
        self.note(r)
    }
}

/// One output file being written (see the module docs).
pub struct Output {
    path: PathBuf,
    w: Option<OutputWriter>,
}

fn named(path: &Path, what: &str, e: impl std::fmt::Display) -> Error {
    Error::file(path, format!("{what}: {e}"))
}

impl Output {
    /// Opens `path` for writing: a temporary beside it, or the file itself
    /// when it exists and is not a regular file, or standard output for `-`.
    pub fn create(path: impl AsRef<Path>) -> Result<Output> {
        let path = path.as_ref();
        if path.as_os_str() == "-" {
            return Ok(Output { path: path.into(), w: Some(OutputWriter::new(Sink::Stdout(BufWriter::new(io::stdout())))) });
        }
        // a link is followed: the file it names is replaced, the link stays
        let target = match std::fs::symlink_metadata(path) {
            Ok(m) if m.file_type().is_symlink() => match std::fs::canonicalize(path) {
                Ok(t) => t,
                // a dangling link: written through (creates its target)
                Err(_) => path.to_path_buf(),
            },
            _ => path.to_path_buf(),
        };
        let existing = std::fs::metadata(&target).ok();
        if let Some(m) = &existing
            && !m.is_file()
        {
            if m.is_dir() {
                return Err(Error::file(path, "is a directory, not a file to write"));
            }
            let f = std::fs::OpenOptions::new().write(true).open(&target).map_err(|e| named(path, "cannot open for writing", e))?;
            return Ok(Output { path: path.into(), w: Some(OutputWriter::new(Sink::InPlace(BufWriter::new(f)))) });
        }
        let dir = match target.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let name = target.file_name().map_or_else(|| "output".into(), |n| n.to_string_lossy().into_owned());
        let prefix = format!(".{name}.");
        let mut b = tempfile::Builder::new();
        b.prefix(&prefix).suffix(".tmp");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            // a new file's mode as `File::create` would give it (the umask
            // applies); an existing file keeps its own
            let mode = existing.as_ref().map_or(0o666, |m| m.permissions().mode() & 0o7777);
            b.permissions(std::fs::Permissions::from_mode(mode));
        }
        // registered before it exists: a signal between the two still removes it
        let mut p = pending();
        if p.abandoned {
            return Err(Error::file(path, "not written: interrupted"));
        }
        let tmp = b.tempfile_in(&dir).map_err(|e| named(path, "cannot create a temporary file beside it", e))?;
        let (file, temp) = tmp.keep().map_err(|e| named(path, "cannot keep the temporary file", e.error))?;
        #[cfg(unix)]
        if let Some(m) = &existing {
            // (the umask may have narrowed the mode asked for at creation)
            let _ = file.set_permissions(m.permissions());
        }
        p.temps.push(temp.clone());
        drop(p);
        Ok(Output {
            path: path.into(),
            w: Some(OutputWriter::new(Sink::Temp { file: BufWriter::with_capacity(1 << 16, file), temp, target })),
        })
    }

    /// The path as given.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The writer (buffered).
    pub fn writer(&mut self) -> &mut OutputWriter {
        self.w.as_mut().expect("an output is written until it is committed")
    }

    /// Flushes and syncs what was written and puts it in place: renames the
    /// temporary over the target (the previous file stays until then). Any
    /// write, flush, sync or rename error is an error naming the path (the
    /// temporary removed, the previous file untouched).
    pub fn commit(self) -> Result<()> {
        self.finish(true)
    }

    /// [`Output::commit`] without the sync: complete and in place (an error
    /// or a signal still leaves the previous file), durable once
    /// [`sync_written`] ran for its directory. For many files in a row (a
    /// directory of frames), where a sync per file would cost more than the
    /// frames themselves.
    pub fn commit_unsynced(self) -> Result<()> {
        self.finish(false)
    }

    fn finish(mut self, sync: bool) -> Result<()> {
        let mut w = self.w.take().expect("committed once");
        let path = self.path.clone();
        let flushed = w.flush();
        if let Some(e) = w.first_error.take() {
            discard(w.sink);
            return Err(Error::file(&path, format!("cannot write: {e}")));
        }
        if let Err(e) = flushed {
            discard(w.sink);
            return Err(named(&path, "cannot write", e));
        }
        match w.sink {
            Sink::Stdout(_) => Ok(()),
            Sink::InPlace(f) => {
                let f = f.into_inner().map_err(|e| named(&path, "cannot write", e.error()))?;
                match f.sync_all() {
                    // (a device or FIFO may not sync: what matters was written)
                    Err(e) if matches!(e.raw_os_error(), Some(22) | Some(25) | Some(95)) => Ok(()),
                    r => r.map_err(|e| named(&path, "cannot write", e)),
                }
            }
            Sink::Temp { file, temp, target } => {
                let f = match file.into_inner() {
                    Ok(f) => f,
                    Err(e) => {
                        let why = named(&path, "cannot write", e.error());
                        forget_temp(&temp, true);
                        return Err(why);
                    }
                };
                if sync && let Err(e) = f.sync_all() {
                    forget_temp(&temp, true);
                    return Err(named(&path, "cannot write (sync)", e));
                }
                drop(f);
                let mut p = pending();
                if p.abandoned {
                    drop(p);
                    forget_temp(&temp, true);
                    return Err(Error::file(&path, "not written: interrupted"));
                }
                if let Err(e) = std::fs::rename(&temp, &target) {
                    let _ = std::fs::remove_file(&temp);
                    p.temps.retain(|t| t != &temp);
                    return Err(named(&path, "cannot replace", e));
                }
                p.temps.retain(|t| t != &temp);
                drop(p);
                // the rename itself made durable (best effort: not every file
                // system syncs a directory, and the output is complete either way)
                if sync
                    && let Some(d) = target.parent().filter(|d| !d.as_os_str().is_empty())
                    && let Ok(d) = File::open(d)
                {
                    let _ = d.sync_all();
                }
                Ok(())
            }
        }
    }
}

impl OutputWriter {
    fn new(sink: Sink) -> Self {
        OutputWriter { sink, failed: None, first_error: None }
    }
}

/// Removes a temporary (when `remove`) and forgets it.
fn forget_temp(temp: &Path, remove: bool) {
    let mut p = pending();
    if remove {
        let _ = std::fs::remove_file(temp);
    }
    p.temps.retain(|t| t != temp);
}

fn discard(sink: Sink) {
    if let Sink::Temp { file, temp, .. } = sink {
        // (its buffer is dropped unwritten: the file is removed anyway)
        let (f, _) = file.into_parts();
        drop(f);
        forget_temp(&temp, true);
    }
}

impl Drop for Output {
    fn drop(&mut self) {
        // uncommitted (an error on the way): the temporary goes, the previous file stays
        if let Some(w) = self.w.take() {
            discard(w.sink);
        }
    }
}

/// Makes the files [`Output::commit_unsynced`] put in directory `dir`
/// durable: one sync of its file system (Linux), else of the directory.
pub fn sync_written(dir: &Path) -> Result<()> {
    let d = File::open(dir).map_err(|e| named(dir, "cannot open to sync", e))?;
    #[cfg(target_os = "linux")]
    rustix::fs::syncfs(&d).map_err(|e| named(dir, "cannot sync", std::io::Error::from(e)))?;
    #[cfg(not(target_os = "linux"))]
    let _ = d.sync_all();
    Ok(())
}

/// [`write_png`] committed with [`Output::commit_unsynced`] (see there).
pub fn write_png_unsynced(path: impl AsRef<Path>, img: &image::RgbImage) -> Result<()> {
    let mut out = Output::create(path)?;
    encode_png(&mut out, img)?;
    out.commit_unsynced()
}

fn encode_png(out: &mut Output, img: &image::RgbImage) -> Result<()> {
    use image::ImageEncoder;
    let enc = image::codecs::png::PngEncoder::new(out.writer());
    enc.write_image(img.as_raw(), img.width(), img.height(), image::ExtendedColorType::Rgb8)
        .map_err(|e| named(out.path(), "cannot write PNG", e))
}

/// Writes an 8-bit RGB PNG to `path` atomically (see [`Output`]).
pub fn write_png(path: impl AsRef<Path>, img: &image::RgbImage) -> Result<()> {
    let mut out = Output::create(path)?;
    // (an error drops the output uncommitted: the temporary goes)
    encode_png(&mut out, img)?;
    out.commit()
}

/// Writes `bytes` to `path` atomically (see [`Output`]).
pub fn write_bytes(path: impl AsRef<Path>, bytes: &[u8]) -> Result<()> {
    write_with(path, |w| w.write_all(bytes))
}

/// Writes `path` atomically with `f` (see [`Output`]): `f`'s error is an
/// error naming the path, and nothing replaces the previous file.
pub fn write_with(path: impl AsRef<Path>, f: impl FnOnce(&mut OutputWriter) -> io::Result<()>) -> Result<()> {
    let mut out = Output::create(path)?;
    if let Err(e) = f(out.writer()) {
        let path = out.path().to_path_buf();
        drop(out);
        return Err(named(&path, "cannot write", e));
    }
    out.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temps_in(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".tmp"))
            .collect()
    }

    #[test]
    fn a_committed_output_replaces_the_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.bin");
        std::fs::write(&p, b"old").unwrap();
        write_bytes(&p, b"new bytes").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"new bytes");
        assert!(temps_in(dir.path()).is_empty());
    }

    #[test]
    fn a_failed_or_dropped_output_keeps_the_previous_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.bin");
        std::fs::write(&p, b"old").unwrap();
        let e = write_with(&p, |w| {
            w.write_all(b"partial")?;
            Err(io::Error::other("encoder failed"))
        })
        .unwrap_err();
        assert!(e.to_string().contains("a.bin") && e.to_string().contains("encoder failed"), "{e}");
        let mut out = Output::create(&p).unwrap();
        out.writer().write_all(b"never committed").unwrap();
        drop(out);
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
        assert!(temps_in(dir.path()).is_empty());
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_full_device_is_an_error_naming_it_and_is_not_replaced() {
        for n in [1, 100_000] {
            let e = write_bytes("/dev/full", &vec![7u8; n]).unwrap_err();
            assert!(e.to_string().contains("/dev/full"), "{e}");
        }
        assert!(std::fs::metadata("/dev/full").unwrap().file_type().is_char_device_like());
    }

    #[cfg(target_os = "linux")]
    trait CharDevice {
        fn is_char_device_like(&self) -> bool;
    }
    #[cfg(target_os = "linux")]
    impl CharDevice for std::fs::FileType {
        fn is_char_device_like(&self) -> bool {
            use std::os::unix::fs::FileTypeExt;
            self.is_char_device()
        }
    }

    #[test]
    fn a_symlink_is_followed_and_kept() {
        let dir = tempfile::tempdir().unwrap();
        let real = dir.path().join("real.txt");
        std::fs::write(&real, b"old").unwrap();
        let link = dir.path().join("link.txt");
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(&real, &link).unwrap();
            write_bytes(&link, b"new").unwrap();
            assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
            assert_eq!(std::fs::read(&real).unwrap(), b"new");
        }
    }
}
