//! The BVH on the GPU: its two-child nodes (`gpu::bvh::gpu_nodes`) and its triangle indices in
//! leaf order; the walk is `shaders/walks/bvh.wgsl`.

use std::borrow::Cow;

use super::{Lattice, WalkSpec, WalkUpload, bytes};
use crate::accel::{Aabb, BvhAccel};
use crate::gpu::bvh::gpu_nodes;
use crate::gpu::constants::BVH_STACK;
use crate::{Error, Result};

pub const SPEC: WalkSpec = WalkSpec {
    structure: "bvh",
    wgsl: include_str!("../shaders/walks/bvh.wgsl"),
    prefix: "bvh",
    arrays: &[("bvh_nodes", "bvh_nodes"), ("refs", "bvh_prims")],
    device_build: false,
    software_max_tris: None,
};

pub fn upload(b: &BvhAccel, bounds: Aabb) -> Result<WalkUpload<'_>> {
    if b.bvh.depth >= BVH_STACK as usize {
        // The builder bounds the depth below the stack (`STACK`); checked all the same, since
        // an overflow would lose hits silently.
        return Err(Error::InvalidInput(format!(
            "the BVH is {} levels deep; the GPU walk's stack holds {BVH_STACK}",
            b.bvh.depth
        )));
    }
    let nodes = gpu_nodes(&b.bvh)?;
    Ok(WalkUpload {
        spec: &SPEC,
        arrays: vec![Cow::Owned(bytemuck::cast_slice(&nodes).to_vec()), bytes(&b.bvh.prims)],
        // The walk reads only the bounds (ray generation clips to them).
        lattice: Lattice::bounds_only(bounds),
    })
}
