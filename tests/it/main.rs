//! The integration tests, one crate: a module per subject, `common` for the
//! helpers they share. One binary links the library once; `cargo test --release
//! --test it MODULE::` runs one subject (for example `golden::` or `invariants::`).

mod common;

mod accuracy;
mod bcc;
mod bench_cli;
mod bench_matrix;
mod bricks;
mod cli;
mod cli_inputs;
mod clip;
mod deluxe_binary;
mod deluxe_matched;
mod deluxe_rle;
#[cfg(feature = "mpi")]
mod distributed;
mod extreme_values;
mod focus;
mod geometry;
mod golden;
mod invariants;
mod io_bounded_inputs;
mod io_fuzz;
mod io_outputs;
mod io_real;
mod io_synth;
mod lean_cubic;
mod lean_frame;
mod memory;
mod orientation;
mod perspective;
mod perspective_binary;
mod plan;
mod quality;
mod readme;
mod reconstruction;
mod rle;
mod rle_reuse;
mod stress;
mod surface_truth;
mod switch_cost;
mod tissues;
