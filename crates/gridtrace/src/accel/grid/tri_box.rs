//! Exact triangle/box overlap by the separating axis theorem (Akenine-Möller 2001):
//! 3 box face normals, the triangle normal, and the 9 edge cross products.
//!
//! The grid uses it to put a triangle only into the cells it really touches; a bounding-box
//! assignment puts a long diagonal sliver into O(n^2) cells it never touches.

use glam::Vec3;

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
