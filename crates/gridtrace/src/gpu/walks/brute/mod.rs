//! Brute force on the GPU: no arrays of its own (it reads the shared triangles); the walk is
//! `brute.wgsl`.

use super::{Lattice, WalkSpec, WalkUpload};
use crate::accel::Aabb;
use crate::accel::StructureId;

pub const SPEC: WalkSpec = WalkSpec {
    structure: StructureId::Brute,
    name: "brute",
    wgsl: &[include_str!("brute.wgsl")],
    prefix: "brute",
    arrays: &[],
    device_build: false,
    tlas: None,
    // Four triangles a loop iteration (brute.wgsl) times llvmpipe's 65,535 iterations.
    software_max_tris: Some(4 * 65_535),
    constants: &[],
    bottom: None,
};

pub fn upload(bounds: Aabb) -> WalkUpload<'static> {
    WalkUpload {
        spec: &SPEC,
        arrays: Vec::new(),
        lattice: Lattice::bounds_only(bounds),
    }
}
