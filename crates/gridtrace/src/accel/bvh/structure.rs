//! The eight-wide BVH under the structure contract. It keeps its own copy of the triangles in
//! leaf blocks, so its walks ignore the ones `Accel` holds; moved triangles refit its boxes.

use glam::Vec3;

use super::BvhAccel;
use crate::Result;
use crate::accel::AccelParams;
use crate::accel::contract::{AccelStructure, Walks};
use crate::accel::{Counters, Hit, PACKET, Ray, TriAccel};
use crate::util::fmt_bytes;

impl AccelStructure for BvhAccel {
    fn build(tris: &[TriAccel], params: &AccelParams) -> Result<BvhAccel> {
        params.read("bvh", &[], |_, _| Ok(()))?;
        Ok(BvhAccel::build(tris))
    }

    /// The tree is kept and its boxes recomputed: much cheaper than a rebuild, at a quality
    /// that degrades as the vertices move away from the build pose. Cannot fail (the count is
    /// checked by `Accel::update`).
    fn update(&mut self, tris: &[TriAccel]) -> Result<&'static str> {
        self.refit(tris);
        Ok("refitted")
    }

    fn memory(&self) -> Vec<(&'static str, usize)> {
        vec![("bvh", BvhAccel::memory(self))]
    }

    fn summary(&self) -> String {
        format!(
            "bvh {} wide nodes, depth {}, {}",
            self.nodes.len(),
            self.bvh.depth,
            fmt_bytes(BvhAccel::memory(self))
        )
    }
}

/// The BVH's walks, written in its own files (`walk.rs`, `packet.rs`, `all_hits.rs`,
/// `closest.rs`) as methods that need not the triangles `Accel` holds: its leaf blocks keep
/// their own copy.
impl Walks for BvhAccel {
    #[inline]
    fn intersect<C: Counters>(&self, _tris: &[TriAccel], ray: &Ray, counters: &mut C) -> Hit {
        BvhAccel::intersect(self, ray, counters)
    }

    #[inline]
    fn occluded<C: Counters>(&self, _tris: &[TriAccel], ray: &Ray, counters: &mut C) -> bool {
        BvhAccel::occluded(self, ray, counters)
    }

    #[inline]
    fn intersect_packet<C: Counters>(&self, _tris: &[TriAccel], rays: &[Ray], counters: &mut [C]) -> [Hit; PACKET] {
        BvhAccel::intersect_packet(self, rays, counters)
    }

    #[inline]
    fn occluded_packet<C: Counters>(&self, _tris: &[TriAccel], rays: &[Ray], counters: &mut [C]) -> [bool; PACKET] {
        BvhAccel::occluded_packet(self, rays, counters)
    }

    /// The rays interleaved with prefetching; the normal taken from the hit's block while it
    /// is still in cache (looked up afterwards it is a cache miss per hit).
    #[inline]
    fn intersect_batch_each(&self, _tris: &[TriAccel], rays: &[Ray], f: impl FnMut(usize, Hit, Vec3)) {
        BvhAccel::intersect_batch_each(self, rays, f)
    }

    /// The interleaved single walks alone: a stream's rays are not coherent at the leaves'
    /// scale (`BvhAccel::traced` has the figures).
    fn intersect_stream_each(&self, _tris: &[TriAccel], rays: &[Ray], f: impl FnMut(usize, Hit, Vec3)) {
        BvhAccel::intersect_stream_each(self, rays, f)
    }

    fn occluded_batch(&self, _tris: &[TriAccel], rays: &[Ray], out: &mut [bool]) {
        BvhAccel::occluded_batch(self, rays, out)
    }

    /// The tree walked with no early exit (`all_hits.rs`); a triangle is in one leaf only.
    fn all_hits(&self, _tris: &[TriAccel], ray: &Ray, out: &mut Vec<Hit>) {
        BvhAccel::all_hits(self, ray, out)
    }

    /// The all-hits walk counting instead of listing, rays interleaved (`all_hits.rs`).
    fn count_hits_batch(&self, _tris: &[TriAccel], rays: &[Ray], out: &mut [u32]) {
        BvhAccel::count_hits_batch(self, rays, out)
    }

    /// The searches interleaved with prefetching (`closest.rs`).
    fn closest_points_batch(
        &self,
        _tris: &[TriAccel],
        points: &[[f32; 3]],
        out: &mut [crate::accel::closest::ClosestPoint],
    ) {
        BvhAccel::closest_points_batch(self, points, out)
    }

    /// Branch and bound over the structure's own cells or nodes (`closest.rs`).
    fn closest_point(&self, _tris: &[TriAccel], p: glam::Vec3) -> crate::accel::closest::ClosestPoint {
        BvhAccel::closest_point(self, p)
    }
}
