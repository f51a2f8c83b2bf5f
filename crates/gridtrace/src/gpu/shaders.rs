//! WGSL sources: the shared file and one per kernel. WGSL has no includes, so a kernel's module
//! is the generated constant prelude, then `common.wgsl`, `bvh.wgsl` and `irregular.wgsl`, then
//! the kernel's own file.

use super::constants::wgsl_prelude;

pub const COMMON: &str = include_str!("shaders/common.wgsl");
/// BVH traversal, shared like `COMMON` (the grid's DDA is in `COMMON`).
pub const BVH: &str = include_str!("shaders/bvh.wgsl");
/// The irregular grid's traversal, shared like `COMMON`.
pub const IRREGULAR: &str = include_str!("shaders/irregular.wgsl");
pub const RAYGEN: &str = include_str!("shaders/raygen.wgsl");
pub const TRAVERSE: &str = include_str!("shaders/traverse.wgsl");
pub const OCCLUSION: &str = include_str!("shaders/occlusion.wgsl");
pub const SHADE: &str = include_str!("shaders/shade.wgsl");
pub const RESOLVE: &str = include_str!("shaders/resolve.wgsl");
pub const INDIRECT: &str = include_str!("shaders/indirect.wgsl");
/// Every kernel with its name.
pub const KERNELS: [(&str, &str); 6] = [
    ("raygen", RAYGEN),
    ("traverse", TRAVERSE),
    ("occlusion", OCCLUSION),
    ("shade", SHADE),
    ("resolve", RESOLVE),
    ("indirect", INDIRECT),
];

/// The prelude, `common.wgsl`, `bvh.wgsl` and `irregular.wgsl`: every declaration the kernels
/// share (layout tests parse this).
pub fn common_source() -> String {
    format!("{}\n{}\n{}\n{}", wgsl_prelude(), COMMON, BVH, IRREGULAR)
}

/// The whole module of one kernel, as the device compiles it.
pub fn module_source(kernel: &str) -> String {
    format!("{}\n{}", common_source(), kernel)
}

/// The GPU grid build's shared file and kernels (`grid_build/`): their own bindings, so their
/// modules are the prelude, `build/common.wgsl` and the kernel, without the tracer's files.
pub const BUILD_COMMON: &str = include_str!("shaders/build/common.wgsl");
pub const BUILD_REFS: &str = include_str!("shaders/build/refs.wgsl");
pub const BUILD_SCAN: &str = include_str!("shaders/build/scan.wgsl");
pub const BUILD_SORT: &str = include_str!("shaders/build/sort.wgsl");
pub const BUILD_DISTANCE: &str = include_str!("shaders/build/distance.wgsl");

/// The whole module of one grid-build kernel.
pub fn build_module_source(kernel: &str) -> String {
    format!("{}\n{}\n{}", wgsl_prelude(), BUILD_COMMON, kernel)
}
