//! The `shearwarp` command-line tool: `render`, `rotate`, `info`, `export`,
//! `bench` and (feature `viewer`) `view`. See [`app`].
mod app;

fn main() -> std::process::ExitCode {
    app::mark_start();
    app::cli::main()
}
