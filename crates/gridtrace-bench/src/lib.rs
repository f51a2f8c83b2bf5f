//! gridtrace-bench: the paper's matrix (scenes x resolutions x accel x mode x backend), grid-resolution
//! sweeps, scaling with triangle and pixel count, the proximity-cloud study, and the reports
//! (JSON, CSV, a Markdown table laid out like the paper's Tables 1-3, PNG charts).
//!
//! Every timing is repeated after warm-up runs; rows keep all repetitions, their median and the
//! best (the paper reports best values of several runs).

pub mod ablation;
pub mod build_scaling;
pub mod charts;
pub mod hardware;
pub mod irregular;
mod machine;
pub mod query_study;
pub mod rays;
pub mod report;
pub mod scenes;
pub mod studies;
mod timing;

use gridtrace::AccelParams;
use gridtrace::accel::dims_str;
use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::Serialize;

use gridtrace::accel::{AccelKind, Resolution};
use gridtrace::gpu::{GpuContext, GpuRenderer};
use gridtrace::render::{Mode, PixelFormat, RayCounts, RenderOptions};
use gridtrace::scene::PreparedScene;
use gridtrace::{Error, Result};

pub use machine::Machine;
pub use scenes::{BenchScene, PAPER_SCENES, build_paper_scene, find_data_dir, paper_ms};
pub use timing::{Summary, repeat, time_cpu, time_gpu};

/// Where a benchmark row ran.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum BenchBackend {
    Cpu,
    Gpu,
}

impl BenchBackend {
    pub fn name(self) -> &'static str {
        match self {
            BenchBackend::Cpu => "cpu",
            BenchBackend::Gpu => "gpu",
        }
    }
}

/// What to run.
#[derive(Debug, Clone)]
pub struct BenchConfig {
    pub scenes: Vec<String>,
    pub resolutions: Vec<(u32, u32)>,
    pub accels: Vec<AccelKind>,
    pub modes: Vec<Mode>,
    pub warmup: u32,
    pub reps: u32,
    /// Use the paper's hand-tuned grid dims for its scenes (else `grid`).
    pub paper_grids: bool,
    pub grid: Resolution,
    pub data_dir: Option<PathBuf>,
    /// The GPU kernels' variants for the GPU rows (`--gpu-variant`).
    pub gpu_variants: gridtrace::gpu::GpuVariants,
}

impl BenchConfig {
    /// The paper's matrix: four scenes, 256/512/768 squared, grid and pc, three modes.
    pub fn paper() -> Self {
        BenchConfig {
            scenes: PAPER_SCENES.iter().map(|s| s.name.to_string()).collect(),
            resolutions: vec![(256, 256), (512, 512), (768, 768)],
            accels: vec![AccelKind::Grid, AccelKind::ProximityCloud],
            modes: vec![Mode::Cast, Mode::Shadow, Mode::Trace],
            warmup: 1,
            reps: 5,
            paper_grids: false,
            grid: Resolution::default(),
            data_dir: None,
            gpu_variants: gridtrace::gpu::GpuVariants::default(),
        }
    }

    /// Small and fast: torus knot and Stanford bunny at 128x128, 1 warm-up, 3 repetitions.
    pub fn quick() -> Self {
        BenchConfig {
            scenes: vec!["torus-knot".into(), "stanford-bunny".into()],
            resolutions: vec![(128, 128)],
            warmup: 1,
            reps: 3,
            ..Self::paper()
        }
    }
}

/// Ray counts in a report.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq, Eq)]
pub struct Rays {
    pub eye: u64,
    pub shadow: u64,
    pub reflection: u64,
    pub total: u64,
}

impl From<RayCounts> for Rays {
    fn from(r: RayCounts) -> Self {
        Rays {
            eye: r.eye,
            shadow: r.shadow,
            reflection: r.reflection,
            total: r.total(),
        }
    }
}

/// One cell of the matrix.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub scene: String,
    pub backend: BenchBackend,
    pub mode: String,
    pub accel: String,
    pub width: u32,
    pub height: u32,
    pub grid_dims: [u32; 3],
    /// Every timed repetition (ms): CPU wall time, or GPU time (timestamps where available).
    pub times_ms: Vec<f64>,
    #[serde(flatten)]
    pub summary: Summary,
    pub rays: Rays,
    /// Rays per microsecond of the best run.
    pub mrays_per_s: f64,
    pub paper_ms: Option<f64>,
    /// Paper ms / our best ms.
    pub speedup: Option<f64>,
    /// GPU only: the best repetition's wall-clock time (the row's time), its GPU time (the
    /// stages' timestamps summed) and per-stage GPU times, its host round trips and bytes
    /// written to and read from the device.
    pub gpu_wall_ms: Option<f64>,
    pub gpu_ms: Option<f64>,
    pub gpu_stages_ms: Option<BTreeMap<String, f64>>,
    pub gpu_timestamps: Option<bool>,
    pub gpu_round_trips: Option<u32>,
    pub gpu_bytes_up: Option<u64>,
    pub gpu_bytes_down: Option<u64>,
    /// The wall time's parts on the host's clock: preparing and submitting, waiting for the
    /// device (its work, the transfers, the driver), reading the results out.
    pub gpu_host_prepare_ms: Option<f64>,
    pub gpu_host_wait_ms: Option<f64>,
    pub gpu_host_readout_ms: Option<f64>,
}

/// A scene as benchmarked: counts, grid and memory.
#[derive(Debug, Clone, Serialize)]
pub struct SceneInfo {
    pub name: String,
    pub title: String,
    pub description: String,
    /// Triangles in the scene's mesh.
    pub triangles: usize,
    /// Triangles traced (zero-area ones dropped).
    pub triangles_traced: usize,
    pub degenerate_dropped: usize,
    pub paper_triangles: Option<usize>,
    pub grid: GridInfo,
    /// Bytes of each CPU array.
    pub memory_cpu: BTreeMap<String, u64>,
    pub memory_cpu_total: u64,
    /// Bytes of each GPU buffer (scene and work buffers of the largest frame), when run there.
    pub memory_gpu: Option<BTreeMap<String, u64>>,
    pub memory_gpu_total: Option<u64>,
    /// The paper's model `M = n*96 + cells*16`.
    pub memory_paper_model: u64,
}

#[derive(Debug, Clone, Serialize)]
pub struct GridInfo {
    /// `paper` (hand-tuned dims), `auto:LAMBDA` or `fixed`.
    pub choice: String,
    pub dims: [u32; 3],
    pub cells: usize,
    pub empty_cells: usize,
    pub references: usize,
    pub refs_per_triangle: f64,
    pub build_ms: f64,
}

impl GridInfo {
    pub fn of(prepared: &PreparedScene, choice: String) -> Self {
        let s = &prepared.grid().stats;
        GridInfo {
            choice,
            dims: s.dims,
            cells: s.cells,
            empty_cells: s.empty_cells,
            references: s.references,
            refs_per_triangle: s.refs_per_triangle(),
            build_ms: s.build_ms,
        }
    }
}

/// The best of `runs` runs of `f`, in ms (the examples' timer).
pub fn best_of_ms(runs: usize, mut f: impl FnMut()) -> f64 {
    (0..runs)
        .map(|_| {
            let t0 = std::time::Instant::now();
            f();
            t0.elapsed().as_secs_f64() * 1e3
        })
        .fold(f64::INFINITY, f64::min)
}

pub fn resolution_name(r: Resolution) -> String {
    match r {
        Resolution::Auto { lambda } => format!("auto:{lambda}"),
        Resolution::Fixed(d) => dims_str(d),
    }
}

fn cpu_row(scene: &str, prepared: &PreparedScene, opts: &RenderOptions, cfg: &BenchConfig) -> Result<Row> {
    let (times, summary, rays) = time_cpu(prepared, opts, cfg.warmup, cfg.reps)?;
    Ok(make_row(scene, BenchBackend::Cpu, prepared, opts, times, summary, rays))
}

fn make_row(
    scene: &str,
    backend: BenchBackend,
    prepared: &PreparedScene,
    opts: &RenderOptions,
    times: Vec<f64>,
    summary: Summary,
    rays: RayCounts,
) -> Row {
    let accel = prepared.accel.kind();
    let paper = paper_ms(scene, opts.mode, (opts.width, opts.height), accel);
    Row {
        scene: scene.into(),
        backend,
        mode: opts.mode.name().into(),
        accel: accel.name().into(),
        width: opts.width,
        height: opts.height,
        grid_dims: prepared.accel.grid().map_or([0; 3], |g| g.stats.dims),
        times_ms: times,
        summary,
        rays: rays.into(),
        mrays_per_s: rays.total() as f64 / (summary.best_ms * 1e3).max(1e-9),
        paper_ms: paper,
        speedup: paper.map(|p| p / summary.best_ms.max(1e-9)),
        gpu_wall_ms: None,
        gpu_ms: None,
        gpu_stages_ms: None,
        gpu_timestamps: None,
        gpu_round_trips: None,
        gpu_host_prepare_ms: None,
        gpu_host_wait_ms: None,
        gpu_host_readout_ms: None,
        gpu_bytes_up: None,
        gpu_bytes_down: None,
    }
}

fn gpu_row(
    scene: &str,
    prepared: &PreparedScene,
    gpu: &mut GpuRenderer,
    opts: &RenderOptions,
    cfg: &BenchConfig,
) -> Result<Row> {
    let (times, summary, s) = time_gpu(gpu, prepared, opts, cfg.warmup, cfg.reps)?;
    let s = &s;
    let mut row = make_row(scene, BenchBackend::Gpu, prepared, opts, times, summary, s.render.rays);
    row.gpu_wall_ms = Some(s.wall_ms);
    row.gpu_ms = s.gpu_ms();
    row.gpu_stages_ms = Some(s.timings.stages_ms.iter().map(|(k, v)| (k.to_string(), *v)).collect());
    row.gpu_timestamps = Some(s.timings.from_timestamps);
    row.gpu_round_trips = Some(s.round_trips);
    row.gpu_bytes_up = Some(s.uploaded_bytes);
    row.gpu_bytes_down = Some(s.downloaded_bytes);
    row.gpu_host_prepare_ms = Some(s.timings.host.prepare_ms);
    row.gpu_host_wait_ms = Some(s.timings.host.wait_ms);
    row.gpu_host_readout_ms = Some(s.timings.host.readout_ms);
    Ok(row)
}

/// Results of the matrix.
#[derive(Debug, Clone, Default, Serialize)]
pub struct MatrixResult {
    pub scenes: Vec<SceneInfo>,
    pub rows: Vec<Row>,
    /// Scenes left out, with the reason.
    pub skipped: Vec<String>,
}

/// Runs the matrix on the CPU and, when `gpu` is given, on the GPU too. Every scene's renderer
/// shares the one GPU context (device and compiled kernels). `log` receives one line per scene
/// and per row.
pub fn run_matrix(
    cfg: &BenchConfig,
    gpu: Option<std::sync::Arc<GpuContext>>,
    cpu: bool,
    log: &mut dyn FnMut(&str),
) -> Result<MatrixResult> {
    let data_dir = find_data_dir(cfg.data_dir.as_deref());
    let mut out = MatrixResult::default();
    for name in &cfg.scenes {
        let bs = match build_paper_scene(name, data_dir.as_deref()) {
            Ok(s) => s,
            Err(e) => {
                let msg = format!("skipping scene {name}: {e}");
                log(&msg);
                out.skipped.push(msg);
                continue;
            }
        };
        let res = bs.resolution(cfg.paper_grids, cfg.grid);
        let prepared = bs.scene.prepare(res)?;
        let choice = if cfg.paper_grids && bs.paper_grid.is_some() {
            "paper".to_string()
        } else {
            resolution_name(res)
        };
        let mut info = scene_info(&bs, &prepared, choice);
        log(&format!(
            "scene {}: {} triangles ({} traced; paper {}), grid {} ({}), {}",
            bs.name,
            bs.triangles,
            prepared.accel.tris.len(),
            bs.paper_tris.map_or("-".into(), |n| n.to_string()),
            dims_str(info.grid.dims),
            info.grid.choice,
            bs.description
        ));
        // The grid serves grid and pc (pc's scene a copy switched to it: `with_accel` builds
        // nothing for it); every other kind gets its own structure, built once.
        let mut own: Vec<(AccelKind, PreparedScene)> = Vec::new();
        for &accel in cfg.accels.iter().filter(|&&a| a != prepared.accel.kind()) {
            if !own.iter().any(|(k, _)| *k == accel) {
                own.push((accel, prepared.with_accel(accel, &AccelParams::NONE)?));
            }
        }
        let for_accel = |accel: AccelKind| own.iter().find(|(k, _)| *k == accel).map_or(&prepared, |(_, s)| s);
        if cpu {
            for &(w, h) in &cfg.resolutions {
                for &mode in &cfg.modes {
                    for &accel in &cfg.accels {
                        let opts = RenderOptions::new(w, h, mode);
                        let row = cpu_row(&bs.name, for_accel(accel), &opts, cfg)?;
                        log(&row_line(&row));
                        out.rows.push(row);
                    }
                }
            }
        }
        if let Some(ctx) = &gpu {
            // One renderer per structure uploaded: the grid's (grid, pc) and each other one's.
            let mut grid_gpu = GpuRenderer::new(ctx.clone(), &prepared, &cfg.gpu_variants)?;
            let mut own_gpu: Vec<(AccelKind, GpuRenderer)> = Vec::new();
            for (k, s) in own.iter().filter(|(k, _)| !k.uses_grid()) {
                own_gpu.push((*k, GpuRenderer::new(ctx.clone(), s, &cfg.gpu_variants)?));
            }
            let mut largest = 0u64;
            for &(w, h) in &cfg.resolutions {
                for &mode in &cfg.modes {
                    for &accel in &cfg.accels {
                        // As `render` asks: 8-bit pixels, packed on the device.
                        let opts = RenderOptions::new(w, h, mode).with_pixels(PixelFormat::Srgb8);
                        let r = match own_gpu.iter_mut().find(|(k, _)| *k == accel) {
                            Some((_, r)) => r,
                            None => {
                                grid_gpu.set_traversal(accel)?;
                                &mut grid_gpu
                            }
                        };
                        let row = gpu_row(&bs.name, for_accel(accel), r, &opts, cfg)?;
                        log(&row_line(&row));
                        out.rows.push(row);
                        if !accel.uses_grid() {
                            // The scene's memory is the paper's structure's (the grid's).
                            continue;
                        }
                        let mem: BTreeMap<String, u64> =
                            r.memory().into_iter().map(|(k, v)| (k.to_string(), v)).collect();
                        let total = mem.values().sum();
                        if total > largest {
                            largest = total;
                            info.memory_gpu = Some(mem);
                            info.memory_gpu_total = Some(total);
                        }
                    }
                }
            }
        }
        out.scenes.push(info);
    }
    Ok(out)
}

pub fn scene_info(bs: &BenchScene, prepared: &PreparedScene, choice: String) -> SceneInfo {
    let memory_cpu: BTreeMap<String, u64> = prepared
        .memory()
        .into_iter()
        .map(|(k, v)| (k.to_string(), v as u64))
        .collect();
    SceneInfo {
        name: bs.name.clone(),
        title: bs.title.clone(),
        description: bs.description.clone(),
        triangles: bs.triangles,
        triangles_traced: prepared.accel.tris.len(),
        degenerate_dropped: prepared.degenerate_dropped,
        paper_triangles: bs.paper_tris,
        grid: GridInfo::of(prepared, choice),
        memory_cpu_total: memory_cpu.values().sum(),
        memory_cpu,
        memory_gpu: None,
        memory_gpu_total: None,
        memory_paper_model: prepared.paper_memory_model().unwrap_or(0) as u64,
    }
}

/// One line per row for the console.
pub fn row_line(r: &Row) -> String {
    let paper = match (r.paper_ms, r.speedup) {
        (Some(p), Some(s)) => format!("  paper {p:.0} ms, speed-up {s:.2}x"),
        _ => String::new(),
    };
    format!(
        "  {:<14} {} {:<6} {:<4} {:>4}x{:<4} best {:>9.2} ms  median {:>9.2} ms  {:>8} rays  {:>7.2} Mrays/s{paper}",
        r.scene,
        r.backend.name(),
        r.mode,
        r.accel,
        r.width,
        r.height,
        r.summary.best_ms,
        r.summary.median_ms,
        r.rays.total,
        r.mrays_per_s
    )
}

/// Least-squares slope of `log y` against `log x` (the growth exponent), with its intercept;
/// `None` with fewer than two usable points.
pub fn loglog_fit(points: &[(f64, f64)]) -> Option<(f64, f64)> {
    let p: Vec<(f64, f64)> = points
        .iter()
        .filter(|(x, y)| *x > 0.0 && *y > 0.0 && x.is_finite() && y.is_finite())
        .map(|(x, y)| (x.ln(), y.ln()))
        .collect();
    if p.len() < 2 {
        return None;
    }
    let n = p.len() as f64;
    let mx = p.iter().map(|q| q.0).sum::<f64>() / n;
    let my = p.iter().map(|q| q.1).sum::<f64>() / n;
    let sxx: f64 = p.iter().map(|q| (q.0 - mx).powi(2)).sum();
    if sxx == 0.0 {
        return None;
    }
    let sxy: f64 = p.iter().map(|q| (q.0 - mx) * (q.1 - my)).sum();
    let slope = sxy / sxx;
    Some((slope, my - slope * mx))
}

/// Everything one `gridtrace bench` run measured.
#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    pub gridtrace_version: String,
    pub command_line: Vec<String>,
    /// Seconds since the Unix epoch when the report was made.
    pub unix_time: u64,
    pub machine: Machine,
    pub config: ConfigInfo,
    #[serde(flatten)]
    pub matrix: MatrixResult,
    pub grid_sweep: Vec<studies::Sweep>,
    /// The CPU's series, then the GPU's when one ran.
    pub scaling: Vec<studies::Scaling>,
    pub pc_study: Vec<studies::PcStudyRow>,
    pub query_study: Vec<studies::QueryStudyRow>,
    pub irregular_sweep: Vec<irregular::IrregularSweepRow>,
    pub ablation: Vec<ablation::AblationRow>,
    /// Build time against triangle count (`--build-scaling`).
    pub build_scaling: Vec<build_scaling::BuildPoint>,
    pub ray_export: Option<studies::RayExport>,
}

/// The configuration, as recorded in the report.
#[derive(Debug, Clone, Serialize)]
pub struct ConfigInfo {
    pub scenes: Vec<String>,
    pub resolutions: Vec<[u32; 2]>,
    pub accels: Vec<String>,
    pub modes: Vec<String>,
    pub backends: Vec<String>,
    pub warmup: u32,
    pub reps: u32,
    pub paper_grids: bool,
    pub grid: String,
    pub data_dir: Option<String>,
}

impl ConfigInfo {
    pub fn of(cfg: &BenchConfig, backends: &[BenchBackend]) -> Self {
        ConfigInfo {
            scenes: cfg.scenes.clone(),
            resolutions: cfg.resolutions.iter().map(|&(w, h)| [w, h]).collect(),
            accels: cfg.accels.iter().map(|a| a.name().to_string()).collect(),
            modes: cfg.modes.iter().map(|m| m.name().to_string()).collect(),
            backends: backends.iter().map(|b| b.name().to_string()).collect(),
            warmup: cfg.warmup,
            reps: cfg.reps,
            paper_grids: cfg.paper_grids,
            grid: resolution_name(cfg.grid),
            data_dir: find_data_dir(cfg.data_dir.as_deref()).map(|p| p.display().to_string()),
        }
    }
}

impl BenchReport {
    pub fn new(cfg: &BenchConfig, backends: &[BenchBackend], machine: Machine, matrix: MatrixResult) -> Self {
        BenchReport {
            gridtrace_version: env!("CARGO_PKG_VERSION").to_string(),
            command_line: std::env::args().collect(),
            unix_time: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs()),
            machine,
            config: ConfigInfo::of(cfg, backends),
            matrix,
            grid_sweep: Vec::new(),
            scaling: Vec::new(),
            pc_study: Vec::new(),
            query_study: Vec::new(),
            irregular_sweep: Vec::new(),
            ablation: Vec::new(),
            build_scaling: Vec::new(),
            ray_export: None,
        }
    }
}

/// An error for a bad benchmark request.
pub fn invalid(msg: impl Into<String>) -> Error {
    Error::InvalidInput(msg.into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_median_best() {
        let s = Summary::of(&[3.0, 1.0, 2.0, 10.0]);
        assert_eq!(s.best_ms, 1.0);
        assert_eq!(s.median_ms, 2.5);
        assert_eq!(Summary::of(&[5.0, 1.0, 2.0]).median_ms, 2.0);
    }

    #[test]
    fn loglog_slope() {
        let pts: Vec<(f64, f64)> = (1..6)
            .map(|i| (i as f64 * 10.0, 3.0 * (i as f64 * 10.0).powf(0.5)))
            .collect();
        let (s, _) = loglog_fit(&pts).unwrap();
        assert!((s - 0.5).abs() < 1e-9);
        assert!(loglog_fit(&[(1.0, 1.0)]).is_none());
    }
}
