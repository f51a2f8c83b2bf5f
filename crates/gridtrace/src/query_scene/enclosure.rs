//! A few points whose convex hull holds every vertex of a mesh: the corners of its 64-sided
//! discrete-orientation polytope (k-DOP), computed once per mesh. An instance's world box is
//! the box of these points through its transform.
//!
//! Why: the top level's boxes decide how many instances a ray is carried into. The box of the
//! own-space box's eight corners, turned, is loose: a randomly turned Stanford Bunny's is about
//! 1.5 times the exact box a side. Measured (2026-12-05, 100 randomly turned and scaled Bunnies,
//! 100,000 random rays as `examples/instances_vs_flat.rs` casts them), the boxes a ray enters:
//! turned own-space box 2.44, this polytope's corners 1.38, the exact box of every transformed
//! vertex 1.29. With 1M rays the exact boxes took the two levels from 1.74x to 1.37x the merged
//! flat scene's time. The exact box needs every vertex through the transform on each move (36k
//! for the Bunny); the polytope's corners are 124 (the Bunny's), a fraction of a microsecond.
//!
//! The polytope is the intersection of the half-spaces `d . x <= h(d)`, `h(d)` the largest
//! `d . v` over the vertices, for 64 directions: the 26-DOP's (the axes, so that an untransformed
//! instance's box is the mesh's own box, the 12 edge and 8 corner diagonals) and 38 spread by
//! the golden angle. Its corners are found by brute force over triples of planes (41,664, a few
//! ms once per mesh), each solved in f64 and kept if no other plane cuts it off.

use glam::{DVec3, Mat4, Vec3, Vec4};

use crate::accel::Aabb;

/// Directions beyond the 26-DOP's, spread over the sphere by the golden angle. 38 (64 planes in
/// all, 124 corners for the Bunny) left 1.38 boxes a ray; 102 more (251 corners) 1.33.
const SPREAD: usize = 38;

/// The polytope's corners, or the mesh box's eight corners where the polytope could not be
/// trusted (no vertex, or corners whose box does not hold the mesh's: a guard, never seen).
/// `bounds` is the vertices' box (the mesh keeps it).
pub(crate) fn dop_corners(vertices: &[[f32; 3]], bounds: Aabb) -> Vec<Vec3> {
    if bounds.is_empty() {
        return Vec::new();
    }
    let corners = polytope_corners(vertices, bounds);
    let held = corners.iter().fold(Aabb::EMPTY, |b, &p| b.grow(p));
    let slack = (bounds.extent().max_element() * 1e-6).max(f32::MIN_POSITIVE);
    let holds =
        !held.is_empty() && held.min.cmple(bounds.min + slack).all() && held.max.cmpge(bounds.max - slack).all();
    if holds { corners } else { box_corners(&bounds) }
}

/// The corners as the moves read them: one array a coordinate, four corners a lane group
/// (the last group filled up with the first corner, which changes no box).
#[derive(Debug, Clone, Default)]
pub(crate) struct Enclosure {
    xyz: [Vec<Vec4>; 3],
}

impl Enclosure {
    pub fn new(corners: &[Vec3]) -> Enclosure {
        let lanes = |a: usize| -> Vec<Vec4> {
            corners
                .chunks(4)
                .map(|c| Vec4::from_array([0, 1, 2, 3].map(|k| c.get(k).unwrap_or(&corners[0])[a])))
                .collect()
        };
        Enclosure {
            xyz: [lanes(0), lanes(1), lanes(2)],
        }
    }

    /// The box of the corners through `m` (an affine transform): for each world axis the
    /// least and the most of that row of `m` applied to the corners, summed in the order
    /// `Mat4::transform_point3` sums (the same floats), four corners an operation. Written in
    /// `Vec4`s because the compiler left the plain loop scalar: 60% of a thousand instances'
    /// move (`set_transforms`, goal 1 ms) went to it.
    pub fn world_box(&self, m: &Mat4) -> Aabb {
        let [xs, ys, zs] = &self.xyz;
        if xs.is_empty() {
            return Aabb::EMPTY;
        }
        let mut lo = Vec3::ZERO;
        let mut hi = Vec3::ZERO;
        for r in 0..3 {
            let (a, b, c) = (
                Vec4::splat(m.x_axis[r]),
                Vec4::splat(m.y_axis[r]),
                Vec4::splat(m.z_axis[r]),
            );
            let mut l = Vec4::INFINITY;
            let mut h = Vec4::NEG_INFINITY;
            for ((&x, &y), &z) in xs.iter().zip(ys).zip(zs) {
                let v = a * x + b * y + c * z;
                l = l.min(v);
                h = h.max(v);
            }
            let t = m.w_axis[r];
            lo[r] = l.min_element() + t;
            hi[r] = h.max_element() + t;
        }
        Aabb { min: lo, max: hi }
    }
}

/// The eight corners of a box.
pub(crate) fn box_corners(b: &Aabb) -> Vec<Vec3> {
    (0..8)
        .map(|k| {
            Vec3::new(
                if k & 1 == 0 { b.min.x } else { b.max.x },
                if k & 2 == 0 { b.min.y } else { b.max.y },
                if k & 4 == 0 { b.min.z } else { b.max.z },
            )
        })
        .collect()
}

/// The polytope's 64 plane normals (unit length).
fn directions() -> Vec<DVec3> {
    let mut d = Vec::with_capacity(26 + SPREAD);
    for x in -1i32..=1 {
        for y in -1i32..=1 {
            for z in -1i32..=1 {
                if (x, y, z) != (0, 0, 0) {
                    d.push(DVec3::new(x as f64, y as f64, z as f64).normalize());
                }
            }
        }
    }
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    for i in 0..SPREAD {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / SPREAD as f64;
        let r = (1.0 - z * z).sqrt();
        let a = golden * i as f64;
        d.push(DVec3::new(r * a.cos(), r * a.sin(), z));
    }
    d
}

fn polytope_corners(vertices: &[[f32; 3]], bounds: Aabb) -> Vec<Vec3> {
    // Relative to the box's centre, so that the planes' offsets (and the solves' rounding) are
    // on the scale of the mesh, not of where it sits.
    let centre = bounds.center().as_dvec3();
    let dirs = directions();
    let mut h = vec![f64::NEG_INFINITY; dirs.len()];
    for v in vertices {
        let p = Vec3::from(*v).as_dvec3() - centre;
        for (h, d) in h.iter_mut().zip(&dirs) {
            *h = h.max(d.dot(p));
        }
    }
    // A corner is kept where every plane holds it within `tol`: kept a hair outside rather than
    // lost (a lost corner would shrink the hull; one too many only widens it by `tol`).
    let scale = h.iter().fold(0f64, |m, &x| m.max(x.abs())).max(f64::MIN_POSITIVE);
    let tol = scale * 1e-9;
    let mut corners: Vec<[u32; 3]> = Vec::new();
    let n = dirs.len();
    for i in 0..n {
        for j in i + 1..n {
            let jk_base = dirs[i].cross(dirs[j]);
            if jk_base.length_squared() < 1e-12 {
                continue;
            }
            for k in j + 1..n {
                let (a, b, c) = (dirs[i], dirs[j], dirs[k]);
                let det = a.dot(b.cross(c));
                // Near-coplanar normals meet far away, if at all; a corner where they meet is
                // also met by a better-conditioned triple of its planes.
                if det.abs() < 1e-6 {
                    continue;
                }
                let p = (b.cross(c) * h[i] + c.cross(a) * h[j] + a.cross(b) * h[k]) / det;
                if dirs.iter().zip(&h).all(|(d, &h)| d.dot(p) <= h + tol) {
                    // Within the box, as the axis planes hold the polytope (a corner `tol`
                    // outside is pulled in: the untransformed box is then the mesh's own).
                    let p = (p + centre).as_vec3().clamp(bounds.min, bounds.max);
                    corners.push(p.to_array().map(f32::to_bits));
                }
            }
        }
    }
    // Where more than three planes meet, each triple gives the corner again.
    corners.sort_unstable();
    corners.dedup();
    corners
        .into_iter()
        .map(|c| Vec3::from_array(c.map(f32::from_bits)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat4, Quat};

    fn bounds_of(v: &[[f32; 3]]) -> Aabb {
        v.iter().fold(Aabb::EMPTY, |b, &p| b.grow(Vec3::from(p)))
    }

    /// Under any transform, the box of the corners holds the box of every vertex, and is not
    /// much larger (the Bunny-like blob here: within 15% a side).
    #[test]
    fn corners_hold_the_mesh_under_any_turn() {
        let mut rng = crate::util::Rng::new(11);
        // A lumpy blob: points on a sphere pushed in and out, and a flat square (all on one
        // plane, where the polytope is thin).
        let blob: Vec<[f32; 3]> = (0..3000)
            .map(|_| {
                let d =
                    Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, rng.next_f32() - 0.5).normalize_or(Vec3::X);
                let r = 1.0 + 0.3 * (5.0 * d.x).sin() * (3.0 * d.y).cos();
                (d * r * Vec3::new(1.0, 0.6, 0.8) + Vec3::new(10.0, -3.0, 2.0)).to_array()
            })
            .collect();
        let flat: Vec<[f32; 3]> = (0..200).map(|_| [rng.next_f32(), rng.next_f32(), 0.5]).collect();
        for (name, mesh) in [("blob", &blob), ("flat", &flat)] {
            let corners = dop_corners(mesh, bounds_of(mesh));
            assert!(
                corners.len() > 8 && corners.len() < 400,
                "{name}: {} corners",
                corners.len()
            );
            for _ in 0..200 {
                let q = Quat::from_xyzw(
                    rng.next_f32() - 0.5,
                    rng.next_f32() - 0.5,
                    rng.next_f32() - 0.5,
                    rng.next_f32() - 0.5,
                )
                .normalize();
                let m = Mat4::from_scale_rotation_translation(
                    Vec3::new(0.5 + rng.next_f32(), 0.5 + rng.next_f32(), 0.5 + rng.next_f32()),
                    q,
                    Vec3::splat(rng.next_f32() * 100.0),
                );
                let of =
                    |ps: &mut dyn Iterator<Item = Vec3>| ps.fold(Aabb::EMPTY, |b, p| b.grow(m.transform_point3(p)));
                let exact = of(&mut mesh.iter().map(|&v| Vec3::from(v)));
                let held = of(&mut corners.iter().copied());
                assert_eq!(Enclosure::new(&corners).world_box(&m), held, "{name}: the arrays' box");
                let slack = exact.extent().max_element() * 1e-5;
                assert!(
                    held.min.cmple(exact.min + slack).all() && held.max.cmpge(exact.max - slack).all(),
                    "{name}: {held:?} does not hold {exact:?}"
                );
                if name == "blob" {
                    let grown = held.extent() / exact.extent();
                    assert!(grown.max_element() < 1.15, "{name}: {grown} times the exact box");
                }
            }
        }
    }

    #[test]
    fn an_untransformed_mesh_keeps_its_own_box() {
        let v = [[0.0, 0.0, 0.0], [1.0, 2.0, 0.5], [0.3, -1.0, 4.0], [2.0, 2.0, 2.0]];
        let held = dop_corners(&v, bounds_of(&v))
            .iter()
            .fold(Aabb::EMPTY, |b, &p| b.grow(p));
        assert_eq!(held.min, Vec3::new(0.0, -1.0, 0.0));
        assert_eq!(held.max, Vec3::new(2.0, 2.0, 4.0));
        assert!(dop_corners(&[], Aabb::EMPTY).is_empty());
        // One point: a polytope of no size, all its corners that point.
        assert!(
            dop_corners(&[[1.0, 2.0, 3.0]], bounds_of(&[[1.0, 2.0, 3.0]]))
                .iter()
                .all(|&p| p == Vec3::new(1.0, 2.0, 3.0))
        );
    }
}
