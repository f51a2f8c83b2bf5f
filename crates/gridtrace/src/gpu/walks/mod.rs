//! Each structure's GPU side, a folder each (`walks/NAME/`): its arrays (group 1 of the walking
//! kernels, in binding order), its lattice fields of the scene uniform, its WGSL constants and
//! node layouts, the variants that apply to it alone, its device build if it has one (the
//! grid's `grid/build/`), and its WGSL walk (`NAME/NAME.wgsl`, which declares those arrays and
//! defines `NAME_closest`, `NAME_any` and `NAME_closest_point`). The
//! kernels never name a structure: traverse, occlusion and closest point call `walk_closest`,
//! `walk_any` and `walk_closest_point`, three lines generated per structure
//! (`WalkSpec::entry_points`), and each structure gets its own pipelines of them,
//! compiled when a scene of it is first uploaded (`Kernels::walk`).
//!
//! Adding a structure's GPU side: a folder here with its walk file, its `WalkSpec` and its
//! upload, one entry of `WALKS` and one arm of `upload_of` (and of `device_structure` for a walk
//! by ray query, whose structure the device builds: `hwrt`).

mod brute;
pub mod bvh;
pub mod grid;
pub(crate) mod hwrt;
mod irregular;
pub mod two_level;

use crate::accel::StructureId;
use std::borrow::Cow;
use std::sync::Arc;

use glam::{UVec3, Vec3};

use crate::accel::{Aabb, Structure};
use crate::gpu::bindings::STRUCTURE_ARRAYS_MAX;
use crate::gpu::constants::{self, WgslConst};
use crate::gpu::context::GpuContext;
use crate::gpu::layout::SceneUniform;
use crate::scene::PreparedScene;
use crate::{Error, Result};

/// The closest-point search over a lattice (rings, then the ball), for the walks whose structure is one (the grid's
/// cells, the irregular grid's top cells): each defines the cell it calls, `point_ring_cell`.
const POINT_RING: &str = include_str!("point_ring.wgsl");

/// What the GPU needs to know of a structure before any scene: its walk and its arrays' names.
#[derive(Debug)]
pub struct WalkSpec {
    /// The structure it walks (the registry's `structure` column).
    pub structure: StructureId,
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
    /// Whether a moved mesh's structure is rebuilt on the device (`grid/build/`: the
    /// uniform grid's); the others are updated on the CPU and uploaded again.
    pub device_build: bool,
    /// The most triangles the walk can take on a software adapter, whose shader loops end
    /// after 65,535 iterations (`None`: no limit; every other walk's loops are bounded by
    /// cells or nodes, far below it).
    pub software_max_tris: Option<u32>,
    /// The WGSL name of a top-level acceleration structure the walk traces by ray query
    /// (`hwrt`), bound in group 1 after the arrays (binding `arrays.len()`) and built on the
    /// device at upload (`device_structure`); its modules start with `enable wgpu_ray_query;`
    /// and need a device with ray queries. `None` for the software walks.
    pub tlas: Option<&'static str>,
    /// The structure's own WGSL constants, by WGSL name: they join the prelude of every module
    /// (`wgsl_prelude`), so its walk and its device build read the host's values.
    pub constants: &'static [(&'static str, WgslConst)],
    /// For a walk of two levels (`two_level/`): the bottom structure's prefix, whose
    /// `{bottom}_closest_in` and `{bottom}_any_in` walk one mesh's part of the shared arrays,
    /// named by the mesh's header (`MeshHeader`), under the top level's walk; its last array is
    /// the top level's (`two_level::TOP_LEVEL_ARRAY`). `None`: a walk of one level. A walk of
    /// two levels with a `tlas` (`hwrt::INSTANCES`) has the driver walk both levels.
    pub bottom: Option<&'static str>,
}

impl WalkSpec {
    /// The lines that make this walk the module's `walk_closest`, `walk_any` and (for a walk of
    /// one level) `walk_closest_point` (the nearest point of the mesh: squared distance,
    /// triangle, u, v). A ray's mask reaches the walk (`ray_mask` in common.wgsl); a walk of
    /// one level has no instances to mask and drops it. A walk of two levels also gets its
    /// bottom walk's two lines (`bottom_closest`, `bottom_any`) and the top level's binding.
    pub fn entry_points(&self) -> String {
        let p = self.prefix;
        let rays = format!(
            "fn walk_closest(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, mask: u32, work: ptr<function, u32>) -> GpuHit {{ return {p}_closest(o, d, t_min, t_max, {m}work); }}\n\
             fn walk_any(o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, mask: u32) -> bool {{ return {p}_any(o, d, t_min, t_max{m_last}); }}\n",
            m = if self.bottom.is_some() { "mask, " } else { "" },
            m_last = if self.bottom.is_some() { ", mask" } else { "" },
        );
        match self.bottom {
            // Two levels the driver walks (`hwrt::INSTANCES`): its TLAS is the top level and
            // the meshes' BLASes the bottom, so no top-level array or bottom walk of ours.
            Some(_) if self.tlas.is_some() => rays,
            None => format!(
                "{rays}fn walk_closest_point(point: vec3<f32>, work: ptr<function, u32>) -> GpuHit {{ return {p}_closest_point(point, work); }}\n"
            ),
            Some(b) => format!(
                "{rays}@group(1) @binding({top}) var<storage, read> {name}: array<TopRec>;\n\
                 fn bottom_closest(h: MeshHeader, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32, work: ptr<function, u32>) -> GpuHit {{ return {b}_closest_in(h, o, d, t_min, t_max, work); }}\n\
                 fn bottom_any(h: MeshHeader, o: vec3<f32>, d: vec3<f32>, t_min: f32, t_max: f32) -> bool {{ return {b}_any_in(h, o, d, t_min, t_max); }}\n",
                top = self.arrays.len() - 1,
                name = two_level::TOP_LEVEL_ARRAY.1,
            ),
        }
    }

    /// Whether the walk searches for nearest points (the closest-point kernel is compiled with
    /// it): the walks of one level. The two levels answer rays only; a scene's point queries
    /// run on its merged mesh (`query_scene/merged.rs`).
    pub fn points(&self) -> bool {
        self.bottom.is_none()
    }
}

/// Every GPU walk: each structure's default first, then the BVH's variants
/// (`gpu::variants`), then the walks of two levels (`two_level`).
pub const WALKS: [&WalkSpec; 16] = [
    &grid::SPEC,
    &bvh::SPEC,
    &irregular::SPEC,
    &brute::SPEC,
    &hwrt::SPEC,
    &bvh::SPEC_SHORT,
    &bvh::SPEC_WIDE8,
    &bvh::SPEC_WIDE8_SHORT,
    &two_level::BVH,
    &two_level::BVH_SHORT,
    &two_level::BRUTE,
    &two_level::GRID,
    &two_level::IRREGULAR,
    &two_level::BVH_WIDE8,
    &two_level::BVH_WIDE8_SHORT,
    &hwrt::INSTANCES,
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

/// Every WGSL constant: the shared ones (`constants::SHARED`), then each walk's, each name once
/// (walks of one structure share their list; `tests` check that no name has two values).
pub fn wgsl_constants() -> Vec<(&'static str, WgslConst)> {
    let mut all: Vec<(&'static str, WgslConst)> = constants::SHARED.to_vec();
    for w in WALKS {
        for &(name, value) in w.constants {
            if !all.iter().any(|&(n, _)| n == name) {
                all.push((name, value));
            }
        }
    }
    all
}

/// The WGSL declarations of every constant, prepended to every module (the tracer's kernels and
/// the grid build's): a module that re-declares one fails to compile.
pub fn wgsl_prelude() -> String {
    constants::prelude_of(&wgsl_constants())
}

/// Whether the structure named `structure` traces by ray query (`WalkSpec::tlas`): it runs
/// only on an adapter with ray queries (`GpuContext::ray_query`).
pub fn needs_ray_queries(structure: StructureId) -> bool {
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
    /// A two-level lattice's top cells are `2^shift` cells on a side (the irregular grid's top
    /// cells over its virtual voxels); 0 for one level.
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

impl Lattice {
    /// Writes the lattice into the scene uniform's fields (the others are left as they are).
    pub(crate) fn write_to(&self, u: &mut SceneUniform) {
        u.bounds_min = self.bounds.min.to_array();
        u.bounds_max = self.bounds.max.to_array();
        u.dims = self.dims.to_array();
        u.cell_size = self.cell_size.to_array();
        u.inv_cell_size = self.inv_cell_size.to_array();
        u.shift = self.shift;
    }
}

/// A scene's structure as the GPU takes it: which walk, its arrays (bytes, in `spec.arrays`
/// order) and its lattice.
pub struct WalkUpload<'a> {
    pub spec: &'static WalkSpec,
    pub arrays: Vec<Cow<'a, [u8]>>,
    pub lattice: Lattice,
}

/// The one place the GPU backend reads `scene.accel.structure`; the variants choose the BVH's
/// layout and stack (`bvh_walk`; the other structures have one walk each).
pub fn upload_of(scene: &PreparedScene, bvh_walk: bvh::BvhWalk) -> Result<WalkUpload<'_>> {
    let upload = match &scene.accel.structure {
        Structure::Grid(g) => grid::upload(g),
        Structure::Bvh(b) => bvh::upload(b, &scene.accel.tris, scene.accel.bounds(), bvh_walk)?,
        Structure::Irregular(g) => irregular::upload(g),
        Structure::Brute(_) => brute::upload(scene.accel.bounds()),
        Structure::Hwrt(h) => hwrt::upload(h, &scene.accel.tris, scene.accel.bounds())?,
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

/// A structure that the device rebuilds when its mesh moves (`WalkSpec::device_build`), kept
/// between builds with its pipelines and buffers.
pub(crate) enum DeviceBuilder {
    Grid(grid::build::GpuGrid),
}

/// What a rebuild on the device left: the arrays to bind in place of the uploaded ones (by
/// their `WalkSpec::arrays` label), the new lattice, the bytes of each array, and the build's
/// own figures.
pub(crate) struct DeviceBuilt<'a> {
    pub arrays: Vec<(&'static str, &'a wgpu::Buffer)>,
    pub lattice: Lattice,
    pub memory: Vec<(&'static str, u64)>,
    pub stats: grid::build::GpuBuildStats,
}

/// Rebuilds the scene's structure on `ctx`'s device over its moved triangles (`gpu_tris`, the
/// scene's triangles as uploaded), with `builder` (made on first use): the one place the
/// renderer's updates read which structure it has. An error for a structure without a device
/// build (`WalkSpec::device_build`), which the CPU updates and the renderer uploads again.
pub(crate) fn rebuild_on_device<'b>(
    builder: &'b mut Option<DeviceBuilder>,
    ctx: &Arc<GpuContext>,
    gpu_tris: &wgpu::Buffer,
    scene: &PreparedScene,
) -> Result<DeviceBuilt<'b>> {
    match &scene.accel.structure {
        Structure::Grid(g) => {
            let builder = match builder {
                Some(b) => b,
                None => builder.insert(DeviceBuilder::Grid(grid::build::GpuGrid::new(ctx.clone())?)),
            };
            let DeviceBuilder::Grid(gpu_grid) = builder;
            grid::rebuild_on_device(gpu_grid, gpu_tris, &scene.accel.tris, g.resolution)
        }
        other => Err(Error::Gpu(format!(
            "structure '{}' has no build on the device; it is updated on the CPU and uploaded",
            other.kind().name()
        ))),
    }
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
    /// The printed f32s read back as the same bits (naga's own reading is checked in
    /// tests/gpu_layout.rs).
    #[test]
    fn f32_literals_round_trip() {
        for (name, value) in wgsl_constants() {
            if let WgslConst::F32(v) = value {
                let text = constants::f32_literal(v);
                let back: f32 = text.trim_end_matches('f').parse().unwrap();
                assert_eq!(back.to_bits(), v.to_bits(), "{name}: {text}");
            }
        }
    }

    /// A name two lists declare has one value (the prelude keeps the first).
    #[test]
    fn a_name_has_one_value() {
        let lists = std::iter::once(&constants::SHARED[..]).chain(WALKS.iter().map(|w| w.constants));
        let mut seen: Vec<(&str, WgslConst)> = Vec::new();
        for list in lists {
            for &(name, value) in list {
                match seen.iter().find(|(n, _)| *n == name) {
                    Some(&(_, v)) => assert_eq!(v, value, "{name}"),
                    None => seen.push((name, value)),
                }
            }
        }
        let all = wgsl_constants();
        assert_eq!(all.len(), seen.len());
    }

    #[test]
    fn the_largest_walk_uses_the_whole_array_budget() {
        let most = WALKS.iter().map(|w| w.arrays.len()).max();
        assert_eq!(most, Some(STRUCTURE_ARRAYS_MAX));
    }
}
