//! The `shearwarp` command-line tool; see [`shearwarp::cli`].
fn main() -> std::process::ExitCode {
    shearwarp::cli::main()
}
