//! The command line's outputs: the image type an output path names, the
//! animations (GIF, APNG) and plots written through the library's atomic
//! [`shearwarp::output`], and the signal handler that leaves no temporary
//! behind (Ctrl-C, SIGTERM, SIGHUP: every temporary removed, the previous
//! files untouched, exit 128 + the signal's number).

use std::io::Write;
use std::path::Path;

use shearwarp::output::{Output, OutputWriter};
use shearwarp::{Error, Result};

/// The image types an output path may name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageKind {
    Png,
    Gif,
    Apng,
}

/// The extensions [`image_kind`] knows.
pub const IMAGE_EXTENSIONS: &str = ".png, .gif, .apng";

/// The image type of output `path`, from its extension; an unknown or
/// missing extension is an error listing the known ones, except for standard
/// output (`-`) and an existing file that is not a regular one (a device, a
/// FIFO), which take PNG.
pub fn image_kind(path: &Path) -> std::result::Result<ImageKind, String> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("png") => Ok(ImageKind::Png),
        Some("gif") => Ok(ImageKind::Gif),
        Some("apng") => Ok(ImageKind::Apng),
        _ if path.as_os_str() == "-" || std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir()) => Ok(ImageKind::Png),
        Some(e) => Err(format!("{}: unknown image type .{e} (known: {IMAGE_EXTENSIONS})", path.display())),
        None => Err(format!("{}: no extension to tell the image type (known: {IMAGE_EXTENSIONS})", path.display())),
    }
}

/// Writes one image as `kind`.
pub fn write_image(path: &Path, kind: ImageKind, img: &image::RgbImage) -> Result<()> {
    match kind {
        ImageKind::Png => shearwarp::output::write_png(path, img),
        ImageKind::Gif => write_gif(path, std::slice::from_ref(img)),
        ImageKind::Apng => write_apng(path, std::slice::from_ref(img)),
    }
}

fn failed(out: Output, what: &str, e: impl std::fmt::Display) -> Error {
    let path = out.path().to_path_buf();
    // (dropped uncommitted: the temporary goes, the previous file stays)
    drop(out);
    Error::file(path, format!("{what}: {e}"))
}

/// Writes an endlessly looping animated GIF, 40 ms per frame.
pub fn write_gif(path: &Path, frames: &[image::RgbImage]) -> Result<()> {
    use image::codecs::gif::{GifEncoder, Repeat};
    let mut out = Output::create(path)?;
    {
        let mut enc = GifEncoder::new_with_speed(out.writer(), 10);
        if let Err(e) = enc.set_repeat(Repeat::Infinite) {
            drop(enc);
            return Err(failed(out, "cannot write GIF", e));
        }
        for fr in frames {
            let rgba = image::DynamicImage::ImageRgb8(fr.clone()).to_rgba8();
            if let Err(e) = enc.encode_frame(image::Frame::from_parts(rgba, 0, 0, image::Delay::from_numer_denom_ms(40, 1))) {
                drop(enc);
                return Err(failed(out, "cannot write GIF frame", e));
            }
        }
        // dropping the encoder writes the trailer; an error doing so is kept
        // by the output's writer and reported by the commit
    }
    out.commit()
}

/// Writes an animated PNG, 25 frames per second.
pub fn write_apng(path: &Path, frames: &[image::RgbImage]) -> Result<()> {
    let Some(first) = frames.first() else { return Err(Error::file(path, "no frames to write")) };
    let mut out = Output::create(path)?;
    let res = (|w: &mut OutputWriter| -> std::result::Result<(), png::EncodingError> {
        let mut enc = png::Encoder::new(w, first.width(), first.height());
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_animated(frames.len() as u32, 0)?;
        enc.set_frame_delay(1, 25)?;
        let mut w = enc.write_header()?;
        for fr in frames {
            w.write_image_data(fr.as_raw())?;
        }
        w.finish()
    })(out.writer());
    match res {
        Ok(()) => out.commit(),
        Err(e) => Err(failed(out, "cannot write APNG", e)),
    }
}

/// Writes text (CSV, JSON, SVG) atomically.
pub fn write_text(path: &Path, text: &str) -> Result<()> {
    shearwarp::output::write_with(path, |w| w.write_all(text.as_bytes()))
}

/// Prints `text` to standard output, checked: a write error (a full disk
/// behind a redirection) is an error; a closed pipe (`… | head`) ends the
/// program quietly, as the command line's other reports do.
pub fn print_text(text: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => std::process::exit(0),
        Err(e) => Err(Error::file("standard output", format!("cannot write: {e}"))),
    }
}

/// Installs the handler of SIGINT, SIGTERM and SIGHUP (a thread: remove
/// every temporary output, exit 128 + the signal) and ignores SIGXFSZ, so a
/// file-size limit is a write error (reported, the temporary removed) rather
/// than a kill that would leave the temporary behind.
pub fn install_signal_handlers() {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM, SIGXFSZ};
    // (the flag is never read: registering it replaces SIGXFSZ's default action)
    let _ = signal_hook::flag::register(SIGXFSZ, std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false)));
    let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]) else { return };
    let _ = std::thread::Builder::new().name("signals".into()).spawn(move || {
        if let Some(sig) = signals.forever().next() {
            let removed = shearwarp::output::abandon_pending();
            let name = match sig {
                SIGINT => "SIGINT",
                SIGTERM => "SIGTERM",
                _ => "SIGHUP",
            };
            let what = if removed > 0 { "; the unfinished output was removed, the previous file is untouched" } else { "" };
            let _ = writeln!(std::io::stderr(), "\nshearwarp: interrupted ({name}){what}");
            std::process::exit(128 + sig);
        }
    });
}
