//! Camera rays at a few translated instances of one mesh, two levels against the same
//! triangles merged flat, on the CPU (issue 52: the BVH's 8-ray packets for rays carried into
//! an instance). K instances of the mesh, translated only, on a 5-wide grid 1.2 mesh diagonals
//! apart; a W x H pinhole camera (45 degrees vertical field of view) DIST diagonals in front
//! of the instances' middle, its rays Open3D's (`create_rays_pinhole_fov`: not normalised, row-major).
//! The two scenes alternate, ROUNDS rounds; prints each side's median and range, and how many
//! answers differ. `GRIDTRACE_BVH_PACKETS=0` walks every ray singly (the flat mesh's camera
//! rays too); `GRIDTRACE_BVH_PACKETS=all` lets the rays carried into the instances take the
//! 8-ray packets as well (`BvhAccel::traced`: they walk singly otherwise).
//!
//! `cargo run --release -p gridtrace --example carried_packets -- MESH [K] [W] [H] [ROUNDS]
//! [DIST]` (defaults 10 instances, 320 x 240, 21 rounds, 8 diagonals).
use std::time::Instant;

use glam::{Mat4, Vec3};
use gridtrace::{AccelSpec, Backend, QueryScene};

fn main() -> gridtrace::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = args
        .get(1)
        .expect("usage: carried_packets MESH [K] [W] [H] [ROUNDS] [DIST]");
    let arg = |i: usize, d: usize| args.get(i).map_or(d, |s| s.parse().expect("a count"));
    let (k, w, h, rounds) = (arg(2, 10), arg(3, 320), arg(4, 240), arg(5, 21));
    let dist: f32 = args.get(6).map_or(8.0, |s| s.parse().expect("a distance"));
    let mesh = gridtrace::io::load_mesh(std::path::Path::new(path))?;
    let verts: Vec<[f32; 3]> = mesh.positions.iter().map(|p| p.to_array()).collect();
    let (lo, hi) = mesh.bounds();
    let size = (hi - lo).length();
    let centre = (lo + hi) * 0.5;
    let transforms: Vec<Mat4> = (0..k)
        .map(|i| {
            let (col, row) = ((i % 5) as f32 - 2.0, (i / 5) as f32 - 0.5);
            Mat4::from_translation(Vec3::new(col, row, 0.0) * 1.2 * size)
        })
        .collect();
    let opts = gridtrace::query::QueryOptions {
        accel: "bvh".parse::<AccelSpec>().expect("bvh"),
        backend: Backend::Cpu,
        ..Default::default()
    };
    let mut inst = QueryScene::new(opts.clone());
    let first = inst.add_placed(verts.clone(), mesh.triangles.clone(), &transforms)?[0];
    // A moved scene walks the two levels even with one instance (a static one of a single
    // geometry would be traced as the merged mesh).
    inst.set_transform(first, transforms[0])?;
    let mut flat = QueryScene::new(opts);
    let (mut wv, mut wf) = (Vec::new(), Vec::new());
    for t in &transforms {
        let base = wv.len() as u32;
        wv.extend(mesh.positions.iter().map(|p| t.transform_point3(*p).to_array()));
        wf.extend(mesh.triangles.iter().map(|f| f.map(|i| i + base)));
    }
    flat.add_triangles(wv, wf, None)?;
    // The camera looks at the middle of the instances' centres.
    let target = centre + transforms.iter().map(|t| t.w_axis.truncate()).sum::<Vec3>() / k as f32;
    let eye = target + Vec3::Z * dist * size;
    let rays = gridtrace::sensor::create_rays_pinhole_fov(
        45.0,
        target.as_dvec3().to_array(),
        eye.as_dvec3().to_array(),
        [0.0, 1.0, 0.0],
        w as u32,
        h as u32,
    )?;
    let (mut ti, mut tf) = (Vec::new(), Vec::new());
    let (mut hi_, mut hf) = (None, None);
    for round in 0..=rounds {
        let t0 = Instant::now();
        hi_ = Some(inst.cast_rays(&rays)?);
        let t1 = Instant::now();
        hf = Some(flat.cast_rays(&rays)?);
        let t2 = Instant::now();
        if round > 0 {
            // The first round builds.
            ti.push((t1 - t0).as_secs_f64() * 1e3);
            tf.push((t2 - t1).as_secs_f64() * 1e3);
        }
    }
    let stats = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        (v[v.len() / 2], v[0], v[v.len() - 1])
    };
    let ((mi, li, hi_i), (mf, lf, hi_f)) = (stats(&mut ti), stats(&mut tf));
    let (a, b) = (hi_.expect("a round"), hf.expect("a round"));
    let differ = a
        .t_hit
        .iter()
        .zip(&b.t_hit)
        .filter(|(x, y)| x != y && (*x - *y).abs() > 1e-5 * x.abs().max(y.abs()))
        .count();
    let hits = a.t_hit.iter().filter(|t| t.is_finite()).count();
    println!(
        "{k} translated instances, {w}x{h} camera rays {dist} diagonals away ({hits} hit): two levels {mi:.2} ms ({li:.2}-{hi_i:.2}), flat {mf:.2} ms ({lf:.2}-{hi_f:.2}): {:.2}x (medians of {rounds}); {differ} t differ beyond 1e-5",
        mi / mf
    );
    Ok(())
}
