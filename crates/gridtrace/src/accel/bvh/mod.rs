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
use super::{Aabb, Counters, Hit, PACKET, Ray, TMax, TriAccel, TriAccel4};

mod all_hits;
mod box_test;
mod build;
mod closest;
mod coherent;
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
}

impl BvhAccel {
    pub fn build(tris: &[TriAccel]) -> BvhAccel {
        let boxes = padded_boxes(tris);
        let centers: Vec<Vec3> = boxes.par_iter().map(Aabb::center).collect();
        let bvh = Bvh::build(&boxes, &centers);
        let (nodes, blocks, lane_prims) = collapse(&bvh, tris);
        BvhAccel {
            bvh,
            nodes: HugePageArray::from_slice(&nodes),
            blocks: HugePageArray::from_slice(&blocks),
            lane_prims: HugePageArray::from_slice(&lane_prims),
        }
    }

    /// Closest hit with `t_min <= t < t_max`; `tri` indexes the triangles given to `build`.
    /// `counters.cell()` counts nodes visited.
    pub fn intersect<C: Counters>(&self, ray: &Ray, t_min: f32, t_max: f32, counters: &mut C) -> Hit {
        let mut w = Walk::new(ray, t_min, t_max);
        self.walk::<false, C>(&mut w, counters);
        self.result(&w.best)
    }

    /// Any hit with `t_min <= t < t_max`.
    pub fn occluded<C: Counters>(&self, ray: &Ray, t_min: f32, t_max: f32, counters: &mut C) -> bool {
        let mut w = Walk::new(ray, t_min, t_max);
        self.walk::<true, C>(&mut w, counters);
        w.best.is_hit()
    }

    /// Closest hits of a batch of rays, `out[i]` for `rays[i]`: the same answers as `intersect`,
    /// faster (`traced`).
    pub fn intersect_batch(&self, rays: &[Ray], t_min: f32, t_max: f32, out: &mut [Hit]) {
        self.traced::<false>(rays, t_min, TMax::One(t_max), |i, best| out[i] = self.result(best));
    }

    /// Closest hits of a batch handed to `f(i, hit, normal)` as each ray `rays[i]` is done, in
    /// no particular order, with the hit's geometric normal (`TriAccel::normal`; zero for a
    /// miss). The normal comes from the block of the hit triangle, tested last or nearly so
    /// and still in cache. A caller can write its own output format here, without a pass over
    /// an intermediate array.
    #[inline]
    pub fn intersect_batch_each(&self, rays: &[Ray], t_min: f32, t_max: TMax<'_>, mut f: impl FnMut(usize, Hit, Vec3)) {
        self.traced::<false>(rays, t_min, t_max, |i, best| {
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
    pub fn occluded_batch(&self, rays: &[Ray], t_min: f32, t_max: f32, out: &mut [bool]) {
        self.traced::<true>(rays, t_min, TMax::One(t_max), |i, best| out[i] = best.is_hit());
    }

    /// Traces a batch, handing each ray's walk result (`Walk::best`) to `finish(i, best)`.
    /// Rays come in groups of `PACKET` consecutive ones: a group that looks coherent
    /// (`coherent::coherent`: a camera's or a sensor's neighbouring rays) is walked as one
    /// packet (`coherent.rs`); the other rays are walked one by one, `LANES` of them
    /// interleaved, each step prefetching what its ray touches next, so that one ray's wait
    /// for memory overlaps the others' work (incoherent rays spend most of their time waiting
    /// for nodes and triangles, one dependent load after another). The same answers either way.
    fn traced<const ANY: bool>(&self, rays: &[Ray], t_min: f32, t_max: TMax<'_>, mut finish: impl FnMut(usize, &Hit)) {
        // Not for a limit per ray (the two levels' streams, `TMax::Each`): measured (2026-12-05,
        // 320x240 camera rays at 10 Bunny instances, rays carried into each instance), the
        // packets took 65 us a packet, 30x the interleaved single walks' time for the same
        // rays, where the same camera's packets on the flat mesh take 0.3 us; the cause is not
        // found yet (translated-only instances show it too), so those batches walk singly.
        let limits_per_ray = matches!(t_max, TMax::Each(_));
        if crate::accel::simd::has_wide() && rays.len() >= PACKET && coherent::packets_enabled() && !limits_per_ray {
            let extent = self.extent();
            // Indices of the rays left to the interleaved walks (u32: a batch is cut into
            // work items far smaller than 2^32 rays; checked).
            let mut rest: Vec<u32> = Vec::new();
            for (g, group) in rays.chunks(PACKET).enumerate() {
                let start = g * PACKET;
                if group.len() == PACKET && coherent::coherent(group, extent) {
                    let limits = std::array::from_fn(|k| t_max.of(start + k));
                    // SAFETY: the CPU runs the eight-lane build, checked above.
                    let a = unsafe { self.walk_coherent::<ANY>(group, t_min, limits) };
                    for (k, best) in a.best.iter().enumerate() {
                        if a.redo >> k & 1 != 0 {
                            finish(start + k, &self.walk_best::<ANY>(&group[k], t_min, limits[k]));
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
            return self.interleaved::<ANY>(rest, t_min, t_max, |i, w| finish(i, &w.best));
        }
        self.interleaved::<ANY>(rays.iter().enumerate(), t_min, t_max, |i, w| finish(i, &w.best))
    }

    /// One ray's single walk, its result as `Walk::best` (a packet's ray with a tie).
    fn walk_best<const ANY: bool>(&self, ray: &Ray, t_min: f32, t_max: f32) -> Hit {
        let mut w = Walk::new(ray, t_min, t_max);
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
