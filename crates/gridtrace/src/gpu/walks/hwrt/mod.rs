//! `hwrt` on the GPU: rays traced by the GPU's ray-tracing hardware through wgpu's ray queries
//! (`hwrt.wgsl`), over acceleration structures the device builds at upload
//! (`build.rs`: one bottom-level structure over the triangles, one top-level structure with one
//! instance). Closest-point queries have no ray query: they walk the BVH that `accel::hwrt`
//! keeps, with the BVH's own walk (binary nodes, private stack), whose arrays are this walk's
//! group-1 arrays, the top-level structure bound after them.

mod build;

pub use build::build_on_device;

use super::bvh::{self, BvhLayout, BvhStack, BvhWalk};
use super::{WalkSpec, WalkUpload};
use crate::Result;
use crate::accel::hwrt::Hwrt;
use crate::accel::{Aabb, TriAccel};

pub const SPEC: WalkSpec = WalkSpec {
    structure: "hwrt",
    name: "hwrt",
    // The BVH's walk for the closest points, then the ray queries.
    wgsl: &[bvh::BINARY, bvh::BINARY_PRIVATE, include_str!("hwrt.wgsl")],
    prefix: "hwrt",
    arrays: bvh::SPEC.arrays,
    // Rebuilt at each upload (a moved mesh is uploaded again): see `build.rs`.
    device_build: false,
    tlas: Some("hwrt_tlas"),
    // The driver's walk has no shader loop of ours; the closest-point walk is bounded by nodes.
    software_max_tris: None,
    constants: bvh::SPEC.constants,
    bottom: None,
};

/// The BVH's arrays for the closest points, in the layout `SPEC`'s BVH walk reads whatever the
/// variants say (`bvh=` and `stack=` choose the BVH structure's walk, not this one's).
pub fn upload<'a>(h: &'a Hwrt, tris: &[TriAccel], bounds: Aabb) -> Result<WalkUpload<'a>> {
    let binary_private = BvhWalk {
        layout: BvhLayout::Binary,
        stack: BvhStack::Private,
    };
    let mut up = bvh::upload(&h.bvh, tris, bounds, binary_private)?;
    up.spec = &SPEC;
    Ok(up)
}
