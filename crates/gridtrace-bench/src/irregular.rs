//! The irregular grid's parameter study: each parameter set's build (time, cells, references,
//! bytes) and its traversal on incoherent rays (work and speed), beside the uniform grid with
//! proximity clouds and the BVH on the same rays, in one run.

use gridtrace::AccelParams;
use rayon::prelude::*;
use serde::Serialize;

use super::query_study::incoherent_rays;
use super::{Summary, repeat};
use gridtrace::Result;
use gridtrace::accel::{Accel, AccelKind, Hit, IrregularParams, Ray, TraversalCounters};

/// The parameter sets `--irregular-sweep` tries by default: the defaults, then one parameter
/// changed at a time.
pub fn default_sweep() -> Vec<IrregularParams> {
    let d = IrregularParams::default();
    vec![
        d,
        IrregularParams { expand_passes: 0, ..d },
        IrregularParams { merge_passes: 0, ..d },
        IrregularParams { top_density: 0.03, ..d },
        IrregularParams { top_density: 0.5, ..d },
        IrregularParams { cell_density: 0.5, ..d },
        IrregularParams { cell_density: 8.0, ..d },
        IrregularParams { merge_alpha: 0.9, ..d },
        IrregularParams { merge_alpha: 1.2, ..d },
    ]
}

/// The parameters as `--irregular` spells them.
pub fn params_str(p: &IrregularParams) -> String {
    format!(
        "top={},cell={},alpha={},merge={},expand={}",
        p.top_density, p.cell_density, p.merge_alpha, p.merge_passes, p.expand_passes
    )
}

#[derive(Debug, Clone, Serialize)]
pub struct IrregularSweepRow {
    pub scene: String,
    pub triangles: usize,
    pub accel: String,
    /// The irregular grid's parameters (`params_str`); empty for the other structures.
    pub params: String,
    pub build_ms: f64,
    /// Cells (grids) or nodes (BVH).
    pub cells: usize,
    pub refs_per_triangle: f64,
    /// Bytes of the structure's own arrays (triangles excluded) per triangle.
    pub bytes_per_triangle: f64,
    pub rays: usize,
    /// Cells stepped through (grids) or nodes visited (BVH) per ray.
    pub steps_per_ray: f64,
    pub tri_tests_per_ray: f64,
    #[serde(flatten)]
    pub summary: Summary,
    pub mrays_per_s: f64,
}

/// Times closest hits of `rays` incoherent rays per mesh through each structure (all threads,
/// `Accel::intersect_batch` in chunks), pc and bvh first, then the irregular grid with each
/// parameter set.
pub fn irregular_sweep(
    meshes: &[(String, Vec<gridtrace::accel::TriAccel>)],
    rays: usize,
    sweep: &[IrregularParams],
    warmup: u32,
    reps: u32,
    log: &mut dyn FnMut(&str),
) -> Result<Vec<IrregularSweepRow>> {
    let mut rows = Vec::new();
    for (name, tris) in meshes {
        let mut builds: Vec<(AccelKind, String, f64, Accel)> = Vec::new();
        for kind in [AccelKind::ProximityCloud, AccelKind::Bvh] {
            let t0 = std::time::Instant::now();
            let a = Accel::build(tris.clone(), kind, &AccelParams::NONE)?;
            builds.push((kind, String::new(), t0.elapsed().as_secs_f64() * 1e3, a));
        }
        for p in sweep {
            let t0 = std::time::Instant::now();
            let a = Accel::build(tris.clone(), AccelKind::Irregular, &p.to_params())?;
            builds.push((AccelKind::Irregular, params_str(p), t0.elapsed().as_secs_f64() * 1e3, a));
        }
        let (o, d) = incoherent_rays(builds[0].3.bounds(), rays, 7);
        let ray_vec: Vec<Ray> = o
            .iter()
            .zip(&d)
            .map(|(a, b)| Ray::new((*a).into(), (*b).into()))
            .collect();
        for (kind, params, build_ms, accel) in &builds {
            let mut out = vec![Hit::MISS; ray_vec.len()];
            let (times, _) = repeat(warmup, reps, || {
                let t0 = std::time::Instant::now();
                ray_vec
                    .par_chunks(4096)
                    .zip(out.par_chunks_mut(4096))
                    .for_each(|(r, h)| accel.intersect_batch(r, h));
                Ok((t0.elapsed().as_secs_f64() * 1e3, ()))
            })?;
            let sample = ray_vec.len().min(100_000);
            let mut c = TraversalCounters::default();
            for r in &ray_vec[..sample] {
                accel.intersect(r, &mut c);
            }
            let n = tris.len().max(1) as f64;
            let structure_bytes: usize = accel
                .memory()
                .iter()
                .filter(|(k, _)| *k != "triangles")
                .map(|(_, b)| b)
                .sum();
            let (cells, refs) = match (accel.grid(), accel.bvh(), accel.irregular()) {
                (Some(g), _, _) => (g.stats.cells, g.stats.references),
                (_, Some(b), _) => (b.nodes.len(), tris.len()),
                (_, _, Some(g)) => (g.stats.cells, g.stats.references),
                _ => (0, 0),
            };
            let summary = Summary::of(&times);
            let row = IrregularSweepRow {
                scene: name.clone(),
                triangles: tris.len(),
                accel: kind.name().into(),
                params: params.clone(),
                build_ms: *build_ms,
                cells,
                refs_per_triangle: refs as f64 / n,
                bytes_per_triangle: structure_bytes as f64 / n,
                rays: ray_vec.len(),
                steps_per_ray: c.cells as f64 / sample.max(1) as f64,
                tri_tests_per_ray: c.tri_tests as f64 / sample.max(1) as f64,
                summary,
                mrays_per_s: ray_vec.len() as f64 / (summary.best_ms * 1e3).max(1e-9),
            };
            log(&format!(
                "  irregular-sweep {:<16} {:<9} {:<40} build {:>7.1} ms {:>8} cells {:>5.2} refs/tri {:>6.1} B/tri {:>6.2} steps {:>6.2} tests  best {:>8.2} ms {:>6.2} Mrays/s",
                row.scene,
                row.accel,
                row.params,
                row.build_ms,
                row.cells,
                row.refs_per_triangle,
                row.bytes_per_triangle,
                row.steps_per_ray,
                row.tri_tests_per_ray,
                summary.best_ms,
                row.mrays_per_s
            ));
            rows.push(row);
        }
    }
    Ok(rows)
}

/// The sweep's scenes: a torus knot alone (always), and with the mesh data the Stanford Bunny
/// alone and the paper's bunny in a room (a small dense mesh in a large empty box: where a
/// uniform grid is at its worst).
pub fn sweep_scenes(data_dir: Option<&std::path::Path>) -> Vec<(String, gridtrace::scene::Scene)> {
    use gridtrace::scene::{builtin, procedural};
    let mut v = vec![(
        "torus-knot-hi".to_string(),
        builtin::mesh_scene(procedural::torus_knot(2, 3, 0.16, 1024, 32), false),
    )];
    if let Some(d) = data_dir {
        if let Ok(m) = gridtrace::io::load_mesh(&d.join("bunny/bun_zipper.ply")) {
            v.push(("stanford-bunny".into(), builtin::mesh_scene(m, false)));
        }
        if let Ok(s) = super::scenes::bunny_room(d) {
            v.push(("bunny-room".into(), s));
        }
    }
    v
}
