//! Procedural meshes for the built-in scenes, tests and scaling studies (no files needed).

use std::f32::consts::TAU;

use glam::{Mat4, Vec3};

use super::Mesh;

/// Grid-tessellated tube around a closed curve: `rings` segments along it, `sides` around it.
fn tube(curve: impl Fn(f32) -> Vec3, radius: f32, rings: u32, sides: u32) -> Mesh {
    let mut m = Mesh::default();
    let h = 1e-3;
    for i in 0..rings {
        let s = i as f32 / rings as f32 * TAU;
        let c = curve(s);
        let t = (curve(s + h) - curve(s - h)).normalize();
        // A frame that turns with the curve: binormal from the tangent and the position.
        let b = t.cross(c).normalize();
        let n = b.cross(t);
        for j in 0..sides {
            let a = j as f32 / sides as f32 * TAU;
            let dir = n * a.cos() + b * a.sin();
            m.positions.push(c + dir * radius);
            m.normals.push(dir);
        }
    }
    for i in 0..rings {
        let i1 = (i + 1) % rings;
        for j in 0..sides {
            let j1 = (j + 1) % sides;
            let (a, b, c, d) = (i * sides + j, i1 * sides + j, i1 * sides + j1, i * sides + j1);
            m.triangles.push([a, b, c]);
            m.triangles.push([a, c, d]);
        }
    }
    m
}

/// A (p, q) torus knot of unit-ish size with a tube; `2 * rings * sides` triangles.
pub fn torus_knot(p: u32, q: u32, tube_radius: f32, rings: u32, sides: u32) -> Mesh {
    let (p, q) = (p as f32, q as f32);
    tube(
        move |s| {
            let r = 2.0 + (q * s).cos();
            Vec3::new(r * (p * s).cos(), (q * s).sin(), r * (p * s).sin()) * (1.0 / 3.0)
        },
        tube_radius,
        rings,
        sides,
    )
}

/// UV sphere with `stacks * slices` quads (poles as fans).
pub fn uv_sphere(center: Vec3, radius: f32, stacks: u32, slices: u32) -> Mesh {
    let mut m = Mesh::default();
    for i in 0..=stacks {
        let theta = i as f32 / stacks as f32 * std::f32::consts::PI;
        for j in 0..slices {
            let phi = j as f32 / slices as f32 * TAU;
            let n = Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin());
            m.positions.push(center + n * radius);
            m.normals.push(n);
        }
    }
    for i in 0..stacks {
        for j in 0..slices {
            let j1 = (j + 1) % slices;
            let (a, b, c, d) = (
                i * slices + j,
                (i + 1) * slices + j,
                (i + 1) * slices + j1,
                i * slices + j1,
            );
            if i != 0 {
                m.triangles.push([a, c, d]);
            }
            if i != stacks - 1 {
                m.triangles.push([a, b, c]);
            }
        }
    }
    // Pole rows repeat one point `slices` times; the fan triangles above use distinct points
    // except at the pole ring itself, which has been skipped, so no zero-area triangles remain.
    m
}

/// Icosphere: a closed, watertight sphere, `20 * 4^level` triangles (shared vertices welded).
pub fn icosphere(center: Vec3, radius: f32, level: u32) -> Mesh {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut pos: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut tris: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..level {
        let mut mid = std::collections::HashMap::new();
        let mut midpoint = |a: u32, b: u32, pos: &mut Vec<Vec3>| {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                pos.push(((pos[a as usize] + pos[b as usize]) * 0.5).normalize());
                pos.len() as u32 - 1
            })
        };
        let mut next = Vec::with_capacity(tris.len() * 4);
        for [a, b, c] in tris {
            let ab = midpoint(a, b, &mut pos);
            let bc = midpoint(b, c, &mut pos);
            let ca = midpoint(c, a, &mut pos);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        tris = next;
    }
    Mesh {
        normals: pos.clone(),
        positions: pos.iter().map(|&n| center + n * radius).collect(),
        triangles: tris,
        ..Default::default()
    }
}

/// Axis-aligned box from `min` to `max` with `n x n` quads per face; faces point inwards if
/// `inward` (a room), outwards otherwise. Corner and edge vertices are shared (watertight).
pub fn box_mesh(min: Vec3, max: Vec3, n: u32, inward: bool) -> Mesh {
    let mut m = Mesh::default();
    let mut index = std::collections::HashMap::new();
    let n = n.max(1);
    // Lattice coordinates (i, j, k) in 0..=n identify shared vertices exactly.
    let mut vid = |l: [u32; 3], m: &mut Mesh| -> u32 {
        *index.entry(l).or_insert_with(|| {
            let f = Vec3::new(l[0] as f32, l[1] as f32, l[2] as f32) / n as f32;
            m.positions.push(min + (max - min) * f);
            m.positions.len() as u32 - 1
        })
    };
    for axis in 0..3 {
        for side in [0, n] {
            let (a1, a2) = ((axis + 1) % 3, (axis + 2) % 3);
            for i in 0..n {
                for j in 0..n {
                    let l = |di: u32, dj: u32| {
                        let mut c = [0u32; 3];
                        c[axis] = side;
                        c[a1] = i + di;
                        c[a2] = j + dj;
                        c
                    };
                    let q = [
                        vid(l(0, 0), &mut m),
                        vid(l(1, 0), &mut m),
                        vid(l(1, 1), &mut m),
                        vid(l(0, 1), &mut m),
                    ];
                    // Winding: outward normal is +axis on the max side; flip for inward/min.
                    let flip = (side == 0) ^ inward;
                    if flip {
                        m.triangles.push([q[0], q[2], q[1]]);
                        m.triangles.push([q[0], q[3], q[2]]);
                    } else {
                        m.triangles.push([q[0], q[1], q[2]]);
                        m.triangles.push([q[0], q[2], q[3]]);
                    }
                }
            }
        }
    }
    m
}

/// A square in the y = 0 plane of side `size`, centred at the origin, `n x n` quads, facing +y.
pub fn plane(size: f32, n: u32) -> Mesh {
    let mut m = Mesh::default();
    let n = n.max(1);
    for i in 0..=n {
        for j in 0..=n {
            let x = (i as f32 / n as f32 - 0.5) * size;
            let z = (j as f32 / n as f32 - 0.5) * size;
            m.positions.push(Vec3::new(x, 0.0, z));
        }
    }
    for i in 0..n {
        for j in 0..n {
            let a = i * (n + 1) + j;
            let (b, c, d) = (a + 1, a + n + 2, a + n + 1);
            m.triangles.push([a, b, c]);
            m.triangles.push([a, c, d]);
        }
    }
    m
}

/// Applies an affine transform to positions and (by the inverse transpose) to normals.
pub fn transform(mesh: &mut Mesh, m: Mat4) {
    for p in &mut mesh.positions {
        *p = m.transform_point3(*p);
    }
    let n = m.inverse().transpose();
    for v in &mut mesh.normals {
        *v = n.transform_vector3(*v).normalize_or_zero();
    }
    if m.determinant() < 0.0 {
        for t in &mut mesh.triangles {
            t.swap(1, 2);
        }
    }
}
