//! `gridtrace`: the command-line tool. Thin: parsing, printing and files; the work is in the
//! library.

mod bench;
mod common;
mod info;
mod rays;
mod render;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "gridtrace",
    version,
    about = "Ray tracing on a uniform grid with proximity clouds, on the CPU and any GPU"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene to a PNG.
    Render(render::RenderArgs),
    /// Print mesh and grid statistics and memory use.
    Info(info::InfoArgs),
    /// Cast rays from a file at a mesh and write the hits to a file.
    Rays(rays::RaysArgs),
    /// Benchmark the paper's scenes and modes (and grid sweeps, scaling, proximity clouds).
    Bench(bench::BenchArgs),
}

fn main() {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(a) => render::run(a),
        Command::Info(a) => info::run(a),
        Command::Rays(a) => rays::run(a),
        Command::Bench(a) => bench::run(a),
    };
    if let Err(e) = result {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
