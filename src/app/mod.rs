//! The application around the renderer: everything a person runs, nothing a
//! library user needs.
//!
//! - [`cli`]: argument parsing, loading, the `render` / `rotate` / `info` /
//!   `export` commands, reports and image/animation output;
//! - [`bench`]: `shearwarp bench`, the speed-against-error matrix of every
//!   variant against the reference renderer, with tables and plots;
//! - [`viewer`] (feature `viewer`): `shearwarp view`, the interactive window.

pub mod bench;
pub mod cli;
pub mod viewer;

/// The median of `v` (sorted in place), `None` for no values: each report
/// says what an empty column shows.
pub fn median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) })
}
