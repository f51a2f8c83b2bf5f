//! The two levels' closest hits against the same triangles merged flat, on the CPU: K
//! instances of one mesh (random rotations, uniform scales 0.5-1.5, translations in a cube of
//! six mesh diagonals, as `bench/instances.py`), and random rays (origins on a sphere around
//! the scene, aimed at uniform points of its box). The two scenes alternate, ROUNDS rounds;
//! prints each side's median and the ratio, and how many answers differ.
//!
//! `cargo run --release -p gridtrace --example instances_vs_flat -- MESH [K] [RAYS] [ROUNDS]`
//! (defaults 100 instances, 1,000,000 rays, 5 rounds).
use std::time::Instant;

use glam::{Mat4, Vec3};
use gridtrace::{AccelSpec, Backend, QueryScene};

fn main() -> gridtrace::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("usage: instances_vs_flat MESH [K] [RAYS] [ROUNDS]");
    let arg = |i: usize, d: usize| args.get(i).map_or(d, |s| s.parse().expect("a count"));
    let (k, n, rounds) = (arg(2, 100), arg(3, 1_000_000), arg(4, 5));
    let mesh = gridtrace::io::load_mesh(std::path::Path::new(path))?;
    let verts: Vec<[f32; 3]> = mesh.positions.iter().map(|p| p.to_array()).collect();
    let (lo, hi) = mesh.bounds();
    let size = (hi - lo).length();
    // The examples' one stream (`util::Xorshift`): the same draws on every build.
    let mut rng = gridtrace::util::Xorshift::default();
    let transforms: Vec<Mat4> = (0..k).map(|_| rng.similarity(6.0 * size)).collect();
    let mut unit = move || rng.unit();
    let opts = gridtrace::query::QueryOptions {
        accel: "bvh".parse::<AccelSpec>().expect("bvh"),
        backend: Backend::Cpu,
        ..Default::default()
    };
    let mut inst = QueryScene::new(opts.clone());
    inst.add_placed(verts.clone(), mesh.triangles.clone(), &transforms)?;
    // What an instance costs: 1,000 instances' scene less one instance's, per instance.
    let held = |k: usize| -> gridtrace::Result<usize> {
        let mut s = QueryScene::new(opts.clone());
        let placed: Vec<Mat4> = transforms.iter().cycle().take(k).copied().collect();
        let first = s.add_placed(verts.clone(), mesh.triangles.clone(), &placed)?[0];
        s.set_transform(first, transforms[0])?;
        s.cast_rays(&[[0.0, 0.0, 0.0, 0.0, 0.0, 1.0]])?;
        Ok(s.memory_bytes())
    };
    let (one, many) = (held(1)?, held(1000)?);
    println!(
        "memory: {:.0} bytes an instance more (1,000 instances)",
        (many - one) as f64 / 999.0
    );
    let mut flat = QueryScene::new(opts.clone());
    let (mut wv, mut wf) = (Vec::new(), Vec::new());
    for t in &transforms {
        let base = wv.len() as u32;
        wv.extend(mesh.positions.iter().map(|p| t.transform_point3(*p).to_array()));
        wf.extend(mesh.triangles.iter().map(|f| f.map(|i| i + base)));
    }
    let (wlo, whi) = wv.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(l, h), p| {
        (l.min(Vec3::from(*p)), h.max(Vec3::from(*p)))
    });
    flat.add_triangles(wv, wf, None)?;
    let (c, r) = ((wlo + whi) * 0.5, (whi - wlo).length());
    let rays: Vec<[f32; 6]> = (0..n)
        .map(|_| {
            let u = loop {
                let v = Vec3::new(unit(), unit(), unit()) * 2.0 - Vec3::ONE;
                if v.length_squared() > 1e-4 && v.length_squared() <= 1.0 {
                    break v.normalize();
                }
            };
            let o = c + u * r;
            let d = wlo + (whi - wlo) * Vec3::new(unit(), unit(), unit()) - o;
            [o.x, o.y, o.z, d.x, d.y, d.z]
        })
        .collect();
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
            ti.push((t1 - t0).as_secs_f64());
            tf.push((t2 - t1).as_secs_f64());
        }
    }
    let med = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (mi, mf) = (med(&mut ti), med(&mut tf));
    let (a, b) = (hi_.expect("a round"), hf.expect("a round"));
    let differ = a
        .t_hit
        .iter()
        .zip(&b.t_hit)
        .filter(|(x, y)| x != y && (*x - *y).abs() > 1e-5 * x.abs().max(y.abs()))
        .count();
    let hits = a.t_hit.iter().filter(|t| t.is_finite()).count();
    println!(
        "{k} instances, {n} random rays ({hits} hit): two levels {:.1} ms, flat {:.1} ms: {:.2}x (medians of {rounds}); {differ} t differ beyond 1e-5",
        mi * 1e3,
        mf * 1e3,
        mi / mf
    );
    Ok(())
}
