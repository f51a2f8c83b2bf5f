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
//! asking for the hardware. It implements no `Walks` of its own: `Accel`'s `walk!` hands its
//! CPU-side walks to the BVH.

use crate::Result;
use crate::accel::AccelParams;
use crate::accel::TriAccel;
use crate::accel::bvh::BvhAccel;
use crate::accel::contract::AccelStructure;

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
}
