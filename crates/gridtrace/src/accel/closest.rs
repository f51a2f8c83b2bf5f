//! Closest points on the mesh: for a query point, the nearest point of any triangle, its
//! distance, the triangle and the barycentrics there. Every structure answers it
//! (`BvhAccel::closest_point`, `Grid::closest_point`, `IrregularGrid::closest_point`) with the
//! answer of the brute-force oracle here (`closest_point_brute`), and `closest_points` runs a
//! batch over whichever structure an `Accel` holds.
//!
//! **Which triangle.** Where several triangles are equally near (a point on a shared edge or
//! vertex, two coincident meshes), the answer is the smallest squared distance as computed by
//! `closest_on_triangle`, then the smallest triangle index. The distance of a triangle is a
//! pure function of the triangle's floats and the point's, so every structure computes the very
//! same value for it; the structures prune only what is *strictly* farther than the best so far
//! (with conservative bounds), so they all see every tie and name the same triangle as brute
//! force.
//!
//! **Zero-area triangles.** The grids put a triangle into the cells its exact overlap test
//! accepts, and that test's plane axis is the triangle's normal: for a triangle whose vertices
//! are collinear only up to rounding (a normal of pure rounding noise) it can refuse cells the
//! triangle touches. No ray can hit such a triangle, so rays never cared; its nearest points
//! are real. The grids' answers are exact for every triangle with a well-defined plane and for
//! exactly degenerate ones (zero normal: points, repeated vertices, exactly collinear); the BVH
//! (boxes only) and brute force are exact for all. Scene preparation (`TraceMesh`) drops
//! triangles whose normal is exactly zero, not these.
//!
//! **Misses.** No triangle at all: `tri = u32::MAX`, `dist_sq = inf`, a NaN point. A query
//! point with a NaN or infinite coordinate has no meaningful nearest point: `tri = u32::MAX`
//! and `dist_sq = NaN` (`ClosestPoint::INVALID`), not a panic. Squared distances are `f32`:
//! points farther than about 1e19 from the mesh overflow to infinity.

use glam::Vec3;
use rayon::prelude::*;

use super::{Accel, TriAccel};
use crate::Result;

pub(crate) mod shells;

/// The nearest point of a mesh to a query point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClosestPoint {
    /// The nearest point, `v0 + u * e1 + v * e2` of triangle `tri` (NaN when there is none).
    pub point: Vec3,
    /// Squared distance from the query point to `point` (inf when there is no triangle, NaN
    /// for a query point that is not finite).
    pub dist_sq: f32,
    /// Index of the triangle in the triangles the structure was built over (`Accel::tris`);
    /// `u32::MAX` when there is none.
    pub tri: u32,
    /// Barycentric weights of the triangle's second (`u`) and third (`v`) vertex, as `Hit`
    /// gives them.
    pub u: f32,
    pub v: f32,
}

impl ClosestPoint {
    /// No triangle (an empty mesh): what a search starts from.
    pub const NONE: ClosestPoint = ClosestPoint {
        point: Vec3::NAN,
        dist_sq: f32::INFINITY,
        tri: u32::MAX,
        u: 0.0,
        v: 0.0,
    };

    /// The answer for a query point with a NaN or infinite coordinate.
    pub const INVALID: ClosestPoint = ClosestPoint {
        dist_sq: f32::NAN,
        ..Self::NONE
    };

    /// Whether a triangle was found.
    pub fn is_found(&self) -> bool {
        self.tri != u32::MAX
    }

    /// The distance (`sqrt(dist_sq)`).
    pub fn distance(&self) -> f32 {
        self.dist_sq.sqrt()
    }

    /// Whether a candidate at `dist_sq` on triangle `tri` beats this one: nearer, or as near
    /// and a smaller index (the tie rule every structure follows).
    #[inline(always)]
    pub fn is_beaten_by(&self, dist_sq: f32, tri: u32) -> bool {
        dist_sq < self.dist_sq || (dist_sq == self.dist_sq && tri < self.tri)
    }

    /// Offers triangle `t` (index `tri`) for query point `p`: keeps it if it beats the best.
    #[inline(always)]
    pub fn offer(&mut self, t: &TriAccel, tri: u32, p: Vec3) {
        let c = closest_on_triangle(t, p);
        if self.is_beaten_by(c.dist_sq, tri) {
            *self = ClosestPoint {
                point: c.point,
                dist_sq: c.dist_sq,
                tri,
                u: c.u,
                v: c.v,
            };
        }
    }
}

/// The nearest point of one triangle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TriPoint {
    pub point: Vec3,
    pub dist_sq: f32,
    /// Barycentric weights of `v1` and `v2`.
    pub u: f32,
    pub v: f32,
}

/// The point of triangle `t` nearest to `p` (Ericson, Real-Time Collision Detection, 5.1.5):
/// which Voronoi region of the triangle (three vertices, three edges, the face) holds `p`,
/// decided by signs of dot products, then the projection onto that feature.
///
/// Written on `TriAccel`'s `v0, e1, e2`: `p - v1` is `(p - v0) - e1`, so no vertex is rebuilt.
/// The face region divides by `va + vb + vc`, which is `|e1 x e2|^2` in exact arithmetic; for a
/// degenerate or sliver triangle rounding can make it zero or make one of the three negative,
/// and the face formula would give NaN or a point off the triangle. There the nearest point of
/// the three edges is taken instead (a zero-area triangle *is* its edges; a sliver's face is
/// within rounding of them). The point is always `v0 + u e1 + v e2` and the distance is
/// measured to that point, so `dist_sq` is the distance to what is reported.
#[inline(always)]
pub fn closest_on_triangle(t: &TriAccel, p: Vec3) -> TriPoint {
    let a = Vec3::from(t.v0);
    let (ab, ac) = t.edges();
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    let (u, v) = 'region: {
        if d1 <= 0.0 && d2 <= 0.0 {
            break 'region (0.0, 0.0); // vertex v0
        }
        let bp = ap - ab;
        let d3 = ab.dot(bp);
        let d4 = ac.dot(bp);
        if d3 >= 0.0 && d4 <= d3 {
            break 'region (1.0, 0.0); // vertex v1
        }
        let vc = d1 * d4 - d3 * d2;
        if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
            break 'region (d1 / (d1 - d3), 0.0); // edge v0-v1
        }
        let cp = ap - ac;
        let d5 = ab.dot(cp);
        let d6 = ac.dot(cp);
        if d6 >= 0.0 && d5 <= d6 {
            break 'region (0.0, 1.0); // vertex v2
        }
        let vb = d5 * d2 - d1 * d6;
        if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
            break 'region (0.0, d2 / (d2 - d6)); // edge v0-v2
        }
        let va = d3 * d6 - d5 * d4;
        if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
            let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
            break 'region (1.0 - w, w); // edge v1-v2
        }
        let denom = va + vb + vc;
        if va >= 0.0 && vb >= 0.0 && vc >= 0.0 && denom > 0.0 && denom.is_finite() {
            let inv = 1.0 / denom;
            break 'region (vb * inv, vc * inv); // the face
        }
        nearest_on_edges(ap, ab, ac)
    };
    let point = a + ab * u + ac * v;
    TriPoint {
        point,
        dist_sq: (p - point).length_squared(),
        u,
        v,
    }
}

/// Barycentrics `(u, v)` of the nearest point to `a + ap` on the three edges of the triangle
/// `a, a + ab, a + ac`: the fallback of `closest_on_triangle` for (nearly) degenerate
/// triangles. A zero-length edge clamps to its first end.
#[cold]
fn nearest_on_edges(ap: Vec3, ab: Vec3, ac: Vec3) -> (f32, f32) {
    // Parameter in [0, 1] of the nearest point of segment `o + s d` to the origin of `q`.
    let along = |q: Vec3, d: Vec3| {
        let len2 = d.length_squared();
        if len2 > 0.0 {
            (q.dot(d) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        }
    };
    let s_ab = along(ap, ab);
    let s_ac = along(ap, ac);
    let bc = ac - ab;
    let s_bc = along(ap - ab, bc);
    let cands = [(s_ab, 0.0), (0.0, s_ac), (1.0 - s_bc, s_bc)];
    let mut best = (0.0, 0.0);
    let mut best_d = f32::INFINITY;
    for (u, v) in cands {
        let d = (ap - ab * u - ac * v).length_squared();
        if d < best_d {
            best_d = d;
            best = (u, v);
        }
    }
    best
}

/// The oracle: every triangle tested, the tie rule applied (`ClosestPoint`).
pub fn closest_point_brute(tris: &[TriAccel], p: Vec3) -> ClosestPoint {
    if !p.is_finite() {
        return ClosestPoint::INVALID;
    }
    let mut best = ClosestPoint::NONE;
    for (i, t) in tris.iter().enumerate() {
        best.offer(t, i as u32, p);
    }
    best
}

/// Whether triangle `t`'s box may hold a point within `dist_sq` of `p` (ties included): false
/// only when it is certainly farther, so a triangle it drops could not beat a best at
/// `dist_sq`. The box comes from the stored vertices and is widened by a
/// rounding bound of the coordinates involved (16 ulps of the largest), as the BVH's leaf test
/// (`bvh/closest.rs`).
#[inline(always)]
pub(crate) fn tri_box_within(t: &TriAccel, p: Vec3, dist_sq: f32) -> bool {
    let v0 = Vec3::from(t.v0);
    let (v1, v2) = (Vec3::from(t.v1), Vec3::from(t.v2));
    let (lo, hi) = (v0.min(v1).min(v2), v0.max(v1).max(v2));
    let d = (lo - p).max(p - hi).max(Vec3::ZERO);
    let scale = lo.abs().max(hi.abs()).max(p.abs()).max_element();
    let reach = dist_sq.sqrt() + scale * (16.0 * f32::EPSILON);
    // Dropped only when certainly greater, so that NaN (never, for finite input) would keep
    // the triangle.
    d.length_squared().partial_cmp(&(reach * reach)) != Some(std::cmp::Ordering::Greater)
}

/// Squared distance from `p` to the box `[lo, hi]` (0 inside).
#[inline(always)]
pub(crate) fn box_dist_sq(p: Vec3, lo: Vec3, hi: Vec3) -> f32 {
    let d = (lo - p).max(p - hi).max(Vec3::ZERO);
    d.length_squared()
}

/// The nearest point of the mesh in `accel` to `p`, through its structure.
pub fn closest_point(accel: &Accel, p: Vec3) -> ClosestPoint {
    accel.closest_point(p)
}

/// Points per work item: enough to keep a structure's interleaved searches busy, few enough to
/// balance the cores.
const BATCH: usize = 256;

/// The nearest points of a batch, `out[i]` for `points[i]`, on all cores. An error (not a
/// panic) when the structure is stale (`Accel::check_current`).
///
/// The points are searched in their Morton order (`point_order`), the answers given back in
/// theirs: neighbours follow each other, so a search finds its nodes in cache, and the BVH's
/// starts from its neighbour's answer (`bvh/closest.rs`). Every answer is the one a lone
/// search gives, bit for bit.
pub fn closest_points(accel: &Accel, points: &[[f32; 3]]) -> Result<Vec<ClosestPoint>> {
    accel.check_current()?;
    let order = super::point_order::morton_order(points);
    let sorted: Vec<[f32; 3]> = order.par_iter().map(|&i| points[i as usize]).collect();
    let mut found = vec![ClosestPoint::NONE; points.len()];
    found
        .par_chunks_mut(BATCH)
        .zip(sorted.par_chunks(BATCH))
        .for_each(|(o, p)| accel.closest_points_batch(p, o));
    let mut out = vec![ClosestPoint::NONE; points.len()];
    for (&i, c) in order.iter().zip(found) {
        out[i as usize] = c;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::Rng;

    #[test]
    fn closest_on_triangle_in_each_region() {
        // The right triangle (0,0,0), (2,0,0), (0,2,0).
        let t = TriAccel::new(Vec3::ZERO, Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0));
        let cases = [
            // (query, nearest point, u, v)
            (Vec3::new(0.5, 0.5, 3.0), Vec3::new(0.5, 0.5, 0.0), 0.25, 0.25), // face
            (Vec3::new(-1.0, -1.0, 1.0), Vec3::ZERO, 0.0, 0.0),               // v0
            (Vec3::new(3.0, -1.0, 0.0), Vec3::new(2.0, 0.0, 0.0), 1.0, 0.0),  // v1
            (Vec3::new(-1.0, 3.0, 0.0), Vec3::new(0.0, 2.0, 0.0), 0.0, 1.0),  // v2
            (Vec3::new(1.0, -1.0, 0.0), Vec3::new(1.0, 0.0, 0.0), 0.5, 0.0),  // edge v0-v1
            (Vec3::new(-1.0, 1.5, 0.0), Vec3::new(0.0, 1.5, 0.0), 0.0, 0.75), // edge v0-v2
            (Vec3::new(2.0, 2.0, -1.0), Vec3::new(1.0, 1.0, 0.0), 0.5, 0.5),  // edge v1-v2
        ];
        for (p, q, u, v) in cases {
            let c = closest_on_triangle(&t, p);
            assert!((c.point - q).length() < 1e-6, "{p}: {c:?}");
            assert!((c.u - u).abs() < 1e-6 && (c.v - v).abs() < 1e-6, "{p}: {c:?}");
            assert!((c.dist_sq - (p - q).length_squared()).abs() < 1e-5, "{p}: {c:?}");
        }
    }

    /// Against a dense sampling of the triangle: never farther than the nearest sample, never
    /// nearer than the true distance allows (the samples are within `h` of every point).
    #[test]
    fn closest_on_triangle_against_sampling() {
        let mut rng = Rng::new(4);
        let mut r = |s: f32| Vec3::new(rng.range(-s, s), rng.range(-s, s), rng.range(-s, s));
        for i in 0..300 {
            let a = r(1.0);
            let (b, c) = if i % 4 == 0 {
                // Slivers and collinear triangles.
                let d = r(1.0);
                (a + d, a + d * 0.5 + r(1e-4) * (i % 8) as f32)
            } else {
                (a + r(1.0), a + r(1.0))
            };
            let t = TriAccel::new(a, b, c);
            let p = r(2.0);
            let got = closest_on_triangle(&t, p);
            let n = 200;
            let mut sampled = f32::INFINITY;
            for i in 0..=n {
                for j in 0..=n - i {
                    let (u, v) = (i as f32 / n as f32, j as f32 / n as f32);
                    let (e1, e2) = t.edges();
                    let q = Vec3::from(t.v0) + e1 * u + e2 * v;
                    sampled = sampled.min((p - q).length());
                }
            }
            let h = (t.edges().0.length() + t.edges().1.length()) / n as f32;
            let d = got.dist_sq.sqrt();
            assert!(d <= sampled + 1e-5, "{i}: {d} > sampled {sampled}");
            assert!(d >= sampled - h - 1e-5, "{i}: {d} < sampled {sampled} - {h}");
            assert!((0.0..=1.0).contains(&got.u) && (0.0..=1.0).contains(&got.v) && got.u + got.v <= 1.0 + 1e-6);
        }
    }

    #[test]
    fn ties_go_to_the_smaller_index() {
        let t = TriAccel::new(Vec3::ZERO, Vec3::X, Vec3::Y);
        let c = closest_point_brute(&[t, t, t], Vec3::new(0.2, 0.2, 1.0));
        assert_eq!(c.tri, 0);
        let far = TriAccel::new(Vec3::splat(5.0), Vec3::splat(6.0), Vec3::new(5.0, 6.0, 7.0));
        assert_eq!(closest_point_brute(&[far, t, t], Vec3::new(0.2, 0.2, 1.0)).tri, 1);
        assert_eq!(closest_point_brute(&[t], Vec3::new(f32::NAN, 0.0, 0.0)).tri, u32::MAX);
        assert_eq!(closest_point_brute(&[], Vec3::ZERO).dist_sq, f32::INFINITY);
    }
}
