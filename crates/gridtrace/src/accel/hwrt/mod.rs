//! `hwrt`: the GPU's ray-tracing hardware, through wgpu's ray queries. The structure that rays
//! walk is the driver's: one bottom-level acceleration structure over the triangles and one
//! top-level structure with a single instance, built on the device at upload
//! (`gpu/walks/hwrt/`). Nothing of it exists on the CPU.
//!
//! What this CPU side keeps is a BVH (`accel::bvh`), for the two things a ray query cannot do:
//! closest-point queries (the GPU walks the BVH's nodes for them, `gpu/walks/hwrt/`; the CPU
//! asks this BVH) and the library's CPU-side answers for a scene prepared for `hwrt` (all-hits
//! counts and lists, the tests' reference walks). It is the one structure that builds on
//! another: the ray queries replace the BVH's ray walk, nothing else of it. The backends refuse
//! to *trace* `hwrt` on the CPU (the registry's `cpu` column is false): asking for it there is
//! asking for the hardware.

use glam::Vec3;

use crate::Result;
use crate::accel::AccelParams;
use crate::accel::bvh::BvhAccel;
use crate::accel::closest::ClosestPoint;
use crate::accel::contract::AccelStructure;
use crate::accel::{Counters, Hit, PACKET, Ray, TMax, TriAccel};

/// The BVH kept beside the device's acceleration structures (see the module's note).
#[derive(Debug, Clone)]
pub struct Hwrt {
    pub bvh: BvhAccel,
    /// Triangles when built, for the summary.
    pub triangles: usize,
}

impl AccelStructure for Hwrt {
    fn build(tris: &[TriAccel], params: &AccelParams) -> Result<Hwrt> {
        params.read("hwrt", &[], |_, _| Ok(()))?;
        Ok(Hwrt {
            bvh: AccelStructure::build(tris, &AccelParams::NONE)?,
            triangles: tris.len(),
        })
    }

    /// The BVH is refitted here; the device's structures are rebuilt from the moved triangles
    /// when the scene is uploaded again (`gpu/walks/hwrt/`).
    fn update(&mut self, tris: &[TriAccel]) -> Result<&'static str> {
        AccelStructure::update(&mut self.bvh, tris)?;
        Ok("rebuilt on the device (its CPU-side BVH refitted)")
    }

    fn memory(&self) -> Vec<(&'static str, usize)> {
        // The BVH kept for closest points; the device's structures are the driver's (the
        // vertices they were built from: `GpuRenderer::memory`'s `ray-query geometry`).
        AccelStructure::memory(&self.bvh)
    }

    fn summary(&self) -> String {
        format!(
            "hardware ray queries over {} triangles (built on the device; closest points by a BVH: {})",
            self.triangles,
            AccelStructure::summary(&self.bvh)
        )
    }

    fn intersect<C: Counters>(&self, tris: &[TriAccel], ray: &Ray, t_min: f32, t_max: f32, counters: &mut C) -> Hit {
        AccelStructure::intersect(&self.bvh, tris, ray, t_min, t_max, counters)
    }

    fn occluded<C: Counters>(&self, tris: &[TriAccel], ray: &Ray, t_min: f32, t_max: f32, counters: &mut C) -> bool {
        AccelStructure::occluded(&self.bvh, tris, ray, t_min, t_max, counters)
    }

    fn intersect_packet<C: Counters>(
        &self,
        tris: &[TriAccel],
        rays: &[Ray],
        t_min: f32,
        t_max: f32,
        counters: &mut [C],
    ) -> [Hit; PACKET] {
        AccelStructure::intersect_packet(&self.bvh, tris, rays, t_min, t_max, counters)
    }

    fn occluded_packet<C: Counters>(
        &self,
        tris: &[TriAccel],
        rays: &[Ray],
        t_min: f32,
        t_max: [f32; PACKET],
        counters: &mut [C],
    ) -> [bool; PACKET] {
        AccelStructure::occluded_packet(&self.bvh, tris, rays, t_min, t_max, counters)
    }

    fn intersect_batch_each(
        &self,
        tris: &[TriAccel],
        rays: &[Ray],
        t_min: f32,
        t_max: TMax<'_>,
        f: impl FnMut(usize, Hit, Vec3),
    ) {
        AccelStructure::intersect_batch_each(&self.bvh, tris, rays, t_min, t_max, f)
    }

    fn occluded_batch(&self, tris: &[TriAccel], rays: &[Ray], t_min: f32, t_max: f32, out: &mut [bool]) {
        AccelStructure::occluded_batch(&self.bvh, tris, rays, t_min, t_max, out)
    }

    fn all_hits(&self, tris: &[TriAccel], ray: &Ray, t_min: f32, t_max: f32, out: &mut Vec<Hit>) {
        AccelStructure::all_hits(&self.bvh, tris, ray, t_min, t_max, out)
    }

    fn count_hits_batch(&self, tris: &[TriAccel], rays: &[Ray], t_min: f32, t_max: f32, out: &mut [u32]) {
        AccelStructure::count_hits_batch(&self.bvh, tris, rays, t_min, t_max, out)
    }

    fn closest_point(&self, tris: &[TriAccel], p: Vec3) -> ClosestPoint {
        AccelStructure::closest_point(&self.bvh, tris, p)
    }

    fn closest_points_batch(&self, tris: &[TriAccel], points: &[[f32; 3]], out: &mut [ClosestPoint]) {
        AccelStructure::closest_points_batch(&self.bvh, tris, points, out)
    }
}
