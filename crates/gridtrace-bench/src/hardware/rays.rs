//! The suite's ray batches: camera rays in image order (coherent, as programs pass a camera's
//! rays) and incoherent rays (`query_study::incoherent_rays`), per mesh and structure, on the
//! GPU (every variant) and the CPU's cores, the GPU's hits checked against the CPU's.

use std::sync::Arc;
use std::time::Instant;

use serde::Serialize;

use gridtrace::accel::{Hit, Ray};
use gridtrace::gpu::{GpuContext, GpuRenderer, GpuVariants, HostPhases};
use gridtrace::query::{Backend, QueryOptions, TraceMesh};
use gridtrace::{AccelKind, Mesh, Result};

use super::frames::{cpu_reference, frame_accels, open_gpu, variants_for};
use super::{Budget, Plan};
use crate::query_study::incoherent_rays;
use crate::timing::{Summary, host_medians, interleaved, repeat_warm};

/// Rays whose GPU hit may differ from the CPU's (a fraction): rays through an edge or a vertex
/// may name either triangle, or a different t within rounding. More is a mismatch.
pub const MAX_DIFFERING_HITS: f64 = 0.001;

/// One batch measurement.
#[derive(Debug, Clone, Serialize)]
pub struct RayRow {
    pub mesh: String,
    pub triangles: usize,
    /// `camera` (image order) or `incoherent`.
    pub set: String,
    pub accel: String,
    pub backend: String,
    pub variant: String,
    pub rays: usize,
    /// Wall time of the whole batch query (upload, trace, readback), ms.
    #[serde(flatten)]
    pub wall: Summary,
    pub mrays_per_s: f64,
    pub hit_fraction: f64,
    /// GPU time (timestamps summed) of the timed batches: median, where the adapter has them.
    pub gpu_median_ms: Option<f64>,
    /// Medians of the wall time's parts on the host (prepare, wait, readout); `None` on the CPU.
    pub host_ms: Option<HostPhases>,
    /// Rays whose hit differs from the CPU's (fraction; 0 on the CPU).
    pub differing_from_cpu: f64,
    /// Bytes over the bus a ray, each way (the rays up, the answers down, with each chunk's
    /// constants and timestamps); `None` on the CPU.
    pub bytes_up_per_ray: Option<f64>,
    pub bytes_down_per_ray: Option<f64>,
    /// Pipelined chunks of the batch (one submission each); `None` on the CPU.
    pub chunks: Option<u32>,
}

/// The answers a GPU ray row asks for: hits with u, v (what the CPU rows answer), or the
/// lean forms a caller may ask for instead, timed beside them on the default variant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Asked {
    HitsUv,
    /// (t, triangle): 8 bytes a ray down.
    Hits,
    /// Occlusion within t < 1e30 (as likely as a hit): one bit a ray down.
    Occlusion,
    /// Every hit counted (`GpuRenderer::all_hits`: k + 1 closest walks for k hits): 4 bytes a
    /// ray down; checked as a hit where the count is above 0.
    Counts,
    /// Every hit listed: the counts' sums (4 bytes a ray), then 16 bytes a hit, after a second
    /// round trip; checked as the counts.
    Lists,
}

/// Camera rays of `mesh`'s auto-framed view, `n` of them in image order (row by row).
pub fn camera_rays(mesh: &Mesh, n: usize) -> Vec<Ray> {
    let scene = gridtrace::scene::builtin::mesh_scene(mesh.clone(), false);
    let side = (n as f64).sqrt().ceil() as u32;
    let frame = scene.camera.frame(side, side);
    (0..n as u32).map(|i| frame.ray(i % side, i / side)).collect()
}

#[allow(clippy::too_many_arguments)]
pub fn ray_study(
    plan: &Plan,
    gpu: &Arc<GpuContext>,
    meshes: &[(String, Mesh)],
    variants: &[GpuVariants],
    budget: &Budget,
    skipped: &mut Vec<String>,
    mismatches: &mut Vec<String>,
    log: &mut dyn FnMut(&str),
) -> Result<Vec<RayRow>> {
    let mut rows = Vec::new();
    for (name, mesh) in meshes {
        for accel in frame_accels(gpu) {
            if !budget.allows(&format!("rays of {name} with {}", accel.name()), skipped) {
                continue;
            }
            // The CPU's rows and reference hits: the structure's own, or its stand-in's (`hwrt`
            // has no CPU walk: the BVH's).
            let mesh_for = |accel: AccelKind| {
                let opts = QueryOptions {
                    accel: accel.into(),
                    backend: Backend::Cpu,
                    ..Default::default()
                };
                TraceMesh::from_mesh(mesh.clone(), &opts)
            };
            let on_cpu = cpu_reference(accel);
            let tm = mesh_for(accel)?;
            let cpu_tm = if on_cpu == accel { None } else { Some(mesh_for(on_cpu)?) };
            let (o, d) = incoherent_rays(tm.prepared().accel.bounds(), plan.rays, 7);
            let incoherent: Vec<Ray> = o
                .iter()
                .zip(&d)
                .map(|(a, b)| Ray::new((*a).into(), (*b).into()))
                .collect();
            let mut renderers = variants_for(variants, accel)
                .map(|v| Ok((v.changes(), open_gpu(gpu, tm.prepared(), v)?)))
                .collect::<Result<Vec<(String, GpuRenderer)>>>()?;
            for (set, rays) in [("camera", camera_rays(mesh, plan.rays)), ("incoherent", incoherent)] {
                let head = |backend: &str, variant: &str| RowHead {
                    mesh: name,
                    triangles: tm.triangle_count(),
                    set,
                    accel,
                    backend: backend.to_string(),
                    variant: variant.to_string(),
                };
                let cpu = cpu_tm.as_ref().unwrap_or(&tm);
                let (cpu_times, cpu_hits) = timed(plan.reps, || cpu.intersect_rays(&rays))?;
                let row = RowHead {
                    accel: on_cpu,
                    ..head("cpu", "-")
                }
                .row(&rays, &cpu_times, &cpu_hits, 0.0);
                log(&row_line(&row));
                rows.push(row);
                // Every variant timed in rounds across them (`interleaved`), and the default's
                // lean answers beside them.
                let asks: Vec<(usize, Asked)> = (0..renderers.len())
                    .map(|k| (k, Asked::HitsUv))
                    .chain([
                        (0, Asked::Hits),
                        (0, Asked::Occlusion),
                        (0, Asked::Counts),
                        (0, Asked::Lists),
                    ])
                    .collect();
                let runs = interleaved(asks.len(), 0.0, plan.reps, |j| {
                    let (k, asked) = asks[j];
                    let r = &mut renderers[k].1;
                    let t0 = Instant::now();
                    let hits = ask(r, &rays, asked)?;
                    let ms = t0.elapsed().as_secs_f64() * 1e3;
                    Ok((ms, (hits, r.last_query_stats().clone())))
                })?;
                for ((times, mut outs), &(k, asked)) in runs.into_iter().zip(&asks) {
                    let variant = match asked {
                        Asked::HitsUv => renderers[k].0.clone(),
                        Asked::Hits => "answers=t,tri".to_string(),
                        Asked::Occlusion => "answers=occlusion".to_string(),
                        Asked::Counts => "answers=counts".to_string(),
                        Asked::Lists => "answers=lists".to_string(),
                    };
                    let variant = &variant;
                    let last = outs.last().expect("at least one timed run").1.clone();
                    let gpu_median_ms = Summary::median_of(outs.iter().filter_map(|o| o.1.gpu_ms()));
                    let host = host_medians(outs.iter().map(|o| o.1.timings.host));
                    let hits = outs.pop().expect("at least one timed run").0;
                    let differing = if matches!(asked, Asked::Occlusion | Asked::Counts | Asked::Lists) {
                        let n = hits
                            .iter()
                            .zip(&cpu_hits)
                            .filter(|(a, b)| a.is_hit() != b.is_hit())
                            .count();
                        n as f64 / hits.len().max(1) as f64
                    } else {
                        differing_hits(&hits, &cpu_hits)
                    };
                    if differing > MAX_DIFFERING_HITS {
                        mismatches.push(format!(
                            "rays {name} {set} {} {variant}: {:.3}% of hits differ from the CPU's",
                            accel.name(),
                            100.0 * differing
                        ));
                    }
                    let mut row = head("gpu", variant).row(&rays, &times, &hits, differing);
                    row.gpu_median_ms = gpu_median_ms;
                    row.host_ms = Some(host);
                    let per_ray = |b: u64| b as f64 / rays.len().max(1) as f64;
                    row.bytes_up_per_ray = Some(per_ray(last.uploaded_bytes));
                    row.bytes_down_per_ray = Some(per_ray(last.downloaded_bytes));
                    row.chunks = Some(last.chunks);
                    log(&row_line(&row));
                    rows.push(row);
                }
            }
        }
    }
    Ok(rows)
}

/// A GPU batch asking for `asked`, its answers as hits to check against the CPU's: without
/// u, v those are 0; occlusion answers as a hit at t = 0 or a miss (checked against the
/// CPU's hits: occluded where the CPU hits anything).
fn ask(r: &mut GpuRenderer, rays: &[Ray], asked: Asked) -> Result<Vec<Hit>> {
    let rays_of = gridtrace::gpu::RaySlice::new(rays);
    match asked {
        Asked::HitsUv => r.intersect(rays),
        Asked::Hits => r.intersect_of(&rays_of, (0.0, 1e30), false),
        Asked::Occlusion => Ok(r.occluded_of(&rays_of, (0.0, 1e30))?.into_iter().map(any_hit).collect()),
        Asked::Counts | Asked::Lists => {
            let answer = if asked == Asked::Counts {
                gridtrace::gpu::AllHits::Counts
            } else {
                gridtrace::gpu::AllHits::Lists
            };
            let mut hit = vec![false; rays.len()];
            r.all_hits(
                &rays_of,
                (0.0, f32::INFINITY),
                u32::MAX,
                &[0],
                answer,
                |first, counts, _| {
                    for (k, &c) in counts.iter().enumerate() {
                        hit[first + k] = c > 0;
                    }
                },
            )?;
            Ok(hit.into_iter().map(any_hit).collect())
        }
    }
}

/// A hit standing for "something is hit" (occlusion, a count above 0), or a miss.
fn any_hit(hit: bool) -> Hit {
    if hit {
        Hit {
            t: 0.0,
            tri: 0,
            u: 0.0,
            v: 0.0,
        }
    } else {
        Hit::MISS
    }
}

/// One warm-up, then `reps` timed runs of `f` (wall ms); the last run's hits.
fn timed(reps: u32, mut f: impl FnMut() -> Result<Vec<Hit>>) -> Result<(Vec<f64>, Vec<Hit>)> {
    let (times, mut outs) = repeat_warm(1, 0.0, reps, || {
        let t0 = Instant::now();
        let hits = f()?;
        Ok((t0.elapsed().as_secs_f64() * 1e3, hits))
    })?;
    Ok((times, outs.pop().expect("at least one timed run")))
}

/// Rays whose hits differ: one hits and the other misses, or the two t are more than 1e-4
/// (relative) apart. A different triangle at the same t (an edge) is the same hit.
fn differing_hits(a: &[Hit], b: &[Hit]) -> f64 {
    let n = a
        .iter()
        .zip(b)
        .filter(|(x, y)| match (x.is_hit(), y.is_hit()) {
            (false, false) => false,
            (true, true) => (x.t - y.t).abs() > 1e-4 * x.t.abs().max(1.0),
            _ => true,
        })
        .count();
    n as f64 / a.len().max(1) as f64
}

struct RowHead<'a> {
    mesh: &'a str,
    triangles: usize,
    set: &'static str,
    accel: AccelKind,
    backend: String,
    variant: String,
}

impl RowHead<'_> {
    fn row(self, rays: &[Ray], times: &[f64], hits: &[Hit], differing: f64) -> RayRow {
        let wall = Summary::of(times);
        RayRow {
            mesh: self.mesh.to_string(),
            triangles: self.triangles,
            set: self.set.into(),
            accel: self.accel.name().into(),
            backend: self.backend,
            variant: self.variant,
            rays: rays.len(),
            wall,
            mrays_per_s: rays.len() as f64 / (wall.median_ms * 1e3).max(1e-9),
            hit_fraction: hits.iter().filter(|h| h.is_hit()).count() as f64 / rays.len().max(1) as f64,
            gpu_median_ms: None,
            host_ms: None,
            differing_from_cpu: differing,
            bytes_up_per_ray: None,
            bytes_down_per_ray: None,
            chunks: None,
        }
    }
}

fn row_line(r: &RayRow) -> String {
    format!(
        "  rays {:<15} {:<10} {:<9} {:<3} {:<12} {} rays: {:.2} ms ({:.2} Mrays/s), {:.1}% hit{}",
        r.mesh,
        r.set,
        r.accel,
        r.backend,
        r.variant,
        r.rays,
        r.wall.median_ms,
        r.mrays_per_s,
        100.0 * r.hit_fraction,
        r.gpu_median_ms.map_or(String::new(), |ms| format!(", GPU {ms:.2} ms"))
    )
}
