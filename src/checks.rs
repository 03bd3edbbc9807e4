//! Sanity checks and warnings shared by the command-line tools: bounds on
//! the thread count, volumes too thin to render, and warnings about frames
//! that are not what they may seem (an iso value outside the data, an empty
//! image). Quiet: callers print what these return.

use crate::composite::Mode;
use crate::error::{Error, Result};
use crate::render::Renderer;

/// The largest thread count accepted: 8 per core. More threads than that
/// only add start-up and scheduling cost (`--threads 100000` used to hang).
pub fn max_threads() -> usize {
    8 * std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Checks a `--threads` count (0 = every core) against [`max_threads`].
pub fn check_threads(threads: usize) -> Result<()> {
    let max = max_threads();
    if threads > max {
        return Err(Error::value(
            "--threads",
            format!("{threads} is more than {max} (8 per core on this machine's {} cores); 0 uses every core", max / 8),
        ));
    }
    Ok(())
}

/// A volume one voxel thick along an axis has no cells there, so shear-warp
/// would draw an empty image: an error naming the axis.
pub fn check_renderable(dims: [usize; 3]) -> Result<()> {
    if let Some(a) = dims.iter().position(|&n| n < 2) {
        return Err(Error::value(
            "volume",
            format!(
                "{}×{}×{} is one voxel thick along {}, and shear-warp renders the cells between voxels, so the image would \
                 be empty; `shearwarp info` describes it",
                dims[0],
                dims[1],
                dims[2],
                ["x", "y", "z"][a]
            ),
        ));
    }
    Ok(())
}

/// A density for messages: plain, or in scientific notation when huge or tiny
/// (a ±FLT_MAX sentinel prints as `-3.4028235e38`, not 39 digits).
pub fn fmt_density(x: f32) -> String {
    if x != 0.0 && !(1e-4..1e9).contains(&x.abs()) { format!("{x:e}") } else { format!("{x}") }
}

/// Warnings about the frame `r` last rendered, whose image has `coverage`
/// (fraction of covered pixels): an iso value outside the data's range, or
/// nothing visible. Empty when the image is what it looks like.
/// `bytes` in binary units: `512 B`, `3.2 KiB`, `108.3 MiB`, `1.50 GiB`.
pub fn fmt_bytes(bytes: u64) -> String {
    const K: f64 = 1024.0;
    let b = bytes as f64;
    if b < K {
        format!("{bytes} B")
    } else if b < K * K {
        format!("{:.1} KiB", b / K)
    } else if b < K * K * K {
        format!("{:.1} MiB", b / (K * K))
    } else {
        format!("{:.2} GiB", b / (K * K * K))
    }
}

/// Parses a byte count with an optional binary suffix: `4096`, `512k`,
/// `300M`, `2G`, `1.5G` (k/M/G/T = 2^10/2^20/2^30/2^40; a trailing `B` or `iB`
/// is allowed).
pub fn parse_bytes(s: &str) -> Result<u64> {
    let t = s.trim();
    let t = t.strip_suffix("iB").or_else(|| t.strip_suffix('B')).unwrap_or(t);
    let (num, mult) = match t.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => {
            let m = match c.to_ascii_lowercase() {
                'k' => 1u64 << 10,
                'm' => 1 << 20,
                'g' => 1 << 30,
                't' => 1 << 40,
                _ => return Err(Error::value("byte count", format!("'{s}': the suffix must be k, M, G or T"))),
            };
            (&t[..i], m)
        }
        _ => (t, 1),
    };
    let x: f64 = num.trim().parse().map_err(|_| Error::value("byte count", format!("'{s}' is not a number of bytes (e.g. 512M, 2G)")))?;
    let v = x * mult as f64;
    if !(v.is_finite() && v >= 1.0 && v < 2f64.powi(63)) {
        return Err(Error::value("byte count", format!("'{s}' must be at least 1 byte and finite")));
    }
    Ok(v as u64)
}

pub fn frame_warnings(r: &Renderer, coverage: f64) -> Vec<String> {
    let mut w = Vec::new();
    let (lo, hi) = r.value_range();
    let n = fmt_density;
    if r.settings().mode == Mode::Iso {
        let iso = r.iso();
        if iso > hi {
            w.push(format!("the iso value {} is above the data's largest value {}: nothing can be visible", n(iso), n(hi)));
        } else if iso <= lo {
            w.push(format!("the iso value {} is at or below the data's smallest value {}: the whole volume box is opaque", n(iso), n(lo)));
        }
    }
    if coverage == 0.0 {
        w.push(format!(
            "nothing is visible in the image (tissue {}, iso {}, data range {} … {}); try another --tissue or --iso",
            r.classification_name(),
            n(r.iso()),
            n(lo),
            n(hi)
        ));
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_and_formatting() {
        assert!(check_threads(0).is_ok() && check_threads(max_threads()).is_ok());
        let e = check_threads(max_threads() + 1).unwrap_err().to_string();
        assert!(e.contains("--threads") && e.contains("8 per core"), "{e}");
        assert!(check_renderable([2, 2, 2]).is_ok());
        assert!(check_renderable([5, 1, 5]).unwrap_err().to_string().contains("along y"));
        assert_eq!(fmt_density(-f32::MAX), "-3.4028235e38");
        assert_eq!(fmt_density(-1000.0), "-1000");
        assert_eq!(fmt_density(0.0), "0");
        assert_eq!(parse_bytes("4096").unwrap(), 4096);
        assert_eq!(parse_bytes("512k").unwrap(), 512 << 10);
        assert_eq!(parse_bytes("300M").unwrap(), 300 << 20);
        assert_eq!(parse_bytes("1.5G").unwrap(), 3 << 29);
        assert_eq!(parse_bytes("2GiB").unwrap(), 2 << 30);
        assert_eq!(parse_bytes("64MB").unwrap(), 64 << 20);
        for bad in ["", "x", "12Q", "-5M", "NaN", "0", "1e300G"] {
            assert!(parse_bytes(bad).is_err(), "{bad}");
        }
        assert_eq!(fmt_bytes(512), "512 B");
        assert_eq!(fmt_bytes(108 << 20), "108.0 MiB");
    }
}
