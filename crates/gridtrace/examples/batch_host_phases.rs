//! Times warm GPU ray batches on a mesh and splits their wall time into the host's phases
//! (prepare: the rays written for the device; wait; readout: the answers converted), medians
//! of REPS batches after one to warm up, for each answer form (hits with u, v; (t, triangle);
//! occlusion bits), with the bytes each way per ray:
//! `cargo run --release -p gridtrace --example batch_host_phases -- MESH [RAYS] [REPS]`
//! (rays from a sphere round the mesh towards its centre, with the BVH).
use glam::Vec3;
use gridtrace::AccelParams;
use gridtrace::accel::{AccelKind, Ray};
use gridtrace::gpu::{Answer, GpuContext, GpuRenderer, RaySlice};
use gridtrace::scene::builtin::mesh_scene;

fn main() -> gridtrace::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("usage: batch_host_phases MESH [RAYS] [REPS]");
    let n: usize = args.get(2).map_or(1_000_000, |r| r.parse().expect("RAYS is a count"));
    let reps: usize = args.get(3).map_or(7, |r| r.parse().expect("REPS is a count"));
    let mesh = gridtrace::io::load_mesh(std::path::Path::new(path))?;
    let scene = mesh_scene(mesh, false).prepare_for(AccelKind::Bvh, &AccelParams::NONE)?;
    let ctx = std::sync::Arc::new(GpuContext::new()?);
    println!("adapter {}", ctx.describe());
    let mut gpu = GpuRenderer::new(ctx, &scene, &gridtrace::gpu::GpuVariants::default())?;
    let b = scene.accel.bounds();
    let (centre, radius) = (b.center(), b.extent().length());
    // A deterministic spread of origins on a sphere (a golden-angle spiral), each aimed at
    // the centre: every ray is different, most of them hit.
    let rays: Vec<Ray> = (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let phi = i as f32 * 2.399_963;
            let r = (1.0 - z * z).sqrt();
            let origin = centre + radius * Vec3::new(r * phi.cos(), r * phi.sin(), z);
            Ray::new(origin, centre - origin)
        })
        .collect();
    for (name, answer) in [
        ("hits+uv", Answer::Hits { uv: true }),
        ("hits", Answer::Hits { uv: false }),
        ("occlusion", Answer::Occlusion),
    ] {
        let mut runs = Vec::new();
        for rep in 0..=reps {
            let mut answered = 0usize;
            let t_max = if answer == Answer::Occlusion {
                1.0
            } else {
                f32::INFINITY
            };
            gpu.cast(&RaySlice::new(&rays), (0.0, t_max), answer, |_, a| {
                answered += std::hint::black_box(match a {
                    gridtrace::gpu::ChunkAnswers::Hits(h) => h.len(),
                    gridtrace::gpu::ChunkAnswers::HitsUv(h) => h.len(),
                    gridtrace::gpu::ChunkAnswers::Occlusion(b) => b.len(),
                    gridtrace::gpu::ChunkAnswers::Range(t) => t.len(),
                    gridtrace::gpu::ChunkAnswers::Points { hits, .. } => hits.len(),
                    gridtrace::gpu::ChunkAnswers::Winding(w) => w.len(),
                })
            })?;
            let s = gpu.last_query_stats().clone();
            if rep > 0 {
                runs.push(s);
            }
        }
        let median = |f: &dyn Fn(&gridtrace::gpu::GpuQueryStats) -> f64| {
            let mut v: Vec<f64> = runs.iter().map(f).collect();
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let last = runs.last().expect("REPS > 0");
        println!(
            "{name}: {n} rays, {reps} warm batches, {} chunks, {:.2} B up and {:.2} B down a ray; medians: wall {:.2} ms; host prepare {:.2}, wait {:.2}, readout {:.2} ms",
            last.chunks,
            last.uploaded_bytes as f64 / n as f64,
            last.downloaded_bytes as f64 / n as f64,
            median(&|s| s.wall_ms),
            median(&|s| s.timings.host.prepare_ms),
            median(&|s| s.timings.host.wait_ms),
            median(&|s| s.timings.host.readout_ms)
        );
    }
    Ok(())
}
