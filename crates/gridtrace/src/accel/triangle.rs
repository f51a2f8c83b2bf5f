//! Triangles stored the way the paper stores them: the first vertex and the two edges from it,
//! which saves two vector subtractions in every Möller-Trumbore test.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// One triangle as the traversal sees it. Plain `f32` fields (no `Vec3`, whose alignment
/// differs between Rust and WGSL) so this exact struct is also the GPU storage layout: 36 bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct TriAccel {
    pub v0: [f32; 3],
    pub e1: [f32; 3],
    pub e2: [f32; 3],
}

/// Result of a ray/triangle test: ray parameter and barycentrics of v1 (`u`) and v2 (`v`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TriHit {
    pub t: f32,
    pub u: f32,
    pub v: f32,
}

/// Barycentric slack: a hit within this fraction of the triangle's size outside an edge still
/// counts. Exactly on a shared edge, rounding (which differs between the CPU and GPU compilers,
/// e.g. fused multiply-adds) can put the point a hair outside *both* triangles and let the ray
/// through; the slack makes both accept it instead.
pub const BARY_EPS: f32 = 1.0e-6;

/// Ulps of the rounding-error bound used as barycentric slack in `TriAccel::intersect`
/// (about 6 are derived; 8 leaves room for fused multiply-adds on GPUs).
pub const SLACK_ULPS: f32 = 8.0;

/// Upper limit of the error-bound slack. For a ray grazing the triangle's plane the bound (and the
/// real error) is large and MT's u, v are meaningless; accepting them would report hits far
/// outside the triangle, where the grid (rightly) does not look.
pub const MAX_SLACK: f32 = 1.0e-3;

/// How far outside a triangle a hit `TriAccel::intersect` accepts can lie, per axis, relative
/// to the triangle's largest box extent: the barycentric slack admits points up to
/// `BARY_EPS + MAX_SLACK` outside an edge along each of the two edges, whose components along an
/// axis are at most the box's extent there (10% spare). The grid's cell assignment and the BVH's
/// boxes are padded by this much, so that they find every hit a brute-force test finds.
pub const SLACK_PAD: f32 = 2.0 * (BARY_EPS + MAX_SLACK) * 1.1;

/// Padding for a triangle's box (see `SLACK_PAD`): relative to its size, plus a few ulps of its
/// coordinates (rebuilding `v1`, `v2` from `v0 + e` rounds).
pub fn slack_pad(lo: Vec3, hi: Vec3) -> f32 {
    SLACK_PAD * (hi - lo).max_element() + 4.0 * f32::EPSILON * lo.abs().max(hi.abs()).max_element()
}

#[inline(always)]
fn l1(v: Vec3) -> f32 {
    v.x.abs() + v.y.abs() + v.z.abs()
}

/// Rounding-error bounds of Möller-Trumbore's computed `u` and `v` (see `TriAccel::intersect`),
/// uncapped and without `BARY_EPS`.
#[inline(always)]
fn bary_error_bounds(s: Vec3, dir: Vec3, e1: Vec3, e2: Vec3, inv_det: f32) -> (f32, f32) {
    let (s1, d1, a1, b1) = (l1(s), l1(dir), l1(e1), l1(e2));
    let scale = SLACK_ULPS * f32::EPSILON * d1 * inv_det.abs();
    (scale * b1 * (s1 + a1), scale * a1 * (s1 + b1))
}

/// Squared cosine bound for "ray parallel to the triangle" (see `TriAccel::intersect`).
pub const PARALLEL_COS2: f32 = 1.0 / (1u64 << 40) as f32;

impl TriAccel {
    pub fn new(a: Vec3, b: Vec3, c: Vec3) -> Self {
        TriAccel {
            v0: a.to_array(),
            e1: (b - a).to_array(),
            e2: (c - a).to_array(),
        }
    }

    pub fn vertices(&self) -> [Vec3; 3] {
        let v0 = Vec3::from(self.v0);
        [v0, v0 + Vec3::from(self.e1), v0 + Vec3::from(self.e2)]
    }

    /// Unnormalised geometric normal `e1 x e2`.
    pub fn normal(&self) -> Vec3 {
        Vec3::from(self.e1).cross(Vec3::from(self.e2))
    }

    /// Two-sided Möller-Trumbore. Returns a hit with `t_min < t < t_max`.
    ///
    /// Rays (nearly) in the triangle's plane are rejected by a *relative* determinant test:
    /// `det = e1 . (dir x e2) = |e1| |dir x e2| cos(a)`, and `|cos(a)| < 2^-20` means the ray
    /// lies within about 1e-4 degrees of the plane. There `det` is dominated by rounding and MT
    /// returns arbitrary t, u, v (seen: a "hit" 0.6 units off the triangle). An absolute
    /// epsilon would depend on the scene's scale and reject small, valid triangles. A grazing
    /// ray through a closed mesh still hits the neighbouring triangles, so nothing leaks.
    /// The barycentric bounds are inclusive and slightly widened (`BARY_EPS`), so a ray through a
    /// shared edge hits both triangles.
    #[inline(always)]
    pub fn intersect(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<TriHit> {
        let e1 = Vec3::from(self.e1);
        let e2 = Vec3::from(self.e2);
        let p = dir.cross(e2);
        let det = e1.dot(p);
        if det == 0.0 {
            return None;
        }
        let inv_det = 1.0 / det;
        let s = origin - Vec3::from(self.v0);
        // First against the widest slack there can be, which rejects most candidates cheaply.
        const LOOSE: f32 = BARY_EPS + MAX_SLACK;
        let u = s.dot(p) * inv_det;
        if !(-LOOSE..=1.0 + LOOSE).contains(&u) {
            return None;
        }
        let q = s.cross(e1);
        let v = dir.dot(q) * inv_det;
        if v < -LOOSE || u + v > 1.0 + 2.0 * LOOSE {
            return None;
        }
        if !(-BARY_EPS..=1.0 + BARY_EPS).contains(&u) || v < -BARY_EPS || u + v > 1.0 + BARY_EPS {
            // Near an edge: the slack is a rounding-error bound, so that a ray through a shared
            // edge is accepted by at least one of the two triangles whatever the rounding (CPU
            // or GPU, fused or not). u = (s.p)/det with p = dir x e2: the computed s, p and dot
            // product are each off by a few ulps of |s|_1 |dir|_1 |e2|_1, and det by a few ulps
            // of |e1|_1 |dir|_1 |e2|_1 (which scales u, at most 1 at an edge); likewise v with
            // e1. The bound grows with the origin's distance relative to the triangle's size,
            // which a fixed slack cannot follow (docs/robustness.md).
            let (err_u, err_v) = bary_error_bounds(s, dir, e1, e2, inv_det);
            let tol_u = BARY_EPS + err_u.min(MAX_SLACK);
            let tol_v = BARY_EPS + err_v.min(MAX_SLACK);
            if u < -tol_u || u > 1.0 + tol_u || v < -tol_v || u + v > 1.0 + tol_u + tol_v {
                return None;
            }
        }
        let t = e2.dot(q) * inv_det;
        if !(t > t_min && t < t_max) {
            return None;
        }
        // The grazing test last: it is a pure filter, and most candidates never get here.
        if det * det <= PARALLEL_COS2 * e1.length_squared() * p.length_squared() {
            return None;
        }
        Some(TriHit { t, u, v })
    }

    /// The larger rounding-error bound of `intersect`'s barycentrics for this ray (uncapped;
    /// infinite for a ray parallel to the plane). Above `MAX_SLACK` the computed u and v, and so
    /// whether `intersect` reports a hit, are not determined by the geometry: the fuzzer found a
    /// 10,000-long, 0.06-wide sliver that a ray from 10,000 units away "hit" 3 units beyond its
    /// end (error bound 2.0). Tests use it to skip such rays, where no two traversal orders can
    /// be expected to agree with brute force.
    pub fn barycentric_error_bound(&self, origin: Vec3, dir: Vec3) -> f32 {
        let e1 = Vec3::from(self.e1);
        let e2 = Vec3::from(self.e2);
        let det = e1.dot(dir.cross(e2));
        let (err_u, err_v) = bary_error_bounds(origin - Vec3::from(self.v0), dir, e1, e2, 1.0 / det);
        err_u.max(err_v)
    }
}
