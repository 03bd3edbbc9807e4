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
