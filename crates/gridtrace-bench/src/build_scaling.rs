//! Build time against triangle count: what a structure costs to build (or rebuild, every frame
//! of an animation), from a thousand to millions of triangles. The uniform grid with its
//! proximity cloud on the CPU (one thread and every core), on the GPU (`GpuGrid`, the device
//! build), and the BVH on the CPU, on the same triangles; Embree's BVH build comes from
//! `crates/gridtrace-py/bench/build_vs_embree.py` over the meshes `export` writes, and joins the
//! table and chart through `with_embree`.

use gridtrace::AccelParams;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use gridtrace::accel::grid::Grid;
use gridtrace::accel::{Accel, AccelKind, Resolution, TriAccel};
use gridtrace::gpu::{GpuContext, GpuGrid};
use gridtrace::{Error, Result};
use serde::Serialize;

use crate::scenes::ScalingMesh;

/// One mesh's builds, best of the repetitions, in milliseconds.
#[derive(Debug, Clone, Serialize)]
pub struct BuildPoint {
    pub mesh: String,
    pub source: String,
    pub triangles: usize,
    pub grid_dims: [u32; 3],
    pub references: usize,
    /// Grid + proximity cloud on one CPU thread.
    pub cpu_1t_ms: f64,
    /// The same on every core.
    pub cpu_ms: f64,
    pub cpu_threads: usize,
    /// The BVH (binned SAH, eight-wide collapse) on every core.
    pub bvh_ms: f64,
    /// Grid + proximity cloud built on the GPU: the stages' timestamps where the adapter has
    /// them, else the wall time of the build's submission and its one read-back.
    pub gpu_ms: Option<f64>,
    pub gpu_from_timestamps: bool,
    /// Why there is no GPU figure: the build handed the grid to the CPU
    /// (`GpuBuildStats::cpu_fallback`), or the mesh is over the device's limits.
    pub gpu_fallback: Option<String>,
    /// Embree's BVH build (embreex, every core), when given.
    pub embree_ms: Option<f64>,
}

/// The meshes' triangles, as the scene preparation makes them (degenerate ones dropped).
fn triangles(m: &gridtrace::Mesh) -> Vec<TriAccel> {
    TriAccel::from_mesh(m)
}

/// The best of `reps` runs of `f` after one warm-up, in ms, and the last result.
fn best<T>(reps: u32, mut f: impl FnMut() -> Result<T>) -> Result<(f64, T)> {
    let mut out = f()?;
    let mut best = f64::INFINITY;
    for _ in 0..reps.max(1) {
        let t0 = Instant::now();
        out = f()?;
        best = best.min(t0.elapsed().as_secs_f64() * 1e3);
    }
    Ok((best, out))
}

/// Times every build on every mesh.
pub fn build_scaling(
    meshes: &[ScalingMesh],
    gpu: Option<&Arc<GpuContext>>,
    reps: u32,
    log: &mut dyn FnMut(&str),
) -> Result<Vec<BuildPoint>> {
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .map_err(|e| Error::InvalidInput(format!("a one-thread pool: {e}")))?;
    let mut out = Vec::new();
    for m in meshes {
        let tris = triangles(&m.mesh);
        if tris.is_empty() {
            log(&format!("  build scaling: skipping {}: no triangles", m.name));
            continue;
        }
        let (cpu_1t_ms, _) = one.install(|| best(reps, || Grid::build(&tris, Resolution::default())))?;
        let (cpu_ms, grid) = best(reps, || Grid::build(&tris, Resolution::default()))?;
        let (bvh_ms, _) = best(reps, || Accel::build(tris.clone(), AccelKind::Bvh, &AccelParams::NONE))?;
        // The clone is part of what `Accel::build` takes; time it alone and take it off.
        let (clone_ms, _) = best(reps, || Ok(tris.clone()))?;
        let bvh_ms = (bvh_ms - clone_ms).max(0.0);
        let (mut gpu_ms, mut gpu_from_timestamps, mut gpu_fallback) = (None, false, None);
        if let Some(ctx) = gpu {
            let mut fastest = f64::INFINITY;
            // One warm-up build (pipelines, buffers), then the timed ones, as `best` does.
            for rep in 0..=reps.max(1) {
                match GpuGrid::build_from(ctx.clone(), &tris, Resolution::default()) {
                    Ok((_, stats)) => {
                        if rep > 0 {
                            fastest = fastest.min(stats.timings.total_ms);
                        }
                        gpu_from_timestamps = stats.timings.from_timestamps;
                        gpu_fallback = stats
                            .cpu_fallback
                            .as_ref()
                            .map(|w| format!("built on the CPU instead: {w}"));
                    }
                    // A mesh over the device's buffer limits: said in the table, not fatal.
                    Err(Error::Gpu(e)) => {
                        log(&format!("  {}: no GPU build: {e}", m.name));
                        gpu_fallback = Some(format!("over the device's limits: {e}"));
                        break;
                    }
                    Err(e) => return Err(e),
                }
            }
            // A grid the GPU handed to the CPU is no GPU figure.
            gpu_ms = (fastest.is_finite() && gpu_fallback.is_none()).then_some(fastest);
        }
        let p = BuildPoint {
            mesh: m.name.clone(),
            source: m.source.clone(),
            triangles: tris.len(),
            grid_dims: grid.stats.dims,
            references: grid.stats.references,
            cpu_1t_ms,
            cpu_ms,
            cpu_threads: rayon::current_num_threads(),
            bvh_ms,
            gpu_ms,
            gpu_from_timestamps,
            gpu_fallback,
            embree_ms: None,
        };
        log(&format!(
            "  {:<22} {:>10} tris  grid 1 thread {:9.2} ms, {} threads {:9.2} ms, bvh {:9.2} ms{}",
            p.mesh,
            p.triangles,
            p.cpu_1t_ms,
            p.cpu_threads,
            p.cpu_ms,
            p.bvh_ms,
            p.gpu_ms.map_or(String::new(), |g| format!(", gpu {g:9.2} ms"))
        ));
        out.push(p);
    }
    Ok(out)
}

/// Writes each mesh's triangles for the Embree script: `NAME.f32` (x, y, z of each triangle's
/// three corners, little-endian f32) and `index.json` (name -> triangle count).
pub fn export(meshes: &[ScalingMesh], dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let mut index = BTreeMap::new();
    for m in meshes {
        let tris = triangles(&m.mesh);
        let mut bytes = Vec::with_capacity(tris.len() * 36);
        for t in &tris {
            for v in t.vertices() {
                for c in v.to_array() {
                    bytes.extend_from_slice(&c.to_le_bytes());
                }
            }
        }
        let path = dir.join(format!("{}.f32", m.name));
        std::fs::write(&path, bytes).map_err(|e| Error::io(&path, e))?;
        index.insert(m.name.clone(), tris.len());
    }
    let path = dir.join("index.json");
    let text = serde_json::to_string_pretty(&index).map_err(|e| Error::io(&path, std::io::Error::other(e)))?;
    std::fs::write(&path, text).map_err(|e| Error::io(&path, e))
}

/// Adds Embree's build times (a JSON object: mesh name -> ms, as the Embree script writes it).
pub fn with_embree(points: &mut [BuildPoint], path: &Path) -> Result<()> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let ms: BTreeMap<String, f64> = serde_json::from_str(&text)
        .map_err(|e| Error::InvalidInput(format!("{}: not a JSON object of mesh name -> ms: {e}", path.display())))?;
    for p in points {
        p.embree_ms = ms.get(&p.mesh).copied();
    }
    Ok(())
}
