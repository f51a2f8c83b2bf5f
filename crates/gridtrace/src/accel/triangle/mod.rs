//! Triangles stored as their three vertices, tested with the watertight ray/triangle test of
//! Woop, Benthin and Wald ("Watertight Ray/Triangle Intersection", JCGT 2013; as pbrt-v4's
//! `IntersectTriangle`).
//!
//! Why vertices and not the paper's `v0` and two edges: the test is watertight only when the
//! triangles at a shared edge see bit-identical copies of the shared vertices, and `v0 + e1`
//! rebuilt from a stored edge is not the vertex (it rounds). That was the cause of the leaks of
//! the first watertight prototype (docs/robustness.md).

use bytemuck::{Pod, Zeroable};
use glam::{Vec3, Vec4};

use super::lanes::{Lanes, Mask};

/// One triangle as the traversal sees it. Plain `f32` fields (no `Vec3`, whose alignment
/// differs between Rust and WGSL): 36 bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct TriAccel {
    pub v0: [f32; 3],
    pub v1: [f32; 3],
    pub v2: [f32; 3],
}

/// Result of a ray/triangle test: ray parameter and barycentrics of v1 (`u`) and v2 (`v`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TriHit {
    pub t: f32,
    pub u: f32,
    pub v: f32,
}

impl TriHit {
    /// This hit as a structure's `Hit` on triangle `tri`.
    #[inline]
    pub fn on(self, tri: u32) -> super::Hit {
        super::Hit {
            t: self.t,
            tri,
            u: self.u,
            v: self.v,
        }
    }
}

/// How far outside a triangle a point the test accepts can lie, per axis, relative to the
/// triangle's largest box extent; the grid's cell assignment and the BVH's boxes are padded by
/// this much (plus `slack_pad`'s few ulps of the coordinates), so that they find every hit a
/// brute-force test finds.
///
/// The watertight test has no barycentric slack: its edge functions decide "inside" up to the
/// rounding of the sheared vertices. Its `t`, though, is a weighted mean of the vertices'
/// depths along the ray with the computed barycentrics as weights, and for a ray close to the
/// triangle's plane those weights carry relative errors up to about `8 ulp / cos` (ray against
/// the plane; `PARALLEL_COS2` rejects `cos < 2^-20`), which moves the point along the ray. This
/// pad keeps such points inside for `cos` down to about 1e-4; below that a hit can lie outside
/// the padded box and a structure may not report it (as brute force does): rays that graze a
/// triangle to within 1e-4 degrees of its plane, which the tests skip (`TriAccel::grazing_cos`).
pub const SLACK_PAD: f32 = 1.0e-3;

/// Padding for a triangle's box (see `SLACK_PAD`): relative to its size, plus a few ulps of its
/// coordinates (the sheared vertices round at that scale).
pub fn slack_pad(lo: Vec3, hi: Vec3) -> f32 {
    SLACK_PAD * (hi - lo).max_element() + 4.0 * f32::EPSILON * lo.abs().max(hi.abs()).max_element()
}

/// Squared cosine bound for "ray parallel to the triangle" (see `TriAccel::intersect`).
pub const PARALLEL_COS2: f32 = 1.0 / (1u64 << 40) as f32;

/// The axes of a ray's frame in the watertight test: `z` the axis of the direction's largest
/// component, `x` and `y` the next two in cyclic order (so that cross products keep their sign).
#[inline(always)]
fn ray_axes(dir: Vec3) -> [usize; 3] {
    let a = dir.abs();
    // The same comparisons as `LaneRay::new`'s masks (NaN picks z, and then never hits).
    let kz = if a.x > a.y {
        if a.x > a.z { 0 } else { 2 }
    } else if a.y > a.z {
        1
    } else {
        2
    };
    [(kz + 1) % 3, (kz + 2) % 3, kz]
}

/// A ray prepared for the watertight test: its axes (`ray_axes`), its origin in that order,
/// and the shear that maps its direction to `+-z`: `x' = x - sx z`, `y' = y - sy z`, depth
/// `z sz`.
#[derive(Debug, Clone, Copy)]
pub struct ShearedRay {
    pub axes: [usize; 3],
    pub origin: [f32; 3],
    pub sx: f32,
    pub sy: f32,
    pub sz: f32,
    /// `|dir|^2` and `dir[z]^2`, for the grazing test.
    dir_len2: f32,
    dir_z2: f32,
}

impl ShearedRay {
    #[inline(always)]
    pub fn new(origin: Vec3, dir: Vec3) -> ShearedRay {
        let k = ray_axes(dir);
        let sz = 1.0 / dir[k[2]];
        ShearedRay {
            axes: k,
            origin: k.map(|a| origin[a]),
            sx: dir[k[0]] * sz,
            sy: dir[k[1]] * sz,
            sz,
            dir_len2: dir.dot(dir),
            dir_z2: dir[k[2]] * dir[k[2]],
        }
    }

    /// Vertex `p` in the ray's frame: sheared `x`, `y` and the unscaled depth `z`.
    #[inline(always)]
    fn shear(&self, p: [f32; 3]) -> [f32; 3] {
        let [kx, ky, kz] = self.axes;
        let a = [p[kx] - self.origin[0], p[ky] - self.origin[1], p[kz] - self.origin[2]];
        [a[0] - self.sx * a[2], a[1] - self.sy * a[2], a[2]]
    }
}

/// The three edge functions of sheared vertices `p` (twice the signed areas of the triangles
/// the ray's point `(0, 0)` makes with each edge; `e[i]` is the edge opposite vertex `i`).
///
/// Each is a plain difference of two rounded products, which is exactly antisymmetric: the
/// triangle on the other side of a shared edge computes the same two products from the same
/// bits and gets exactly the negated value, so no ray passes between the two (the sign test
/// below puts it in one of them, or in both on an exact 0). A fused multiply-add would break
/// that; Rust never fuses on its own. When some but not all are exactly 0 they are recomputed
/// in `f64`, where the products of `f32`s are exact and the difference is 0 only if it truly
/// is (as pbrt does): an `f32` 0 from two products that round together would otherwise count
/// a ray beside a vertex or an edge as on it. All three 0 is a triangle seen exactly edge-on
/// (its determinant is 0): a miss either way.
#[inline(always)]
fn edge_functions(p: &[[f32; 3]; 3]) -> [f32; 3] {
    let ef = |a: [f32; 3], b: [f32; 3]| a[0] * b[1] - a[1] * b[0];
    let e = [ef(p[1], p[2]), ef(p[2], p[0]), ef(p[0], p[1])];
    let zeros = e.iter().filter(|&&x| x == 0.0).count();
    if zeros == 0 || zeros == 3 {
        e
    } else {
        edge_functions_f64(p)
    }
}

/// `edge_functions` in `f64` (exact products), rounded back to `f32` (which keeps the sign and
/// zero-ness).
#[cold]
#[inline(never)]
fn edge_functions_f64(p: &[[f32; 3]; 3]) -> [f32; 3] {
    let ef = |a: [f32; 3], b: [f32; 3]| (a[0] as f64 * b[1] as f64 - a[1] as f64 * b[0] as f64) as f32;
    [ef(p[1], p[2]), ef(p[2], p[0]), ef(p[0], p[1])]
}

impl TriAccel {
    pub fn new(a: Vec3, b: Vec3, c: Vec3) -> Self {
        TriAccel {
            v0: a.to_array(),
            v1: b.to_array(),
            v2: c.to_array(),
        }
    }

    /// A mesh's triangles with non-zero area, in order: what a scene's preparation traces
    /// (it drops and counts the degenerate ones), for benchmarks and tests that build
    /// structures from a mesh directly.
    pub fn from_mesh(m: &crate::Mesh) -> Vec<TriAccel> {
        m.triangles
            .iter()
            .map(|t| t.map(|i| m.positions[i as usize]))
            .filter(|[a, b, c]| (*b - *a).cross(*c - *a).length_squared() > 0.0)
            .map(|[a, b, c]| TriAccel::new(a, b, c))
            .collect()
    }

    pub fn vertices(&self) -> [Vec3; 3] {
        [self.v0, self.v1, self.v2].map(Vec3::from)
    }

    /// The edges `v1 - v0` and `v2 - v0`.
    #[inline(always)]
    pub fn edges(&self) -> (Vec3, Vec3) {
        let v0 = Vec3::from(self.v0);
        (Vec3::from(self.v1) - v0, Vec3::from(self.v2) - v0)
    }

    /// Unnormalised geometric normal `(v1 - v0) x (v2 - v0)`.
    pub fn normal(&self) -> Vec3 {
        let (e1, e2) = self.edges();
        e1.cross(e2)
    }

    /// `|cos|` of the angle between `dir` and the triangle's normal, in `f64`: below about
    /// 1e-4 the hit `intersect` reports can lie outside the padded boxes (`SLACK_PAD`), so
    /// tests that compare structures with brute force skip rays whose hit grazes that closely.
    pub fn grazing_cos(&self, dir: Vec3) -> f64 {
        let [a, b, c] = self.vertices().map(|v| v.as_dvec3());
        let n = (b - a).cross(c - a);
        let d = dir.as_dvec3();
        (n.dot(d) / (n.length() * d.length())).abs()
    }

    /// The watertight test, two-sided. Returns a hit with `t_min <= t < t_max` (a ray that
    /// starts on the surface hits it at `t = t_min`, as Embree and Open3D count it).
    ///
    /// The vertices are moved into the ray's frame (`ShearedRay`: origin at 0, direction along
    /// `z`), where the ray is the point `(0, 0)` and the test is whether that point lies inside
    /// the 2D triangle: the three edge functions all `>= 0` or all `<= 0` (`edge_functions`
    /// says why a shared edge cannot let a ray through). `u`, `v` and `t` follow from them.
    ///
    /// Rays (nearly) in the triangle's plane are rejected by a *relative* determinant test:
    /// `|cos(a)| < 2^-20` between the ray and the plane. There the edge functions are rounding
    /// noise relative to their sum, and the barycentrics (and so `t`, their weighted mean of
    /// the vertices' depths) can be off by most of the triangle. A grazing ray through a
    /// closed mesh still hits the neighbouring triangles, so nothing leaks.
    #[inline(always)]
    pub fn intersect(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<TriHit> {
        self.intersect_sheared(&ShearedRay::new(origin, dir), t_min, t_max)
    }

    /// `intersect` for a ray already in its frame (a walk prepares it once per ray).
    #[inline(always)]
    pub fn intersect_sheared(&self, ray: &ShearedRay, t_min: f32, t_max: f32) -> Option<TriHit> {
        let p = [ray.shear(self.v0), ray.shear(self.v1), ray.shear(self.v2)];
        let e = edge_functions(&p);
        if (e[0] < 0.0 || e[1] < 0.0 || e[2] < 0.0) && (e[0] > 0.0 || e[1] > 0.0 || e[2] > 0.0) {
            return None;
        }
        let det = e[0] + e[1] + e[2];
        if det == 0.0 {
            return None;
        }
        let inv_det = 1.0 / det;
        // `+ 0.0` turns a -0 (a ray starting on the triangle: depths of 0 times negative edge
        // functions) into +0, so that a hit at t = 0 has one representation: the BVH's block
        // test takes the least t by value (`min_element`), where -0 and +0 tie and either could
        // come back, and the walks must answer bit for bit alike.
        let t = (e[0] * p[0][2] + e[1] * p[1][2] + e[2] * p[2][2]) * (ray.sz * inv_det) + 0.0;
        if !(t >= t_min && t < t_max) {
            return None;
        }
        // The grazing test last: it is a pure filter, and most candidates never get here.
        // `det = n . dir / dir[z]` (the shear has determinant 1), so this is
        // `cos^2 = (n . dir)^2 / (|n|^2 |dir|^2) <= PARALLEL_COS2`.
        let n = self.normal();
        if det * det * ray.dir_z2 <= PARALLEL_COS2 * n.length_squared() * ray.dir_len2 {
            return None;
        }
        Some(TriHit {
            t,
            u: e[1] * inv_det,
            v: e[2] * inv_det,
        })
    }
}

mod packed;

pub use packed::*;

/// The closest hit among the triangles `refs` names (indices into `tris`) with
/// `t_min <= t < best.t`, into `best`: a grid cell's triangle loop, shared by the uniform and
/// the irregular grid.
#[inline(always)]
pub(crate) fn closest_in<C: super::Counters>(
    tris: &[TriAccel],
    refs: &[u32],
    ray: &super::Ray,
    best: &mut super::Hit,
    counters: &mut C,
) {
    let sheared = ShearedRay::new(ray.origin, ray.dir);
    for &tri in refs {
        counters.tri_test();
        if let Some(h) = tris[tri as usize].intersect_sheared(&sheared, ray.t_min, best.t) {
            *best = h.on(tri);
        }
    }
}

/// Whether any triangle `refs` names is hit in the ray's interval (stops at the first).
#[inline(always)]
pub(crate) fn any_in<C: super::Counters>(tris: &[TriAccel], refs: &[u32], ray: &super::Ray, counters: &mut C) -> bool {
    let sheared = ShearedRay::new(ray.origin, ray.dir);
    refs.iter().any(|&tri| {
        counters.tri_test();
        tris[tri as usize]
            .intersect_sheared(&sheared, ray.t_min, ray.t_max)
            .is_some()
    })
}

#[cfg(test)]
mod tests;
