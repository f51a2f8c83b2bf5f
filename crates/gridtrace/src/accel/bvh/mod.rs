//! A bounding volume hierarchy over the same triangles as the grid: the comparison with other
//! acceleration structures that the paper left as future work, and the structure that serves
//! incoherent ray queries best (a uniform grid cannot adapt to a mesh's uneven density, and a
//! ray that misses crosses every cell on its way).
//!
//! Built top-down as a binary tree with the binned surface area heuristic (Wald 2007; the
//! builder takes boxes and centres only, so it knows nothing of triangles), then collapsed into
//! eight-wide nodes whose eight box tests are one SIMD computation (AVX where the CPU has AVX2,
//! chosen at run time), traversed front to back with a fixed stack. Leaves hold up to eight
//! triangles, stored four to a block (`TriAccel4`) and tested a block at a time, as Embree's
//! `Triangle4`; the SAH counts their cost in blocks.
//! Batches of rays are traced interleaved, with prefetching, to hide memory latency
//! (docs/design.md).

use glam::Vec3;
use rayon::prelude::*;

use super::huge::HugePageArray;
use super::triangle::slack_pad;
use super::{Aabb, Counters, Hit, PACKET, Ray, TriAccel, TriAccel4};

mod all_hits;
mod box_test;
mod build;
mod closest;
mod closest_packet;
mod coherent;
mod footprint;
mod interleave;
mod interval;
mod packet;
mod refit;
mod structure;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_coherent;
#[cfg(test)]
mod tests_queries;
mod walk;
mod wide;

pub(crate) use box_test::{DIR_TINY, FAR_SCALE, T_SLOP, safe_dir};
use build::LEAF_BLOCK;
pub(crate) use build::STACK;
pub use build::{Bvh, BvhNode, MAX_LEAF};
use walk::Walk;
use wide::collapse;
pub use wide::{ChildRef, WIDTH, WideNode};

/// The box of each triangle as the BVH bounds it, padded so that every hit the triangle test
/// accepts lies inside (`SLACK_PAD`). `build` and `refit` both bound triangles with this.
fn padded_boxes(tris: &[TriAccel]) -> Vec<Aabb> {
    tris.par_iter()
        .map(|t| {
            let b = Aabb::from_points(&t.vertices());
            let pad = slack_pad(b.min, b.max);
            Aabb {
                min: b.min - pad,
                max: b.max + pad,
            }
        })
        .collect()
}

/// A BVH over triangles: the eight-wide nodes, and the triangles copied into leaf order, four
/// to a block, so that a leaf's triangles are adjacent in memory and tested together.
#[derive(Debug, Clone)]
pub struct BvhAccel {
    /// The binary SAH tree the wide nodes were collapsed from.
    pub bvh: Bvh,
    /// The arrays a ray reads are in huge pages where the system allows (`HugePageArray`).
    pub nodes: HugePageArray<WideNode>,
    /// The leaves' triangles, each leaf in whole blocks (its last one padded with unused lanes).
    pub blocks: HugePageArray<TriAccel4>,
    /// Index (in the triangles given to `build`) of lane `k` of block `b`, at `4 * b + k`;
    /// `u32::MAX` for an unused lane.
    pub lane_prims: HugePageArray<u32>,
    /// The mean diagonal of the leaves' boxes, for the packet route's decision
    /// (`footprint::cone_cos_sq`).
    leaf_size: f32,
}

impl BvhAccel {
    pub fn build(tris: &[TriAccel]) -> BvhAccel {
        let boxes = padded_boxes(tris);
        let centers: Vec<Vec3> = boxes.par_iter().map(Aabb::center).collect();
        let bvh = Bvh::build(&boxes, &centers);
        let (nodes, blocks, lane_prims) = collapse(&bvh, tris);
        BvhAccel {
            leaf_size: footprint::leaf_size(&bvh),
            bvh,
            nodes: HugePageArray::from_slice(&nodes),
            blocks: HugePageArray::from_slice(&blocks),
            lane_prims: HugePageArray::from_slice(&lane_prims),
        }
    }

    /// Closest hit in the ray's interval; `tri` indexes the triangles given to `build`.
    /// `counters.cell()` counts nodes visited.
    pub fn intersect<C: Counters>(&self, ray: &Ray, counters: &mut C) -> Hit {
        let mut w = Walk::new(ray);
        self.walk::<false, C>(&mut w, counters);
        self.result(&w.best)
    }

    /// Any hit in the ray's interval.
    pub fn occluded<C: Counters>(&self, ray: &Ray, counters: &mut C) -> bool {
        let mut w = Walk::new(ray);
        self.walk::<true, C>(&mut w, counters);
        w.best.is_hit()
    }

    /// Closest hits of a batch of rays, `out[i]` for `rays[i]`: the same answers as `intersect`,
    /// faster (`traced`).
    pub fn intersect_batch(&self, rays: &[Ray], out: &mut [Hit]) {
        self.traced::<false>(rays, Route::Batch, |i, best| out[i] = self.result(best));
    }

    /// Closest hits of a batch handed to `f(i, hit, normal)` as each ray `rays[i]` is done, in
    /// no particular order, with the hit's geometric normal (`TriAccel::normal`; zero for a
    /// miss). The normal comes from the block of the hit triangle, tested last or nearly so
    /// and still in cache. A caller can write its own output format here, without a pass over
    /// an intermediate array.
    #[inline]
    pub fn intersect_batch_each(&self, rays: &[Ray], f: impl FnMut(usize, Hit, Vec3)) {
        self.traced_each(rays, Route::Batch, f)
    }

    /// `intersect_batch_each` for the two levels' streams (`Walks::intersect_stream_each`):
    /// the interleaved single walks alone (`traced` says why).
    pub fn intersect_stream_each(&self, rays: &[Ray], f: impl FnMut(usize, Hit, Vec3)) {
        self.traced_each(rays, Route::Stream, f)
    }

    #[inline]
    fn traced_each(&self, rays: &[Ray], route: Route, mut f: impl FnMut(usize, Hit, Vec3)) {
        self.traced::<false>(rays, route, |i, best| {
            let normal = if best.is_hit() {
                let tri = best.tri as usize;
                self.blocks[tri / LEAF_BLOCK].normal(tri % LEAF_BLOCK)
            } else {
                Vec3::ZERO
            };
            f(i, self.result(best), normal)
        });
    }

    /// Any-hit results of a batch of rays (as `intersect_batch`).
    pub fn occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        self.traced::<true>(rays, Route::Batch, |i, best| out[i] = best.is_hit());
    }

    /// Traces a batch, handing each ray's walk result (`Walk::best`) to `finish(i, best)`.
    /// Rays come in groups of `PACKET` consecutive ones: a group that looks coherent
    /// (`coherent::coherent`: a camera's or a sensor's neighbouring rays) is walked as one
    /// packet (`coherent.rs`); the other rays are walked one by one, `LANES` of them
    /// interleaved, each step prefetching what its ray touches next, so that one ray's wait
    /// for memory overlaps the others' work (incoherent rays spend most of their time waiting
    /// for nodes and triangles, one dependent load after another). The same answers either way.
    fn traced<const ANY: bool>(&self, rays: &[Ray], route: Route, mut finish: impl FnMut(usize, &Hit)) {
        // Not for the two levels' streams (`Route::Stream`) unless
        // `GRIDTRACE_BVH_PACKETS=all`: those batches are one instance's share of a work item's
        // rays, in ray order, and a camera's rays there are not coherent at the scale of the
        // mesh's leaves. Measured (2026-12-05, issue 52, `examples/carried_packets.rs`: 10
        // translated Stanford Bunnies, 320x240 camera rays from 8 diagonals, nodes and
        // triangles counted per packet and for the same rays' single walks): an instance's
        // rays are its rows' runs over its box one after the other, so 203 of the 1,322 packets
        // spanned a row's end and the next row's start (pixels 36 apart, yet within the 8
        // degree cone of `coherent`: the Bunny is 5 degrees wide), and each such packet's
        // interval test covered the Bunny's width: 1,119 nodes and leaves and 3,096 triangle
        // tests a packet, where the same 8 rays' single walks test 17 triangles (78% of all
        // the packets' tests). The packets within a row lose too: 76 nodes and leaves and 162
        // triangle tests a packet against 42 nodes and 40 triangles for the 8 single walks,
        // because a pixel there covers about 120 of the Bunny's triangles: neighbouring rays
        // end in different leaves, and the packet, searched as far as its farthest ray (one
        // that misses searches to infinity), enters more. Time, the two levels' cast: 30-45 ms
        // with the packets, 5.1-11.3 ms without (medians, alternating, a loaded 2-core
        // machine). Not the limits themselves (in the first round every limit is `t_far`, as
        // on the flat path; the answers are equal), nor the carried directions (translated
        // only), nor ties (no ray redone). From 1.5 diagonals, where a packet's rays share
        // leaves (13 nodes and leaves and 20 triangle tests a packet against the singles' 33
        // and 30), the packets were still 5-8% slower (11.5-16.1 against 10.8-15.3 ms). The
        // flat mesh's camera packets are cheap on average because most cross empty space.
        let stream = route == Route::Stream && !coherent::packets_for_streams();
        if crate::accel::simd::has_wide() && rays.len() >= PACKET && coherent::packets_enabled() && !stream {
            let extent = self.extent();
            let (lo, hi) = self
                .bvh
                .nodes
                .first()
                .map_or((Vec3::ZERO, Vec3::ZERO), |n| (n.min.into(), n.max.into()));
            // Indices of the rays left to the interleaved walks (u32: a batch is cut into
            // work items far smaller than 2^32 rays; checked).
            let mut rest: Vec<u32> = Vec::new();
            for (g, group) in rays.chunks(PACKET).enumerate() {
                let start = g * PACKET;
                // The cone narrowed to what the leaves allow at the packet's distance from the
                // scene (`footprint`: far cameras' packets walk singly, 10 Bunnies 8 diagonals
                // away 11.2-15.4 -> 3.6-4.2 ms).
                let cos_sq = footprint::cone_cos_sq(group[0].origin, lo, hi, self.leaf_size);
                if group.len() == PACKET
                    && crate::accel::contract::same_start(group)
                    && coherent::coherent_within(group, extent, cos_sq)
                {
                    // SAFETY: the CPU runs the eight-lane build, checked above.
                    let a = unsafe { self.walk_coherent::<ANY>(group) };
                    for (k, best) in a.best.iter().enumerate() {
                        if a.redo >> k & 1 != 0 {
                            finish(start + k, &self.walk_best::<ANY>(&group[k]));
                        } else {
                            finish(start + k, best);
                        }
                    }
                } else {
                    let end = u32::try_from(start + group.len()).expect("a CPU batch under 2^32 rays");
                    rest.extend(start as u32..end);
                }
            }
            let rest = rest.iter().map(|&i| (i as usize, &rays[i as usize]));
            return self.interleaved::<ANY>(rest, |i, w| finish(i, &w.best));
        }
        self.interleaved::<ANY>(rays.iter().enumerate(), |i, w| finish(i, &w.best))
    }

    /// One ray's single walk, its result as `Walk::best` (a packet's ray with a tie).
    fn walk_best<const ANY: bool>(&self, ray: &Ray) -> Hit {
        let mut w = Walk::new(ray);
        self.walk::<ANY, _>(&mut w, &mut crate::accel::NoCounters);
        w.best
    }

    /// Bytes of the nodes, the triangle blocks and the index map.
    pub fn memory(&self) -> usize {
        std::mem::size_of_val(&self.nodes[..])
            + std::mem::size_of_val(&self.blocks[..])
            + std::mem::size_of_val(&self.lane_prims[..])
    }
}

/// Where a batch's rays come from, as `BvhAccel::traced` weighs its packets: a caller's batch
/// (a camera's or a sensor's neighbouring rays, coherent ones walked as packets) or the two
/// levels' streams (one instance's share of a work item's rays, not coherent at its leaves'
/// scale).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Route {
    Batch,
    Stream,
}
