//! `gridtrace bench`: the paper's benchmark matrix and studies; the work is in
//! `gridtrace_bench`, this file parses, prints and writes.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use gridtrace::gpu::GpuContext;
use gridtrace::{AccelKind, Mode, Resolution};
use gridtrace_bench::{self as bench, BenchBackend, BenchConfig, BenchReport, Machine, scenes};

use crate::common::{kind_parser, mode_parser, parse_res};

mod study;
mod suite;

use study::Run;
use suite::run_hardware_suite;

/// Where the benchmark runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BenchBackendArg {
    /// The CPU, and the GPU too if a hardware adapter is found (else it says so).
    Auto,
    /// The GPU only (fails without an adapter).
    Gpu,
    /// The CPU only.
    Cpu,
    /// Both (fails without an adapter).
    Both,
}

#[derive(Args)]
pub struct BenchArgs {
    /// Small and fast (well under a minute): torus knot and Stanford bunny at 128x128, 1 warm-up,
    /// 3 repetitions, CPU only unless --backend says otherwise. Explicit options still apply.
    #[arg(long)]
    quick: bool,
    /// Scenes, comma separated: knight, torus-knot, bunny, stanford-bunny (default: all four).
    #[arg(long, value_delimiter = ',')]
    scenes: Vec<String>,
    /// Image sizes in pixels, comma separated, each WxH or N for N x N (default: 256,512,768).
    #[arg(long, value_name = "WxH|N", value_delimiter = ',', value_parser = parse_res, allow_hyphen_values = true)]
    res: Vec<(u32, u32)>,
    /// Accelerations, comma separated: grid, pc, bvh (default: grid and pc, the paper's).
    #[arg(long, value_delimiter = ',', value_parser = kind_parser())]
    accel: Vec<AccelKind>,
    /// Modes, comma separated: cast, shadow, trace (default: all three).
    #[arg(long, value_delimiter = ',', value_parser = mode_parser())]
    mode: Vec<Mode>,
    /// auto (CPU, plus the GPU if found), cpu, gpu or both. Default: auto (cpu with --quick).
    #[arg(long, value_enum)]
    backend: Option<BenchBackendArg>,
    #[command(flatten)]
    gpu: crate::common::GpuVariantArgs,
    /// Untimed runs before the timed ones.
    // Hyphen values on numbers: a negative one then gets "invalid value", not clap's advice to
    // write "-- -1".
    #[arg(long, allow_hyphen_values = true)]
    warmup: Option<u32>,
    /// Timed repetitions per cell (median and best are reported).
    #[arg(long, allow_hyphen_values = true)]
    reps: Option<u32>,
    /// Use the paper's hand-tuned grid dims (14x16x14, 16^3, 20^3, 128^3) instead of --grid.
    #[arg(long)]
    paper_grids: bool,
    /// Grid resolution for the scenes: auto, auto:LAMBDA, N or AxBxC.
    #[arg(long, default_value = "auto", value_parser = |s: &str| s.parse::<Resolution>())]
    grid: Resolution,
    /// Folder of the mesh files (default: ../shared/data/meshes from the current directory or
    /// beside the checkout the executable was built in; or $GRIDTRACE_DATA_DIR).
    #[arg(long)]
    data_dir: Option<PathBuf>,
    /// Write bench.json, bench.csv, bench.md and PNG charts into this folder.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Also sweep the grid resolution (cells per triangle 0.5..32 and the paper's dims) for each
    /// scene, at the first resolution, first mode and first accel.
    #[arg(long)]
    sweep_grid: bool,
    /// Also measure time per ray against triangle count (bunny and dragon series, icospheres
    /// up to 1.3 M triangles) and against pixel count, with fitted growth exponents.
    #[arg(long)]
    scaling: bool,
    /// Also time the builds against triangle count: the grid and proximity cloud on the CPU
    /// (1 thread and all), on the GPU (when one is benchmarked), and the BVH, on meshes of 1k to
    /// --build-max-tris triangles (icospheres, torus knots and the scaling series' files).
    #[arg(long)]
    build_scaling: bool,
    /// Largest mesh of --build-scaling, in triangles (with --quick at most 100,000).
    #[arg(long, default_value_t = 10_500_000, value_name = "N")]
    build_max_tris: usize,
    /// With --build-scaling: write each mesh's triangles here for the Embree script
    /// (crates/gridtrace-py/bench/build_vs_embree.py).
    #[arg(long, value_name = "DIR", requires = "build_scaling")]
    export_meshes: Option<PathBuf>,
    /// With --build-scaling: Embree's build times (the Embree script's JSON), for the table and
    /// chart.
    #[arg(long, value_name = "FILE", requires = "build_scaling")]
    embree: Option<PathBuf>,
    /// Also count traversal work (cells, jumps, triangle tests per ray) grid vs pc on sparse
    /// scenes (sparse-room, a mesh seen from far away) and the torus knot.
    #[arg(long)]
    pc_study: bool,
    /// Also time ray queries (`TraceMesh::intersect`) with incoherent rays (the Python
    /// benchmark's: from a sphere around the mesh at random points of its box), grid, pc and
    /// bvh, on the Stanford Bunny and the Dragon when present and a torus knot always.
    #[arg(long)]
    query_study: bool,
    /// Also measure what the paper's optimisations buy by turning each off, comma separated:
    /// shadow-any-hit (shadow rays find closest hits instead), compaction (GPU: no compacted
    /// queues; finished rays idle in their slots). At the first resolution, every scene,
    /// accel and mode with shadow rays, on each backend it applies to.
    #[arg(long, value_delimiter = ',', value_name = "NAMES",
          value_parser = clap::builder::PossibleValuesParser::new(gridtrace::render::Ablation::NAMES))]
    ablate: Vec<String>,
    /// Also sweep the irregular grid's build parameters on the query study's meshes and the
    /// bunny in a room (incoherent rays, pc and bvh beside it). Each value is a parameter set
    /// as `--irregular` spells it (`top=0.12,cell=2`), separated by ';'; `default` tries the
    /// defaults and one change at a time.
    #[arg(long, value_name = "SETS")]
    irregular_sweep: Option<String>,
    /// Rays per mesh for --query-study.
    #[arg(long, default_value_t = 1_000_000, allow_hyphen_values = true)]
    query_rays: usize,
    /// Write the rays of a CPU run (first scene and resolution, the most complete mode asked
    /// for, first accel) as 6 little-endian f32 per ray: origin xyz, direction xyz.
    #[arg(long)]
    export_rays: Option<PathBuf>,
    /// Write the hit t of each exported ray as one little-endian f32 (inf for a miss).
    #[arg(long)]
    export_hits: Option<PathBuf>,
    /// Run a prepared suite instead of the matrix. `hardware`: what a first run on GPU
    /// hardware must answer, within 5 minutes on one GPU (every structure and GPU variant on
    /// the Stanford Bunny, the Dragon and the paper's scenes at 1920x1080 and one 4096x4096
    /// frame, GPU results checked against the CPU's; 1M camera and 1M incoherent rays per mesh;
    /// GPU grid builds of 100k-10M triangles; the CPU cores for the ratios). Needs a GPU
    /// adapter (a software one is used with a loud warning). With --quick: a small run (a
    /// software adapter finishes it in under 3 minutes). Writes hardware.json and
    /// hardware.md into --out (default: hardware-suite).
    #[arg(long, value_enum, value_name = "SUITE")]
    suite: Option<Suite>,
}

/// The prepared suites.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Suite {
    Hardware,
}

/// Opens the GPU for the chosen backend; `Ok(None)` means CPU only. Prints the adapter.
fn open_gpu(b: BenchBackendArg) -> gridtrace::Result<Option<GpuContext>> {
    match b {
        BenchBackendArg::Cpu => Ok(None),
        BenchBackendArg::Gpu | BenchBackendArg::Both => {
            let c = GpuContext::new()?;
            println!("GPU adapter: {}", c.describe());
            if c.is_software() {
                println!("  (a software adapter: its times are CPU speed, not GPU speed)");
            }
            Ok(Some(c))
        }
        // The library's rule (`Backend::open_device`): no adapter, or a software one alone,
        // means the CPU only.
        BenchBackendArg::Auto => {
            let (ctx, notes) = gridtrace::Backend::Auto.open_device()?;
            for n in notes {
                println!("note: {n}");
            }
            Ok(ctx.map(|c| {
                println!("GPU adapter: {}", c.describe());
                std::sync::Arc::try_unwrap(c).unwrap_or_else(|_| unreachable!("a fresh context has one owner"))
            }))
        }
    }
}

pub fn run(a: BenchArgs) -> gridtrace::Result<()> {
    if a.suite == Some(Suite::Hardware) {
        return run_hardware_suite(&a);
    }
    let t0 = Instant::now();
    let cfg = config(&a)?;
    let backend = a.backend.unwrap_or(if a.quick {
        BenchBackendArg::Cpu
    } else {
        BenchBackendArg::Auto
    });
    let gpu = open_gpu(backend)?.map(std::sync::Arc::new);
    let run_cpu = backend != BenchBackendArg::Gpu;
    let mut backends = Vec::new();
    if run_cpu {
        backends.push(BenchBackend::Cpu);
    }
    if gpu.is_some() {
        backends.push(BenchBackend::Gpu);
    }
    let machine = Machine::detect(gpu.as_deref());
    println!(
        "CPU: {} ({} logical cores, {} threads); OS: {}",
        machine.cpu_model, machine.logical_cores, machine.threads, machine.os
    );
    let data_dir = scenes::find_data_dir(cfg.data_dir.as_deref());
    println!(
        "mesh data: {}",
        data_dir
            .as_ref()
            .map_or("not found (scenes that need files are skipped)".into(), |p| p
                .display()
                .to_string())
    );
    println!(
        "matrix: {} scene(s) x {} resolution(s) x {} accel x {} mode(s) x backend {}; {} warm-up, {} reps",
        cfg.scenes.len(),
        cfg.resolutions.len(),
        cfg.accels.len(),
        cfg.modes.len(),
        backends.iter().map(|b| b.name()).collect::<Vec<_>>().join("+"),
        cfg.warmup,
        cfg.reps
    );
    let mut log = |s: &str| println!("{s}");
    let matrix = bench::run_matrix(&cfg, gpu.clone(), run_cpu, &mut log)?;
    let mut report = BenchReport::new(&cfg, &backends, machine, matrix);
    let run = Run {
        a: &a,
        cfg: &cfg,
        data_dir,
        gpu,
        run_cpu,
        backend,
    };
    // The studies, each only when asked for, in this order (each appends to the report).
    if a.sweep_grid {
        run.sweep_grid(&mut report)?;
    }
    if a.scaling {
        run.scaling(&mut report)?;
    }
    if a.build_scaling {
        run.build_scaling(&mut report)?;
    }
    if a.pc_study {
        run.pc_study(&mut report)?;
    }
    if a.query_study {
        run.query_study(&mut report)?;
    }
    if let Some(sets) = &a.irregular_sweep {
        run.irregular_sweep(sets, &mut report)?;
    }
    if !a.ablate.is_empty() {
        run.ablate(&mut report)?;
    }
    if a.export_rays.is_some() || a.export_hits.is_some() {
        run.export_rays(&mut report)?;
    }
    if let Some(dir) = &a.out {
        run.write_out(dir, &report)?;
    }
    println!("bench finished in {:.1} s", t0.elapsed().as_secs_f64());
    Ok(())
}

/// The matrix's configuration: `--quick` or the paper's, with the options given applied and
/// checked.
fn config(a: &BenchArgs) -> gridtrace::Result<BenchConfig> {
    let mut cfg = if a.quick {
        BenchConfig::quick()
    } else {
        BenchConfig::paper()
    };
    if !a.scenes.is_empty() {
        cfg.scenes = a.scenes.clone();
    }
    for s in &cfg.scenes {
        if scenes::paper_scene(s).is_none() {
            let names: Vec<_> = scenes::PAPER_SCENES.iter().map(|s| s.name).collect();
            return Err(bench::invalid(format!(
                "unknown scene '{s}'; scenes: {}",
                names.join(", ")
            )));
        }
    }
    if !a.res.is_empty() {
        cfg.resolutions = a.res.clone();
    }
    if !a.accel.is_empty() {
        cfg.accels = a.accel.clone();
    }
    if !a.mode.is_empty() {
        cfg.modes = a.mode.clone();
    }
    if cfg.modes.contains(&Mode::Heat) {
        return Err(bench::invalid(
            "heat is not a benchmark mode; use cast, shadow or trace",
        ));
    }
    if let Some(w) = a.warmup {
        cfg.warmup = w;
    }
    if let Some(r) = a.reps {
        if r == 0 {
            return Err(bench::invalid("--reps must be at least 1"));
        }
        cfg.reps = r;
    }
    cfg.paper_grids = a.paper_grids;
    cfg.grid = a.grid;
    cfg.data_dir = a.data_dir.clone();
    cfg.gpu_variants = a.gpu.gpu_variant;
    if let Some(d) = &cfg.data_dir
        && !d.is_dir()
    {
        return Err(bench::invalid(format!("--data-dir {} is not a folder", d.display())));
    }

    Ok(cfg)
}
