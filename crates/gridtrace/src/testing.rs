//! Test support shared by the unit tests, the integration tests (CPU and GPU), the benchmarks and
//! the fuzzers: scenes and adversarial ray sets. Public so every consumer draws the same rays.

use glam::Vec3;

use crate::accel::{Aabb, GridAccel, Ray, TriAccel};
use crate::scene::procedural;
use crate::util::Rng;

/// A random triangle soup: `n` triangles with sizes from slivers to large, in a unit-ish cube.
pub fn triangle_soup(n: usize, seed: u64) -> Vec<TriAccel> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|i| {
            let c = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
            let size = [0.02, 0.1, 0.4][i % 3];
            let mut p = || c + Vec3::new(rng.range(-size, size), rng.range(-size, size), rng.range(-size, size));
            let (a, b, mut cc) = (p(), p(), p());
            if i % 17 == 0 {
                // Long thin sliver.
                cc = a + (b - a) * 0.5 + Vec3::new(1e-3, -1e-3, 2e-3);
            }
            TriAccel::new(a, b, cc)
        })
        .filter(|t| t.normal().length_squared() > 0.0)
        .collect()
}

/// A flat scene: a tessellated square in the z = 0.25 plane plus a flat random soup in it.
pub fn flat_scene(seed: u64) -> Vec<TriAccel> {
    let mut tris: Vec<TriAccel> = Vec::new();
    let m = procedural::plane(2.0, 12);
    for t in &m.triangles {
        let [a, b, c] = t.map(|i| {
            let p = m.positions[i as usize];
            Vec3::new(p.x, p.z, 0.25)
        });
        tris.push(TriAccel::new(a, b, c));
    }
    let mut rng = Rng::new(seed);
    for _ in 0..400 {
        let c = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), 0.25);
        let mut p = || c + Vec3::new(rng.range(-0.2, 0.2), rng.range(-0.2, 0.2), 0.0);
        let t = TriAccel::new(p(), p(), p());
        if t.normal().length_squared() > 0.0 {
            tris.push(t);
        }
    }
    tris
}

fn unit_dir(rng: &mut Rng) -> Vec3 {
    loop {
        let v = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
        let l = v.length_squared();
        if l > 1e-4 && l <= 1.0 {
            return v / l.sqrt();
        }
    }
}

/// Adversarial ray set over `accel`: random rays from outside and inside the grid, rays aimed
/// exactly at vertices and at points on edges, axis-parallel rays (also through vertices), rays
/// in cell-boundary planes and through grid corners, and rays that miss the grid. Directions are
/// not all normalised.
pub fn ray_set(accel: &GridAccel, n: usize, seed: u64) -> Vec<Ray> {
    let mut rng = Rng::new(seed);
    let g = &accel.grid;
    let b = g.bounds;
    let ext = b.extent();
    let big = Aabb {
        min: b.min - ext * 0.5,
        max: b.max + ext * 0.5,
    };
    let point_in = |bb: &Aabb, rng: &mut Rng| {
        Vec3::new(
            rng.range(bb.min.x, bb.max.x),
            rng.range(bb.min.y, bb.max.y),
            rng.range(bb.min.z, bb.max.z),
        )
    };
    let axes = [Vec3::X, Vec3::Y, Vec3::Z, -Vec3::X, -Vec3::Y, -Vec3::Z];
    let mut rays = Vec::with_capacity(n);
    while rays.len() < n {
        let kind = rays.len() % 9;
        let tri = &accel.tris[rng.below(accel.tris.len() as u32) as usize];
        let [v0, v1, v2] = tri.vertices();
        let ray = match kind {
            // Random origin around the grid (often outside it), random direction.
            0 => Ray::new(point_in(&big, &mut rng), unit_dir(&mut rng)),
            // Origin inside the grid.
            1 => Ray::new(point_in(&b, &mut rng), unit_dir(&mut rng) * rng.range(0.1, 10.0)),
            // Aimed exactly at a vertex.
            2 => {
                let o = point_in(&big, &mut rng);
                Ray::new(o, [v0, v1, v2][rng.below(3) as usize] - o)
            }
            // Aimed at a point on an edge.
            3 => {
                let o = point_in(&big, &mut rng);
                let (a, c) = [(v0, v1), (v1, v2), (v2, v0)][rng.below(3) as usize];
                let f = [0.5, 0.25, rng.next_f32()][rng.below(3) as usize];
                Ray::new(o, a + (c - a) * f - o)
            }
            // Axis-parallel, random origin.
            4 => Ray::new(point_in(&big, &mut rng), axes[rng.below(6) as usize]),
            // Axis-parallel through a vertex or an edge midpoint.
            5 => {
                let d = axes[rng.below(6) as usize];
                let target = [v0, v1, v2, (v0 + v1) * 0.5][rng.below(4) as usize];
                Ray::new(target - d * ext.max_element() * rng.range(0.1, 2.0), d)
            }
            // In a cell-boundary plane (origin on a boundary, direction within the plane).
            6 => {
                let axis = rng.below(3) as usize;
                let k = rng.below(g.dims[axis] + 1) as f32;
                let mut o = point_in(&big, &mut rng);
                o[axis] = b.min[axis] + k * g.cell_size[axis];
                let mut d = unit_dir(&mut rng);
                d[axis] = 0.0;
                if d.length_squared() == 0.0 {
                    d[(axis + 1) % 3] = 1.0;
                }
                Ray::new(o, d)
            }
            // Through a grid corner (a lattice point of cell corners).
            7 => {
                let corner = b.min
                    + Vec3::new(
                        rng.below(g.dims.x + 1) as f32,
                        rng.below(g.dims.y + 1) as f32,
                        rng.below(g.dims.z + 1) as f32,
                    ) * g.cell_size;
                let o = point_in(&big, &mut rng);
                Ray::new(o, corner - o)
            }
            // Misses: from outside, pointing away from the grid.
            _ => {
                let o = point_in(&big, &mut rng);
                let away = (o - b.center()).normalize_or(Vec3::X);
                let mut d = unit_dir(&mut rng);
                if d.dot(away) < 0.0 {
                    d = -d;
                }
                Ray::new(
                    b.center() + (o - b.center()).normalize_or(Vec3::X) * b.diagonal() * 2.0,
                    d,
                )
            }
        };
        if ray.dir.length_squared() > 0.0 && ray.dir.is_finite() {
            rays.push(ray);
        }
    }
    rays
}
