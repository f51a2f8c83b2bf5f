//! Nearest points and signed distances on the CPU, for profiling and A/B runs: a scene of one
//! mesh (`accel="bvh"` unless ACCEL is given), N points uniform in its box grown by a tenth a
//! side (as `bench/queries_vs_peers.py`), ROUNDS rounds of `compute_distance` and of
//! `compute_signed_distance` after a first call that builds the structures.
//!
//! `cargo run --release -p gridtrace --example closest_phases -- MESH [N] [ROUNDS] [ACCEL]`
use std::time::Instant;

use gridtrace::query::{Backend, QueryOptions};
use gridtrace::{AccelSpec, QueryScene};

fn main() -> gridtrace::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("usage: closest_phases MESH [N] [ROUNDS] [ACCEL]");
    let n: usize = args.get(2).map_or(200_000, |s| s.parse().expect("a count"));
    let rounds: usize = args.get(3).map_or(3, |s| s.parse().expect("a count"));
    let accel: AccelSpec = args
        .get(4)
        .map_or("bvh", |s| s.as_str())
        .parse()
        .map_err(gridtrace::Error::InvalidInput)?;
    let mesh = gridtrace::io::load_mesh(std::path::Path::new(path))?;
    // The examples' one stream (`util::Xorshift`): the same points on every build.
    let points = gridtrace::util::Xorshift::default().points_around(mesh.bounds(), 0.1, n);
    let mut scene = QueryScene::new(QueryOptions {
        accel,
        backend: Backend::Cpu,
        ..Default::default()
    });
    let verts: Vec<[f32; 3]> = mesh.positions.iter().map(|p| p.to_array()).collect();
    scene.add_triangles(verts, mesh.triangles.clone(), None)?;
    scene.compute_signed_distance(&points[..1])?;
    let mut sum = 0.0f64;
    for _ in 0..rounds {
        let t0 = Instant::now();
        let d = scene.compute_distance(&points)?;
        let t1 = t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        let s = scene.compute_signed_distance(&points)?;
        let t2 = t0.elapsed().as_secs_f64();
        sum += d.iter().chain(&s).map(|&x| f64::from(x)).sum::<f64>();
        println!("distance {t1:.3} s, signed {t2:.3} s ({n} points)");
    }
    println!("checksum {sum:.6e}");
    Ok(())
}
