//! The BVH's nearest-point query: branch and bound down the eight-wide tree. A node's eight
//! child boxes are measured against the point at once (squared distance to each box, 0 inside),
//! the children that may hold something nearer than the best so far are pushed nearest last,
//! so the nearest is opened first and finds a good bound early; a popped entry farther than the
//! (since improved) best is dropped unopened.
//!
//! The boxes are the triangles' boxes padded for the triangle test (`padded_boxes`), so
//! a box's distance is a true lower bound on its triangles' computed distances. Pruning is
//! strict (`>`): an equally near triangle is still tested and the tie rule (smallest index,
//! `accel::closest`) decides as brute force does. The blocks hold the triangles in leaf order;
//! `lane_prims` gives back each one's index in the input.

use glam::{Vec3, Vec4};

use super::BvhAccel;
use super::box_test::Pending;
use super::build::{LEAF_BLOCK, STACK};
use super::interleave::interleave;
use super::walk::LANES;
use super::wide::{ChildRef, WIDTH, WideNode};
use crate::accel::TriAccel4;
use crate::accel::closest::ClosestPoint;
use crate::accel::lanes::{Lanes, Mask};

/// Entries the stack can hold: a node pops one entry and pushes at most `WIDTH`, and no path
/// has more than `STACK` nodes.
const CAPACITY: usize = STACK * (WIDTH - 1) + 1;

impl BvhAccel {
    /// The point of the triangles the BVH was built over nearest to `p`; `tri` indexes those
    /// triangles (not the leaf order). The answer of `closest_point_brute`, tie rule included.
    pub fn closest_point(&self, p: Vec3) -> ClosestPoint {
        if !p.is_finite() {
            return ClosestPoint::INVALID;
        }
        if self.blocks.is_empty() {
            return ClosestPoint::NONE;
        }
        let mut w = PointWalk::new(p);
        while !w.step(self) {}
        w.best
    }

    /// The nearest points of a batch, `out[i]` for `points[i]`: `closest_point`'s answers,
    /// faster. Each search is a chain of dependent loads (a node, then the child it picks);
    /// `LANES` searches run at once, one step each in turn, each step prefetching the node or
    /// leaf its search visits next, so that one search's wait overlaps the others' work (as the
    /// ray batches do, `walk.rs`). Each search keeps its own stack and order: the same answer,
    /// bit for bit.
    ///
    /// Where the CPU runs eight lanes, eight consecutive points share one walk instead
    /// (`closest_packet.rs`): the same answers. 200,000 points uniform in the Stanford Dragon's
    /// box: 0.80 s interleaved, 0.51 s in packets (2-core Xeon, `closest_points` example, 2026-12-05).
    pub fn closest_points_batch(&self, points: &[[f32; 3]], out: &mut [ClosestPoint]) {
        assert_eq!(points.len(), out.len(), "one answer per point");
        if self.blocks.is_empty() {
            for (o, p) in out.iter_mut().zip(points) {
                *o = self.closest_point(Vec3::from(*p));
            }
            return;
        }
        if crate::accel::simd::has_wide() {
            // SAFETY: the CPU runs AVX2, checked just above.
            unsafe { self.closest_points_packets(points, out) };
            return;
        }
        self.closest_points_interleaved(points, out);
    }

    /// `closest_points_batch` point by point, `LANES` searches interleaved (the path without
    /// AVX2; the tests hold both to the lone search).
    pub(super) fn closest_points_interleaved(&self, points: &[[f32; 3]], out: &mut [ClosestPoint]) {
        let mut walks: [PointWalk; LANES] = std::array::from_fn(|_| PointWalk::new(Vec3::ZERO));
        let mut points_left = points.iter().enumerate();
        interleave(
            &mut walks,
            |w, done| {
                if let Some(i) = done {
                    if w.seeded && !w.best.is_found() {
                        // Nothing within the neighbour's bound (rounding at a surface): the
                        // search again, unbounded.
                        w.reset(w.p);
                        return Some(i);
                    }
                    out[i] = w.best;
                }
                // The next finite point's search, bounded by the distance to the answer this
                // lane just found (a point of the mesh); non-finite ones are answered on the way.
                let neighbour = w.best;
                for (i, p) in points_left.by_ref() {
                    let p = Vec3::from(*p);
                    if p.is_finite() {
                        w.reset(p);
                        if neighbour.is_found() {
                            w.seed(neighbour.point);
                        }
                        return Some(i);
                    }
                    out[i] = ClosestPoint::INVALID;
                }
                None
            },
            |w| w.step(self),
            |w| {
                self.prefetch(&Pending {
                    child: w.current.1,
                    t_enter: 0.0,
                })
            },
        );
    }

    /// Offers the triangles of leaf `child` to `best`: a block's four triangle boxes are
    /// measured against the point at once, and only the triangles whose box is within the best
    /// distance get the full test (most of a leaf near a ball's rim is not).
    #[inline(always)]
    fn closest_in_leaf(&self, child: ChildRef, p: Vec3, best: &mut ClosestPoint) {
        let first = child.index() as usize;
        for b in first..first + (child.count() as usize).div_ceil(LEAF_BLOCK) {
            let block = &self.blocks[b];
            let mut near = tri_box_near_mask(block, p, best.dist_sq);
            while near != 0 {
                let k = near.trailing_zeros() as usize;
                near &= near - 1;
                let tri = self.lane_prims[b * LEAF_BLOCK + k];
                if tri != u32::MAX {
                    best.offer(&block.lane(k), tri, p);
                }
            }
        }
    }
}

/// The lanes of `block` whose triangle's box may hold a point within `dist_sq` of `p`, bit `k`
/// for lane `k` (`box_near_bits`, the boxes from the stored vertices).
#[inline(always)]
fn tri_box_near_mask(block: &TriAccel4, p: Vec3, dist_sq: f32) -> u32 {
    let lo = [0, 1, 2].map(|a| block.v0[a].min(block.v1[a]).min(block.v2[a]));
    let hi = [0, 1, 2].map(|a| block.v0[a].max(block.v1[a]).max(block.v2[a]));
    let p = [0, 1, 2].map(|a| Vec4::splat(p[a]));
    box_near_bits::<4, Vec4>(lo, hi, p, Vec4::splat(dist_sq))
}

/// The lanes whose box `lo..hi` may hold a point within `dist_sq` of `p` (a triangle's box in
/// each lane at one point, or one box at a point in each lane: `closest_packet.rs`), bit `k`
/// for lane `k`. The test must never drop a triangle whose *computed* distance is at most
/// `dist_sq` (ties included), so it is widened: a lane is dropped only when its box is
/// farther than the best distance by more than a rounding bound of the coordinates involved
/// (16 ulps of the largest).
#[inline(always)]
pub(super) fn box_near_bits<const N: usize, L: Lanes<N>>(lo: [L; 3], hi: [L; 3], p: [L; 3], dist_sq: L) -> u32 {
    let mut d2 = L::ZERO;
    let mut scale = L::ZERO;
    for a in 0..3 {
        let d = (lo[a] - p[a]).max(p[a] - hi[a]).max(L::ZERO);
        d2 = d2 + d * d;
        scale = scale.max(lo[a].abs()).max(hi[a].abs()).max(p[a].abs());
    }
    let slack = scale * L::splat(16.0 * f32::EPSILON);
    // `!(far)`, so that NaN (never, for finite input) would keep the lane.
    let reach = dist_sq.sqrt() + slack;
    !d2.gt(reach * reach).bits() & ((1u32 << N) - 1)
}

/// The squared distance a search from `p` starts bounded by, given `q`, a point of the mesh
/// (a neighbour's nearest point): `|p - q|^2` a thousandth wider against rounding (`seed`).
/// None where it bounds nothing useful (0: `p` is `q`; not finite).
#[inline(always)]
pub(super) fn seed_bound(p: Vec3, q: Vec3) -> Option<f32> {
    let bound = (p - q).length_squared() * 1.001;
    (bound.is_finite() && bound > 0.0).then_some(bound)
}

/// One point's branch and bound, resumable one node or leaf at a time (so that a batch can
/// interleave several).
struct PointWalk {
    p: Vec3,
    best: ClosestPoint,
    /// (squared distance to the box, child): the entries still to open. Entries below `len`
    /// are written before they are read.
    stack: [(f32, ChildRef); CAPACITY],
    len: usize,
    /// The entry the next step opens.
    current: (f32, ChildRef),
    /// Whether `best` started as a bound (`seed`), not at infinity.
    seeded: bool,
}

impl PointWalk {
    fn new(p: Vec3) -> PointWalk {
        PointWalk {
            p,
            best: ClosestPoint::NONE,
            stack: [(0.0, ChildRef(0)); CAPACITY],
            len: 0,
            // The root as a node at distance 0.
            current: (0.0, ChildRef(0)),
            seeded: false,
        }
    }

    /// Bounds the search by the distance to `q`, a point of the mesh (a neighbour's nearest
    /// point): nothing farther is opened. Every triangle within the bound is still tested
    /// and pruning stays strict, so the answer is the unbounded search's whenever it lies
    /// within the bound; where rounding puts it just outside (the bound is widened by a
    /// thousandth against that), nothing is found and the batch searches again without one.
    /// With Morton-ordered points (`accel::closest::closest_points`) the bound is near the
    /// answer: 200,000 points uniform in the Stanford Dragon's box grown by a tenth took
    /// 0.82 s against 1.03 s unbounded (`QueryScene::compute_distance`, 2-core Xeon; the
    /// Morton order alone changed nothing).
    #[inline(always)]
    fn seed(&mut self, q: Vec3) {
        if let Some(bound) = seed_bound(self.p, q) {
            self.best.dist_sq = bound;
            self.seeded = true;
        }
    }

    /// Starts over at `p`, keeping the stack's memory where it is.
    #[inline(always)]
    fn reset(&mut self, p: Vec3) {
        self.p = p;
        self.best = ClosestPoint::NONE;
        self.len = 0;
        self.current = (0.0, ChildRef(0));
        self.seeded = false;
    }

    /// Opens `current` (a leaf's triangles, or a node's children worth opening, pushed far to
    /// near so that the nearest is popped first), then pops the next entry that may still
    /// hold something nearer than the best. True when none is left.
    #[inline(always)]
    fn step(&mut self, accel: &BvhAccel) -> bool {
        let (_, child) = self.current;
        if child.count() > 0 {
            accel.closest_in_leaf(child, self.p, &mut self.best);
        } else {
            let node = &accel.nodes[child.index() as usize];
            let dist = child_box_dist_sq(node, self.p);
            let mut open = [(0.0f32, ChildRef(0)); WIDTH];
            let mut n = 0;
            for (k, &d) in dist.iter().enumerate() {
                // An unused slot has the empty box (low > high); its distance says nothing.
                let used = node.planes[0][0][k] <= node.planes[1][0][k];
                if used && d <= self.best.dist_sq {
                    insert_far_first(&mut open, &mut n, (d, node.child[k]));
                }
            }
            self.stack[self.len..self.len + n].copy_from_slice(&open[..n]);
            self.len += n;
        }
        while self.len > 0 {
            self.len -= 1;
            let entry = self.stack[self.len];
            if entry.0 <= self.best.dist_sq {
                self.current = entry;
                return false;
            }
        }
        true
    }
}

/// Puts `entry` among the first `n` of `open` (sorted far to near by their distance, so that
/// the nearest is pushed last and popped first) and counts it.
#[inline(always)]
pub(super) fn insert_far_first(open: &mut [(f32, ChildRef); WIDTH], n: &mut usize, entry: (f32, ChildRef)) {
    let mut at = *n;
    while at > 0 && open[at - 1].0 < entry.0 {
        open[at] = open[at - 1];
        at -= 1;
    }
    open[at] = entry;
    *n += 1;
}

/// Squared distance from `p` to each child box of `node` (0 inside), lane by lane: eight
/// independent computations the compiler vectorises.
#[inline(always)]
fn child_box_dist_sq(node: &WideNode, p: Vec3) -> [f32; WIDTH] {
    let mut out = [0.0f32; WIDTH];
    for a in 0..3 {
        let (lo, hi) = (&node.planes[0][a], &node.planes[1][a]);
        for k in 0..WIDTH {
            let d = (lo[k] - p[a]).max(p[a] - hi[k]).max(0.0);
            out[k] += d * d;
        }
    }
    out
}
