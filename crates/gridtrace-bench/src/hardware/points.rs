//! The suite's point queries: nearest points (every structure the GPU walks) and generalised
//! winding numbers (the fast winding tree, accuracy 2: the sign of signed distance and
//! occupancy) for points uniform in each mesh's box grown by a tenth a side, on the GPU and
//! the CPU's cores, the GPU's answers checked against the CPU's.

use std::sync::Arc;
use std::time::Instant;

use serde::Serialize;

use gridtrace::accel::winding::FastWinding;
use gridtrace::gpu::{GpuContext, GpuQueryStats, GpuVariants};
use gridtrace::query::{Backend, QueryOptions, TraceMesh};
use gridtrace::{AccelKind, Mesh, Result};

use super::frames::{cpu_reference, frame_accels, open_gpu};
use super::{Budget, Plan};
use crate::timing::{Summary, repeat_warm};

/// Points whose GPU answer may differ from the CPU's (a fraction): a distance more than 1e-4
/// (relative) apart, or a winding number more than 1e-3 apart. More is a mismatch.
pub const MAX_DIFFERING_POINTS: f64 = 0.001;

/// One point-query measurement.
#[derive(Debug, Clone, Serialize)]
pub struct PointRow {
    pub mesh: String,
    pub triangles: usize,
    /// `closest` (nearest points) or `winding` (winding numbers, accuracy 2).
    pub query: String,
    /// The structure searched (`closest`); `-` for winding numbers (their own tree).
    pub accel: String,
    pub backend: String,
    pub points: usize,
    /// Wall time of the whole query (upload, search, readback), ms.
    #[serde(flatten)]
    pub wall: Summary,
    pub mpoints_per_s: f64,
    /// GPU time (timestamps summed), median, where the adapter has them.
    pub gpu_median_ms: Option<f64>,
    /// Bytes over the bus a point, each way; `None` on the CPU.
    pub bytes_up_per_point: Option<f64>,
    pub bytes_down_per_point: Option<f64>,
    /// Points whose answer differs from the CPU's (fraction; 0 on the CPU).
    pub differing_from_cpu: f64,
}

/// Points uniform in `mesh`'s box grown by a tenth of its size a side (the set).
fn points_in_box(mesh: &TraceMesh, n: usize) -> Vec<[f32; 3]> {
    let b = mesh.prepared().accel.bounds();
    let grow = (b.max - b.min) * 0.1;
    let (lo, size) = (b.min - grow, (b.max - b.min) + 2.0 * grow);
    let mut rng = gridtrace::util::Rng::new(0x853c_49e6_748f_ea9b);
    let mut next = || rng.next_f32();
    (0..n)
        .map(|_| (lo + size * glam::Vec3::new(next(), next(), next())).to_array())
        .collect()
}

pub fn point_study(
    plan: &Plan,
    gpu: &Arc<GpuContext>,
    meshes: &[(String, Mesh)],
    budget: &Budget,
    skipped: &mut Vec<String>,
    mismatches: &mut Vec<String>,
    log: &mut dyn FnMut(&str),
) -> Result<Vec<PointRow>> {
    let mut rows = Vec::new();
    for (name, mesh) in meshes {
        let mesh_for = |accel: AccelKind| {
            let opts = QueryOptions {
                accel: accel.into(),
                backend: Backend::Cpu,
                ..QueryOptions::default()
            };
            TraceMesh::from_mesh(mesh.clone(), &opts)
        };
        let mut head = PointHead {
            mesh: name,
            triangles: 0,
            points: plan.rays,
        };
        for accel in frame_accels(gpu) {
            if !budget.allows(&format!("closest points of {name} with {}", accel.name()), skipped) {
                continue;
            }
            let tm = mesh_for(accel)?;
            let cpu = mesh_for(cpu_reference(accel))?;
            head.triangles = tm.triangle_count();
            let points = points_in_box(&tm, plan.rays);
            let want = timed(plan, || Ok((cpu.closest_points_with(Backend::Cpu, &points)?, None)))?;
            rows.push(head.row("closest", accel.name(), "cpu", &want.times, None, 0.0));
            let mut r = open_gpu(gpu, tm.prepared(), &GpuVariants::default())?;
            let tris = &tm.prepared().accel.tris;
            let got = timed(plan, || {
                let c = r.closest_points(tris, &points)?;
                Ok((c, Some(r.last_query_stats().clone())))
            })?;
            let differ = want
                .last
                .iter()
                .zip(&got.last)
                .filter(|(a, b)| (a.distance() - b.distance()).abs() > 1e-4 * a.distance().max(1e-3))
                .count() as f64
                / points.len().max(1) as f64;
            rows.push(head.row("closest", accel.name(), "gpu", &got.times, Some(&got.stats), differ));
            check(&mut rows, mismatches, log);
        }
        if !budget.allows(&format!("winding numbers of {name}"), skipped) {
            continue;
        }
        let tm = mesh_for(AccelKind::Bvh)?;
        let tris = &tm.prepared().accel.tris;
        let points = points_in_box(&tm, plan.rays);
        // The tree built once, outside the times (the query's cost; its build is the CPU's,
        // measured in bench/winding_vs_libigl.py).
        let tree = FastWinding::build(tris);
        let want = timed(plan, || Ok((tree.winding_numbers_at(tris, &points, 2.0), None)))?;
        rows.push(head.row("winding", "-", "cpu", &want.times, None, 0.0));
        let mut r = open_gpu(gpu, tm.prepared(), &GpuVariants::default())?;
        let got = timed(plan, || {
            let w = r.winding_numbers(&tree, &points, 2.0)?;
            Ok((w, Some(r.last_query_stats().clone())))
        })?;
        let differ = want
            .last
            .iter()
            .zip(&got.last)
            .filter(|(a, b)| (*a - *b).abs() > 1e-3)
            .count() as f64
            / points.len().max(1) as f64;
        rows.push(head.row("winding", "-", "gpu", &got.times, Some(&got.stats), differ));
        check(&mut rows, mismatches, log);
    }
    Ok(rows)
}

/// Logs the last two rows (CPU, GPU) and records a mismatch where the GPU's answers differ.
fn check(rows: &mut [PointRow], mismatches: &mut Vec<String>, log: &mut dyn FnMut(&str)) {
    let n = rows.len();
    for r in &rows[n - 2..] {
        log(&format!(
            "  points {:<15} {:<8} {:<9} {:<3} {} points: {:.2} ms ({:.2} Mpoints/s){}",
            r.mesh,
            r.query,
            r.accel,
            r.backend,
            r.points,
            r.wall.median_ms,
            r.mpoints_per_s,
            r.gpu_median_ms.map_or(String::new(), |ms| format!(", GPU {ms:.2} ms"))
        ));
    }
    let g = &rows[n - 1];
    if g.differing_from_cpu > MAX_DIFFERING_POINTS {
        mismatches.push(format!(
            "points {} {} {}: {:.3}% of answers differ from the CPU's",
            g.mesh,
            g.query,
            g.accel,
            100.0 * g.differing_from_cpu
        ));
    }
}

/// The timed runs of one query: each run's wall time (ms), the last run's answers and every
/// run's GPU statistics (none on the CPU).
struct Runs<T> {
    times: Vec<f64>,
    last: T,
    stats: Vec<GpuQueryStats>,
}

/// One warm-up, then `reps` timed runs of `f`.
fn timed<T>(plan: &Plan, mut f: impl FnMut() -> Result<(T, Option<GpuQueryStats>)>) -> Result<Runs<T>> {
    let (times, mut outs) = repeat_warm(1, plan.warmup_ms, plan.reps, || {
        let t0 = Instant::now();
        let out = f()?;
        Ok((t0.elapsed().as_secs_f64() * 1e3, out))
    })?;
    let stats: Vec<GpuQueryStats> = outs.iter().filter_map(|o| o.1.clone()).collect();
    let last = outs.pop().expect("at least one timed run").0;
    Ok(Runs { times, last, stats })
}

struct PointHead<'a> {
    mesh: &'a str,
    triangles: usize,
    points: usize,
}

impl PointHead<'_> {
    fn row(
        &self,
        query: &str,
        accel: &str,
        backend: &str,
        times: &[f64],
        gpu: Option<&Vec<GpuQueryStats>>,
        differing: f64,
    ) -> PointRow {
        let wall = Summary::of(times);
        let last = gpu.and_then(|s| s.last());
        let per_point = |b: u64| b as f64 / self.points.max(1) as f64;
        PointRow {
            mesh: self.mesh.to_string(),
            triangles: self.triangles,
            query: query.into(),
            accel: accel.into(),
            backend: backend.into(),
            points: self.points,
            wall,
            mpoints_per_s: self.points as f64 / (wall.median_ms * 1e3).max(1e-9),
            gpu_median_ms: gpu.and_then(|s| Summary::median_of(s.iter().filter_map(GpuQueryStats::gpu_ms))),
            bytes_up_per_point: last.map(|s| per_point(s.uploaded_bytes)),
            bytes_down_per_point: last.map(|s| per_point(s.downloaded_bytes)),
            differing_from_cpu: differing,
        }
    }
}
