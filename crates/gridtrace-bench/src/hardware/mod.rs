//! `gridtrace bench --suite hardware`: the one command a first run on GPU hardware makes. A GPU
//! is lent to this project rarely and for minutes, so everything a hardware run must answer is
//! in one prepared, time-bounded run that writes one JSON and one Markdown report:
//!
//! - frames (`frames.rs`): every structure and every GPU variant on the Stanford Bunny, the
//!   Dragon and the paper's scenes at 1920x1080, eye/shadow/trace rays, wall time beside GPU
//!   time, each image checked against the CPU's before it counts; one 4096x4096 frame; the
//!   same frames on the machine's CPU cores for the ratio;
//! - ray batches (`rays.rs`): 1M camera rays in image order and 1M incoherent rays per mesh,
//!   every structure, GPU and CPU, hits checked against the CPU's;
//! - GPU grid builds of 100k to 10M triangles beside the CPU's (`build_scaling`).
//!
//! Every part checks the time left (`Plan::budget_s`) before it starts and says what it
//! skipped, so a run cut short still brings its report back. `--quick` is the same run, small
//! enough for a software adapter (and a test).

mod builds;
mod frames;
mod markdown;
mod points;
mod rays;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use serde::Serialize;

use gridtrace::gpu::{GpuContext, GpuVariants};
use gridtrace::{AccelKind, Mode, Result};

use crate::{Machine, scenes};

pub use builds::BuildRow;
pub use frames::FrameRow;
pub use points::PointRow;
pub use rays::{RayRow, camera_rays};

/// What one suite run covers.
#[derive(Debug, Clone, Serialize)]
pub struct Plan {
    pub quick: bool,
    /// Scenes of the frames, most important first (a run cut short keeps the first).
    pub frame_scenes: Vec<String>,
    /// Meshes of the ray batches.
    pub ray_meshes: Vec<String>,
    /// Frames of the matrix (1920x1080; quick: 192x108).
    pub frame_size: (u32, u32),
    /// The one large frame (4096x4096; quick: 512x512).
    pub big_frame: (u32, u32),
    /// cast, shadow, trace (the rows name them).
    #[serde(skip)]
    pub modes: Vec<Mode>,
    /// Rays per batch of the ray study (1M; quick: 20k).
    pub rays: usize,
    /// Largest mesh of the grid builds (10M triangles; quick: 30k).
    pub build_max_tris: usize,
    /// Timed repetitions per measurement (median reported), after warm-ups of at least
    /// `warmup_ms`.
    pub reps: u32,
    pub warmup_ms: f64,
    /// The whole run's time, seconds: parts that would start later are skipped (and listed).
    pub budget_s: f64,
}

impl Plan {
    /// The hardware run: within the time the lent machine's script gives it (300 s).
    pub fn full() -> Plan {
        Plan {
            quick: false,
            frame_scenes: ["stanford-bunny", "dragon", "knight", "torus-knot", "bunny"]
                .map(String::from)
                .to_vec(),
            ray_meshes: ["stanford-bunny", "dragon"].map(String::from).to_vec(),
            frame_size: (1920, 1080),
            big_frame: (4096, 4096),
            modes: vec![Mode::Cast, Mode::Shadow, Mode::Trace],
            rays: 1_000_000,
            build_max_tris: 10_000_000,
            reps: 5,
            warmup_ms: 200.0,
            budget_s: 270.0,
        }
    }

    /// Small enough for a software adapter on two cores (under 3 minutes), every part kept.
    pub fn quick() -> Plan {
        Plan {
            quick: true,
            frame_scenes: ["torus-knot", "stanford-bunny"].map(String::from).to_vec(),
            ray_meshes: ["torus-knot"].map(String::from).to_vec(),
            frame_size: (96, 54),
            big_frame: (512, 512),
            modes: vec![Mode::Cast, Mode::Shadow, Mode::Trace],
            rays: 10_000,
            build_max_tris: 30_000,
            reps: 1,
            warmup_ms: 0.0,
            budget_s: 170.0,
        }
    }
}

/// The adapter as the report records it (the reader must be able to tell a GPU from a
/// software rasteriser at a glance).
#[derive(Debug, Clone, Serialize)]
pub struct AdapterRecord {
    pub name: String,
    pub vendor: u32,
    pub device: u32,
    pub device_type: String,
    pub driver: String,
    pub driver_info: String,
    pub backend: String,
    pub software: bool,
    pub timestamps: bool,
    /// Subgroup operations (the `appends=subgroup` variant runs only with them).
    pub subgroups: bool,
    /// `nvidia-smi`'s name, driver, clocks and memory, where the tool exists.
    pub nvidia_smi: Option<String>,
}

impl AdapterRecord {
    pub fn of(ctx: &GpuContext) -> AdapterRecord {
        let i = &ctx.info;
        let smi = std::process::Command::new("nvidia-smi")
            .args([
                "--query-gpu=name,driver_version,clocks.sm,clocks.max.sm,clocks.mem,memory.total,power.limit",
                "--format=csv",
            ])
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string());
        AdapterRecord {
            name: i.name.clone(),
            vendor: i.vendor,
            device: i.device,
            device_type: format!("{:?}", i.device_type),
            driver: i.driver.clone(),
            driver_info: i.driver_info.clone(),
            backend: format!("{:?}", i.backend),
            software: ctx.is_software(),
            timestamps: ctx.timestamps,
            subgroups: ctx.subgroups,
            nvidia_smi: smi,
        }
    }
}

/// Everything one suite run measured.
#[derive(Debug, Clone, Serialize)]
pub struct HardwareReport {
    pub gridtrace_version: String,
    pub command_line: Vec<String>,
    pub unix_time: u64,
    pub machine: Machine,
    pub adapter: AdapterRecord,
    pub plan: Plan,
    /// The GPU variants run (`--gpu-variant` syntax; the default first). Each row names its
    /// variant by what differs from the default (`GpuVariants::changes`).
    pub variants: Vec<String>,
    pub frames: Vec<FrameRow>,
    pub big_frame: Vec<FrameRow>,
    pub rays: Vec<RayRow>,
    /// Nearest points and winding numbers (`points.rs`).
    #[serde(default)]
    pub points: Vec<PointRow>,
    pub builds: Vec<BuildRow>,
    /// Parts not run, and why (missing files, the time budget).
    pub skipped: Vec<String>,
    /// GPU results that differed from the CPU's beyond the stated tolerance: any entry here
    /// makes the run's figures suspect.
    pub mismatches: Vec<String>,
    pub elapsed_s: f64,
}

/// The clock against the plan's budget. Each part of the suite may start its items until its
/// share of the budget has passed (`FRAMES_UNTIL` and so on), so a part that runs long cuts
/// its own tail, not the parts after it.
pub(crate) struct Budget {
    started: Instant,
    budget_s: f64,
    /// The current part's end, as a fraction of the budget.
    until: f64,
}

/// Where each part's share of the budget ends (fractions of it).
const FRAMES_UNTIL: f64 = 0.55;
const BIG_FRAME_UNTIL: f64 = 0.65;
const RAYS_UNTIL: f64 = 0.85;
const BUILDS_UNTIL: f64 = 0.9;

impl Budget {
    /// Whether an item of the current part may start; when not, it is listed as skipped.
    pub fn allows(&self, item: &str, skipped: &mut Vec<String>) -> bool {
        let used = self.started.elapsed().as_secs_f64();
        if used < self.budget_s * self.until {
            return true;
        }
        skipped.push(format!(
            "{item}: its part's share of the time budget ({:.0} of {:.0} s) was spent",
            self.budget_s * self.until,
            self.budget_s
        ));
        false
    }

    fn part(&mut self, until: f64) -> &Budget {
        self.until = until;
        self
    }

    pub fn elapsed_s(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
    }
}

/// The scanned meshes the suite knows by name (from the data folder), `None` for other names.
fn study_mesh(name: &str, data_dir: Option<&Path>) -> Option<Result<gridtrace::Mesh>> {
    let file = match name {
        "stanford-bunny" => "bunny/bun_zipper.ply",
        "dragon" => "dragon/dragon_vrip_binary.ply",
        _ => return None,
    };
    Some(match data_dir {
        Some(d) => gridtrace::io::load_mesh(&d.join(file)),
        None => Err(gridtrace::Error::InvalidInput(format!(
            "no mesh data folder for {file} (--data-dir or GRIDTRACE_DATA_DIR)"
        ))),
    })
}

/// The procedural meshes the ray batches know by name: the paper's torus knot.
fn procedural_mesh(name: &str) -> Result<gridtrace::Mesh> {
    match name {
        "torus-knot" => Ok(gridtrace::scene::procedural::torus_knot(2, 3, 0.16, 1024, 32)),
        _ => Err(gridtrace::Error::InvalidInput(format!("no mesh named '{name}'"))),
    }
}

/// Runs the suite on `gpu` (and the CPU's cores for the ratios) and returns its report, which
/// is also written into `out` after each part (`write`): a run stopped from outside keeps what
/// it had measured.
pub fn run(
    plan: &Plan,
    gpu: Arc<GpuContext>,
    data_dir: Option<&Path>,
    variants: &[GpuVariants],
    out: &Path,
    log: &mut dyn FnMut(&str),
) -> Result<HardwareReport> {
    let mut budget = Budget {
        started: Instant::now(),
        budget_s: plan.budget_s,
        until: 1.0,
    };
    let adapter = AdapterRecord::of(&gpu);
    if adapter.software {
        log(&format!(
            "WARNING: the adapter is a SOFTWARE one ({}): it runs shaders on the CPU, so every GPU figure below is CPU speed, not GPU speed",
            gpu.describe()
        ));
    }
    let mut skipped = Vec::new();
    // A variant the adapter cannot run (subgroup appends without subgroups) is left out, said.
    let variants: Vec<GpuVariants> = variants
        .iter()
        .filter(|v| match v.supported_on(&gpu) {
            Ok(()) => true,
            Err(why) => {
                skipped.push(format!("variant {}: {why}", v.changes()));
                false
            }
        })
        .copied()
        .collect();
    let variants = &variants[..];
    // A structure the adapter cannot run (`hwrt` without ray queries) is left out, said.
    skipped.extend(AccelKind::ALL.into_iter().filter_map(|k| frames::not_offered(&gpu, k)));
    let mut meshes = Vec::new();
    for name in &plan.ray_meshes {
        match study_mesh(name, data_dir).unwrap_or_else(|| procedural_mesh(name)) {
            Ok(m) => meshes.push((name.clone(), m)),
            Err(e) => skipped.push(format!("rays of {name}: {e}")),
        }
    }
    let mut frame_scenes: Vec<scenes::BenchScene> = Vec::new();
    for name in &plan.frame_scenes {
        // The paper's scenes as the matrix builds them; other meshes (read once, shared with
        // the ray batches) alone on a floor.
        let scene = if scenes::paper_scene(name).is_some() {
            scenes::build_paper_scene(name, data_dir)
        } else if let Some((_, m)) = meshes.iter().find(|(n, _)| n == name) {
            Ok(frames::mesh_bench_scene(name, m.clone()))
        } else {
            match study_mesh(name, data_dir) {
                Some(mesh) => mesh.map(|m| frames::mesh_bench_scene(name, m)),
                None => scenes::build_paper_scene(name, data_dir),
            }
        };
        match scene {
            Ok(s) => frame_scenes.push(s),
            Err(e) => skipped.push(format!("frames of {name}: {e}")),
        }
    }
    let mut report = HardwareReport {
        gridtrace_version: env!("CARGO_PKG_VERSION").to_string(),
        command_line: std::env::args().collect(),
        unix_time: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs()),
        machine: Machine::detect(Some(&gpu)),
        adapter,
        plan: plan.clone(),
        variants: variants.iter().map(|v| v.to_string()).collect(),
        frames: Vec::new(),
        big_frame: Vec::new(),
        rays: Vec::new(),
        points: Vec::new(),
        builds: Vec::new(),
        skipped,
        mismatches: Vec::new(),
        elapsed_s: 0.0,
    };
    // The matrix first (the question the hardware run is for), then the big frame, rays,
    // builds; each within its share of the budget, the report written after each.
    let r = &mut report;
    r.frames = frames::frame_matrix(
        plan,
        &gpu,
        &frame_scenes,
        variants,
        budget.part(FRAMES_UNTIL),
        &mut r.skipped,
        &mut r.mismatches,
        log,
    )?;
    checkpoint(r, &budget, out)?;
    r.big_frame = frames::big_frame(
        plan,
        &gpu,
        &frame_scenes,
        budget.part(BIG_FRAME_UNTIL),
        &mut r.skipped,
        &mut r.mismatches,
        log,
    )?;
    checkpoint(r, &budget, out)?;
    r.rays = rays::ray_study(
        plan,
        &gpu,
        &meshes,
        variants,
        budget.part(RAYS_UNTIL),
        &mut r.skipped,
        &mut r.mismatches,
        log,
    )?;
    checkpoint(r, &budget, out)?;
    // The point queries share the ray batches' part of the budget.
    r.points = points::point_study(
        plan,
        &gpu,
        &meshes,
        budget.part(RAYS_UNTIL),
        &mut r.skipped,
        &mut r.mismatches,
        log,
    )?;
    checkpoint(r, &budget, out)?;
    r.builds = builds::grid_builds(plan, &gpu, budget.part(BUILDS_UNTIL), &mut r.skipped, log)?;
    checkpoint(r, &budget, out)?;
    Ok(report)
}

/// The report as far as it got, written.
fn checkpoint(r: &mut HardwareReport, budget: &Budget, out: &Path) -> Result<()> {
    r.elapsed_s = budget.elapsed_s();
    write(r, out).map(|_| ())
}

/// Writes `hardware.json` and `hardware.md` into `dir`.
pub fn write(report: &HardwareReport, dir: &Path) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|e| gridtrace::Error::io(dir, e))?;
    let json = dir.join("hardware.json");
    let md = dir.join("hardware.md");
    let text = serde_json::to_string_pretty(report).map_err(|e| gridtrace::Error::InvalidInput(format!("{e}")))?;
    std::fs::write(&json, text).map_err(|e| gridtrace::Error::io(&json, e))?;
    std::fs::write(&md, markdown::markdown(report)).map_err(|e| gridtrace::Error::io(&md, e))?;
    Ok(vec![json, md])
}
