//! Numbers the kernels and the host must agree on: the ones every kernel shares, defined once
//! here ([`SHARED`]); each structure's own are beside its walk (`WalkSpec::constants`). The
//! WGSL side never types them: `walks::wgsl_prelude` prints them all (through [`prelude_of`]) as
//! `const` declarations that are prepended to every kernel module (see
//! `shaders::module_source`), so a kernel that re-declares one fails to compile, and
//! `tests/gpu_layout.rs` checks naga's values against `walks::wgsl_constants` bit for bit.

use std::fmt::Write as _;
use std::sync::atomic::{AtomicU32, Ordering};

use crate::accel::AccelKind;
use crate::accel::triangle::PARALLEL_COS2;
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

/// Invocations per workgroup of every per-ray kernel (`@workgroup_size(WORKGROUP)`).
pub const WORKGROUP: u32 = 64;
/// Most workgroups in x of one dispatch; larger dispatches go 2-D (`flat_index` in common.wgsl),
/// which keeps them under WebGPU's 65535 per dimension.
pub const MAX_GROUPS_X: u32 = 32768;

/// The limit in force: `MAX_GROUPS_X` unless a test lowered it (`set_max_groups_x`) to make
/// small dispatches take the 2-D path, which a frame reaches only past 2M rays in one queue.
static GROUPS_X_LIMIT: AtomicU32 = AtomicU32::new(MAX_GROUPS_X);

/// The most workgroups in x of one dispatch, host and WGSL alike (see `GROUPS_X_LIMIT`).
pub fn max_groups_x() -> u32 {
    GROUPS_X_LIMIT.load(Ordering::Relaxed)
}

/// Lowers the 2-D dispatch threshold for the process (1..=`MAX_GROUPS_X`), for kernels
/// compiled after the call. Correct at any value and even while other threads dispatch: the
/// kernels index by the dispatch's own `num_workgroups`, and the limit only decides its shape.
#[doc(hidden)]
pub fn set_max_groups_x(n: u32) {
    GROUPS_X_LIMIT.store(n.clamp(1, MAX_GROUPS_X), Ordering::Relaxed);
}
/// `GpuHit::tri` of a miss.
pub const MISS: u32 = u32::MAX;

/// Lights a GPU frame takes at most: the lights are a uniform array of this length (8 KiB),
/// not a storage buffer, because the shading kernel would otherwise bind 11 storage buffers
/// and WebGPU's adapters give 8 to 10 a stage (`bindings::storage_buffers_needed`). Every light
/// costs each pixel a shadow ray, so a frame past a few dozen is already slow; the CPU tracer
/// has no such limit.
pub const MAX_LIGHTS: u32 = 256;

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

/// `PassUniform::accel`: `ACCEL_PC` (1) when the walk jumps over empty space with the
/// proximity cloud, else 0. Only the uniform grid's walk reads it (`grid` and `pc` share one
/// structure and one pipeline); every other structure's kernels are their own.
pub const fn accel_code(accel: AccelKind) -> u32 {
    matches!(accel, AccelKind::ProximityCloud) as u32
}

/// Workgroups for `n` items, `per_group` to a workgroup, as a 2-D dispatch of at most
/// `MAX_GROUPS_X` (`max_groups_x()`) in x (so under WebGPU's 65535 per dimension).
pub(crate) fn dispatch_groups(n: u32, per_group: u32) -> (u32, u32) {
    let g = n.div_ceil(per_group);
    let x = g.min(max_groups_x());
    (x, if x == 0 { 0 } else { g.div_ceil(x) })
}

/// A constant's value as WGSL will see it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WgslConst {
    U32(u32),
    F32(f32),
}

/// The constants every kernel shares, by WGSL name (each structure's are its
/// `WalkSpec::constants`). The triangle test's slack constants are `TriAccel::intersect`'s own,
/// so both backends accept the same hits.
pub const SHARED: [(&str, WgslConst); 19] = [
    ("SLOT_QUEUE_A", WgslConst::U32(SLOT_QUEUE_A as u32)),
    ("SLOT_SHADOW", WgslConst::U32(SLOT_SHADOW as u32)),
    ("SLOT_SHADOW_TOTAL", WgslConst::U32(SLOT_SHADOW_TOTAL as u32)),
    ("SLOT_REFLECT_TOTAL", WgslConst::U32(SLOT_REFLECT_TOTAL as u32)),
    ("COUNTER_SLOTS", WgslConst::U32(COUNTER_SLOTS as u32)),
    ("MODE_CAST", WgslConst::U32(mode_code(Mode::Cast))),
    ("MODE_SHADOW", WgslConst::U32(mode_code(Mode::Shadow))),
    ("MODE_TRACE", WgslConst::U32(mode_code(Mode::Trace))),
    ("MODE_HEAT", WgslConst::U32(mode_code(Mode::Heat))),
    ("ACCEL_PC", WgslConst::U32(accel_code(AccelKind::ProximityCloud))),
    ("MISS", WgslConst::U32(MISS)),
    ("MAX_LIGHTS", WgslConst::U32(MAX_LIGHTS)),
    ("WORKGROUP", WgslConst::U32(WORKGROUP)),
    ("MAX_GROUPS_X", WgslConst::U32(MAX_GROUPS_X)),
    ("F32_EPSILON", WgslConst::F32(f32::EPSILON)),
    ("PARALLEL_COS2", WgslConst::F32(PARALLEL_COS2)),
    ("WIND_STACK", WgslConst::U32(WIND_STACK)),
    ("WIND_LEAF", WgslConst::U32(crate::accel::winding::DEVICE_LEAF)),
    ("WIND_EMPTY", WgslConst::U32(crate::accel::winding::DEVICE_EMPTY)),
];

/// Entries of the winding kernel's stack (`gpu/winding.rs`): a tree whose walk may need more
/// (`DeviceTree::stack`, eight a level) is refused. 256 holds 32 levels of eight-wide nodes,
/// about 8^32 leaves' worth of a balanced tree; the SAH tree over the Stanford Dragon has 12.
pub const WIND_STACK: u32 = 256;

/// One WGSL literal that denotes exactly `v`: Rust's `{:?}` prints the shortest decimal that
/// parses back to the same f32, and the `f` suffix makes WGSL parse it as an f32 directly (no
/// detour through an abstract float that could round twice).
pub(crate) fn f32_literal(v: f32) -> String {
    assert!(v.is_finite(), "WGSL has no literal for {v}");
    format!("{v:?}f")
}

/// The WGSL declarations of `constants`, one `const NAME: type = value;` a line.
pub fn prelude_of(constants: &[(&str, WgslConst)]) -> String {
    let mut s =
        String::from("// Generated from src/gpu (constants.rs and each walk's): do not declare these names in WGSL.\n");
    for &(name, value) in constants {
        let value = match name {
            "MAX_GROUPS_X" => WgslConst::U32(max_groups_x()),
            _ => value,
        };
        // Writing to a String cannot fail.
        let _ = match value {
            WgslConst::U32(v) => writeln!(s, "const {name}: u32 = {v}u;"),
            WgslConst::F32(v) => writeln!(s, "const {name}: f32 = {};", f32_literal(v)),
        };
    }
    s
}
