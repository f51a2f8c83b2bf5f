//! Nearest points of eight neighbouring points through one walk, a lane a point (where the CPU
//! runs eight lanes: AVX2).
//!
//! A point far from the surface opens the leaves of a whole cap of it (every leaf box nearer
//! than its answer), and the per-point walk (`closest.rs`) spent most of its time in the
//! nodes: each point measures, sorts and pushes the same children its Morton neighbours just
//! did. Here eight neighbours share the walk: a child's box is measured against the eight at
//! once and opened where it may hold something nearer for any of them; at a leaf each
//! triangle's box is measured per point (the per-point walk's test and slack), and the
//! triangle's nearest point is found for the points it may serve at once
//! (`closest_on_triangle`'s arithmetic, lane by lane, `nearest_lanes`). A point's answer is
//! the nearest of every triangle that can be within its best distance, ties to the smallest
//! index: the per-point walk's and brute force's answer, bit for bit (the tests).

use glam::Vec3;

use super::BvhAccel;
use super::build::LEAF_BLOCK;
use super::closest::{box_near_bits, insert_far_first, seed_bound};
use super::wide::{ChildRef, WIDTH};
use crate::accel::TriAccel;
use crate::accel::closest::{ClosestPoint, TriPoint, closest_on_triangle};
use crate::accel::lanes::{F8, Lanes, Mask};

/// Points a packet holds.
pub(super) const PACKET: usize = 8;

/// One packet's points and their answers so far.
struct Packet {
    p: [F8; 3],
    points: [Vec3; PACKET],
    best: [ClosestPoint; PACKET],
    /// `best[k].dist_sq` in lanes; -1 in a lane with no point (nothing is nearer).
    best_d2: F8,
    /// The largest of `best_d2`: an entry farther from every point is dropped.
    reach: f32,
    /// The lanes that hold a point.
    live: u32,
}

impl Packet {
    fn refresh(&mut self) {
        let d2: [f32; PACKET] = std::array::from_fn(|k| {
            if self.live >> k & 1 != 0 {
                self.best[k].dist_sq
            } else {
                -1.0
            }
        });
        self.best_d2 = F8::from_array(d2);
        self.reach = d2.into_iter().fold(f32::NEG_INFINITY, f32::max);
    }
}

impl BvhAccel {
    /// `closest_points_batch` in packets of `PACKET` consecutive points (Morton neighbours
    /// where `accel::closest::closest_points` calls it): the same answers, bit for bit. Each
    /// point's search is bounded by the answer of the point `PACKET` before it, as the
    /// per-point batch bounds it by its lane's last one (`PointWalk::seed`); where that finds
    /// nothing the point is searched again alone, unbounded.
    ///
    /// # Safety
    /// The CPU runs AVX2 (`simd::has_wide`).
    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
    pub(super) unsafe fn closest_points_packets(&self, points: &[[f32; 3]], out: &mut [ClosestPoint]) {
        let mut stack: Vec<(f32, ChildRef)> = Vec::with_capacity(256);
        let mut before: [Option<Vec3>; PACKET] = [None; PACKET];
        for (chunk, answers) in points.chunks(PACKET).zip(out.chunks_mut(PACKET)) {
            let mut pk = Packet {
                p: [F8::ZERO; 3],
                points: [Vec3::ZERO; PACKET],
                best: [ClosestPoint::NONE; PACKET],
                best_d2: F8::ZERO,
                reach: 0.0,
                live: 0,
            };
            let mut slot = [0usize; PACKET];
            let mut n = 0;
            for (k, p) in chunk.iter().enumerate() {
                let p = Vec3::from(*p);
                if p.is_finite() {
                    (pk.points[n], slot[n]) = (p, k);
                    n += 1;
                } else {
                    answers[k] = ClosestPoint::INVALID;
                }
            }
            if n == 0 {
                continue;
            }
            pk.live = (1u32 << n) - 1;
            let mut seeded = [false; PACKET];
            for k in 0..PACKET {
                if k >= n {
                    pk.points[k] = pk.points[0];
                } else if let Some(bound) = before[k].and_then(|q| seed_bound(pk.points[k], q)) {
                    pk.best[k].dist_sq = bound;
                    seeded[k] = true;
                }
            }
            pk.p = [0, 1, 2].map(|a| F8::from_array(std::array::from_fn(|k| pk.points[k][a])));
            pk.refresh();
            self.packet_walk(&mut pk, &mut stack);
            for k in 0..n {
                if seeded[k] && !pk.best[k].is_found() {
                    pk.best[k] = self.closest_point(pk.points[k]);
                }
                answers[slot[k]] = pk.best[k];
                before[k] = pk.best[k].is_found().then_some(pk.best[k].point);
            }
        }
    }

    /// The branch and bound of `pk`'s points: an entry is opened while its box may be within
    /// some point's best distance, nearest first by its nearest point's distance.
    #[inline(always)]
    fn packet_walk(&self, pk: &mut Packet, stack: &mut Vec<(f32, ChildRef)>) {
        stack.clear();
        stack.push((0.0, ChildRef(0)));
        while let Some((d2, child)) = stack.pop() {
            if d2 > pk.reach {
                continue;
            }
            if child.count() > 0 {
                self.packet_leaf(pk, child);
                continue;
            }
            let node = &self.nodes[child.index() as usize];
            let mut open = [(0.0f32, ChildRef(0)); WIDTH];
            let mut n = 0;
            for k in 0..WIDTH {
                // An unused slot has the empty box (low > high).
                let used = node.planes[0][0][k] <= node.planes[1][0][k];
                if !used {
                    continue;
                }
                // Each point's distance to the box, as `child_box_dist_sq` measures it.
                let mut d2 = F8::ZERO;
                for a in 0..3 {
                    let (lo, hi) = (F8::splat(node.planes[0][a][k]), F8::splat(node.planes[1][a][k]));
                    let d = (lo - pk.p[a]).max(pk.p[a] - hi).max(F8::ZERO);
                    d2 = d2 + d * d;
                }
                let near = d2.le(pk.best_d2);
                if near.bits() == 0 {
                    continue;
                }
                let key = F8::select(near, d2, F8::INFINITY)
                    .to_array()
                    .into_iter()
                    .fold(f32::INFINITY, f32::min);
                insert_far_first(&mut open, &mut n, (key, node.child[k]));
            }
            stack.extend_from_slice(&open[..n]);
        }
    }

    /// Offers leaf `child`'s triangles to the points whose best distance their box may beat.
    #[inline(always)]
    fn packet_leaf(&self, pk: &mut Packet, child: ChildRef) {
        let first = child.index() as usize;
        let mut changed = false;
        for b in first..first + (child.count() as usize).div_ceil(LEAF_BLOCK) {
            let block = &self.blocks[b];
            for t in 0..LEAF_BLOCK {
                let tri = self.lane_prims[b * LEAF_BLOCK + t];
                if tri == u32::MAX {
                    continue;
                }
                // `tri_box_near_mask`'s test and slack, a lane a point.
                let lo = [0, 1, 2].map(|a| F8::splat(block.v0[a][t].min(block.v1[a][t]).min(block.v2[a][t])));
                let hi = [0, 1, 2].map(|a| F8::splat(block.v0[a][t].max(block.v1[a][t]).max(block.v2[a][t])));
                let near = box_near_bits::<8, F8>(lo, hi, pk.p, pk.best_d2) & pk.live;
                if near == 0 {
                    continue;
                }
                let tri_data = block.lane(t);
                let lanes = nearest_lanes(&tri_data, pk.p);
                // Only the points it may beat or tie (and the fallback's) look further.
                let mut bits = near & (lanes.dist_sq.le(pk.best_d2).bits() | lanes.fallback);
                if bits == 0 {
                    continue;
                }
                let dist = lanes.dist_sq.to_array();
                let (u, v) = (lanes.u.to_array(), lanes.v.to_array());
                let xyz = lanes.point.map(F8::to_array);
                while bits != 0 {
                    let k = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    let c = if lanes.fallback >> k & 1 != 0 {
                        closest_on_triangle(&tri_data, pk.points[k])
                    } else {
                        TriPoint {
                            point: Vec3::new(xyz[0][k], xyz[1][k], xyz[2][k]),
                            dist_sq: dist[k],
                            u: u[k],
                            v: v[k],
                        }
                    };
                    if pk.best[k].is_beaten_by(c.dist_sq, tri) {
                        pk.best[k] = ClosestPoint {
                            point: c.point,
                            dist_sq: c.dist_sq,
                            tri,
                            u: c.u,
                            v: c.v,
                        };
                        changed = true;
                    }
                }
            }
        }
        if changed {
            pk.refresh();
        }
    }
}

/// `closest_on_triangle` of one triangle at eight points, a lane each.
struct NearestLanes {
    point: [F8; 3],
    dist_sq: F8,
    u: F8,
    v: F8,
    /// Lanes whose point no region claimed (a degenerate or sliver triangle): the scalar
    /// function's edge fallback answers them.
    fallback: u32,
}

/// `closest_on_triangle(t, p)` for the eight points `p`, with its arithmetic in its order (each
/// dot product `(x x' + y y') + z z'`, no fused operations): the same bits in each lane. Every
/// region's candidate is computed in every lane and the first region that holds, in the scalar
/// function's order, is kept.
#[inline(always)]
fn nearest_lanes(t: &TriAccel, p: [F8; 3]) -> NearestLanes {
    let s = |v: Vec3| [F8::splat(v.x), F8::splat(v.y), F8::splat(v.z)];
    let a = Vec3::from(t.v0);
    let (ab, ac) = t.edges();
    let (a8, ab8, ac8) = (s(a), s(ab), s(ac));
    let sub = |x: [F8; 3], y: [F8; 3]| [x[0] - y[0], x[1] - y[1], x[2] - y[2]];
    let dot = |x: [F8; 3], y: [F8; 3]| x[0] * y[0] + x[1] * y[1] + x[2] * y[2];
    let (zero, one) = (F8::ZERO, F8::ONE);
    let ap = sub(p, a8);
    let (d1, d2) = (dot(ab8, ap), dot(ac8, ap));
    let bp = sub(ap, ab8);
    let (d3, d4) = (dot(ab8, bp), dot(ac8, bp));
    let vc = d1 * d4 - d3 * d2;
    let cp = sub(ap, ac8);
    let (d5, d6) = (dot(ab8, cp), dot(ac8, cp));
    let vb = d5 * d2 - d1 * d6;
    let va = d3 * d6 - d5 * d4;
    let denom = va + vb + vc;
    let inv = one / denom;
    let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    // The regions in the scalar function's order: (holds, u, v).
    let regions = [
        (d1.le(zero) & d2.le(zero), zero, zero),
        (d3.ge(zero) & d4.le(d3), one, zero),
        (vc.le(zero) & d1.ge(zero) & d3.le(zero), d1 / (d1 - d3), zero),
        (d6.ge(zero) & d5.le(d6), zero, one),
        (vb.le(zero) & d2.ge(zero) & d6.le(zero), zero, d2 / (d2 - d6)),
        (va.le(zero) & (d4 - d3).ge(zero) & (d5 - d6).ge(zero), one - w, w),
        (
            va.ge(zero) & vb.ge(zero) & vc.ge(zero) & denom.gt(zero) & denom.abs().lt(F8::INFINITY),
            vb * inv,
            vc * inv,
        ),
    ];
    let (mut u, mut v) = (zero, zero);
    let mut taken = 0u32;
    for (holds, ru, rv) in regions.into_iter().rev() {
        // Reversed, so that the first region that holds is the last written.
        u = F8::select(holds, ru, u);
        v = F8::select(holds, rv, v);
        taken |= holds.bits();
    }
    let point = [
        a8[0] + ab8[0] * u + ac8[0] * v,
        a8[1] + ab8[1] * u + ac8[1] * v,
        a8[2] + ab8[2] * u + ac8[2] * v,
    ];
    let q = sub(p, point);
    let dist_sq = dot(q, q);
    NearestLanes {
        point,
        dist_sq,
        u,
        v,
        fallback: !taken & 0xff,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::Rng;

    /// `nearest_lanes` gives `closest_on_triangle`'s bits in every lane it claims, over every
    /// region: ordinary triangles, slivers and zero-area ones (a point, a segment, collinear
    /// vertices), with points around them and on them. The lanes it leaves to the scalar
    /// fallback are counted and printed: none on these triangles (a zero-area triangle's point
    /// is claimed by a vertex or edge region; only rounding could leave one).
    #[test]
    fn lanes_follow_the_scalar_nearest_point() {
        if !crate::accel::simd::has_wide() {
            return;
        }
        // SAFETY: the CPU runs AVX2, checked just above.
        let fallbacks = unsafe { check_lanes() };
        println!("lanes left to the fallback: {fallbacks}");
    }

    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
    unsafe fn check_lanes() -> usize {
        let mut rng = Rng::new(0x1A4E);
        let mut r = |s: f32| Vec3::new(rng.range(-s, s), rng.range(-s, s), rng.range(-s, s));
        let mut fallbacks = 0;
        for i in 0..4000 {
            let (a, d, e) = (r(1.0), r(0.3), r(0.3));
            let t = match i % 5 {
                0 => TriAccel::new(a, a + d, a + e),
                1 => TriAccel::new(a, a + d, a + d * 0.5 + r(1e-6)),
                2 => TriAccel::new(a, a + d, a + d * 2.0),
                3 => TriAccel::new(a, a + d, a + d),
                _ => TriAccel::new(a, a, a),
            };
            let points: [Vec3; PACKET] = std::array::from_fn(|k| match k {
                0 => Vec3::from(t.v0),
                1 => Vec3::from(t.v1) * 0.5 + Vec3::from(t.v2) * 0.5,
                _ => a + r(0.5),
            });
            let p = [0, 1, 2].map(|c| F8::from_array(std::array::from_fn(|k| points[k][c])));
            let lanes = nearest_lanes(&t, p);
            let xyz = lanes.point.map(F8::to_array);
            let (dist, u, v) = (lanes.dist_sq.to_array(), lanes.u.to_array(), lanes.v.to_array());
            for (k, &q) in points.iter().enumerate() {
                if lanes.fallback >> k & 1 != 0 {
                    fallbacks += 1;
                    continue;
                }
                let c = closest_on_triangle(&t, q);
                let got = [xyz[0][k], xyz[1][k], xyz[2][k], dist[k], u[k], v[k]].map(f32::to_bits);
                let want = [c.point.x, c.point.y, c.point.z, c.dist_sq, c.u, c.v].map(f32::to_bits);
                assert_eq!(got, want, "triangle {i} ({t:?}), point {q}");
            }
        }
        fallbacks
    }
}
