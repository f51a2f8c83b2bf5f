//! How often a closest hit names a triangle its hit point lies outside of: for random rays
//! through a mesh's box (origins on a sphere of 2.5 box diagonals around it, aimed at points
//! in the box), the CPU BVH's closest hit, its point `origin + t dir` in `f64` from the reported
//! `t`, projected onto the reported triangle's plane, and the smallest of its barycentric
//! coordinates there. Prints the fraction of hits more than 1e-4 (and 1e-6, 1e-3) outside.
//! `cargo run -p gridtrace --example hit_accuracy -- MESH [RAYS]` (default 1,000,000 rays).
use glam::{DVec3, Vec3};
use gridtrace::accel::{BvhAccel, NoCounters, Ray, TriAccel};

fn main() -> gridtrace::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("usage: hit_accuracy MESH [RAYS]");
    let n: usize = args.get(2).map_or(1_000_000, |s| s.parse().expect("a ray count"));
    let mesh = gridtrace::io::load_mesh(std::path::Path::new(path))?;
    // The triangles a scene traces (zero-area ones dropped: they are never hit).
    let tris = TriAccel::from_mesh(&mesh);
    let accel = BvhAccel::build(&tris);
    let (lo, hi) = mesh.bounds();
    let (centre, diag) = ((lo + hi) * 0.5, (hi - lo).length());
    // The examples' one stream (`util::Xorshift`): the same draws on every build.
    let mut rng = gridtrace::util::Xorshift::default();
    let mut unit = move || rng.unit();
    let (mut hits, mut outside) = (0u64, [0u64; 3]);
    let limits = [1e-6, 1e-4, 1e-3];
    for _ in 0..n {
        let on_sphere = loop {
            let v = Vec3::new(unit(), unit(), unit()) * 2.0 - Vec3::ONE;
            if v.length_squared() > 1e-4 && v.length_squared() <= 1.0 {
                break v.normalize();
            }
        };
        let origin = centre + on_sphere * (2.5 * diag);
        let target = lo + (hi - lo) * Vec3::new(unit(), unit(), unit());
        let ray = Ray::new(origin, target - origin);
        let h = accel.intersect(&ray, &mut NoCounters);
        if !h.is_hit() {
            continue;
        }
        hits += 1;
        let [a, b, c] = tris[h.tri as usize].vertices().map(|v| v.as_dvec3());
        let p = origin.as_dvec3() + ray.dir.as_dvec3() * f64::from(h.t);
        let nrm = (b - a).cross(c - a);
        let w = |x: DVec3, y: DVec3| nrm.dot((x - p).cross(y - p)) / nrm.length_squared();
        let least = w(b, c).min(w(c, a)).min(w(a, b));
        for (k, &l) in limits.iter().enumerate() {
            outside[k] += (least < -l) as u64;
        }
    }
    println!("{path}: {n} random rays, {hits} hits");
    for (k, l) in limits.iter().enumerate() {
        println!(
            "  hit point outside the reported triangle by more than {l:e} (barycentric): {} ({:.2e} of hits)",
            outside[k],
            outside[k] as f64 / hits as f64
        );
    }
    Ok(())
}
