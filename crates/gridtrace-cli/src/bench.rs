//! `gridtrace bench`: the paper's benchmark matrix and studies; the work is in
//! `gridtrace_bench`, this file parses, prints and writes.

use gridtrace::accel::dims_str;
use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use gridtrace::gpu::GpuContext;
use gridtrace::{AccelKind, Mode, RenderOptions, Resolution};
use gridtrace_bench::{self as bench, BenchBackend, BenchConfig, BenchReport, Machine, scenes, studies};

use crate::common::{kind_parser, mode_parser, parse_res};

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

/// `--suite hardware`.
fn run_hardware_suite(a: &BenchArgs) -> gridtrace::Result<()> {
    let t0 = Instant::now();
    let plan = if a.quick {
        bench::hardware::Plan::quick()
    } else {
        bench::hardware::Plan::full()
    };
    let gpu = std::sync::Arc::new(open_gpu(BenchBackendArg::Gpu)?.expect("the GPU backend opens a device or fails"));
    let data_dir = scenes::find_data_dir(a.data_dir.as_deref());
    let variants = gridtrace::gpu::GpuVariants::suite();
    let mut log = |s: &str| println!("{s}");
    let dir = a.out.clone().unwrap_or_else(|| PathBuf::from("hardware-suite"));
    let report = bench::hardware::run(&plan, gpu, data_dir.as_deref(), &variants, &dir, &mut log)?;
    println!("wrote {0}/hardware.json and {0}/hardware.md", dir.display());
    for m in &report.mismatches {
        println!("MISMATCH: {m}");
    }
    for s in &report.skipped {
        println!("skipped: {s}");
    }
    println!("hardware suite finished in {:.1} s", t0.elapsed().as_secs_f64());
    Ok(())
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

/// What every study of one `bench` run shares.
struct Run<'a> {
    a: &'a BenchArgs,
    cfg: &'a BenchConfig,
    data_dir: Option<PathBuf>,
    gpu: Option<std::sync::Arc<GpuContext>>,
    run_cpu: bool,
    backend: BenchBackendArg,
}

impl Run<'_> {
    fn first_res(&self) -> (u32, u32) {
        self.cfg.resolutions[0]
    }

    fn sweep_grid(&self, report: &mut BenchReport) -> gridtrace::Result<()> {
        let (cfg, data_dir, first_res) = (self.cfg, &self.data_dir, self.first_res());
        let mut log = |s: &str| println!("{s}");
        println!(
            "grid sweep ({} {} {}x{}):",
            cfg.modes[0].name(),
            cfg.accels[0].name(),
            first_res.0,
            first_res.1
        );
        let opts = RenderOptions::new(first_res.0, first_res.1, cfg.modes[0], cfg.accels[0]);
        for name in &cfg.scenes {
            match scenes::build_paper_scene(name, data_dir.as_deref()) {
                Ok(bs) => {
                    let sw = studies::grid_sweep(&bs, &opts, cfg.warmup, cfg.reps, &mut log)?;
                    println!(
                        "  {}: best {} {} {:.2} ms; automatic {} {:.2} ms",
                        sw.scene,
                        sw.best,
                        dims_str(sw.best_dims),
                        sw.best_ms,
                        dims_str(sw.auto_dims),
                        sw.auto_ms
                    );
                    report.grid_sweep.push(sw);
                }
                Err(e) => println!("  sweep: skipping {name}: {e}"),
            }
        }
        Ok(())
    }

    fn scaling(&self, report: &mut BenchReport) -> gridtrace::Result<()> {
        let (a, cfg, data_dir, first_res, gpu, run_cpu) = (
            self.a,
            self.cfg,
            &self.data_dir,
            self.first_res(),
            &self.gpu,
            self.run_cpu,
        );
        let mut log = |s: &str| println!("{s}");
        let (max_tris, sides): (usize, &[u32]) = if a.quick {
            (100_000, &[64, 128, 256])
        } else {
            (2_000_000, &[128, 256, 512, 768, 1024])
        };
        println!(
            "scaling (cast {} {}x{}):",
            cfg.accels[0].name(),
            first_res.0,
            first_res.1
        );
        // The CPU series, then the GPU's on the same meshes (the paper's study was on its GPU).
        let mut on: Vec<Option<&std::sync::Arc<GpuContext>>> = Vec::new();
        if run_cpu {
            on.push(None);
        }
        if let Some(g) = gpu.as_ref() {
            on.push(Some(g));
        }
        for g in on {
            println!("  on the {}:", if g.is_some() { "gpu" } else { "cpu" });
            let meshes = studies::scaling_meshes(data_dir.as_deref(), max_tris, &mut log);
            let sc = studies::scaling(
                meshes,
                g,
                first_res,
                sides,
                Mode::Cast,
                cfg.accels[0],
                cfg.warmup,
                cfg.reps,
                &mut log,
            )?;
            for f in &sc.fits {
                println!("  exponent {:<32} {:.3} ({} points)", f.series, f.exponent, f.points);
            }
            report.scaling.push(sc);
        }
        Ok(())
    }

    fn build_scaling(&self, report: &mut BenchReport) -> gridtrace::Result<()> {
        let (a, cfg, data_dir, gpu, backend) = (self.a, self.cfg, &self.data_dir, &self.gpu, self.backend);
        let mut log = |s: &str| println!("{s}");
        let max = if a.quick {
            a.build_max_tris.min(100_000)
        } else {
            a.build_max_tris
        };
        println!("build scaling (up to {max} triangles):");
        let meshes = studies::build_scaling_meshes(data_dir.as_deref(), max, &mut log);
        if let Some(dir) = &a.export_meshes {
            bench::build_scaling::export(&meshes, dir)?;
            println!("  wrote the meshes to {}", dir.display());
        }
        let gpu_ctx = if backend == BenchBackendArg::Cpu {
            None
        } else {
            gpu.as_ref()
        };
        let mut points = bench::build_scaling::build_scaling(&meshes, gpu_ctx, cfg.reps, &mut log)?;
        if let Some(e) = &a.embree {
            bench::build_scaling::with_embree(&mut points, e)?;
        }
        report.build_scaling = points;
        Ok(())
    }

    fn pc_study(&self, report: &mut BenchReport) -> gridtrace::Result<()> {
        let (cfg, data_dir, first_res) = (self.cfg, &self.data_dir, self.first_res());
        let mut log = |s: &str| println!("{s}");
        println!("proximity-cloud study ({}x{}):", first_res.0, first_res.1);
        let far_mesh = data_dir
            .as_ref()
            .and_then(|d| gridtrace::io::load_mesh(&d.join("bunny_lowpoly/bunny_1k.obj")).ok());
        let far_name = if far_mesh.is_some() { "far-bunny" } else { "far-knot" };
        let study_scenes = vec![
            ("sparse-room".to_string(), gridtrace::scene::builtin::sparse_room()),
            (far_name.to_string(), studies::far_mesh_scene(far_mesh)),
            ("torus-knot".to_string(), gridtrace::scene::builtin::knot_box()),
        ];
        report.pc_study = studies::pc_study(
            &study_scenes,
            &[Mode::Cast, Mode::Shadow],
            first_res,
            cfg.warmup,
            cfg.reps,
            &mut log,
        )?;
        Ok(())
    }

    fn query_study(&self, report: &mut BenchReport) -> gridtrace::Result<()> {
        let (a, cfg, data_dir, gpu, run_cpu) = (self.a, self.cfg, &self.data_dir, &self.gpu, self.run_cpu);
        let mut log = |s: &str| println!("{s}");
        println!("ray-query study ({} incoherent rays per mesh):", a.query_rays);
        let mut meshes = vec![(
            "torus-knot-hi".to_string(),
            gridtrace::scene::procedural::torus_knot(2, 3, 0.16, 1024, 32),
        )];
        if let Some(d) = &data_dir {
            for (name, file) in [
                ("stanford-bunny", "bunny/bun_zipper.ply"),
                ("dragon", "dragon/dragon_vrip_binary.ply"),
            ] {
                match gridtrace::io::load_mesh(&d.join(file)) {
                    Ok(m) => meshes.push((name.to_string(), m)),
                    Err(e) => println!("  {name}: skipped ({e})"),
                }
            }
        }
        report.query_study = studies::query_study(
            &meshes,
            a.query_rays,
            run_cpu,
            gpu.as_ref(),
            cfg.warmup,
            cfg.reps,
            &mut log,
        )?;
        Ok(())
    }

    fn irregular_sweep(&self, sets: &str, report: &mut BenchReport) -> gridtrace::Result<()> {
        let (a, cfg, data_dir) = (self.a, self.cfg, &self.data_dir);
        let mut log = |s: &str| println!("{s}");
        let sweep = if sets.trim() == "default" {
            bench::irregular::default_sweep()
        } else {
            sets.split(';')
                .map(|s| s.parse::<gridtrace::accel::IrregularParams>())
                .collect::<Result<Vec<_>, _>>()
                .map_err(gridtrace::Error::InvalidInput)?
        };
        println!("irregular-grid sweep ({} incoherent rays per mesh):", a.query_rays);
        let mut meshes = Vec::new();
        for (name, scene) in bench::irregular::sweep_scenes(data_dir.as_deref()) {
            meshes.push((name, scene.prepare(Resolution::default())?.accel.tris));
        }
        report.irregular_sweep =
            bench::irregular::irregular_sweep(&meshes, a.query_rays, &sweep, cfg.warmup, cfg.reps, &mut log)?;
        Ok(())
    }

    fn ablate(&self, report: &mut BenchReport) -> gridtrace::Result<()> {
        let (a, cfg, data_dir, first_res, gpu, run_cpu) = (
            self.a,
            self.cfg,
            &self.data_dir,
            self.first_res(),
            &self.gpu,
            self.run_cpu,
        );
        let mut log = |s: &str| println!("{s}");
        println!("ablations ({}x{}):", first_res.0, first_res.1);
        let plan = bench::ablation::AblationPlan {
            scenes: &cfg.scenes,
            data_dir: data_dir.as_deref(),
            grid: cfg.grid,
            paper_grids: cfg.paper_grids,
            size: first_res,
            modes: &cfg.modes,
            accels: &cfg.accels,
            ablations: &a.ablate,
            cpu: run_cpu,
            gpu: gpu.as_ref(),
            warmup: cfg.warmup,
            reps: cfg.reps,
        };
        report.ablation = bench::ablation::ablation_study(&plan, &mut log)?;
        Ok(())
    }

    /// Writes the rays (and hits) of one frame of the first scene, for other tracers to run.
    fn export_rays(&self, report: &mut BenchReport) -> gridtrace::Result<()> {
        let (a, cfg, data_dir, first_res) = (self.a, self.cfg, &self.data_dir, self.first_res());
        let mode = [Mode::Trace, Mode::Shadow, Mode::Cast]
            .into_iter()
            .find(|m| cfg.modes.contains(m))
            .unwrap_or(Mode::Cast);
        let name = &cfg.scenes[0];
        let bs = scenes::build_paper_scene(name, data_dir.as_deref())?;
        let prepared = bs
            .scene
            .prepare_for(cfg.accels[0], bs.resolution(cfg.paper_grids, cfg.grid))?;
        let opts = RenderOptions::new(first_res.0, first_res.1, mode, cfg.accels[0]);
        let set = bench::rays::collect_rays(&prepared, &opts)?;
        let c = set.counts();
        if let Some(p) = &a.export_rays {
            set.write_rays(p)?;
        }
        if let Some(p) = &a.export_hits {
            set.write_hits(p)?;
        }
        let hits = set.records.iter().filter(|r| r.t.is_finite()).count() as u64;
        println!(
            "exported {} rays of {name} {} {} {}x{} (eye {}, shadow {}, reflection {}; {hits} with a hit)",
            c.total(),
            mode.name(),
            opts.accel.name(),
            opts.width,
            opts.height,
            c.eye,
            c.shadow,
            c.reflection
        );
        report.ray_export = Some(studies::RayExport {
            scene: name.clone(),
            mode: mode.name().into(),
            accel: opts.accel.name().into(),
            width: opts.width,
            height: opts.height,
            rays_file: a.export_rays.as_ref().map(|p| p.display().to_string()),
            hits_file: a.export_hits.as_ref().map(|p| p.display().to_string()),
            eye: c.eye,
            shadow: c.shadow,
            reflection: c.reflection,
            hits,
        });
        Ok(())
    }

    /// The reports, the charts, and one ray-traced picture per scene that ran.
    fn write_out(&self, dir: &std::path::Path, report: &BenchReport) -> gridtrace::Result<()> {
        let (cfg, data_dir, first_res) = (self.cfg, &self.data_dir, self.first_res());
        let mut files = bench::report::write_reports(report, dir)?;
        files.extend(bench::charts::write_charts(report, dir)?);
        // One ray-traced picture per scene that ran, to see what was measured.
        for s in &report.matrix.scenes {
            let bs = scenes::build_paper_scene(&s.name, data_dir.as_deref())?;
            let prepared = bs.scene.prepare(bs.resolution(cfg.paper_grids, cfg.grid))?;
            let opts = RenderOptions::new(first_res.0, first_res.1, Mode::Trace, AccelKind::Grid);
            let (image, _) = gridtrace::cpu::render(&prepared, &opts, None)?;
            let path = dir.join(format!("scene_{}.png", s.name));
            image.save_png(&path)?;
            files.push(path);
        }
        for f in files {
            println!("wrote {}", f.display());
        }
        Ok(())
    }
}
