//! Numbers the kernels and the host must agree on, defined once here. The WGSL side never types
//! them: [`wgsl_prelude`] prints them as `const` declarations that are prepended to every kernel
//! module (see `shaders::module_source`), so a kernel that re-declares one fails to compile, and
//! `tests/gpu_layout.rs` checks naga's values against [`WGSL_CONSTANTS`] bit for bit.

use std::fmt::Write as _;
use std::sync::atomic::{AtomicU32, Ordering};

use super::bvh::{LEAF_BIT, LEAF_COUNT_SHIFT, LEAF_FIRST_MAX, STACK_DONE};
use crate::accel::AccelKind;
use crate::accel::bvh;
use crate::accel::grid::proximity;
use crate::accel::irregular;
use crate::accel::triangle::{BARY_EPS, MAX_SLACK, PARALLEL_COS2, SLACK_PAD, SLACK_ULPS};
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
/// Elements one workgroup of the GPU grid build's scan sums (256 invocations, 4 each); the
/// host sizes the scan's levels by it.
pub const SCAN_BLOCK: u32 = 1024;
/// Cells one triangle may span in the GPU grid build; a grid with a larger triangle is built
/// on the CPU instead. One invocation walks a triangle's cells, and lavapipe (Mesa's llvmpipe)
/// stops an invocation's loops after 65535 iterations in total, silently: measured, a triangle
/// over 64,000 cells got only its first 22,000 or so. A quarter of that budget leaves room;
/// at the automatic resolution only floor-like triangles of million-triangle scenes come near.
pub const MAX_CELLS_PER_TRI: u32 = 16384;
/// Longest line of cells the GPU distance transform takes (about three loop iterations per
/// cell; see `MAX_CELLS_PER_TRI`). The automatic resolution stays under 1024.
pub const MAX_GPU_LINE: u32 = 16384;
/// Cells with more references keep the GPU placing order (insertion sort is quadratic: 256
/// references take at most 32,640 steps, within the budget above).
pub const SORT_MAX_REFS: u32 = 256;
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

/// `PassUniform::accel`: `ACCEL_PC` (1) when the walk jumps over empty space with the
/// proximity cloud, else 0. Only the uniform grid's walk reads it (`grid` and `pc` share one
/// structure and one pipeline); every other structure's kernels are their own.
pub const fn accel_code(accel: AccelKind) -> u32 {
    matches!(accel, AccelKind::ProximityCloud) as u32
}

/// Invocations per workgroup of the grid build's scan kernels (`build/scan.wgsl`'s `partial`
/// array); the other kernels have `WORKGROUP`.
pub const SCAN_GROUP: u32 = 256;
// A scan block is four elements per invocation of a workgroup (`build/scan.wgsl`).
const _: () = assert!(SCAN_BLOCK == 4 * SCAN_GROUP);

/// Entries of the GPU BVH walk's stack: the CPU builder's bound on the tree's depth (`STACK`),
/// so that no tree can overflow it.
pub const BVH_STACK: u32 = bvh::STACK as u32;

/// A constant's value as WGSL will see it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WgslConst {
    U32(u32),
    F32(f32),
}

/// Every constant of the WGSL prelude, by WGSL name. The triangle test's slack constants are
/// `TriAccel::intersect`'s own, so both backends accept the same hits.
pub const WGSL_CONSTANTS: [(&str, WgslConst); 36] = [
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
    ("WORKGROUP", WgslConst::U32(WORKGROUP)),
    ("MAX_GROUPS_X", WgslConst::U32(MAX_GROUPS_X)),
    ("BARY_EPS", WgslConst::F32(BARY_EPS)),
    ("SLACK_ULPS", WgslConst::F32(SLACK_ULPS)),
    ("MAX_SLACK", WgslConst::F32(MAX_SLACK)),
    ("F32_EPSILON", WgslConst::F32(f32::EPSILON)),
    ("PARALLEL_COS2", WgslConst::F32(PARALLEL_COS2)),
    ("BVH_STACK", WgslConst::U32(BVH_STACK)),
    ("LEAF_BIT", WgslConst::U32(LEAF_BIT)),
    ("LEAF_COUNT_SHIFT", WgslConst::U32(LEAF_COUNT_SHIFT)),
    ("LEAF_FIRST_MAX", WgslConst::U32(LEAF_FIRST_MAX)),
    ("STACK_DONE", WgslConst::U32(STACK_DONE)),
    ("DIR_TINY", WgslConst::F32(bvh::DIR_TINY)),
    ("FAR_SCALE", WgslConst::F32(bvh::FAR_SCALE)),
    ("T_SLOP", WgslConst::F32(bvh::T_SLOP)),
    ("IRR_LEVEL_BITS", WgslConst::U32(irregular::LEVEL_BITS)),
    ("IRR_COORD_BITS", WgslConst::U32(irregular::COORD_BITS)),
    ("IRR_COORD_MASK", WgslConst::U32(irregular::COORD_MASK)),
    ("JUMP_CAP", WgslConst::U32(crate::accel::grid::dda::JUMP_CAP)),
    ("SCAN_GROUP", WgslConst::U32(SCAN_GROUP)),
    ("SLACK_PAD", WgslConst::F32(SLACK_PAD)),
    ("SCAN_BLOCK", WgslConst::U32(SCAN_BLOCK)),
    ("DIST_FAR", WgslConst::U32(proximity::FAR)),
    ("MAX_CELLS_PER_TRI", WgslConst::U32(MAX_CELLS_PER_TRI)),
    ("SORT_MAX_REFS", WgslConst::U32(SORT_MAX_REFS)),
];

/// One WGSL literal that denotes exactly `v`: Rust's `{:?}` prints the shortest decimal that
/// parses back to the same f32, and the `f` suffix makes WGSL parse it as an f32 directly (no
/// detour through an abstract float that could round twice).
fn f32_literal(v: f32) -> String {
    assert!(v.is_finite(), "WGSL has no literal for {v}");
    format!("{v:?}f")
}

/// The WGSL declarations of [`WGSL_CONSTANTS`], one `const NAME: type = value;` a line.
pub fn wgsl_prelude() -> String {
    let mut s = String::from("// Generated from src/gpu/constants.rs: do not declare these names in WGSL.\n");
    for (name, value) in WGSL_CONSTANTS {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The printed f32s read back as the same bits (naga's own reading is checked in
    /// tests/gpu_layout.rs).
    #[test]
    fn f32_literals_round_trip() {
        for (name, value) in WGSL_CONSTANTS {
            if let WgslConst::F32(v) = value {
                let text = f32_literal(v);
                let back: f32 = text.trim_end_matches('f').parse().unwrap();
                assert_eq!(back.to_bits(), v.to_bits(), "{name}: {text}");
            }
        }
    }

    #[test]
    fn names_are_unique() {
        let mut names: Vec<&str> = WGSL_CONSTANTS.iter().map(|(n, _)| *n).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), WGSL_CONSTANTS.len());
    }
}
