//! The fast winding numbers' error against the exact sum, per `accuracy` (libigl's beta), on
//! the shared meshes: points uniform in each mesh's bounding box grown by 10% a side, the
//! winding number of each through `FastWinding::winding_numbers_at` and through every
//! triangle (`winding_number_brute`, in f64), the largest and the mean absolute difference,
//! and how many points change side (the 0.5 that decides inside), with the time of the fast
//! batch (all cores, tree built once):
//! `cargo run --release -p gridtrace-bench --example winding_accuracy [-- POINTS]`
//! (the mesh folder found as `gridtrace bench` finds it: `GRIDTRACE_DATA_DIR`, else
//! `shared/data/meshes` beside the checkout).
use std::time::Instant;

use glam::Vec3;
use gridtrace::accel::winding::{FastWinding, is_inside, winding_number_brute};
use gridtrace::accel::{Aabb, TriAccel};
use gridtrace::util::Rng;
use rayon::prelude::*;

fn main() -> gridtrace::Result<()> {
    let n: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(2000);
    let data = gridtrace_bench::scenes::find_data_dir(None)
        .ok_or_else(|| gridtrace::Error::InvalidInput("no mesh folder (set GRIDTRACE_DATA_DIR)".into()))?;
    for file in [
        "bunny/bun_zipper.ply",
        "dragon/dragon_vrip_res2_binary.ply",
        "dragon/dragon_vrip_binary.ply",
    ] {
        let path = data.join(file);
        if !path.exists() {
            println!("{file}: not present");
            continue;
        }
        let mesh = gridtrace::io::load_mesh(&path)?;
        let tris = TriAccel::from_mesh(&mesh);
        let b = Aabb::from_points(&mesh.positions);
        let (lo, e) = (b.min - b.extent() * 0.1, b.extent() * 1.2);
        let mut rng = Rng::new(55);
        let points: Vec<[f32; 3]> = (0..n)
            .map(|_| (lo + Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * e).to_array())
            .collect();
        let exact: Vec<f32> = points
            .par_iter()
            .map(|p| winding_number_brute(&tris, Vec3::from(*p)))
            .collect();
        let tree = FastWinding::build(&tris);
        println!("{file}: {} triangles, {n} points", tris.len());
        for accuracy in [1.0, 2.0, 3.0, 4.0, 8.0, f64::INFINITY] {
            let t0 = Instant::now();
            let fast = tree.winding_numbers_at(&tris, &points, accuracy);
            let secs = t0.elapsed().as_secs_f64();
            let diffs: Vec<f64> = fast.iter().zip(&exact).map(|(f, x)| (f - x).abs() as f64).collect();
            let worst = diffs.iter().cloned().fold(0.0, f64::max);
            let mean = diffs.iter().sum::<f64>() / n as f64;
            let flipped = fast
                .iter()
                .zip(&exact)
                .filter(|(f, x)| is_inside(**f) != is_inside(**x))
                .count();
            println!(
                "  accuracy {accuracy:>4}: max |error| {worst:.2e}, mean {mean:.2e}, {flipped} points on the other side; {:.1} us a point",
                secs * 1e6 / n as f64
            );
        }
    }
    Ok(())
}
