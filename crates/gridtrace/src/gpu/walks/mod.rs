//! Each structure's GPU side: its arrays (group 1 of the walking kernels, in binding order), its
//! lattice fields of the scene uniform, and its WGSL walk (`shaders/walks/NAME.wgsl`, which
//! declares those arrays and defines `NAME_closest`, `NAME_any` and `NAME_closest_point`). The
//! kernels never name a structure: traverse, occlusion and closest point call `walk_closest`,
//! `walk_any` and `walk_closest_point`, three lines generated per structure
//! (`WalkSpec::entry_points`), and each structure gets its own pipelines of them,
//! compiled when a scene of it is first uploaded (`Kernels::walk`).
//!
//! Adding a structure's GPU side: a walk file, a file here with its `WalkSpec` and its upload,
//! one entry of `WALKS` and one arm of `upload_of` (and of `device_structure` for a walk by
//! ray query, whose structure the device builds: `hwrt`).

mod brute;
pub mod bvh;
mod grid;
mod hwrt;
mod irregular;

use std::borrow::Cow;

use glam::{UVec3, Vec3};

use crate::Result;
use crate::accel::{Aabb, Structure};
use crate::gpu::bindings::STRUCTURE_ARRAYS_MAX;
use crate::gpu::context::GpuContext;
use crate::gpu::variants::GpuVariants;
use crate::scene::PreparedScene;

/// What the GPU needs to know of a structure before any scene: its walk and its arrays' names.
#[derive(Debug)]
pub struct WalkSpec {
    /// The structure, as the registry's `structure` column names it.
    pub structure: &'static str,
    /// The walk's own name: the structure's, or the structure's with the variant that chose
    /// it (`bvh (wide8)`); compiled pipelines are cached by it.
    pub name: &'static str,
    /// The walk's WGSL files, in order (a walk and the stack it uses).
    pub wgsl: &'static [&'static str],
    /// The walk's entry points are `{prefix}_closest`, `{prefix}_any` and
    /// `{prefix}_closest_point`.
    pub prefix: &'static str,
    /// Group 1's arrays in binding order: the name reports use (`GpuRenderer::memory`) and the
    /// WGSL variable's name.
    pub arrays: &'static [(&'static str, &'static str)],
    /// Whether a moved mesh's structure is rebuilt on the device (`gpu::grid_build`: the
    /// uniform grid's); the others are updated on the CPU and uploaded again.
    pub device_build: bool,
    /// The most triangles the walk can take on a software adapter, whose shader loops end
    /// after 65,535 iterations (`None`: no limit; every other walk's loops are bounded by
    /// cells or nodes, far below it).
    pub software_max_tris: Option<u32>,
    /// Keeps its stack in workgroup memory (`stack=short`): its stack file defines the same
    /// functions as the private stack's, so the two never share a module.
    pub short_stack: bool,
    /// The WGSL name of a top-level acceleration structure the walk traces by ray query
    /// (`hwrt`), bound in group 1 after the arrays (binding `arrays.len()`) and built on the
    /// device at upload (`device_structure`); its modules start with `enable wgpu_ray_query;`
    /// and need a device with ray queries. `None` for the software walks.
    pub tlas: Option<&'static str>,
}

impl WalkSpec {
    /// The three lines that make this walk the module's `walk_closest`, `walk_any` and
    /// `walk_closest_point` (the nearest point of the mesh: squared distance, triangle, u, v).
    pub fn entry_points(&self) -> String {
        let p = self.prefix;
        format!(
            "fn walk_closest(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, work: ptr<function, u32>) -> GpuHit {{ return {p}_closest(o, d, t_min, t_max, work); }}\n\
             fn walk_any(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> bool {{ return {p}_any(o, d, t_min, t_max); }}\n\
             fn walk_closest_point(point: vec3<f32>, work: ptr<function, u32>) -> GpuHit {{ return {p}_closest_point(point, work); }}\n"
        )
    }
}

/// Every GPU walk: each structure's default first, then the BVH's variants
/// (`gpu::variants`).
pub const WALKS: [&WalkSpec; 8] = [
    &grid::SPEC,
    &bvh::SPEC,
    &irregular::SPEC,
    &brute::SPEC,
    &hwrt::SPEC,
    &bvh::SPEC_SHORT,
    &bvh::SPEC_WIDE8,
    &bvh::SPEC_WIDE8_SHORT,
];

// Every walk's arrays fit what a device is asked to allow for them (a walk with more fails to
// compile here, not on a device with exactly the budget): raise the budget with the walk.
const _: () = {
    let mut i = 0;
    while i < WALKS.len() {
        assert!(
            WALKS[i].arrays.len() <= STRUCTURE_ARRAYS_MAX,
            "a walk binds more arrays than bindings::STRUCTURE_ARRAYS_MAX"
        );
        i += 1;
    }
};

/// Whether the structure named `structure` traces by ray query (`WalkSpec::tlas`): it runs
/// only on an adapter with ray queries (`GpuContext::ray_query`).
pub fn needs_ray_queries(structure: &str) -> bool {
    WALKS.iter().any(|w| w.structure == structure && w.tlas.is_some())
}

/// The lattice fields of `SceneUniform` that a walk reads: the grid's cells, the irregular
/// grid's virtual voxels, nothing (zeros) for the others.
#[derive(Debug, Clone, Copy)]
pub struct Lattice {
    pub bounds: Aabb,
    pub dims: UVec3,
    /// World-space size of one cell or voxel per axis, and its reciprocal.
    pub cell_size: Vec3,
    pub inv_cell_size: Vec3,
    /// Irregular grid: `IrregularGrid::shift`.
    pub shift: u32,
}

impl Lattice {
    /// Bounds only (the BVH and brute force: ray generation clips to them), no cells.
    pub fn bounds_only(bounds: Aabb) -> Lattice {
        Lattice {
            bounds,
            dims: UVec3::ZERO,
            cell_size: Vec3::ZERO,
            inv_cell_size: Vec3::ZERO,
            shift: 0,
        }
    }
}

/// A scene's structure as the GPU takes it: which walk, its arrays (bytes, in `spec.arrays`
/// order) and its lattice.
pub struct WalkUpload<'a> {
    pub spec: &'static WalkSpec,
    pub arrays: Vec<Cow<'a, [u8]>>,
    pub lattice: Lattice,
}

/// The one place the GPU backend reads `scene.accel.structure`; `variants` choose the BVH's
/// layout and stack (the other structures have one walk each).
pub fn upload_of<'a>(scene: &'a PreparedScene, variants: &GpuVariants) -> Result<WalkUpload<'a>> {
    let upload = match &scene.accel.structure {
        Structure::Grid(g) => grid::upload(g),
        Structure::Bvh(b) => bvh::upload(b, &scene.accel.tris, scene.accel.bounds(), variants)?,
        Structure::Irregular(g) => irregular::upload(g),
        Structure::Brute(_) => brute::upload(scene.accel.bounds()),
        Structure::Hwrt(h) => hwrt::upload(h, &scene.accel.tris, scene.accel.bounds(), variants)?,
    };
    debug_assert_eq!(upload.arrays.len(), upload.spec.arrays.len());
    Ok(upload)
}

/// The acceleration structure a ray-query walk (`WalkSpec::tlas`) binds, built on `ctx`'s
/// device from the scene's triangles: the one place the GPU backend builds one.
pub(crate) fn device_structure(ctx: &GpuContext, scene: &PreparedScene) -> Result<Option<DeviceStructure>> {
    Ok(match &scene.accel.structure {
        Structure::Hwrt(_) => Some(hwrt::build_on_device(ctx, &scene.accel.tris)?),
        _ => None,
    })
}

/// A top-level acceleration structure on the device, with what it cost.
pub(crate) struct DeviceStructure {
    /// Bound after the walk's arrays; it keeps its bottom-level structures alive.
    pub tlas: wgpu::Tlas,
    /// Bytes of the geometry uploaded for the build (the driver's own structures are not
    /// counted: wgpu does not report them).
    pub input_bytes: u64,
}

/// A slice's bytes, borrowed.
fn bytes<T: bytemuck::Pod>(v: &[T]) -> Cow<'_, [u8]> {
    Cow::Borrowed(bytemuck::cast_slice(v))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The budget is no larger than the walks need: a larger one would refuse adapters that
    /// can run every walk.
    #[test]
    fn the_largest_walk_uses_the_whole_array_budget() {
        let most = WALKS.iter().map(|w| w.arrays.len()).max();
        assert_eq!(most, Some(STRUCTURE_ARRAYS_MAX));
    }
}
