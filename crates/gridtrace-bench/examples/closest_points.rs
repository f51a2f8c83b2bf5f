//! Nearest points on the Stanford Bunny (or MESH), per structure: a million random points in
//! its bounding box through `closest::closest_points` (all cores), one run each, Mpts/s,
//! after a check of the first 200 answers against brute force:
//! `cargo run --release -p gridtrace-bench --example closest_points [-- POINTS [KINDS [MESH]]]`
//! (KINDS: a comma-separated subset of `grid,bvh,irregular`)
//! (the mesh folder found as `gridtrace bench` finds it: `GRIDTRACE_DATA_DIR`, else
//! `shared/data/meshes` beside the checkout). Then signed distances (nearest points on the BVH,
//! fast winding numbers for the sign) of the first 100,000 points.
use gridtrace::AccelParams;
use std::time::Instant;

use glam::Vec3;
use gridtrace::accel::closest::{closest_point_brute, closest_points};
use gridtrace::accel::winding::signed_distances;
use gridtrace::accel::{Aabb, Accel, AccelKind, TriAccel};
use gridtrace::util::Rng;

fn main() -> gridtrace::Result<()> {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(1_000_000);
    let kinds: Vec<AccelKind> = match std::env::args().nth(2) {
        Some(list) => list
            .split(',')
            .map(|k| k.parse())
            .collect::<std::result::Result<_, _>>()
            .map_err(gridtrace::Error::InvalidInput)?,
        None => vec![AccelKind::Grid, AccelKind::Bvh, AccelKind::Irregular],
    };
    let data = gridtrace_bench::scenes::find_data_dir(None)
        .ok_or_else(|| gridtrace::Error::InvalidInput("no mesh folder (set GRIDTRACE_DATA_DIR)".into()))?;
    let path = std::env::args()
        .nth(3)
        .map_or_else(|| data.join("bunny/bun_zipper.ply"), std::path::PathBuf::from);
    let mesh = gridtrace::io::load_mesh(&path)?;
    let tris = TriAccel::from_mesh(&mesh);
    let bounds = Aabb::from_points(&mesh.positions);
    let mut rng = Rng::new(2026);
    let points: Vec<[f32; 3]> = (0..n)
        .map(|_| {
            let t = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
            (bounds.min + t * bounds.extent()).to_array()
        })
        .collect();
    println!(
        "{}: {} triangles, {n} random points in its bounding box, {} threads",
        path.display(),
        tris.len(),
        rayon::current_num_threads()
    );
    let check = &points[..n.min(200)];
    for kind in kinds {
        let t0 = Instant::now();
        let accel = Accel::build(tris.clone(), kind, &AccelParams::NONE)?;
        let build_ms = t0.elapsed().as_secs_f64() * 1e3;
        for (p, c) in check.iter().zip(closest_points(&accel, check)?) {
            let truth = closest_point_brute(&tris, Vec3::from(*p));
            assert_eq!((c.tri, c.dist_sq), (truth.tri, truth.dist_sq), "{kind:?} at {p:?}");
        }
        let t0 = Instant::now();
        let out = closest_points(&accel, &points)?;
        let s = t0.elapsed().as_secs_f64();
        let mean = out.iter().map(|c| c.distance() as f64).sum::<f64>() / n as f64;
        println!(
            "{:<10} build {build_ms:7.1} ms  query {:8.1} ms  {:6.2} Mpts/s  (mean distance {mean:.5})",
            accel.structure_name(),
            s * 1e3,
            n as f64 / s / 1e6
        );
    }
    let accel = Accel::build(tris, AccelKind::Bvh, &AccelParams::NONE)?;
    let few = &points[..n.min(100_000)];
    let t0 = Instant::now();
    signed_distances(&accel, few)?;
    let s = t0.elapsed().as_secs_f64();
    println!(
        "signed distance (bvh, fast winding numbers): {} points in {:.1} ms, {:.3} Mpts/s",
        few.len(),
        s * 1e3,
        few.len() as f64 / s / 1e6
    );
    Ok(())
}
