//! Triangles stored the way the paper stores them: the first vertex and the two edges from it,
//! which saves two vector subtractions in every Möller-Trumbore test.

use bytemuck::{Pod, Zeroable};
use glam::{Vec3, Vec4};

use super::lanes::{Lanes, Mask};

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

/// Four triangles side by side, one per SIMD lane (structure of arrays: `v0[axis]` holds that
/// coordinate of all four), so that one `intersect` tests them all. The BVH's leaves are made
/// of these, as Embree's are of its `Triangle4`: a leaf costs about one triangle test instead of
/// up to four, and its triangles are three adjacent cache lines.
///
/// An unused lane is all zeros: its determinant is exactly 0, which is never a hit.
#[repr(C, align(16))]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TriAccel4 {
    pub v0: [Vec4; 3],
    pub e1: [Vec4; 3],
    pub e2: [Vec4; 3],
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

/// `|x| + |y| + |z|`, in the order of `l1`.
#[inline(always)]
fn l1_lanes<const N: usize, L: Lanes<N>>(a: &Lanes3<L>) -> L {
    a[0].abs() + a[1].abs() + a[2].abs()
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

/// `TriAccel::intersect` on `N` lanes at once (a triangle and a ray per lane, with a `t_max`
/// per lane), with bit-identical results: the same operations in the same order (IEEE
/// arithmetic rounds the same in a SIMD lane as in a scalar register, and Rust never fuses
/// multiply-adds on its own). Every early return of the scalar test becomes a lane mask, each
/// the same comparison (negated where the scalar test rejects), so that NaNs fall the same way.
#[inline(always)]
pub fn intersect_lanes<const N: usize, L: Lanes<N>>(
    tri: (&Lanes3<L>, &Lanes3<L>, &Lanes3<L>),
    origin: &Lanes3<L>,
    dir: &Lanes3<L>,
    t_min: f32,
    t_max: L,
) -> LaneHits<N, L> {
    intersect_lanes_cull::<N, L, false>(tri, origin, dir, t_min, t_max)
}

/// `intersect_lanes`, the same `LaneHits` bit for bit; with `CULL` returned as soon as the
/// barycentric and distance checks reject every lane, before the error bound and the grazing
/// test (which only ever reject more): half the work where no lane hits, most of a BVH leaf's
/// blocks (incoherent rays, Stanford Bunny: 5.4 triangles tested per ray, 0.6 hit).
#[inline(always)]
pub fn intersect_lanes_cull<const N: usize, L: Lanes<N>, const CULL: bool>(
    (v0, e1, e2): (&Lanes3<L>, &Lanes3<L>, &Lanes3<L>),
    origin: &Lanes3<L>,
    dir: &Lanes3<L>,
    t_min: f32,
    t_max: L,
) -> LaneHits<N, L> {
    const LOOSE: f32 = BARY_EPS + MAX_SLACK;
    let p = cross_lanes(dir, e2);
    let det = dot_lanes(e1, &p);
    let inv_det = L::ONE / det;
    let s = [origin[0] - v0[0], origin[1] - v0[1], origin[2] - v0[2]];
    let u = dot_lanes(&s, &p) * inv_det;
    let q = cross_lanes(&s, e1);
    let v = dot_lanes(dir, &q) * inv_det;
    let t = dot_lanes(e2, &q) * inv_det;
    let mut ok = det.ne(L::ZERO)
        & u.ge(L::splat(-LOOSE))
        & u.le(L::splat(1.0 + LOOSE))
        & !v.lt(L::splat(-LOOSE))
        & !(u + v).gt(L::splat(1.0 + 2.0 * LOOSE))
        & t.gt(L::splat(t_min))
        & t.lt(t_max);
    if CULL && ok.bits() == 0 {
        return LaneHits { hit: ok, t, u, v };
    }
    // The error-bound slack (see `TriAccel::intersect`). The scalar test skips it inside the
    // `BARY_EPS` box; computing it everywhere changes nothing, since the bounded box always
    // contains that one (each tolerance is at least `BARY_EPS`).
    let d1 = l1_lanes(dir);
    let (s1, a1, b1) = (l1_lanes(&s), l1_lanes(e1), l1_lanes(e2));
    let scale = L::splat(SLACK_ULPS * f32::EPSILON) * d1 * inv_det.abs();
    let err_u = scale * b1 * (s1 + a1);
    let err_v = scale * a1 * (s1 + b1);
    // `f32::min` and the lanes' `min` both return `MAX_SLACK` when the bound is NaN.
    let tol_u = L::splat(BARY_EPS) + err_u.min(L::splat(MAX_SLACK));
    let tol_v = L::splat(BARY_EPS) + err_v.min(L::splat(MAX_SLACK));
    ok = ok
        & !(u.lt(L::ZERO - tol_u) | u.gt(L::ONE + tol_u) | v.lt(L::ZERO - tol_v) | (u + v).gt(L::ONE + tol_u + tol_v));
    // Grazing rays (see `TriAccel::intersect`).
    let e1_len2 = dot_lanes(e1, e1);
    let p_len2 = dot_lanes(&p, &p);
    ok = ok & !(det * det).le(L::splat(PARALLEL_COS2) * e1_len2 * p_len2);
    LaneHits { hit: ok, t, u, v }
}

impl TriAccel4 {
    /// Triangles per block.
    pub const LANES: usize = 4;

    /// Packs up to four triangles; the lanes past `tris.len()` are left unused.
    pub fn pack(tris: &[TriAccel]) -> TriAccel4 {
        assert!(tris.len() <= Self::LANES, "four triangles at most");
        let mut p = TriAccel4 {
            v0: [Vec4::ZERO; 3],
            e1: [Vec4::ZERO; 3],
            e2: [Vec4::ZERO; 3],
        };
        for (k, t) in tris.iter().enumerate() {
            for a in 0..3 {
                p.v0[a][k] = t.v0[a];
                p.e1[a][k] = t.e1[a];
                p.e2[a][k] = t.e2[a];
            }
        }
        p
    }

    /// `TriAccel::normal` of lane `k`, bit for bit.
    #[inline(always)]
    pub fn normal(&self, k: usize) -> Vec3 {
        Vec3::new(self.e1[0][k], self.e1[1][k], self.e1[2][k]).cross(Vec3::new(
            self.e2[0][k],
            self.e2[1][k],
            self.e2[2][k],
        ))
    }

    /// The triangle in lane `k`.
    pub fn lane(&self, k: usize) -> TriAccel {
        TriAccel {
            v0: self.v0.map(|c| c[k]),
            e1: self.e1.map(|c| c[k]),
            e2: self.e2.map(|c| c[k]),
        }
    }

    /// `TriAccel::intersect` on all four lanes at once, with bit-identical results: the same
    /// operations in the same order (IEEE arithmetic rounds the same in a SIMD lane as in a
    /// scalar register, and Rust never fuses multiply-adds on its own). Every early return of the
    /// scalar test becomes a lane mask, each the same comparison (negated where the scalar test
    /// rejects), so that NaNs fall the same way.
    #[inline(always)]
    pub fn intersect(&self, origin: &[Vec4; 3], dir: &[Vec4; 3], t_min: f32, t_max: f32) -> TriHit4 {
        self.intersect_upto(origin, dir, t_min, Vec4::splat(t_max))
    }

    /// One triangle in all four lanes: what `intersect_upto` tests four rays against.
    #[inline(always)]
    pub fn splat(tri: &TriAccel) -> TriAccel4 {
        TriAccel4 {
            v0: tri.v0.map(Vec4::splat),
            e1: tri.e1.map(Vec4::splat),
            e2: tri.e2.map(Vec4::splat),
        }
    }

    /// `intersect` with a `t_max` per lane: four triangles against one ray each, or one
    /// triangle (`splat`) against four rays (a packet walk: each ray up to its own closest hit).
    /// Lane by lane the same bits as `TriAccel::intersect` with that lane's ray and `t_max`.
    #[inline(always)]
    pub fn intersect_upto(&self, origin: &[Vec4; 3], dir: &[Vec4; 3], t_min: f32, t_max: Vec4) -> TriHit4 {
        intersect_lanes((&self.v0, &self.e1, &self.e2), origin, dir, t_min, t_max)
    }
}

/// The closest hit among the triangles `refs` names (indices into `tris`) with
/// `t_min < t < best.t`, into `best`: a grid cell's triangle loop, shared by the uniform and the
/// irregular grid.
#[inline(always)]
pub(crate) fn closest_in<C: super::Counters>(
    tris: &[TriAccel],
    refs: &[u32],
    ray: &super::Ray,
    t_min: f32,
    best: &mut super::Hit,
    counters: &mut C,
) {
    for &tri in refs {
        counters.tri_test();
        if let Some(h) = tris[tri as usize].intersect(ray.origin, ray.dir, t_min, best.t) {
            *best = h.on(tri);
        }
    }
}

/// Whether any triangle `refs` names is hit with `t_min < t < t_max` (stops at the first).
#[inline(always)]
pub(crate) fn any_in<C: super::Counters>(
    tris: &[TriAccel],
    refs: &[u32],
    ray: &super::Ray,
    t_min: f32,
    t_max: f32,
    counters: &mut C,
) -> bool {
    refs.iter().any(|&tri| {
        counters.tri_test();
        tris[tri as usize]
            .intersect(ray.origin, ray.dir, t_min, t_max)
            .is_some()
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
        let (mut hits, mut edge_hits, mut limited) = (0, 0, 0);
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
                let o = target + point(&mut rng, 1.0).normalize_or(Vec3::X) * away;
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
            let corners = (&splat3(tri.v0), &splat3(tri.e1), &splat3(tri.e2));
            let got = intersect_lanes::<N, L>(corners, &load3(origin), &load3(dir), 0.0, L::from_array(t_max));
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
            hits > rays / 2 && edge_hits > rays / 8 && limited > rays / 50,
            "{N} lanes: {hits} hits, {edge_hits} on edges, {limited} cut by t_max, of {rays}"
        );
    }
}
