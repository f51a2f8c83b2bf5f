//! Numbers the kernels and the host must agree on (common.wgsl declares them once more).

use crate::accel::AccelKind;
use crate::render::Mode;

/// Counter slots of the `counters` array (atomic u32s). Slots 0 and 1 are the two ray queues'
/// lengths, alternating as input and output per bounce (the pass uniform says which).
pub const SLOT_QUEUE_A: usize = 0;
/// Shadow queue length, this bounce.
pub const SLOT_SHADOW: usize = 2;
/// Shadow rays emitted over the whole tile (statistics).
pub const SLOT_SHADOW_TOTAL: usize = 3;
/// Reflection rays emitted over the whole tile (statistics).
pub const SLOT_REFLECT_TOTAL: usize = 4;
/// Length of the `counters` array.
pub const COUNTER_SLOTS: usize = 16;

/// Invocations per workgroup of every per-ray kernel (their `@workgroup_size`).
pub const WORKGROUP: u32 = 64;
/// Most workgroups in x of one dispatch; larger dispatches go 2-D (`flat_index` in common.wgsl),
/// which keeps them under WebGPU's 65535 per dimension.
pub const MAX_GROUPS_X: u32 = 32768;
/// `GpuHit::tri` of a miss.
pub const MISS: u32 = u32::MAX;

/// The number `PassUniform::mode` carries for each render mode; the prelude's `MODE_*` names
/// are printed from this same function.
pub const fn mode_code(mode: Mode) -> u32 {
    match mode {
        Mode::Cast => 0,
        Mode::Shadow => 1,
        Mode::Trace => 2,
        Mode::Heat => 3,
    }
}

/// `PassUniform::accel`: 1 walks the proximity clouds (`ACCEL_PC`), 0 the plain grid. The BVH
/// never reaches the GPU (`check_accel`).
pub const fn accel_code(accel: AccelKind) -> u32 {
    match accel {
        AccelKind::ProximityCloud => 1,
        AccelKind::Grid | AccelKind::Bvh => 0,
    }
}
