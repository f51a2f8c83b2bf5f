//! Point queries after each move, on the CPU: K instances of one mesh (random rotations,
//! uniform scales 0.5-1.5, translations in a cube of six mesh diagonals, as
//! `instances_vs_flat`), each step every instance turned and moved a little (a similarity),
//! then distances (and signed distances) at N random points of the scene's box.
//!
//! Two ways, alternating, STEPS steps each:
//! - **two levels**: `set_transforms` then `compute_distance` on the instanced scene (no mesh
//!   structure built: `two_level_points.rs`);
//! - **merged rebuild**: what the point queries did before, a world-space mesh of every
//!   instance's triangles built after the move (here a fresh one-geometry scene of the moved
//!   world triangles, as `Merged::build` makes it) and asked.
//!
//! Also the queries alone (the merged mesh and its winding tree built beforehand), and how many
//! distances differ by more than 1e-5 relative plus 8 ulps of the scene's coordinates (the
//! merged mesh's vertices are rounded once more than the instances'). Prints medians in ms.
//!
//! `cargo run --release -p gridtrace --example points_after_move -- MESH [K] [N] [STEPS]`
//! (defaults 100 instances, 10,000 points, 5 steps).
use std::time::Instant;

use glam::{Mat4, Quat, Vec3};
use gridtrace::{AccelSpec, Backend, QueryScene};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> gridtrace::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("usage: points_after_move MESH [K] [N] [STEPS]");
    let arg = |i: usize, d: usize| args.get(i).map_or(d, |s| s.parse().expect("a count"));
    let (k, n, steps) = (arg(2, 100), arg(3, 10_000), arg(4, 5));
    let mesh = gridtrace::io::load_mesh(std::path::Path::new(path))?;
    let verts: Vec<[f32; 3]> = mesh.positions.iter().map(|p| p.to_array()).collect();
    let (lo, hi) = mesh.bounds();
    let size = (hi - lo).length();
    // The examples' one stream (`util::Xorshift`): the same draws on every build.
    let mut rng = gridtrace::util::Xorshift::default();
    let mut transforms: Vec<Mat4> = (0..k).map(|_| rng.similarity(6.0 * size)).collect();
    let mut unit = move || rng.unit();
    let opts = gridtrace::query::QueryOptions {
        accel: "bvh".parse::<AccelSpec>().expect("bvh"),
        backend: Backend::Cpu,
        ..Default::default()
    };
    let mut inst = QueryScene::new(opts.clone());
    let ids = inst.add_placed(verts.clone(), mesh.triangles.clone(), &transforms)?;
    let merged = |transforms: &[Mat4]| -> gridtrace::Result<QueryScene> {
        let mut flat = QueryScene::new(opts.clone());
        let (mut wv, mut wf) = (Vec::new(), Vec::new());
        for t in transforms {
            let base = wv.len() as u32;
            wv.extend(mesh.positions.iter().map(|p| t.transform_point3(*p).to_array()));
            wf.extend(mesh.triangles.iter().map(|f| f.map(|i| i + base)));
        }
        flat.add_triangles(wv, wf, None)?;
        Ok(flat)
    };
    let c = Vec3::ZERO;
    let half = 3.0 * size + 0.75 * size;
    let points: Vec<[f32; 3]> = (0..n)
        .map(|_| (c + (Vec3::new(unit(), unit(), unit()) - 0.5) * (2.0 * half)).to_array())
        .collect();
    // The first query builds the mesh's structure (once).
    inst.compute_distance(&points[..1])?;
    let builds = inst.structure_builds();
    let (mut two, mut rebuilt, mut two_q, mut merged_q) = (vec![], vec![], vec![], vec![]);
    let (mut two_sd, mut merged_sd) = (vec![], vec![]);
    let (mut differ, mut worst) = (0, 0f32);
    for _ in 0..steps {
        let turn = Quat::from_axis_angle(Vec3::new(unit(), unit(), unit() + 0.1).normalize(), 0.05);
        let shift = (Vec3::new(unit(), unit(), unit()) - 0.5) * (0.05 * size);
        for t in transforms.iter_mut() {
            *t = Mat4::from_translation(shift) * *t * Mat4::from_quat(turn);
        }
        let t0 = Instant::now();
        inst.set_transforms(&ids, &transforms)?;
        let d_two = inst.compute_distance(&points)?;
        two.push(t0.elapsed().as_secs_f64() * 1e3);
        let t0 = Instant::now();
        let flat = merged(&transforms)?;
        let d_merged = flat.compute_distance(&points)?;
        rebuilt.push(t0.elapsed().as_secs_f64() * 1e3);
        // The two answers' points are the same point rounded apart (the merged mesh's
        // vertices are rounded once more): by a few ulps of the scene's coordinates.
        let ulps = 8.0 * f32::EPSILON * half;
        for (a, b) in d_two.iter().zip(&d_merged) {
            worst = worst.max((a - b).abs());
            differ += usize::from((a - b).abs() > 1e-5 * a.abs().max(b.abs()) + ulps);
        }
        // The queries alone, both structures built.
        let t0 = Instant::now();
        inst.compute_distance(&points)?;
        two_q.push(t0.elapsed().as_secs_f64() * 1e3);
        let t0 = Instant::now();
        flat.compute_distance(&points)?;
        merged_q.push(t0.elapsed().as_secs_f64() * 1e3);
        let t0 = Instant::now();
        inst.compute_signed_distance(&points)?;
        two_sd.push(t0.elapsed().as_secs_f64() * 1e3);
        flat.compute_signed_distance(&points[..1])?; // its winding tree built first
        let t0 = Instant::now();
        flat.compute_signed_distance(&points)?;
        merged_sd.push(t0.elapsed().as_secs_f64() * 1e3);
    }
    assert_eq!(inst.structure_builds(), builds, "a move built a mesh structure");
    println!(
        "{k} instances of {} triangles, {n} points, {steps} steps ({}):",
        mesh.triangles.len(),
        gridtrace::backend::describe_cpu()
    );
    let (a, b) = (median(two), median(rebuilt));
    println!(
        "  move + distances: two levels {a:.1} ms, merged rebuild {b:.1} ms ({:.1}x)",
        b / a
    );
    let (a, b) = (median(two_q), median(merged_q));
    println!(
        "  distances alone:  two levels {a:.1} ms, merged {b:.1} ms ({:.2}x)",
        a / b
    );
    let (a, b) = (median(two_sd), median(merged_sd));
    println!(
        "  signed distances alone: two levels {a:.1} ms, merged {b:.1} ms ({:.2}x)",
        a / b
    );
    println!(
        "  distances apart by more than 1e-5 relative and 8 ulps of the scene ({:.1e}): {differ} of {} (largest gap {worst:.1e})",
        8.0 * f32::EPSILON * half,
        n * steps
    );
    Ok(())
}
