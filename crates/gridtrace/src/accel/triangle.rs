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

/// Four triangles side by side, one per SIMD lane (structure of arrays: `v0[axis]` holds that
/// coordinate of all four), so that one `intersect` tests them all. The BVH's leaves are made
/// of these, as Embree's are of its `Triangle4`: a leaf costs about one triangle test instead of
/// up to four, and its triangles are three adjacent cache lines.
///
/// An unused lane is all zeros: its edge functions are all exactly 0 (determinant 0), which is
/// never a hit.
#[repr(C, align(16))]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TriAccel4 {
    pub v0: [Vec4; 3],
    pub v1: [Vec4; 3],
    pub v2: [Vec4; 3],
}

/// The lanes of a `TriAccel4` test that hit, and where.
pub type TriHit4 = LaneHits<4, Vec4>;

/// A `Vec3` computation done on `N` lanes at once: `[x, y, z]`, a triangle or a ray per lane.
type Lanes3<L> = [L; 3];

/// `a x b`, in exactly the operation order of glam's scalar `Vec3::cross`, so that every lane
/// rounds as `TriAccel::intersect` does.
#[inline(always)]
fn cross_lanes<const N: usize, L: Lanes<N>>(a: &Lanes3<L>, b: &Lanes3<L>) -> Lanes3<L> {
    [
        a[1] * b[2] - b[1] * a[2],
        a[2] * b[0] - b[2] * a[0],
        a[0] * b[1] - b[0] * a[1],
    ]
}

/// `a . b`, in the operation order of glam's scalar `Vec3::dot`.
#[inline(always)]
fn dot_lanes<const N: usize, L: Lanes<N>>(a: &Lanes3<L>, b: &Lanes3<L>) -> L {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline(always)]
fn sub_lanes<const N: usize, L: Lanes<N>>(a: &Lanes3<L>, b: &Lanes3<L>) -> Lanes3<L> {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// What a lane-parallel test found: the lanes that hit, and where.
#[derive(Debug, Clone, Copy)]
pub struct LaneHits<const N: usize, L: Lanes<N>> {
    pub hit: L::Mask,
    pub t: L,
    pub u: L,
    pub v: L,
}

impl<const N: usize, L: Lanes<N>> LaneHits<N, L> {
    /// The lanes that hit, bit `k` for lane `k`.
    #[inline(always)]
    pub fn mask(&self) -> u32 {
        self.hit.bits()
    }

    /// The hit of lane `k` (meaningful where `mask` has bit `k`).
    #[inline(always)]
    pub fn lane(&self, k: usize) -> TriHit {
        TriHit {
            t: self.t.to_array()[k],
            u: self.u.to_array()[k],
            v: self.v.to_array()[k],
        }
    }
}

/// `ShearedRay` on `N` lanes: a ray per lane, or one ray in every lane (`uniform`: the axes are
/// then picked by indexing, not by a select per coordinate).
#[derive(Debug, Clone, Copy)]
pub struct LaneRay<const N: usize, L: Lanes<N>> {
    /// The same axes in every lane, when known.
    uniform: Option<[usize; 3]>,
    /// Lanes whose `z` axis is world x, and world y (the others: z).
    z_is_x: L::Mask,
    z_is_y: L::Mask,
    origin: Lanes3<L>,
    sx: L,
    sy: L,
    sz: L,
    dir_len2: L,
    dir_z2: L,
}

impl<const N: usize, L: Lanes<N>> LaneRay<N, L> {
    /// A ray per lane, each prepared as `ShearedRay::new` does, bit for bit.
    #[inline(always)]
    pub fn new(origin: &Lanes3<L>, dir: &Lanes3<L>) -> Self {
        let a = [dir[0].abs(), dir[1].abs(), dir[2].abs()];
        // `ray_axes`' comparisons, lane by lane.
        let x_gt_y = a[0].gt(a[1]);
        let z_is_x = x_gt_y & a[0].gt(a[2]);
        let z_is_y = !x_gt_y & a[1].gt(a[2]);
        let mut r = LaneRay {
            uniform: None,
            z_is_x,
            z_is_y,
            origin: *origin,
            sx: L::ZERO,
            sy: L::ZERO,
            sz: L::ZERO,
            dir_len2: dot_lanes(dir, dir),
            dir_z2: L::ZERO,
        };
        // Coherent rays (a camera's packet) mostly share their axes: then they are picked by
        // indexing, as for one ray (`splat`), not by two selects per coordinate.
        let all = (1u32 << N) - 1;
        let (on_x, on_y) = (z_is_x.bits(), z_is_y.bits());
        r.uniform = match (on_x, on_y) {
            (x, 0) if x == all => Some([1, 2, 0]),
            (0, y) if y == all => Some([2, 0, 1]),
            (0, 0) => Some([0, 1, 2]),
            _ => None,
        };
        r.origin = r.permute(origin);
        let d = r.permute(dir);
        r.sz = L::ONE / d[2];
        r.sx = d[0] * r.sz;
        r.sy = d[1] * r.sz;
        r.dir_z2 = d[2] * d[2];
        r
    }

    /// One ray in every lane.
    #[inline(always)]
    pub fn splat(ray: &ShearedRay) -> Self {
        LaneRay {
            uniform: Some(ray.axes),
            z_is_x: L::Mask::from_bits(0),
            z_is_y: L::Mask::from_bits(0),
            origin: ray.origin.map(L::splat),
            sx: L::splat(ray.sx),
            sy: L::splat(ray.sy),
            sz: L::splat(ray.sz),
            dir_len2: L::splat(ray.dir_len2),
            dir_z2: L::splat(ray.dir_z2),
        }
    }

    /// `p` in the lanes' axis order `[x, y, z]` (see `ray_axes`).
    #[inline(always)]
    fn permute(&self, p: &Lanes3<L>) -> Lanes3<L> {
        if let Some([kx, ky, kz]) = self.uniform {
            return [p[kx], p[ky], p[kz]];
        }
        let pick = |when_x: usize, when_y: usize, when_z: usize| {
            L::select(self.z_is_x, p[when_x], L::select(self.z_is_y, p[when_y], p[when_z]))
        };
        [pick(1, 2, 0), pick(2, 0, 1), pick(0, 1, 2)]
    }

    /// `ShearedRay::shear`, lane by lane.
    #[inline(always)]
    fn shear(&self, p: &Lanes3<L>) -> Lanes3<L> {
        let q = self.permute(p);
        self.shear_xy(&[q[0] - self.origin[0], q[1] - self.origin[1], q[2] - self.origin[2]])
    }

    /// The shear's second step, on a vertex already permuted and less the origin.
    #[inline(always)]
    fn shear_xy(&self, a: &Lanes3<L>) -> Lanes3<L> {
        [a[0] - self.sx * a[2], a[1] - self.sy * a[2], a[2]]
    }

    /// The frame every lane shares, where all lanes have the same axes and bit-identical
    /// origins (a pinhole camera's packet); `None` otherwise.
    #[inline(always)]
    pub fn shared_frame(&self) -> Option<SharedFrame> {
        let axes = self.uniform?;
        let o = [
            self.origin[0].to_array(),
            self.origin[1].to_array(),
            self.origin[2].to_array(),
        ];
        let same = |c: &[f32; N]| c.iter().all(|x| x.to_bits() == c[0].to_bits());
        (same(&o[0]) && same(&o[1]) && same(&o[2])).then_some(SharedFrame {
            axes,
            origin: [o[0][0], o[1][0], o[2][0]],
        })
    }
}

/// The axes and origin of a `LaneRay` whose lanes share them (`LaneRay::shared_frame`): the
/// first step of the shear (permute, subtract the origin) is then the same for every lane and
/// is done once per block of four triangles (`translate4`), instead of once per lane and triangle. The same IEEE
/// operations on the same values, so the same bits (`intersect_frame_cull`).
#[derive(Debug, Clone, Copy)]
pub struct SharedFrame {
    axes: [usize; 3],
    origin: [f32; 3],
}

impl SharedFrame {
    /// A block's four triangles moved into the frame, four at a time (SSE): per corner, per
    /// axis of the frame, the four triangles' coordinates less the origin's.
    #[inline(always)]
    pub fn translate4(&self, block: &TriAccel4) -> [[[f32; 4]; 3]; 3] {
        let [kx, ky, kz] = self.axes;
        let o = self.origin;
        let corner = |c: &[Vec4; 3]| {
            [
                (c[kx] - Vec4::splat(o[0])).to_array(),
                (c[ky] - Vec4::splat(o[1])).to_array(),
                (c[kz] - Vec4::splat(o[2])).to_array(),
            ]
        };
        [corner(&block.v0), corner(&block.v1), corner(&block.v2)]
    }
}

/// `TriAccel::intersect` on `N` lanes at once (a triangle and a ray per lane, with a `t_max`
/// per lane), with bit-identical results: the same operations in the same order (IEEE
/// arithmetic rounds the same in a SIMD lane as in a scalar register, and Rust never fuses
/// multiply-adds on its own). Every early return of the scalar test becomes a lane mask, each
/// the same comparison (negated where the scalar test rejects), so that NaNs fall the same way.
#[inline(always)]
pub fn intersect_lanes<const N: usize, L: Lanes<N>>(
    tri: (&Lanes3<L>, &Lanes3<L>, &Lanes3<L>),
    ray: &LaneRay<N, L>,
    t_min: f32,
    t_max: L,
) -> LaneHits<N, L> {
    intersect_lanes_cull::<N, L, false>(tri, ray, t_min, t_max)
}

/// `intersect_lanes`, the same `LaneHits` bit for bit; with `CULL` returned as soon as the
/// edge and distance checks reject every lane, before the grazing test (which only ever
/// rejects more): most of a BVH leaf's blocks are missed by every lane (incoherent rays,
/// Stanford Bunny: 5.4 triangles tested per ray, 0.6 hit).
#[inline(always)]
pub fn intersect_lanes_cull<const N: usize, L: Lanes<N>, const CULL: bool>(
    (v0, v1, v2): (&Lanes3<L>, &Lanes3<L>, &Lanes3<L>),
    ray: &LaneRay<N, L>,
    t_min: f32,
    t_max: L,
) -> LaneHits<N, L> {
    let p = [ray.shear(v0), ray.shear(v1), ray.shear(v2)];
    let (h, det) = sheared_lanes(&p, ray, t_min, t_max);
    if CULL && h.hit.bits() == 0 {
        return h;
    }
    // Grazing rays (see `TriAccel::intersect`).
    let n = cross_lanes(&sub_lanes(v1, v0), &sub_lanes(v2, v0));
    not_grazing(h, det, dot_lanes(&n, &n), ray)
}

/// `intersect_lanes_cull` for one triangle against every lane of a ray whose lanes share their
/// frame (`LaneRay::shared_frame`): `rel` are the triangle's vertices moved into it
/// (`SharedFrame::translate4`) and splatted. The same `LaneHits`, bit for bit: the per-lane
/// shear starts from the same translated values, and the grazing test's normal is the
/// triangle's own (`tri`, asked for only when some lane hits: `TriAccel::normal`, the
/// operations of `cross_lanes` and `dot_lanes`), in scalar.
#[inline(always)]
pub fn intersect_frame_cull<const N: usize, L: Lanes<N>, const CULL: bool>(
    rel: [Lanes3<L>; 3],
    tri: impl FnOnce() -> TriAccel,
    ray: &LaneRay<N, L>,
    t_min: f32,
    t_max: L,
) -> LaneHits<N, L> {
    let p = [ray.shear_xy(&rel[0]), ray.shear_xy(&rel[1]), ray.shear_xy(&rel[2])];
    let (h, det) = sheared_lanes(&p, ray, t_min, t_max);
    if CULL && h.hit.bits() == 0 {
        return h;
    }
    not_grazing(h, det, L::splat(tri().normal().length_squared()), ray)
}

/// `h` less the lanes whose ray grazes the triangle's plane (`TriAccel::intersect`'s relative
/// determinant test): `det` the lanes' determinants, `n_len2` the squared normal.
#[inline(always)]
fn not_grazing<const N: usize, L: Lanes<N>>(
    h: LaneHits<N, L>,
    det: L,
    n_len2: L,
    ray: &LaneRay<N, L>,
) -> LaneHits<N, L> {
    let grazing = (det * det * ray.dir_z2).le(L::splat(PARALLEL_COS2) * n_len2 * ray.dir_len2);
    LaneHits {
        hit: h.hit & !grazing,
        ..h
    }
}

/// The lanes' test on sheared vertices `p` (`ShearedRay::shear`), up to the grazing test: the
/// hits by edge functions and distance, and the determinants.
#[inline(always)]
fn sheared_lanes<const N: usize, L: Lanes<N>>(
    p: &[Lanes3<L>; 3],
    ray: &LaneRay<N, L>,
    t_min: f32,
    t_max: L,
) -> (LaneHits<N, L>, L) {
    let ef = |a: &Lanes3<L>, b: &Lanes3<L>| a[0] * b[1] - a[1] * b[0];
    let mut e = [ef(&p[1], &p[2]), ef(&p[2], &p[0]), ef(&p[0], &p[1])];
    // `edge_functions`' exact fallback, for the (rare) lanes where some but not all are 0.
    // Written out, not `e.map(|x| ...)`: a closure does not inherit `#[target_feature]`, so in
    // the AVX2 packet walk that closure's comparisons were calls (`_mm256_cmp_ps`,
    // `_mm256_xor_ps` and `array::map` out of line), about 260 instructions an eight-lane
    // triangle test: eye rays 893 -> 673 instructions a ray, camera 1,424 -> 1,037
    // (cachegrind, docs/benchmarks.md).
    let zero = [!e[0].ne(L::ZERO), !e[1].ne(L::ZERO), !e[2].ne(L::ZERO)];
    let refine = (zero[0] | zero[1] | zero[2]) & !(zero[0] & zero[1] & zero[2]);
    if refine.bits() != 0 {
        e = refine_lanes(p, e, refine.bits());
    }
    let neg = e[0].lt(L::ZERO) | e[1].lt(L::ZERO) | e[2].lt(L::ZERO);
    let pos = e[0].gt(L::ZERO) | e[1].gt(L::ZERO) | e[2].gt(L::ZERO);
    let det = e[0] + e[1] + e[2];
    let inv_det = L::ONE / det;
    let t = (e[0] * p[0][2] + e[1] * p[1][2] + e[2] * p[2][2]) * (ray.sz * inv_det) + L::ZERO;
    let ok = !(neg & pos) & det.ne(L::ZERO) & t.ge(L::splat(t_min)) & t.lt(t_max);
    let (u, v) = (e[1] * inv_det, e[2] * inv_det);
    (LaneHits { hit: ok, t, u, v }, det)
}

/// `edge_functions_f64` for the lanes in `lanes` (bits), the others' `e` kept.
#[cold]
#[inline(never)]
fn refine_lanes<const N: usize, L: Lanes<N>>(p: &[Lanes3<L>; 3], e: [L; 3], lanes: u32) -> [L; 3] {
    let p = p.map(|v| v.map(L::to_array));
    let mut e = e.map(L::to_array);
    for k in 0..N {
        if lanes >> k & 1 == 1 {
            let lane = p.map(|v| [v[0][k], v[1][k], v[2][k]]);
            let r = edge_functions_f64(&lane);
            for i in 0..3 {
                e[i][k] = r[i];
            }
        }
    }
    e.map(L::from_array)
}

impl TriAccel4 {
    /// Triangles per block.
    pub const LANES: usize = 4;

    /// Packs up to four triangles; the lanes past `tris.len()` are left unused.
    pub fn pack(tris: &[TriAccel]) -> TriAccel4 {
        assert!(tris.len() <= Self::LANES, "four triangles at most");
        let mut p = TriAccel4 {
            v0: [Vec4::ZERO; 3],
            v1: [Vec4::ZERO; 3],
            v2: [Vec4::ZERO; 3],
        };
        for (k, t) in tris.iter().enumerate() {
            for a in 0..3 {
                p.v0[a][k] = t.v0[a];
                p.v1[a][k] = t.v1[a];
                p.v2[a][k] = t.v2[a];
            }
        }
        p
    }

    /// `TriAccel::normal` of lane `k`, bit for bit.
    #[inline(always)]
    pub fn normal(&self, k: usize) -> Vec3 {
        self.lane(k).normal()
    }

    /// The triangle in lane `k`.
    pub fn lane(&self, k: usize) -> TriAccel {
        TriAccel {
            v0: self.v0.map(|c| c[k]),
            v1: self.v1.map(|c| c[k]),
            v2: self.v2.map(|c| c[k]),
        }
    }

    /// `TriAccel::intersect` on all four lanes at once, with bit-identical results (see
    /// `intersect_lanes`): a ray per lane.
    #[inline(always)]
    pub fn intersect(&self, origin: &[Vec4; 3], dir: &[Vec4; 3], t_min: f32, t_max: f32) -> TriHit4 {
        self.intersect_upto(origin, dir, t_min, Vec4::splat(t_max))
    }

    /// One triangle in all four lanes: what `intersect_upto` tests four rays against.
    #[inline(always)]
    pub fn splat(tri: &TriAccel) -> TriAccel4 {
        TriAccel4 {
            v0: tri.v0.map(Vec4::splat),
            v1: tri.v1.map(Vec4::splat),
            v2: tri.v2.map(Vec4::splat),
        }
    }

    /// `intersect` with a `t_max` per lane: four triangles against one ray each, or one
    /// triangle (`splat`) against four rays (a packet walk: each ray up to its own closest hit).
    /// Lane by lane the same bits as `TriAccel::intersect` with that lane's ray and `t_max`.
    #[inline(always)]
    pub fn intersect_upto(&self, origin: &[Vec4; 3], dir: &[Vec4; 3], t_min: f32, t_max: Vec4) -> TriHit4 {
        let ray = LaneRay::new(origin, dir);
        intersect_lanes((&self.v0, &self.v1, &self.v2), &ray, t_min, t_max)
    }

    /// The four triangles against one prepared ray (a BVH leaf).
    #[inline(always)]
    pub fn intersect_ray(&self, ray: &LaneRay<4, Vec4>, t_min: f32, t_max: f32) -> TriHit4 {
        intersect_lanes((&self.v0, &self.v1, &self.v2), ray, t_min, Vec4::splat(t_max))
    }
}

/// The closest hit among the triangles `refs` names (indices into `tris`) with
/// `t_min <= t < best.t`, into `best`: a grid cell's triangle loop, shared by the uniform and
/// the irregular grid.
#[inline(always)]
pub(crate) fn closest_in<C: super::Counters>(
    tris: &[TriAccel],
    refs: &[u32],
    ray: &super::Ray,
    t_min: f32,
    best: &mut super::Hit,
    counters: &mut C,
) {
    let sheared = ShearedRay::new(ray.origin, ray.dir);
    for &tri in refs {
        counters.tri_test();
        if let Some(h) = tris[tri as usize].intersect_sheared(&sheared, t_min, best.t) {
            *best = h.on(tri);
        }
    }
}

/// Whether any triangle `refs` names is hit with `t_min <= t < t_max` (stops at the first).
#[inline(always)]
pub(crate) fn any_in<C: super::Counters>(
    tris: &[TriAccel],
    refs: &[u32],
    ray: &super::Ray,
    t_min: f32,
    t_max: f32,
    counters: &mut C,
) -> bool {
    let sheared = ShearedRay::new(ray.origin, ray.dir);
    refs.iter().any(|&tri| {
        counters.tri_test();
        tris[tri as usize].intersect_sheared(&sheared, t_min, t_max).is_some()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::lanes::{load3, splat3};
    use crate::util::Rng;

    /// Whether a lane's answer is the scalar test's: both misses, or both hits with the same
    /// bits of t, u and v.
    fn same_bits(want: Option<TriHit>, lane: Option<TriHit>) -> bool {
        match (want, lane) {
            (Some(w), Some(l)) => {
                w.t.to_bits() == l.t.to_bits() && w.u.to_bits() == l.u.to_bits() && w.v.to_bits() == l.v.to_bits()
            }
            (None, None) => true,
            _ => false,
        }
    }

    /// The four-lane test gives bit for bit what the scalar one gives, lane by lane: random
    /// triangles (some slivers, some huge, some far away) and rays aimed at their edges, vertices
    /// and interiors, from near and far, including grazing ones and limits on t.
    #[test]
    fn four_lanes_equal_the_scalar_test() {
        let mut rng = Rng::new(0x7E57);
        let point = |rng: &mut Rng, scale: f32| {
            Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)) * scale
        };
        let (mut hits, mut edge_hits) = (0, 0);
        for round in 0..20_000 {
            let scale = [1.0, 1e-3, 1e3][round % 3];
            let offset = point(&mut rng, [0.0, 10.0, 1e4][round / 3 % 3]);
            let used = 1 + round % 4;
            let tris: Vec<TriAccel> = (0..used)
                .map(|k| {
                    let a = offset + point(&mut rng, scale);
                    let b = a + point(&mut rng, scale);
                    // Every third triangle a sliver.
                    let c = if k % 3 == 2 {
                        a + (b - a) * rng.range(0.0, 1.0) + point(&mut rng, scale * 1e-4)
                    } else {
                        a + point(&mut rng, scale)
                    };
                    TriAccel::new(a, b, c)
                })
                .collect();
            let block = TriAccel4::pack(&tris);
            // Aim at a point of one of the triangles: inside, on an edge or at a vertex.
            let target_tri = tris[round % used].vertices();
            let (wu, wv) = match round % 4 {
                0 => (rng.range(0.0, 1.0), 0.0),
                1 => (1.0, 0.0),
                _ => (rng.range(0.0, 0.6), rng.range(0.0, 0.6)),
            };
            let target = target_tri[0] + (target_tri[1] - target_tri[0]) * wu + (target_tri[2] - target_tri[0]) * wv;
            // From 1 to 100,000 triangle sizes away: the far ones need the error-bound slack.
            let away = scale * 10f32.powf(rng.range(0.0, 5.0));
            let origin = target + point(&mut rng, 1.0).normalize_or(Vec3::X) * away;
            let dir = (target - origin) * rng.range(0.1, 10.0);
            let (t_min, t_max) = if round % 5 == 0 {
                (0.0, rng.range(0.0, 1.5))
            } else {
                (0.0, f32::INFINITY)
            };
            let o4 = origin.to_array().map(Vec4::splat);
            let d4 = dir.to_array().map(Vec4::splat);
            let got = block.intersect(&o4, &d4, t_min, t_max);
            for k in 0..4 {
                let want = tris.get(k).and_then(|t| t.intersect(origin, dir, t_min, t_max));
                let lane = (got.mask() >> k & 1 == 1).then(|| got.lane(k));
                let same = same_bits(want, lane);
                assert!(same, "round {round} lane {k}: scalar {want:?}, four lanes {lane:?}");
                hits += want.is_some() as u32;
                edge_hits += (want.is_some() && wv == 0.0) as u32;
            }
            assert_eq!(block.lane(round % used), tris[round % used]);
        }
        // The rays really exercise hits, edges included.
        assert!(hits > 10_000 && edge_hits > 3_000, "{hits} hits, {edge_hits} on edges");
    }

    /// The lane-parallel test as the packet walk calls it, one triangle in every lane and a
    /// different ray per lane, each with its own `t_max`: every lane gives bit for bit what
    /// the scalar test gives for its ray, four lanes (SSE) and, where the CPU has AVX2, eight
    /// (AVX). Triangles of three sizes, near the origin and far from it; rays at edges,
    /// vertices and interiors from 1 to 100,000 triangle sizes away, grazing ones included.
    /// Every other round the lanes share lane 0's origin (a pinhole's packet), and where they
    /// share their axes too the shared-frame test (`intersect_frame_cull`) gives the same bits.
    #[test]
    fn a_ray_per_lane_equals_the_scalar_test() {
        rays_per_lane::<4, Vec4>();
        #[cfg(target_arch = "x86_64")]
        if crate::accel::simd::has_avx2() {
            // SAFETY: the CPU has AVX2, checked just above.
            unsafe { rays_per_lane_avx() };
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn rays_per_lane_avx() {
        rays_per_lane::<8, crate::accel::lanes::F8>();
    }

    #[inline(always)]
    fn rays_per_lane<const N: usize, L: Lanes<N>>() {
        let mut rng = Rng::new(0x1A_7E5 + N as u64);
        let point = |rng: &mut Rng, scale: f32| {
            Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)) * scale
        };
        let (mut hits, mut edge_hits, mut limited, mut framed) = (0, 0, 0, 0);
        for round in 0..10_000 {
            let scale = [1.0, 1e-3, 1e3][round % 3];
            let offset = point(&mut rng, [0.0, 10.0, 1e4][round / 3 % 3]);
            let a = offset + point(&mut rng, scale);
            let b = a + point(&mut rng, scale);
            let c = if round % 5 == 4 {
                // A sliver.
                a + (b - a) * rng.range(0.0, 1.0) + point(&mut rng, scale * 1e-4)
            } else {
                a + point(&mut rng, scale)
            };
            let tri = TriAccel::new(a, b, c);
            let (mut origin, mut dir, mut t_max, mut on_edge) = ([[0.0; N]; 3], [[0.0; N]; 3], [0.0; N], [false; N]);
            for k in 0..N {
                let (wu, wv) = match (round + k) % 4 {
                    0 => (rng.range(0.0, 1.0), 0.0),
                    1 => (1.0, 0.0),
                    _ => (rng.range(0.0, 0.6), rng.range(0.0, 0.6)),
                };
                on_edge[k] = wv == 0.0;
                let target = a + (b - a) * wu + (c - a) * wv;
                let away = scale * 10f32.powf(rng.range(0.0, 5.0));
                let mut o = target + point(&mut rng, 1.0).normalize_or(Vec3::X) * away;
                // Every other round a pinhole's packet: every lane from lane 0's origin.
                if round % 2 == 1 && k > 0 {
                    o = Vec3::new(origin[0][0], origin[1][0], origin[2][0]);
                }
                let d = (target - o) * rng.range(0.1, 10.0);
                for ax in 0..3 {
                    origin[ax][k] = o[ax];
                    dir[ax][k] = d[ax];
                }
                t_max[k] = if (round + k) % 5 == 0 {
                    rng.range(0.0, 1.5)
                } else {
                    f32::INFINITY
                };
            }
            let corners = (&splat3(tri.v0), &splat3(tri.v1), &splat3(tri.v2));
            let ray = LaneRay::new(&load3(origin), &load3(dir));
            let got = intersect_lanes::<N, L>(corners, &ray, 0.0, L::from_array(t_max));
            // Lanes sharing their frame: the translation once for all (the packet walk's route
            // for a pinhole's packets) gives the same bits.
            assert_eq!(ray.shared_frame().is_some(), round % 2 == 1 && ray.uniform.is_some());
            if let Some(frame) = ray.shared_frame() {
                let [c0, c1, c2] = frame.translate4(&TriAccel4::splat(&tri));
                // (Written out: a closure's `splat3` would not be compiled for AVX.)
                let rel = [
                    splat3([c0[0][0], c0[1][0], c0[2][0]]),
                    splat3([c1[0][0], c1[1][0], c1[2][0]]),
                    splat3([c2[0][0], c2[1][0], c2[2][0]]),
                ];
                let framed_hits = intersect_frame_cull::<N, L, false>(rel, || tri, &ray, 0.0, L::from_array(t_max));
                for k in 0..N {
                    let want = (got.mask() >> k & 1 == 1).then(|| got.lane(k));
                    let lane = (framed_hits.mask() >> k & 1 == 1).then(|| framed_hits.lane(k));
                    assert!(
                        same_bits(want, lane),
                        "{N} lanes, round {round} lane {k}: {want:?}, framed {lane:?}"
                    );
                }
                framed += 1;
            }
            for k in 0..N {
                let o = Vec3::new(origin[0][k], origin[1][k], origin[2][k]);
                let d = Vec3::new(dir[0][k], dir[1][k], dir[2][k]);
                let want = tri.intersect(o, d, 0.0, t_max[k]);
                let lane = (got.mask() >> k & 1 == 1).then(|| got.lane(k));
                let same = same_bits(want, lane);
                assert!(
                    same,
                    "{N} lanes, round {round} lane {k}: scalar {want:?}, lanes {lane:?}"
                );
                hits += want.is_some() as u32;
                edge_hits += (want.is_some() && on_edge[k]) as u32;
                limited += (want.is_none() && t_max[k] < f32::INFINITY) as u32;
            }
        }
        // Hits, hits on edges and rays stopped by their own limit all occur.
        let rays = 10_000 * N as u32;
        assert!(
            hits > rays / 2 && edge_hits > rays / 8 && limited > rays / 50 && framed > 2_000,
            "{N} lanes: {hits} hits, {edge_hits} on edges, {limited} cut by t_max, of {rays}; {framed} rounds framed"
        );
    }

    /// No false hits, no misses inside (`testing::near_miss_rays`: head-on rays 1e-6 or more
    /// beside an edge from 1 and 1e4 units, grazing ones at 1e-3 rad 1e-5 or more beside), and
    /// a ray starting on the triangle hits at `t = 0`, but not with `t_min` above 0: the scalar
    /// test and the four lanes alike. Möller-Trumbore with its barycentric slack hit at 1e-6
    /// outside from 1 unit, and up to 1e-3 from 1e4 or grazing.
    #[test]
    fn near_misses_miss_and_near_hits_hit() {
        let tri = crate::testing::unit_triangle();
        let rays = crate::testing::near_miss_rays();
        for m in &rays {
            let (o, d) = (m.ray.origin, m.ray.dir);
            let scalar = tri.intersect(o, d, 0.0, f32::INFINITY);
            let four = TriAccel4::splat(&tri).intersect(
                &o.to_array().map(Vec4::splat),
                &d.to_array().map(Vec4::splat),
                0.0,
                f32::INFINITY,
            );
            assert_eq!(scalar.is_some(), m.hits, "{m:?}: {scalar:?}");
            assert_eq!(four.mask(), if m.hits { 0xf } else { 0 }, "{m:?}");
            if let Some(t) = m.t {
                // +0 exactly (never -0), in every lane too.
                assert_eq!(scalar.map(|h| h.t.to_bits()), Some(t.to_bits()), "{m:?}");
                assert!((0..4).all(|k| four.lane(k).t.to_bits() == t.to_bits()), "{m:?}");
                assert!(tri.intersect(o, d, 1e-30, f32::INFINITY).is_none(), "{m:?}");
            }
        }
        assert!(rays.len() > 1500, "{} rays", rays.len());
    }

    /// Watertight at shared edges and vertices, by construction: a fan of triangles around a
    /// vertex (with exactly representable but irregular coordinates, seen from far away and
    /// tilted), rays aimed exactly at the centre and at points of the shared edges: every ray
    /// hits at least one triangle of the fan.
    #[test]
    fn rays_through_shared_edges_and_vertices_hit_a_neighbour() {
        let mut rng = Rng::new(0xFA7);
        for round in 0..2_000 {
            let scale = [1.0, 1e-3, 1e3][round % 3];
            let centre = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)) * scale * 10.0;
            let n = 5 + round % 4;
            let rim: Vec<Vec3> = (0..n)
                .map(|k| {
                    let a = (k as f32 + rng.range(-0.3, 0.3)) / n as f32 * std::f32::consts::TAU;
                    centre + Vec3::new(a.cos(), a.sin(), rng.range(-0.3, 0.3)) * scale * rng.range(0.5, 1.5)
                })
                .collect();
            let fan: Vec<TriAccel> = (0..n)
                .map(|k| TriAccel::new(centre, rim[k], rim[(k + 1) % n]))
                .collect();
            let k = round % n;
            // The centre, or a point of a spoke (short of the rim, where the fan ends).
            let target = if round % 2 == 0 {
                centre
            } else {
                centre + (rim[k] - centre) * rng.range(0.0, 0.95)
            };
            let away = scale * 10f32.powf(rng.range(0.0, 4.0));
            let dir = Vec3::new(rng.range(-0.5, 0.5), rng.range(-0.5, 0.5), -1.0);
            let origin = target - dir * away;
            let hit = fan
                .iter()
                .any(|t| t.intersect(origin, dir, 0.0, f32::INFINITY).is_some());
            assert!(
                hit,
                "round {round}: a ray at {target} from {origin} passed through the fan"
            );
        }
    }
}
