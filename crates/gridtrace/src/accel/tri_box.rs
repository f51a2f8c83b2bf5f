//! Exact triangle/box overlap by the separating axis theorem (Akenine-Möller 2001):
//! 3 box face normals, the triangle normal, and the 9 edge cross products.
//!
//! The grid uses it to put a triangle only into the cells it really touches; a bounding-box
//! assignment puts a long diagonal sliver into O(n^2) cells it never touches.

use glam::{BVec4A, Vec3, Vec4};

/// True if the closed triangle `(a, b, c)` and the closed box `center +- half` overlap.
/// Touching counts as overlapping (all comparisons are non-strict), which the grid relies on:
/// a triangle lying exactly on a cell face is put into both cells.
pub fn triangle_overlaps_box(center: Vec3, half: Vec3, a: Vec3, b: Vec3, c: Vec3) -> bool {
    // Move the box to the origin.
    let v0 = a - center;
    let v1 = b - center;
    let v2 = c - center;
    let e0 = v1 - v0;
    let e1 = v2 - v1;
    let e2 = v0 - v2;

    // 9 axes: cross products of the box axes with the triangle edges.
    for e in [e0, e1, e2] {
        for axis in [
            Vec3::new(0.0, -e.z, e.y),
            Vec3::new(e.z, 0.0, -e.x),
            Vec3::new(-e.y, e.x, 0.0),
        ] {
            let p0 = axis.dot(v0);
            let p1 = axis.dot(v1);
            let p2 = axis.dot(v2);
            let r = half.x * axis.x.abs() + half.y * axis.y.abs() + half.z * axis.z.abs();
            if p0.min(p1).min(p2) > r || p0.max(p1).max(p2) < -r {
                return false;
            }
        }
    }

    // 3 axes: the box face normals, i.e. the triangle's bounding box against the box.
    let tmin = v0.min(v1).min(v2);
    let tmax = v0.max(v1).max(v2);
    if tmin.cmpgt(half).any() || tmax.cmplt(-half).any() {
        return false;
    }

    // 1 axis: the triangle's plane against the box.
    let normal = e0.cross(e1);
    let d = normal.dot(v0);
    let r = half.x * normal.x.abs() + half.y * normal.y.abs() + half.z * normal.z.abs();
    d.abs() <= r
}

/// Three coordinates of four lanes: one point (or vector) per lane.
#[derive(Clone, Copy)]
struct V3x4 {
    x: Vec4,
    y: Vec4,
    z: Vec4,
}

impl V3x4 {
    fn splat(v: Vec3) -> V3x4 {
        V3x4 {
            x: Vec4::splat(v.x),
            y: Vec4::splat(v.y),
            z: Vec4::splat(v.z),
        }
    }
    fn sub(self, o: V3x4) -> V3x4 {
        V3x4 {
            x: self.x - o.x,
            y: self.y - o.y,
            z: self.z - o.z,
        }
    }
    /// `x*x' + y*y' + z*z'`, left to right, as `Vec3::dot` and the WGSL's `dot_ordered`.
    fn dot(self, o: V3x4) -> Vec4 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
}

/// `triangle_overlaps_box` for four boxes at once (`centers`, one `half` for all), lane by
/// lane the same operations in the same order, so each lane's answer is the scalar test's bit
/// for bit (the GPU build computes the scalar form; the grid tests check they agree). The
/// grid build's candidate cells of one triangle share its vertices and their half size, so
/// four of them go through the thirteen axes together. Returns a mask, lane i for box i.
pub fn triangle_overlaps_boxes4(centers: [Vec3; 4], half: Vec3, a: Vec3, b: Vec3, c: Vec3) -> BVec4A {
    let center = V3x4 {
        x: Vec4::from_array(centers.map(|p| p.x)),
        y: Vec4::from_array(centers.map(|p| p.y)),
        z: Vec4::from_array(centers.map(|p| p.z)),
    };
    let v0 = V3x4::splat(a).sub(center);
    let v1 = V3x4::splat(b).sub(center);
    let v2 = V3x4::splat(c).sub(center);
    let e0 = v1.sub(v0);
    let e1 = v2.sub(v1);
    let e2 = v0.sub(v2);
    let (hx, hy, hz) = (Vec4::splat(half.x), Vec4::splat(half.y), Vec4::splat(half.z));
    let zero = Vec4::ZERO;
    let mut separated = BVec4A::splat(false);
    for e in [e0, e1, e2] {
        // The scalar test's axes (0, -e.z, e.y), (e.z, 0, -e.x), (-e.y, e.x, 0), zeros included:
        // 0 * v is part of its dot product.
        for axis in [
            V3x4 {
                x: zero,
                y: -e.z,
                z: e.y,
            },
            V3x4 {
                x: e.z,
                y: zero,
                z: -e.x,
            },
            V3x4 {
                x: -e.y,
                y: e.x,
                z: zero,
            },
        ] {
            let p0 = axis.dot(v0);
            let p1 = axis.dot(v1);
            let p2 = axis.dot(v2);
            let r = hx * axis.x.abs() + hy * axis.y.abs() + hz * axis.z.abs();
            separated |= p0.min(p1).min(p2).cmpgt(r) | p0.max(p1).max(p2).cmplt(-r);
        }
        if separated.all() {
            return BVec4A::splat(false);
        }
    }
    // The box's face normals: the triangle's bounding box against the box.
    for (p0, p1, p2, h) in [(v0.x, v1.x, v2.x, hx), (v0.y, v1.y, v2.y, hy), (v0.z, v1.z, v2.z, hz)] {
        separated |= p0.min(p1).min(p2).cmpgt(h) | p0.max(p1).max(p2).cmplt(-h);
    }
    // The triangle's plane: glam's cross (y*z' - y'*z, z*x' - z'*x, x*y' - x'*y).
    let n = V3x4 {
        x: e0.y * e1.z - e1.y * e0.z,
        y: e0.z * e1.x - e1.z * e0.x,
        z: e0.x * e1.y - e1.x * e0.y,
    };
    let d = n.dot(v0);
    let r = hx * n.x.abs() + hy * n.y.abs() + hz * n.z.abs();
    !(separated | d.abs().cmpgt(r))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basic_cases() {
        let c = Vec3::ZERO;
        let h = Vec3::splat(1.0);
        // Triangle through the box.
        assert!(triangle_overlaps_box(
            c,
            h,
            Vec3::new(-3.0, 0.0, 0.0),
            Vec3::new(3.0, 0.1, 0.0),
            Vec3::new(0.0, 3.0, 0.2)
        ));
        // Triangle far away.
        assert!(!triangle_overlaps_box(
            c,
            h,
            Vec3::new(5.0, 5.0, 5.0),
            Vec3::new(6.0, 5.0, 5.0),
            Vec3::new(5.0, 6.0, 5.0)
        ));
        let a = Vec3::new(0.5, 3.0, 0.0);
        let b = Vec3::new(3.0, 0.5, 0.0);
        let cc = Vec3::new(3.0, 3.0, 0.0);
        // bbox [0.5,3]^2 overlaps the box corner region, the triangle (above the line x+y=3.5) does not.
        assert!(!triangle_overlaps_box(c, h, a, b, cc));
        // Triangle touching a face exactly counts.
        assert!(triangle_overlaps_box(
            c,
            h,
            Vec3::new(1.0, -0.5, -0.5),
            Vec3::new(1.0, 0.5, -0.5),
            Vec3::new(1.0, 0.0, 0.5)
        ));
        // Plane of the triangle misses the box even though the bbox overlaps.
        assert!(!triangle_overlaps_box(
            c,
            h,
            Vec3::new(-5.0, -5.0, 4.0),
            Vec3::new(5.0, -5.0, 4.0),
            Vec3::new(0.0, 5.0, -4.5) + Vec3::new(0.0, 0.0, 9.0)
        ));
    }

    /// The four-wide test answers as the scalar one, lane by lane, on random triangles against
    /// boxes placed around them (many touching within rounding: centres on a lattice through
    /// the vertices) and on degenerate ones.
    #[test]
    fn four_wide_equals_scalar() {
        let mut rng = crate::util::Rng::new(11);
        let mut differ = 0;
        let mut yes = 0;
        for case in 0..40_000 {
            let p = |r: &mut crate::util::Rng| Vec3::new(r.range(-2.0, 2.0), r.range(-2.0, 2.0), r.range(-2.0, 2.0));
            let (a, mut b, c) = (p(&mut rng), p(&mut rng), p(&mut rng));
            if case % 10 == 0 {
                b = a; // degenerate: a segment
            }
            let half = Vec3::new(rng.range(0.05, 0.6), rng.range(0.05, 0.6), rng.range(0.05, 0.6));
            let centers: [Vec3; 4] = std::array::from_fn(|i| {
                if case % 2 == 0 {
                    // On the lattice of boxes through vertex a: faces through a.
                    let k = Vec3::new(
                        rng.below(5) as f32 - 2.0,
                        rng.below(5) as f32 - 2.0,
                        rng.below(5) as f32 - 2.0,
                    );
                    a + half + k * half * 2.0 + Vec3::splat(i as f32 * 0.0)
                } else {
                    p(&mut rng)
                }
            });
            let wide = triangle_overlaps_boxes4(centers, half, a, b, c).bitmask();
            for (i, &ctr) in centers.iter().enumerate() {
                let scalar = triangle_overlaps_box(ctr, half, a, b, c);
                yes += scalar as u32;
                if scalar != (wide >> i & 1 == 1) {
                    differ += 1;
                }
            }
        }
        assert_eq!(differ, 0);
        assert!(yes > 5_000, "{yes}");
    }

    /// Sampling check: if some point of the triangle lies inside the box, the test must say yes.
    #[test]
    fn agrees_with_point_sampling() {
        let mut rng = crate::util::Rng::new(7);
        let h = Vec3::splat(0.5);
        let mut yes = 0;
        for _ in 0..20_000 {
            let p = |r: &mut crate::util::Rng| Vec3::new(r.range(-2.0, 2.0), r.range(-2.0, 2.0), r.range(-2.0, 2.0));
            let (a, b, c) = (p(&mut rng), p(&mut rng), p(&mut rng));
            let overlap = triangle_overlaps_box(Vec3::ZERO, h, a, b, c);
            let mut sampled = false;
            for i in 0..=40 {
                for j in 0..=(40 - i) {
                    let (u, v) = (i as f32 / 40.0, j as f32 / 40.0);
                    let q = a + (b - a) * u + (c - a) * v;
                    if q.abs().cmple(h).all() {
                        sampled = true;
                    }
                }
            }
            if sampled {
                assert!(overlap, "missed overlap {a} {b} {c}");
                yes += 1;
            }
        }
        assert!(yes > 1000);
    }
}
