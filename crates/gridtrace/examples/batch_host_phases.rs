//! Times warm GPU ray batches on a mesh and splits their wall time into the host's phases
//! (prepare: the rays' records written for the device; wait; readout: the hits converted),
//! medians of REPS batches after one to warm up:
//! `cargo run --release -p gridtrace --example batch_host_phases -- MESH [RAYS] [REPS]`
//! (rays from a sphere round the mesh towards its centre, closest hits with the BVH).
use glam::Vec3;
use gridtrace::accel::{AccelKind, Ray, Resolution};
use gridtrace::gpu::{GpuContext, GpuRenderer};
use gridtrace::scene::builtin::mesh_scene;

fn main() -> gridtrace::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("usage: batch_host_phases MESH [RAYS] [REPS]");
    let n: usize = args.get(2).map_or(1_000_000, |r| r.parse().expect("RAYS is a count"));
    let reps: usize = args.get(3).map_or(7, |r| r.parse().expect("REPS is a count"));
    let mesh = gridtrace::io::load_mesh(std::path::Path::new(path))?;
    let scene = mesh_scene(mesh, false).prepare_for(AccelKind::Bvh, Resolution::default())?;
    let ctx = std::sync::Arc::new(GpuContext::new()?);
    println!("adapter {}", ctx.describe());
    let mut gpu = GpuRenderer::new(ctx, &scene)?;
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
    gpu.intersect(&rays, 0.0, f32::INFINITY, AccelKind::Bvh)?;
    let mut runs = Vec::new();
    for _ in 0..reps {
        let hits = gpu.intersect(&rays, 0.0, f32::INFINITY, AccelKind::Bvh)?;
        std::hint::black_box(hits);
        let s = gpu.last_query_stats();
        runs.push((s.wall_ms, s.timings.host));
    }
    let median = |f: &dyn Fn(&(f64, gridtrace::gpu::HostPhases)) -> f64| {
        let mut v: Vec<f64> = runs.iter().map(f).collect();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    println!(
        "{n} rays, {reps} warm batches, medians: wall {:.2} ms; host prepare {:.2}, wait {:.2}, readout {:.2} ms",
        median(&|r| r.0),
        median(&|r| r.1.prepare_ms),
        median(&|r| r.1.wait_ms),
        median(&|r| r.1.readout_ms)
    );
    Ok(())
}
