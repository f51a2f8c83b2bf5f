//! `hwrt` on the GPU: rays traced by the GPU's ray-tracing hardware through wgpu's ray queries
//! (`hwrt.wgsl`), over acceleration structures the device builds at upload
//! (`build.rs`: one bottom-level structure over the triangles, one top-level structure with one
//! instance). Closest-point queries have no ray query: they walk the BVH that `accel::hwrt`
//! keeps, with the BVH's own walk (binary nodes, private stack), whose arrays are this walk's
//! group-1 arrays, the top-level structure bound after them.
//!
//! A `QueryScene`'s instances (two levels) are the driver's own: `INSTANCES`, one BLAS a mesh
//! and a TLAS instance a scene instance (`instances.rs`, `instances.wgsl`; the 32-bit masks on
//! the driver's 8 bits: `masks.rs`).

mod build;
pub mod instances;
pub mod masks;

pub use build::build_on_device;

use super::bvh::{self, BvhLayout, BvhStack, BvhWalk};
use super::two_level::records::TOP_LEVEL_ARRAY;
use super::{WalkSpec, WalkUpload};
use crate::Result;
use crate::accel::StructureId;
use crate::accel::hwrt::Hwrt;
use crate::accel::{Aabb, TriAccel};
use crate::gpu::constants::WgslConst;

pub const SPEC: WalkSpec = WalkSpec {
    structure: StructureId::Hwrt,
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

/// `hwrt` over a scene's instances (two levels): the driver walks the TLAS and the meshes'
/// BLASes; the walk's one array is the instance table (`instances.rs`), bound where the two
/// levels bind their top level (a move writes it by that label), the TLAS after it. Rays
/// only (no closest points: a scene's point queries run on its merged mesh).
pub const INSTANCES: WalkSpec = WalkSpec {
    structure: StructureId::Hwrt,
    name: "hwrt (driver instances)",
    wgsl: &[include_str!("instances.wgsl")],
    prefix: "driver",
    arrays: &[(TOP_LEVEL_ARRAY.0, "hwrt_instances")],
    device_build: false,
    tlas: Some("hwrt_driver_tlas"),
    software_max_tris: None,
    constants: &[
        ("DRIVER_CLASSES", WgslConst::U32(masks::CLASSES as u32)),
        ("DRIVER_EXACT_WORD", WgslConst::U32(instances::DRIVER_EXACT_WORD)),
        ("DRIVER_FIRST_RECORD", WgslConst::U32(instances::DRIVER_FIRST_RECORD)),
    ],
    // The driver walks the meshes (their BLASes): no bottom walk of ours (`entry_points`).
    bottom: Some("hwrt"),
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
