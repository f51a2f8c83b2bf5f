//! The buffers the kernels bind, as one table per bind group. Each row gives the binding index,
//! the WGSL variable's name and its access; the same rows produce the bind group layout and, given
//! a buffer for each row, the bind group, so the two cannot disagree. `tests/gpu_layout.rs` checks
//! the rows against the `@group @binding` declarations of the WGSL.

/// How a kernel may use a bound buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    Uniform,
    StorageRead,
    StorageReadWrite,
}

/// One row of a bind group table; `slot` is what the host binds there.
#[derive(Debug, Clone, Copy)]
pub struct Binding<S> {
    pub index: u32,
    /// The WGSL variable's name.
    pub name: &'static str,
    pub access: Access,
    pub slot: S,
}

/// What group 0 binds: everything a kernel of the tile loop reads or writes. Each kernel's own
/// group 0 holds only the rows its module uses (`FRAME_USE`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameSlot {
    SceneUniform,
    CameraUniform,
    /// One bounce's `PassUniform` (a range of the pass uniform buffer).
    PassUniform,
    Tris,
    TriShade,
    Materials,
    Lights,
    /// The bounce's input ray queue (queues A and B swap roles every bounce).
    RaysIn,
    RaysOut,
    Hits,
    ShadowRays,
    Resolve,
    Accum,
    Counters,
}

pub const FRAME_GROUP: u32 = 0;

const fn row<S>(index: u32, name: &'static str, access: Access, slot: S) -> Binding<S> {
    Binding {
        index,
        name,
        access,
        slot,
    }
}

use Access::{StorageRead, StorageReadWrite, Uniform};

/// Group 0, as declared in common.wgsl.
pub const FRAME_BINDINGS: [Binding<FrameSlot>; 14] = [
    row(0, "scene", Uniform, FrameSlot::SceneUniform),
    row(1, "camera", Uniform, FrameSlot::CameraUniform),
    row(2, "pass_", Uniform, FrameSlot::PassUniform),
    row(5, "tris", StorageRead, FrameSlot::Tris),
    row(6, "tri_shade", StorageRead, FrameSlot::TriShade),
    row(7, "materials", StorageRead, FrameSlot::Materials),
    // A uniform array (`constants::MAX_LIGHTS` long): one storage buffer fewer for shading.
    row(8, "lights", Uniform, FrameSlot::Lights),
    row(9, "rays_in", StorageReadWrite, FrameSlot::RaysIn),
    row(10, "rays_out", StorageReadWrite, FrameSlot::RaysOut),
    row(11, "hits", StorageReadWrite, FrameSlot::Hits),
    row(12, "shadow_rays", StorageReadWrite, FrameSlot::ShadowRays),
    row(13, "resolve", StorageReadWrite, FrameSlot::Resolve),
    row(14, "accum", StorageReadWrite, FrameSlot::Accum),
    row(15, "counters", StorageReadWrite, FrameSlot::Counters),
];

/// Group 1 of the walking kernels (traverse, occlusion): the scene's structure's own arrays, as
/// its `gpu::walks::WalkSpec` lists them (binding `i` is `arrays[i]`; every one read-only
/// storage). The indirect kernel's group 1 is its arguments (below): the two never share a
/// pipeline.
pub const STRUCTURE_GROUP: u32 = 1;

/// What group 1 binds: the indirect arguments, written as storage by the one kernel that
/// computes them. Apart from group 0 because a buffer bound as storage in the dispatch that
/// reads it as indirect arguments would be a usage conflict.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IndirectSlot {
    Args,
}

pub const INDIRECT_GROUP: u32 = 1;

/// Group 1, as declared in indirect.wgsl.
pub const INDIRECT_BINDINGS: [Binding<IndirectSlot>; 1] = [row(0, "indirect", StorageReadWrite, IndirectSlot::Args)];

/// What group 1 of the pack kernel binds: the tile's pixels as packed 8-bit sRGB.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PackSlot {
    Packed,
}

pub const PACK_GROUP: u32 = 1;

/// Group 1, as declared in pack.wgsl.
pub const PACK_BINDINGS: [Binding<PackSlot>; 1] = [row(0, "packed", StorageReadWrite, PackSlot::Packed)];

/// What group 1 of the ray batches' two kernels (`batch.wgsl`) binds: the chunk's rays as they
/// came over the bus, the answers going back, and the batch's constants.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BatchSlot {
    Wire,
    Answers,
    Uniform,
    /// A sensor's table and poses (scans: the rays made on the device).
    Sensor,
}

pub const BATCH_GROUP: u32 = 1;
/// The batch's group in a walking kernel that binds it (the all-hits kernels), after the
/// structure's arrays.
pub const BATCH_AFTER_WALK_GROUP: u32 = 2;

/// Group 1, as declared in batch.wgsl.
pub const BATCH_BINDINGS: [Binding<BatchSlot>; 4] = [
    row(0, "wire", StorageRead, BatchSlot::Wire),
    row(1, "answers", StorageReadWrite, BatchSlot::Answers),
    row(2, "batch", Uniform, BatchSlot::Uniform),
    row(3, "sensor", StorageRead, BatchSlot::Sensor),
];

/// What group 2 of the winding kernel (`winding.wgsl`) binds: the fast winding tree's nodes and
/// leaf blocks, as the CPU lays them out (`gpu/winding.rs`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WindingSlot {
    Nodes,
    Blocks,
}

/// The winding kernel's group after the batch's.
pub const WINDING_GROUP: u32 = 2;

/// Group 2 of winding.wgsl.
pub const WINDING_BINDINGS: [Binding<WindingSlot>; 2] = [
    row(0, "wind_nodes", StorageRead, WindingSlot::Nodes),
    row(1, "wind_blocks", StorageRead, WindingSlot::Blocks),
];

/// Every binding of every group as (group, index, WGSL name, access), for checks against WGSL.
pub fn all() -> Vec<(u32, u32, &'static str, Access)> {
    let frame = FRAME_BINDINGS.iter().map(|b| (FRAME_GROUP, b.index, b.name, b.access));
    let indirect = INDIRECT_BINDINGS
        .iter()
        .map(|b| (INDIRECT_GROUP, b.index, b.name, b.access));
    let pack = PACK_BINDINGS.iter().map(|b| (PACK_GROUP, b.index, b.name, b.access));
    let batch = BATCH_BINDINGS.iter().map(|b| (BATCH_GROUP, b.index, b.name, b.access));
    let batch_after_walk = BATCH_BINDINGS
        .iter()
        .map(|b| (BATCH_AFTER_WALK_GROUP, b.index, b.name, b.access));
    frame
        .chain(indirect)
        .chain(pack)
        .chain(batch)
        .chain(batch_after_walk)
        .chain(
            WINDING_BINDINGS
                .iter()
                .map(|b| (WINDING_GROUP, b.index, b.name, b.access)),
        )
        .collect()
}

/// The most arrays a structure's walk binds in group 1 (the irregular grid's four): what the
/// device is asked to allow for them. A fixed budget rather than the walks' maximum, so that
/// opening a device (`context`) needs no walk; `walks` checks every walk against it when the
/// crate compiles.
pub const STRUCTURE_ARRAYS_MAX: usize = 4;

/// Storage rows of a table (what WebGPU counts against `maxStorageBuffersPerShaderStage`).
const fn storage_rows<S>(table: &[Binding<S>]) -> usize {
    let (mut k, mut n) = (0, 0);
    while k < table.len() {
        if !matches!(table[k].access, Access::Uniform) {
            n += 1;
        }
        k += 1;
    }
    n
}

/// What each kernel's module binds, by its name in `shaders::KERNELS` (a walking kernel's:
/// what it uses with any walk): the rows of group 0 it uses, and the storage buffers of its
/// group 1 (a structure's arrays, the indirect arguments, the packed pixels or a batch's
/// buffers). A kernel's group 0 layout has these rows alone, not all of `FRAME_BINDINGS`:
/// WebGPU counts every storage buffer of a pipeline's layout against
/// `maxStorageBuffersPerShaderStage` (8 by default, 10 on SwiftShader), whether the kernel reads
/// it or not, and group 0 holds 10 of them. `tests/gpu_layout.rs` checks each list against
/// naga's analysis of the kernel's modules (a row missing fails pipeline creation; an extra one
/// only costs a binding, but is reported too).
pub const FRAME_USE: [(&str, usize, &[FrameSlot]); 12] = {
    use FrameSlot::*;
    const WALK: usize = STRUCTURE_ARRAYS_MAX;
    [
        (
            "raygen",
            0,
            &[SceneUniform, CameraUniform, PassUniform, RaysIn, Accum, Counters],
        ),
        (
            "traverse",
            WALK,
            &[SceneUniform, PassUniform, Tris, RaysIn, Hits, Accum, Counters],
        ),
        (
            "occlusion",
            WALK,
            &[SceneUniform, PassUniform, Tris, ShadowRays, Counters],
        ),
        (
            "closest point",
            WALK,
            &[SceneUniform, PassUniform, Tris, RaysIn, Hits, Accum, Counters],
        ),
        (
            "shade",
            0,
            &[
                SceneUniform,
                PassUniform,
                Tris,
                TriShade,
                Materials,
                Lights,
                RaysIn,
                RaysOut,
                Hits,
                ShadowRays,
                Resolve,
                Accum,
                Counters,
            ],
        ),
        (
            "resolve",
            0,
            &[PassUniform, RaysIn, ShadowRays, Resolve, Accum, Counters],
        ),
        (
            "indirect",
            storage_rows(&INDIRECT_BINDINGS),
            &[SceneUniform, PassUniform, Counters],
        ),
        ("pack", storage_rows(&PACK_BINDINGS), &[PassUniform, Accum]),
        (
            "batch",
            storage_rows(&BATCH_BINDINGS),
            &[PassUniform, RaysIn, Hits, ShadowRays],
        ),
        // A walking kernel with the batch's buffers in group 2 (`kernels.rs`).
        (
            "all hits",
            WALK + storage_rows(&BATCH_BINDINGS),
            &[SceneUniform, PassUniform, Tris, RaysIn, Counters],
        ),
        ("prefix sum", storage_rows(&BATCH_BINDINGS), &[PassUniform]),
        (
            "winding",
            storage_rows(&BATCH_BINDINGS) + storage_rows(&WINDING_BINDINGS),
            &[PassUniform, RaysIn, Counters],
        ),
    ]
};

/// `FRAME_USE`'s entry of the kernel `name`.
fn use_of(name: &str) -> Option<&'static (&'static str, usize, &'static [FrameSlot])> {
    FRAME_USE.iter().find(|(n, _, _)| *n == name)
}

/// Group 0's rows of the kernel `name` (in `shaders::KERNELS`), in binding order.
pub fn frame_rows(name: &str) -> Vec<Binding<FrameSlot>> {
    let used = use_of(name).map_or(&[][..], |(_, _, slots)| *slots);
    FRAME_BINDINGS
        .iter()
        .filter(|b| used.contains(&b.slot))
        .copied()
        .collect()
}

/// Storage buffers the kernel `name` binds at once: its group 0's storage rows and its group 1.
pub fn storage_buffers_of(name: &str) -> u32 {
    let group1 = use_of(name).map_or(0, |(_, group1, _)| *group1);
    (storage_rows(&frame_rows(name)) + group1) as u32
}

/// Storage buffers a kernel may bind at once, the most over the kernels: the device must allow
/// this many per shader stage.
pub fn storage_buffers_needed() -> u32 {
    FRAME_USE
        .iter()
        .map(|(name, _, _)| storage_buffers_of(name))
        .max()
        .unwrap_or(0)
}

/// The layout entries of a table (every kernel is a compute kernel).
pub fn layout_entries<S>(table: &[Binding<S>]) -> Vec<wgpu::BindGroupLayoutEntry> {
    table
        .iter()
        .map(|b| wgpu::BindGroupLayoutEntry {
            binding: b.index,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: match b.access {
                    Access::Uniform => wgpu::BufferBindingType::Uniform,
                    Access::StorageRead => wgpu::BufferBindingType::Storage { read_only: true },
                    Access::StorageReadWrite => wgpu::BufferBindingType::Storage { read_only: false },
                },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        })
        .collect()
}

/// The bind group entries of a table: `resource` names the buffer for each slot (a `match` over
/// the slot enum, so a slot without a buffer does not compile).
pub fn group_entries<'a, S: Copy>(
    table: &[Binding<S>],
    resource: impl Fn(S) -> wgpu::BindingResource<'a>,
) -> Vec<wgpu::BindGroupEntry<'a>> {
    table
        .iter()
        .map(|b| wgpu::BindGroupEntry {
            binding: b.index,
            resource: resource(b.slot),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Indices and names are unique within a group (a duplicate would make wgpu reject the
    /// layout, but only on a device).
    #[test]
    fn tables_are_unique() {
        let rows = all();
        // Shading's 10 (tris, their shading, materials, three queues, hits, resolve, accum,
        // counters); traversal's 5 and a structure's 4 (the irregular grid's): within
        // SwiftShader's WebGPU (10), and what desktop and mobile Vulkan, Metal (31 buffers a
        // stage, uniforms included) and D3D12 allow. Group 0 in one layout would be 14.
        assert_eq!(storage_buffers_of("shade"), 10);
        assert_eq!(storage_buffers_of("traverse"), 9);
        assert_eq!(storage_buffers_needed(), 10);
        let all_frame = FRAME_BINDINGS.iter().filter(|b| b.access != Access::Uniform).count();
        assert_eq!(all_frame + STRUCTURE_ARRAYS_MAX, 14);
        // Each list names a slot once (that every kernel has one: tests/gpu_layout.rs).
        for (name, _, slots) in FRAME_USE {
            assert_eq!(frame_rows(name).len(), slots.len(), "{name}");
        }
        // Group 1 is a different table in each kernel that binds one (indirect, pack, a
        // structure's arrays): indices are unique within a table, names across all of them.
        let tables = [
            FRAME_BINDINGS.iter().map(|b| b.index).collect::<Vec<_>>(),
            INDIRECT_BINDINGS.iter().map(|b| b.index).collect(),
            PACK_BINDINGS.iter().map(|b| b.index).collect(),
        ];
        for t in &tables {
            for (i, a) in t.iter().enumerate() {
                assert!(!t[i + 1..].contains(a), "binding {a} twice in a table");
            }
        }
        // The batch's table is bound twice, as group 1 of its own kernels and as group 2 of
        // the all-hits kernels (the same buffers, the same names): counted once here.
        let rows: Vec<_> = rows
            .into_iter()
            .filter(|r| !(r.0 == BATCH_AFTER_WALK_GROUP && BATCH_BINDINGS.iter().any(|b| b.name == r.2)))
            .collect();
        for (i, a) in rows.iter().enumerate() {
            for b in &rows[i + 1..] {
                assert_ne!(a.2, b.2, "name {} twice", a.2);
            }
        }
    }
}
