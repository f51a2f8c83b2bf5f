//! Triangles and rays side by side in SIMD lanes: `TriAccel4` (a BVH leaf's four triangles),
//! `LaneRay` (rays prepared once per packet), `SharedFrame` (a pinhole packet's shared origin),
//! and the N-lane watertight test, which rounds every lane exactly as `TriAccel::intersect`.

use super::*;

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
    pub(in crate::accel::triangle) uniform: Option<[usize; 3]>,
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
    let (h, det) = sheared_lanes::<N, L, CULL>(&p, ray, t_min, t_max);
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
    let (h, det) = sheared_lanes::<N, L, CULL>(&p, ray, t_min, t_max);
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
fn sheared_lanes<const N: usize, L: Lanes<N>, const CULL: bool>(
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
    let inside = !(neg & pos) & det.ne(L::ZERO);
    // Most blocks are missed by every lane at the edge test (incoherent rays, Stanford Bunny:
    // 5.4 triangles tested a ray, 0.6 hit): return before the division, whose latency
    // would otherwise sit on every test's path to the cull branch. The lanes' `hit` is the
    // same either way (`t`, `u`, `v` are only read where `hit` is set).
    if CULL && inside.bits() == 0 {
        return (
            LaneHits {
                hit: inside,
                t: L::ZERO,
                u: L::ZERO,
                v: L::ZERO,
            },
            det,
        );
    }
    let inv_det = L::ONE / det;
    let t = (e[0] * p[0][2] + e[1] * p[1][2] + e[2] * p[2][2]) * (ray.sz * inv_det) + L::ZERO;
    let ok = inside & t.ge(L::splat(t_min)) & t.lt(t_max);
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
