//! The suite's grid builds: grid + proximity cloud of torus knots from 100k to 10M triangles on
//! the GPU (`GpuGrid`) beside the CPU's cores, smallest first, each within the budget. (The
//! `--build-scaling` study also times one CPU thread and the BVH, minutes at 10M triangles: more
//! than a hardware run can spend.)

use std::sync::Arc;
use std::time::Instant;

use serde::Serialize;

use gridtrace::accel::{Grid, TriAccel};
use gridtrace::gpu::{GpuContext, GpuGrid};
use gridtrace::{Error, Resolution, Result};

use super::{Budget, Plan};

/// One mesh's builds.
#[derive(Debug, Clone, Serialize)]
pub struct BuildRow {
    pub mesh: String,
    pub triangles: usize,
    /// Best of the plan's repetitions after a warm-up, ms: the CPU's cores, and the GPU's
    /// stages (timestamps, else the build's wall time).
    pub cpu_ms: f64,
    pub gpu_ms: Option<f64>,
    pub gpu_from_timestamps: bool,
    /// Why there is no GPU figure (the build went to the CPU, or the mesh is over the limits).
    pub gpu_fallback: Option<String>,
    /// References of the two grids: equal unless rounding moved boundary triangles.
    pub cpu_references: usize,
    pub gpu_references: Option<u64>,
}

/// Torus knots of about `n` triangles each (`2 * rings * 32`).
fn knot(n: usize) -> (String, Vec<TriAccel>) {
    let rings = (n / 64).max(8) as u32;
    let mesh = gridtrace::scene::procedural::torus_knot(2, 3, 0.16, rings, 32);
    (
        format!("torus-knot-{}", mesh.triangles.len()),
        TriAccel::from_mesh(&mesh),
    )
}

pub fn grid_builds(
    plan: &Plan,
    gpu: &Arc<GpuContext>,
    budget: &Budget,
    skipped: &mut Vec<String>,
    log: &mut dyn FnMut(&str),
) -> Result<Vec<BuildRow>> {
    let sizes: &[usize] = if plan.quick {
        &[10_000, 30_000]
    } else {
        &[100_000, 1_000_000, 3_000_000, 10_000_000]
    };
    let mut rows = Vec::new();
    for &n in sizes.iter().filter(|&&n| n <= plan.build_max_tris.max(10_000)) {
        if !budget.allows(&format!("grid build of {n} triangles"), skipped) {
            continue;
        }
        let (mesh, tris) = knot(n);
        let mut cpu_ms = f64::INFINITY;
        let mut cpu = None;
        for rep in 0..=plan.reps.max(1) {
            let t0 = Instant::now();
            let g = Grid::build(&tris, Resolution::default())?;
            if rep > 0 {
                cpu_ms = cpu_ms.min(t0.elapsed().as_secs_f64() * 1e3);
            }
            cpu = Some(g);
        }
        let cpu = cpu.expect("at least one build");
        let mut row = BuildRow {
            mesh,
            triangles: tris.len(),
            cpu_ms,
            gpu_ms: None,
            gpu_from_timestamps: false,
            gpu_fallback: None,
            cpu_references: cpu.refs.len(),
            gpu_references: None,
        };
        let mut best = f64::INFINITY;
        for rep in 0..=plan.reps.max(1) {
            let t0 = Instant::now();
            match GpuGrid::build_from(gpu.clone(), &tris, Resolution::default()) {
                Ok((_, stats)) => {
                    let wall = t0.elapsed().as_secs_f64() * 1e3;
                    row.gpu_from_timestamps = stats.timings.from_timestamps;
                    let ms = if stats.timings.from_timestamps {
                        stats.timings.total_ms
                    } else {
                        wall
                    };
                    if rep > 0 {
                        best = best.min(ms);
                    }
                    row.gpu_references = Some(stats.references);
                    row.gpu_fallback = stats.cpu_fallback.map(|w| format!("built on the CPU instead: {w}"));
                }
                Err(Error::Gpu(e)) => {
                    row.gpu_fallback = Some(format!("over the device's limits: {e}"));
                    break;
                }
                Err(e) => return Err(e),
            }
        }
        row.gpu_ms = (best.is_finite() && row.gpu_fallback.is_none()).then_some(best);
        log(&format!(
            "  build {:<22} {:>9} tris: cpu {:.1} ms, gpu {}",
            row.mesh,
            row.triangles,
            row.cpu_ms,
            row.gpu_ms.map_or_else(
                || row.gpu_fallback.clone().unwrap_or_default(),
                |g| format!("{g:.1} ms")
            )
        ));
        rows.push(row);
    }
    Ok(rows)
}
