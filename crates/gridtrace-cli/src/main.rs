//! `gridtrace`: the command-line tool. Thin: parsing, printing and files; the work is in the
//! library.

mod animate;
mod animate_instances;
mod bench;
mod common;
mod info;
mod rays;
mod rays_counts;
mod render;
mod scan;
mod view;

use clap::{CommandFactory, Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "gridtrace",
    version = VERSION,
    long_version = long_version(),
    about = "Ray tracing on a uniform grid with proximity clouds, on the CPU and any GPU"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// CPU threads for the work (ray batches, renders, builds); default: one per core. To
    /// measure scaling, or to share the machine.
    #[arg(long, global = true, value_parser = clap::value_parser!(u16).range(1..=gridtrace::util::MAX_THREADS as i64), allow_hyphen_values = true)]
    threads: Option<u16>,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene to a PNG.
    Render(render::RenderArgs),
    /// Print a scene's mesh statistics, its structure's (--accel; auto: the BVH) and memory use,
    /// with the paper's memory model for a grid (--accel grid or pc).
    Info(info::InfoArgs),
    /// Cast rays from a file at a mesh and write the hits to a file.
    Rays(rays::RaysArgs),
    /// Scan a scene with a LiDAR or a depth camera: the point cloud as PLY, the range image as
    /// PNG; --frames N --orbit times scans from a moving pose.
    Scan(scan::ScanArgs),
    /// Benchmark the paper's scenes and modes (and grid sweeps, scaling, proximity clouds).
    Bench(bench::BenchArgs),
    /// Fly around a scene in a window: drag to orbit, wheel to zoom, 1-4 modes, G structure.
    View(view::ViewArgs),
}

/// `gridtrace -V`: the version and the git commit it was built from ("unknown" without git).
const VERSION: &str = concat!(
    env!("CARGO_PKG_VERSION"),
    " (commit ",
    env!("GRIDTRACE_GIT_COMMIT"),
    ")"
);

/// `gridtrace --version`: [`VERSION`], then what the library uses of this machine's CPU.
fn long_version() -> &'static str {
    let text = format!("{VERSION}\ncpu: {}", gridtrace::cpu_features());
    // Parsed once per run; clap wants a string that lives as long as the program.
    Box::leak(text.into_boxed_str())
}

/// Points `XDG_RUNTIME_DIR` at a private folder when it is unset or not a directory.
///
/// Opening a GPU adapter loads the Vulkan loader and drivers (Mesa's lavapipe included), whose
/// window-system code prints "error: XDG_RUNTIME_DIR is invalid or not set in the environment"
/// when the variable is missing (in containers, under `su`, in CI). Nothing fails, but the line
/// looks like a failure on a first run. A folder of our own, mode 0700 like a real runtime dir,
/// keeps it quiet. A valid setting is left alone.
#[cfg(unix)]
fn ensure_runtime_dir() {
    use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
    if std::env::var_os("XDG_RUNTIME_DIR").is_some_and(|d| std::path::Path::new(&d).is_dir()) {
        return;
    }
    // /proc/self belongs to the process's user; without /proc, the pid keeps the name ours.
    let uid = std::fs::metadata("/proc/self").map(|m| m.uid());
    let tag = match uid {
        Ok(uid) => format!("uid{uid}"),
        Err(_) => format!("pid{}", std::process::id()),
    };
    let dir = std::env::temp_dir().join(format!("gridtrace-runtime-{tag}"));
    let _ = std::fs::DirBuilder::new().mode(0o700).create(&dir);
    // Use the folder only if it is a real directory (not a link someone planted in /tmp), ours,
    // and private; otherwise leave the environment as it was (the message is cosmetic).
    let ok = std::fs::symlink_metadata(&dir)
        .is_ok_and(|m| m.is_dir() && uid.as_ref().is_ok_and(|u| m.uid() == *u) && m.permissions().mode() & 0o077 == 0)
        || (uid.is_err() && dir.is_dir());
    if ok {
        // SAFETY: called first thing in `main`, before clap, rayon, indicatif or any GPU code
        // has started a thread, so no other thread can be reading the environment.
        unsafe { std::env::set_var("XDG_RUNTIME_DIR", &dir) };
    }
}

#[cfg(not(unix))]
fn ensure_runtime_dir() {}

/// Ends the process quietly, as Unix tools do, when the reader of its output goes away
/// (`gridtrace render ... | head -1`): the Rust runtime ignores SIGPIPE, so a write to a closed
/// pipe fails with EPIPE and `println!` panics ("failed printing to stdout: Broken pipe", exit
/// 101). With the default action restored, the write ends the process by the signal, and the
/// shell's pipeline takes the status of its last command (`head`'s 0). Files the command had yet
/// to write are not written, as with any tool whose reader left.
#[cfg(unix)]
fn restore_sigpipe() {
    // SAFETY: `signal` with SIG_DFL installs no handler of ours; it is called first thing in
    // `main`, before any other thread exists that could be changing signal dispositions.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

#[cfg(not(unix))]
fn restore_sigpipe() {}

fn main() {
    restore_sigpipe();
    ensure_runtime_dir();
    let cli = Cli::parse();
    // Build parameters are read by each structure (the library's registry knows no keys), so
    // clap cannot check them; they are checked here, before any work, and refused as clap
    // refuses other bad arguments: its message form and exit status 2.
    let accel = match &cli.command {
        Command::Render(a) => Some(("render", &a.accel_args)),
        Command::Info(a) => Some(("info", &a.accel_args)),
        Command::Rays(a) => Some(("rays", &a.accel_args)),
        Command::View(a) => Some(("view", &a.accel_args)),
        Command::Scan(a) => Some(("scan", &a.accel_args)),
        Command::Bench(_) => None,
    };
    if let Some((name, Err(e))) = accel.map(|(name, a)| (name, a.check())) {
        // The subcommand's own usage line under the message, as clap prints for its errors.
        let mut cmd = Cli::command();
        cmd.build();
        let sub = cmd.find_subcommand_mut(name).expect("a subcommand of Cli");
        sub.error(clap::error::ErrorKind::ValueValidation, e).exit();
    }
    if let Some(n) = cli.threads {
        // Before any parallel work: the global pool is built once, on first use.
        if let Err(e) = rayon::ThreadPoolBuilder::new().num_threads(n.into()).build_global() {
            eprintln!("error: --threads {n}: could not start the thread pool: {e}");
            std::process::exit(1);
        }
    }
    let result = match cli.command {
        // `render --animate` is its own loop (a structure update per frame), on the same options.
        Command::Render(a) if a.animate => animate::run(&a),
        Command::Render(a) => render::run(a),
        Command::Info(a) => info::run(a),
        // `rays --counts` answers another query (every hit) on the same input.
        Command::Rays(a) if a.counts && a.make.is_none() => rays_counts::run(a),
        Command::Rays(a) => rays::run(a),
        Command::Scan(a) => scan::run(a),
        Command::Bench(a) => bench::run(a),
        Command::View(a) => view::run(a),
    };
    if let Err(e) = result {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
