//! The fast winding numbers' build and query times on the Stanford Dragon (871,414 triangles)
//! or the mesh given: points uniform in its bounding box grown by 10% a side, then the batch
//! (`winding_numbers_at`, all cores) at each accuracy, best of three, in nanoseconds a point,
//! through each of the two trees: the one a scene builds for winding numbers alone
//! (`FastWinding::build`, Morton order: the tree `compute_winding_number` walks when no ray
//! structure is built) and the ray BVH's collapsed (`FastWinding::from_bvh`, what a scene
//! that has built its BVH walks):
//! `cargo run --release -p gridtrace-bench --example winding_speed [-- POINTS [MESH]]`
//! (the Rust side of `crates/gridtrace-py/bench/winding_vs_libigl.py`; the mesh folder found
//! as `gridtrace bench` finds it).
use std::time::Instant;

use glam::Vec3;
use gridtrace::accel::winding::FastWinding;
use gridtrace::accel::{Aabb, TriAccel};
use gridtrace::util::Rng;

fn main() -> gridtrace::Result<()> {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(1_000_000);
    let path = match std::env::args().nth(2) {
        Some(p) => p.into(),
        None => gridtrace_bench::scenes::find_data_dir(None)
            .ok_or_else(|| gridtrace::Error::InvalidInput("no mesh folder (set GRIDTRACE_DATA_DIR)".into()))?
            .join("dragon/dragon_vrip_binary.ply"),
    };
    let mesh = gridtrace::io::load_mesh(&path)?;
    let tris = TriAccel::from_mesh(&mesh);
    let b = Aabb::from_points(&mesh.positions);
    let (lo, e) = (b.min - b.extent() * 0.1, b.extent() * 1.2);
    let mut rng = Rng::new(2018);
    let points: Vec<[f32; 3]> = (0..n)
        .map(|_| (lo + Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * e).to_array())
        .collect();
    println!(
        "{}: {} triangles, {n} points, {} threads",
        path.display(),
        tris.len(),
        rayon::current_num_threads()
    );
    let t0 = Instant::now();
    let bvh = gridtrace::accel::bvh::BvhAccel::build(&tris);
    let t_bvh = t0.elapsed().as_secs_f64();
    let t0 = Instant::now();
    let tree = FastWinding::from_bvh(&bvh.bvh, &tris);
    let t_moments = t0.elapsed().as_secs_f64();
    let t0 = Instant::now();
    let own = FastWinding::build(&tris);
    println!(
        "  build: {:.3} s on its own; the ray BVH {t_bvh:.3} s, then the moments and wide tree from it {t_moments:.3} s",
        t0.elapsed().as_secs_f64()
    );
    for (name, tree) in [("its own tree", &own), ("the ray BVH's tree", &tree)] {
        println!("  through {name}:");
        for accuracy in [1.0, 2.0, 4.0] {
            let best = (0..3)
                .map(|_| {
                    let t0 = Instant::now();
                    std::hint::black_box(tree.winding_numbers_at(&tris, &points, accuracy));
                    t0.elapsed().as_secs_f64()
                })
                .fold(f64::INFINITY, f64::min);
            println!(
                "    accuracy {accuracy}: {best:.3} s, {:.0} ns a point",
                best * 1e9 / n as f64
            );
        }
    }
    Ok(())
}
