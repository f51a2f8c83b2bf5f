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

/// A triangle as the GPU reads it: `TriAccel`'s vertex and two edges, each padded to 16 bytes
/// (48 bytes, where `TriAccel` packs 36). A GPU loads an aligned 16-byte group in one access; a
/// 36-byte record is nine 4-byte loads through its index, and every third triangle straddles
/// a 32-byte sector more. The pads are zero.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuTri {
    pub v0: [f32; 3],
    pub _pad0: u32,
    pub e1: [f32; 3],
    pub _pad1: u32,
    pub e2: [f32; 3],
    pub _pad2: u32,
}

impl GpuTri {
    pub fn new(t: &crate::accel::TriAccel) -> GpuTri {
        GpuTri {
            v0: t.v0,
            _pad0: 0,
            e1: t.e1,
            _pad1: 0,
            e2: t.e2,
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
    /// Floats a wire ray: 6 (origin, direction; the interval below for every ray) or 8
    /// (origin, t_min, direction, t_max).
    pub stride: u32,
    /// 1: the rays go to the shadow queue and the answers are occlusion bits; 0: queue A and
    /// closest hits.
    pub to_shadow: u32,
    /// The interval of every ray when `stride` is 6.
    pub t_min: f32,
    pub t_max: f32,
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

/// A node of the BVH the GPU walks (64 bytes): a binary node holding both children's boxes, so
/// that one node fetch tests both and the ray descends into the nearer (Aila and Laine 2009).
/// The boxes are interleaved as their layout has it, `xy01` = child 0's x and y slabs,
/// `xy11` = child 1's, `z01` = both z slabs, so every field is one 16-byte load.
/// `child[k]` is a stack entry (`gpu/walks/bvh/binary.rs`, `encode_leaf`): an inner node's
/// index, or a leaf's triangle range.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuBvhNode {
    /// Child 0: lo.x, hi.x, lo.y, hi.y.
    pub xy0: [f32; 4],
    /// Child 1: lo.x, hi.x, lo.y, hi.y.
    pub xy1: [f32; 4],
    /// lo.z, hi.z of child 0, then of child 1.
    pub z01: [f32; 4],
    /// The children as stack entries, then the node's position in its parent (`parent << 1 |
    /// slot`, `STACK_DONE` at the root: only the short stack's climb reads it); the last word
    /// is unused.
    pub child: [u32; 4],
}

/// An 8-wide compressed BVH node (`bvh=wide8`; `Bvh8Node` in shaders/walks/bvh8.wgsl, which
/// says what each word holds; gpu/walks/bvh/wide8.rs builds them). 80 bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct GpuBvh8Node {
    /// The origin's bits (xyz) and the scale exponents and inner mask (w).
    pub p_e: [u32; 4],
    /// First child node, first triangle, leaf counts (a nibble per slot), parent position.
    pub info: [u32; 4],
    /// Quantized planes, a byte per slot: lo x, lo y | lo z, hi x | hi y, hi z.
    pub q0: [u32; 4],
    pub q1: [u32; 4],
    pub q2: [u32; 4],
}

/// The uniform of one GPU grid-build dispatch (`shaders/build/common.wgsl`): the lattice, the
/// sizes, and the scan level or distance axis it works on. 80 bytes, one per 256-byte slot.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GridBuildUniform {
    pub bounds_min: [f32; 3],
    pub n_tris: u32,
    pub cell_size: [f32; 3],
    pub n_cells: u32,
    pub inv_cell_size: [f32; 3],
    /// Slots of the references buffer; a build that needs more is run again, larger.
    pub refs_capacity: u32,
    pub margin: [f32; 3],
    /// Distance transform: the axis of this pass (0 = x).
    pub axis: u32,
    pub dims: [u32; 3],
    /// Elements of this scan level, or lines of this distance pass.
    pub n: u32,
    /// Scan: where this level's elements (`in_offset`) and block totals (`out_offset`) are in
    /// the sums buffer.
    pub in_offset: u32,
    pub out_offset: u32,
    /// Scan: 1 on the top level, whose single block total is the number of references.
    pub last: u32,
    pub _pad0: u32,
}
