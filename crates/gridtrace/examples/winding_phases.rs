//! The fast winding numbers' phases on the CPU, for profiling: the Morton tree's build and the
//! query of N points uniform in the mesh's box grown by a tenth a side (as
//! `bench/winding_vs_libigl.py`), each ROUNDS times; prints each round's seconds and the
//! error against the exact sum on the first 500 points.
//!
//! `cargo run --release -p gridtrace --example winding_phases -- MESH [N] [ROUNDS] [ACCURACY] [CHECKED]`
//! (CHECKED: the points held to the exact sum, default 500; 0 for profiling)
use std::time::Instant;

use glam::Vec3;
use gridtrace::accel::TriAccel;
use gridtrace::accel::winding::{FastWinding, winding_number_brute};

fn main() -> gridtrace::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("usage: winding_phases MESH [N] [ROUNDS] [ACCURACY]");
    let n: usize = args.get(2).map_or(1_000_000, |s| s.parse().expect("a count"));
    let rounds: usize = args.get(3).map_or(3, |s| s.parse().expect("a count"));
    let accuracy: f64 = args.get(4).map_or(2.0, |s| s.parse().expect("a number"));
    let mesh = gridtrace::io::load_mesh(std::path::Path::new(path))?;
    let tris: Vec<TriAccel> = mesh
        .triangles
        .iter()
        .map(|t| {
            TriAccel::new(
                mesh.positions[t[0] as usize],
                mesh.positions[t[1] as usize],
                mesh.positions[t[2] as usize],
            )
        })
        .collect();
    // The examples' one stream (`util::Xorshift`): the same points on every build.
    let points = gridtrace::util::Xorshift::default().points_around(mesh.bounds(), 0.1, n);
    let mut tree = None;
    for _ in 0..rounds {
        let t0 = Instant::now();
        tree = Some(FastWinding::build(&tris));
        println!("build {:.3} s", t0.elapsed().as_secs_f64());
    }
    let tree = tree.expect("one round");
    let mut answers = Vec::new();
    for _ in 0..rounds {
        let t0 = Instant::now();
        answers = tree.winding_numbers_at(&tris, &points, accuracy);
        println!("query {:.3} s ({} points)", t0.elapsed().as_secs_f64(), n);
    }
    let check: usize = args.get(5).map_or(500, |s| s.parse().expect("a count"));
    let check = n.min(check);
    let (mut worst, mut mean) = (0.0f32, 0.0f32);
    for (p, w) in points[..check].iter().zip(&answers) {
        let e = (winding_number_brute(&tris, Vec3::from(*p)) - w).abs();
        worst = worst.max(e);
        mean += e / check.max(1) as f32;
    }
    println!("error on {check} points: max {worst:.3e}, mean {mean:.3e}");
    Ok(())
}
