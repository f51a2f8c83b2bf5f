//! GPU-only storage and uniform layouts. Each is `#[repr(C)]` and `Pod`, and is declared once
//! more in `shaders/common.wgsl`; `tests/gpu_layout.rs` parses that file and checks every size
//! and field offset against these structs (and against `Cell`, `TriAccel`, `PointLight` and
//! `CameraFrame`, which the CPU path shares).

use bytemuck::{Pod, Zeroable};

/// Per-triangle shading data: the three vertex normals and the material (40 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct TriShade {
    pub n0: [f32; 3],
    pub n1: [f32; 3],
    pub n2: [f32; 3],
    pub material: u32,
}

#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuMaterial {
    pub diffuse: [f32; 3],
    pub reflectivity: f32,
}

/// A triangle as the GPU reads it: `TriAccel`'s three vertices, each padded to 16 bytes
/// (48 bytes, where `TriAccel` packs 36). A GPU loads an aligned 16-byte group in one access; a
/// 36-byte record is nine 4-byte loads through its index, and every third triangle straddles
/// a 32-byte sector more. The pads are zero.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuTri {
    pub v0: [f32; 3],
    pub _pad0: u32,
    pub v1: [f32; 3],
    pub _pad1: u32,
    pub v2: [f32; 3],
    pub _pad2: u32,
}

impl GpuTri {
    pub fn new(t: &crate::accel::TriAccel) -> GpuTri {
        GpuTri {
            v0: t.v0,
            _pad0: 0,
            v1: t.v1,
            _pad1: 0,
            v2: t.v2,
            _pad2: 0,
        }
    }

    /// The triangles as the kernels read them (`tris` in common.wgsl and build/common.wgsl).
    pub fn all(tris: &[crate::accel::TriAccel]) -> Vec<GpuTri> {
        tris.iter().map(GpuTri::new).collect()
    }
}

/// A queued ray (eye, reflection or shadow), 48 bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct RayRec {
    pub origin: [f32; 3],
    /// Index into the tile's accumulation buffer (batch queries: the ray's index).
    pub pixel: u32,
    pub dir: [f32; 3],
    pub t_max: f32,
    /// Path throughput; for shadow rays the contribution if unoccluded (zeroed if occluded).
    pub weight: [f32; 3],
    pub t_min: f32,
}

/// A closest hit; a miss has `t = inf`, `tri = u32::MAX`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuHit {
    pub t: f32,
    pub tri: u32,
    pub u: f32,
    pub v: f32,
}

/// Scene constants (uniform; vec3 fields are 16-byte aligned in WGSL uniforms, so each is
/// followed by a 4-byte scalar).
///
/// The uniform grid and the irregular grid both count their planes on a regular lattice over
/// `bounds_min..bounds_max`, so they share its fields: for the uniform grid the lattice is its
/// cells, for the irregular grid its virtual voxels (`IrregularGrid::voxel_dims`,
/// `voxel_size`), whose top cells are `dims >> shift`. A BVH scene leaves them zero.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct SceneUniform {
    pub bounds_min: [f32; 3],
    pub ray_epsilon: f32,
    pub bounds_max: [f32; 3],
    pub n_lights: u32,
    /// World-space size of one cell (irregular grid: one virtual voxel) per axis.
    pub cell_size: [f32; 3],
    pub n_tris: u32,
    /// `1 / cell_size`, computed on the host as the CPU walks compute it (`Vec3::recip`), so
    /// both backends map a point to the same cell or voxel; a GPU's division may differ by ulps.
    pub inv_cell_size: [f32; 3],
    pub _pad0: u32,
    /// Cells (irregular grid: virtual voxels) per axis.
    pub dims: [u32; 3],
    /// Irregular grid: levels of the finest top cell (`IrregularGrid::shift`); zero otherwise.
    pub shift: u32,
    pub background: [f32; 3],
    pub _pad2: u32,
    pub ambient: [f32; 3],
    pub _pad3: u32,
}

/// Per-pass constants: which bounce, which counter slots are the input and output queues.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct PassUniform {
    pub depth: u32,
    pub in_slot: u32,
    pub out_slot: u32,
    pub tile_offset: u32,
    pub tile_pixels: u32,
    pub mode: u32,
    pub accel: u32,
    pub max_depth: u32,
    /// 1: compacted queues (the tracer); 0: the `no_compaction` ablation (common.wgsl).
    pub compact: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}

/// A ray batch's constants (`batch.wgsl`): how its rays arrive and what it answers.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct BatchUniform {
    /// Words a wire ray: 6 (origin, direction; the interval and mask below for every ray), 8
    /// (origin, t_min, direction, t_max; the mask below) or 9 (those and the ray's mask); 0:
    /// no wire, the rays made on the device from a sensor's table and poses (`sensor` below).
    pub stride: u32,
    /// 1: the rays go to the shadow queue and the answers are occlusion bits; 0: queue A and
    /// closest hits.
    pub to_shadow: u32,
    /// The interval of every ray when `stride` is 6 (or 0).
    pub t_min: f32,
    pub t_max: f32,
    /// The mask of every ray when `stride` is 6, 8 or 0 (`ray_mask` in common.wgsl).
    pub mask: u32,
    /// 1: closest hits answer `t` alone (4 bytes a ray: a sensor's range); 0: (t, triangle).
    pub range_only: u32,
    /// The batch's index of the chunk's first ray (a sensor's rays are numbered across
    /// chunks: environment, row, column).
    pub first: u32,
    /// A sensor's cells (rows x columns) and columns, and where its poses start in `sensor`
    /// (in floats; its table of rays, six floats a cell, starts at 0).
    pub cells: u32,
    pub cols: u32,
    pub poses_at: u32,
    /// Poses an environment: `cols` (a rolling scan: one a column) or 1 (one for all).
    pub pose_cols: u32,
    pub _pad0: u32,
}

/// Arguments of the two indirect dispatches the `indirect` kernel writes: workgroups (x, y, z)
/// for the kernels over the input ray queue, then for the occlusion kernel over the shadow queue.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct IndirectArgs {
    pub rays: [u32; 3],
    pub shadow: [u32; 3],
}

impl IndirectArgs {
    /// Byte offset of the ray queue's dispatch arguments (for `dispatch_workgroups_indirect`).
    pub const RAYS_OFFSET: u64 = std::mem::offset_of!(IndirectArgs, rays) as u64;
    /// Byte offset of the shadow queue's dispatch arguments.
    pub const SHADOW_OFFSET: u64 = std::mem::offset_of!(IndirectArgs, shadow) as u64;
}

/// Counter slots (defined with the other constants WGSL shares).
pub use super::constants::{COUNTER_SLOTS, SLOT_QUEUE_A, SLOT_REFLECT_TOTAL, SLOT_SHADOW, SLOT_SHADOW_TOTAL};
