//! The ray-query study: incoherent rays (the Python benchmark's) through the library's batch
//! API, every structure, on the CPU and the GPU, with each walk's work per ray.

use serde::Serialize;

use super::{Summary, repeat};
use glam::Vec3;
use gridtrace::Result;
use gridtrace::accel::AccelKind;

/// One mesh and acceleration of the ray-query study.
#[derive(Debug, Clone, Serialize)]
pub struct QueryStudyRow {
    pub scene: String,
    pub triangles: usize,
    pub accel: String,
    /// cpu or gpu.
    pub backend: String,
    /// Building the acceleration (grid, plus the BVH for `bvh`), milliseconds.
    pub build_ms: f64,
    pub rays: usize,
    pub threads: usize,
    pub hit_fraction: f64,
    /// Grid cells, or BVH nodes visited per ray (the CPU walks eight-wide nodes, the GPU
    /// two-wide ones).
    pub cells_per_ray: f64,
    pub tri_tests_per_ray: f64,
    #[serde(flatten)]
    pub summary: Summary,
    pub mrays_per_s: f64,
}

/// The ray set of the Python benchmark (`crates/gridtrace-py/bench/bench_vs_embree.py`): origins
/// uniform on a sphere of radius one bounding-box diagonal around the mesh, aimed at uniform
/// random points of its bounding box. Incoherent: neighbouring rays share nothing.
pub fn incoherent_rays(bounds: gridtrace::accel::Aabb, n: usize, seed: u64) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let mut rng = gridtrace::util::Rng::new(seed);
    let (c, r) = (bounds.center(), bounds.diagonal());
    let (mut origins, mut dirs) = (Vec::with_capacity(n), Vec::with_capacity(n));
    while origins.len() < n {
        let v = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
        if !(1e-6..=1.0).contains(&v.length_squared()) {
            continue;
        }
        let o = c + r * v.normalize();
        let target = Vec3::new(
            rng.range(bounds.min.x, bounds.max.x),
            rng.range(bounds.min.y, bounds.max.y),
            rng.range(bounds.min.z, bounds.max.z),
        );
        origins.push(o.to_array());
        dirs.push((target - o).normalize().to_array());
    }
    (origins, dirs)
}

fn ms_since(t0: std::time::Instant) -> f64 {
    t0.elapsed().as_secs_f64() * 1e3
}

/// Work per ray of one structure's walk, counted on a sample of the rays: cells (grid, pc) or
/// nodes (BVH) visited, and triangle tests. `gpu_bvh_walk`: count the GPU's BVH walk over
/// two-wide nodes (`gpu::bvh::walk` counts it on the CPU, step for step) instead of the CPU's.
fn work_per_ray(tm: &gridtrace::query::TraceMesh, gpu_bvh_walk: bool, o: &[[f32; 3]], d: &[[f32; 3]]) -> (f64, f64) {
    use gridtrace::accel::{Ray, TraversalCounters};
    let sample = o.len().min(100_000);
    let scene = tm.prepared();
    let mut c = TraversalCounters::default();
    let gpu_bvh = match (gpu_bvh_walk, scene.accel.bvh()) {
        (true, Some(b)) => gridtrace::gpu::bvh::gpu_nodes(&b.bvh).ok().map(|n| (n, &b.bvh.prims)),
        _ => None,
    };
    for i in 0..sample {
        let r = Ray::new(o[i].into(), d[i].into());
        match &gpu_bvh {
            Some((nodes, prims)) => {
                gridtrace::gpu::bvh::walk::<false, _>(nodes, prims, &scene.accel.tris, &r, 0.0, f32::INFINITY, &mut c);
            }
            None => {
                scene.accel.intersect(&r, &mut c);
            }
        }
    }
    let n = sample.max(1) as f64;
    (c.cells as f64 / n, c.tri_tests as f64 / n)
}

/// Times ray queries with `rays` incoherent rays per mesh, for every acceleration: on the CPU
/// (`cpu`) the whole library call as Python makes it (`TraceMesh::intersect`: validation,
/// parallel traversal, output arrays) with the current rayon thread count, and on the GPU
/// (`gpu`) the batch query (`GpuRenderer::intersect`: upload, dispatches, read-back), on the
/// same rays.
pub fn query_study(
    meshes: &[(String, gridtrace::Mesh)],
    rays: usize,
    cpu: bool,
    gpu: Option<&std::sync::Arc<gridtrace::gpu::GpuContext>>,
    warmup: u32,
    reps: u32,
    log: &mut dyn FnMut(&str),
) -> Result<Vec<QueryStudyRow>> {
    use gridtrace::accel::Ray;
    use gridtrace::query::{Backend, QueryOptions, TraceMesh};
    let mut rows = Vec::new();
    for (name, mesh) in meshes {
        // The structures the CPU traces (`hwrt`'s rays are the hardware suite's).
        for accel in AccelKind::ALL.into_iter().filter(|k| k.entry().cpu) {
            let opts = QueryOptions {
                accel: accel.into(),
                backend: Backend::Cpu,
                ..Default::default()
            };
            let t0 = std::time::Instant::now();
            let tm = TraceMesh::from_mesh(mesh.clone(), &opts)?;
            let build_ms = t0.elapsed().as_secs_f64() * 1e3;
            let (o, d) = incoherent_rays(tm.prepared().accel.bounds(), rays, 7);
            let mut runs: Vec<(&str, Vec<f64>, usize)> = Vec::new();
            if cpu {
                let (times, hits) = repeat(warmup, reps, || {
                    let t0 = std::time::Instant::now();
                    let h = tm.intersect(&o, &d, 0.0, f32::INFINITY)?;
                    Ok((ms_since(t0), h.t.iter().filter(|t| t.is_finite()).count()))
                })?;
                runs.push(("cpu", times, hits[0]));
            }
            if let Some(ctx) = gpu {
                let mut r = gridtrace::gpu::GpuRenderer::new(
                    ctx.clone(),
                    tm.prepared(),
                    &gridtrace::gpu::GpuVariants::default(),
                )?;
                let ray_vec: Vec<Ray> = o
                    .iter()
                    .zip(&d)
                    .map(|(a, b)| Ray::new((*a).into(), (*b).into()))
                    .collect();
                let (times, hits) = repeat(warmup, reps, || {
                    let t0 = std::time::Instant::now();
                    let h = r.intersect(&ray_vec)?;
                    Ok((ms_since(t0), h.iter().filter(|h| h.is_hit()).count()))
                })?;
                runs.push(("gpu", times, hits[0]));
            }
            // Counted once per walk: the grids walk alike on both backends, the BVH differs.
            let mut work: [Option<(f64, f64)>; 2] = [None; 2];
            for (backend, times, hits) in runs {
                let gpu_walk = backend == "gpu" && accel == AccelKind::Bvh;
                let (cells_per_ray, tri_tests_per_ray) =
                    *work[gpu_walk as usize].get_or_insert_with(|| work_per_ray(&tm, gpu_walk, &o, &d));
                let summary = Summary::of(&times);
                let row = QueryStudyRow {
                    scene: name.clone(),
                    triangles: tm.triangle_count(),
                    accel: accel.name().into(),
                    backend: backend.into(),
                    build_ms,
                    rays,
                    threads: rayon::current_num_threads(),
                    hit_fraction: hits as f64 / rays.max(1) as f64,
                    cells_per_ray,
                    tri_tests_per_ray,
                    summary,
                    mrays_per_s: rays as f64 / (summary.best_ms * 1e3).max(1e-9),
                };
                log(&format!(
                    "  query-study {:<16} {:<4} {} build {:>7.1} ms  {:>6.2} cells/nodes  {:>6.2} tri tests per ray  best {:>8.2} ms  {:>7.2} Mrays/s",
                    row.scene,
                    row.accel,
                    row.backend,
                    row.build_ms,
                    row.cells_per_ray,
                    row.tri_tests_per_ray,
                    summary.best_ms,
                    row.mrays_per_s
                ));
                rows.push(row);
            }
        }
    }
    Ok(rows)
}
