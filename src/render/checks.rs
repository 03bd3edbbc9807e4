//! Sanity checks and warnings shared by the command-line tools: bounds on
//! the thread count, volumes too thin to render, and warnings about frames
//! that are not what they may seem (an iso value outside the data, an empty
//! image). Quiet: callers print what these return.

use super::Renderer;
pub use super::settings::{check_threads, max_threads};
use crate::composite::Mode;
use crate::error::{Error, Result};
use crate::fmt::fmt_density;

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

/// Warnings about the frame `r` last rendered, whose image has `coverage`
/// (fraction of covered pixels): an iso value outside the data's range, or
/// nothing visible. Empty when the image is what it looks like.
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
    fn thread_and_volume_bounds() {
        assert!(check_threads(0).is_ok() && check_threads(max_threads()).is_ok());
        let e = check_threads(max_threads() + 1).unwrap_err().to_string();
        assert!(e.contains("--threads") && e.contains("8 per core"), "{e}");
        assert!(check_renderable([2, 2, 2]).is_ok());
        assert!(check_renderable([5, 1, 5]).unwrap_err().to_string().contains("along y"));
    }
}
